// python/src/bind_core.cpp — trellis::core: Model, ModelBuilder, scenes, Data, and the algorithms
// (kinematics, mass matrix, constraints, dynamics, linearization, tangent basis, energy).
#include "common.hpp"

#include "trellis/core/dynamics.hpp"
#include "trellis/core/kinematics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model_builder.hpp"
#include "trellis/core/scene.hpp"

#include <algorithm>
#include <chrono>

namespace trellis::python {

namespace {

/// Python's Scene: the model shared (Data, problems and solutions keep it alive) and the state.
struct PyScene {
  ModelPtr model;
  Eigen::VectorXd q, dq, u;
  std::string name, description;
  Eigen::VectorXd lowerLimit, upperLimit, effortLimit;  // a URDF's <limit>s; empty without one
  std::vector<std::string> warnings;                    // what was read but not modelled
};

PyScene toPyScene(Scene&& s) {
  return PyScene{std::make_shared<Model>(std::move(s.model)), std::move(s.q), std::move(s.dq),
                 std::move(s.u), std::move(s.name), std::move(s.description),
                 std::move(s.lowerLimit), std::move(s.upperLimit), std::move(s.effortLimit),
                 std::move(s.warnings)};
}

std::vector<std::string> frameNames(const Model& model) {
  std::vector<std::string> names;
  names.reserve(model.frames().size());
  for (const FramePlacement& f : model.frames()) names.push_back(f.name);
  return names;
}

std::vector<std::string> constraintNames(const Model& model) {
  std::vector<std::string> names;
  for (const Constraint& c : model.constraints()) names.push_back(c.name);
  return names;
}

/// Name lookups raise KeyError (a missing name is a missing key), with the C++ message.
template <class F>
int lookup(F&& f) {
  try {
    return f();
  } catch (const std::out_of_range& e) {
    throw py::key_error(e.what());
  }
}

void loadState(PyData& d, const VectorRef& q, const VectorRef& dq) {
  loadVector(q, d.q, "q", "model.nq");
  loadVector(dq, d.dq, "dq", "model.nq");
}
void loadState(PyData& d, const VectorRef& q, const VectorRef& dq, const VectorRef& u) {
  loadState(d, q, dq);
  loadVector(u, d.u, "u", "model.nu");
}

const char* kStateArgs =
    "\n\nArguments: q, dq (nq,) and u (nu,), any float array-like (copied into the Data's "
    "buffers; no allocation).";

}  // namespace

void bindCore(py::module_& m) {
  // ---- Model ---------------------------------------------------------------------------------
  py::class_<Model, ModelPtr>(m, "Model",
      "The validated, immutable description of a mechanical system (a tree of frames with masses, "
      "forces, potentials and constraints). Made by load_scene / parse_scene or "
      "ModelBuilder.finalize(); it cannot be changed. State x = [q; dq] (nx = 2 nq), inputs u (nu).")
      .def_property_readonly("name", &Model::name)
      .def_property_readonly("nq", &Model::nq, "number of configuration variables n")
      .def_property_readonly("nx", [](const Model& mo) { return 2 * mo.nq(); }, "state size 2n")
      .def_property_readonly("nu", &Model::nu, "number of inputs m")
      .def_property_readonly("nc", &Model::nc, "number of constraint rows")
      .def_property_readonly("nholonomic", &Model::nholonomic, "rows of h(q) = 0")
      .def_property_readonly("nframes", &Model::nframes)
      .def_property_readonly("config_names", &Model::configNames,
                             "configuration variable names, in the order of q")
      .def_property_readonly("input_names", &Model::inputNames, "input names, in the order of u")
      .def_property_readonly("frame_names", &frameNames)
      .def_property_readonly("constraint_names", &constraintNames, "one per constraint row")
      .def_property_readonly("state_names", [](const Model& mo) {
            std::vector<std::string> names = mo.configNames();
            for (const std::string& c : mo.configNames()) names.push_back("d" + c);
            return names;
          }, "names of x = [q; dq]: the configuration names, then 'd' + each")
      .def_property_readonly("gravity", [](const Model& mo) { return toArray(mo.gravity()); })
      .def_property_readonly("damping", [](const Model& mo) { return toArray(mo.damping()); },
                             "viscous damping coefficient per configuration (nq,)")
      .def("config_index", [](const Model& mo, const std::string& n) {
            return lookup([&] { return mo.configIndex(n); }); }, py::arg("name"),
           "index of a configuration variable in q; KeyError if absent")
      .def("input_index", [](const Model& mo, const std::string& n) {
            return lookup([&] { return mo.inputIndex(n); }); }, py::arg("name"))
      .def("frame_index", [](const Model& mo, const std::string& n) {
            return lookup([&] { return mo.frameIndex(n); }); }, py::arg("name"))
      .def("__repr__", [](const Model& mo) {
        return "<trellis_mech.Model '" + mo.name() + "': nq=" + std::to_string(mo.nq()) +
               ", nu=" + std::to_string(mo.nu()) + ", nc=" + std::to_string(mo.nc()) + ">";
      });

  // ---- Scene ---------------------------------------------------------------------------------
  py::class_<PyScene>(m, "Scene", "A model and the state stored in its scene file.")
      .def_readonly("model", &PyScene::model)
      .def_property_readonly("q", [](const PyScene& s) { return toArray(s.q); }, "(nq,)")
      .def_property_readonly("dq", [](const PyScene& s) { return toArray(s.dq); }, "(nq,)")
      .def_property_readonly("u", [](const PyScene& s) { return toArray(s.u); }, "(nu,)")
      .def_property_readonly("x", [](const PyScene& s) {
            Eigen::VectorXd x(2 * s.q.size());
            x << s.q, s.dq;
            return toArray(x);
          }, "[q; dq] (nx,)")
      .def_readonly("name", &PyScene::name)
      .def_readonly("description", &PyScene::description)
      .def_property_readonly("lower_limit", [](const PyScene& s) { return toArray(s.lowerLimit); },
                             "(nq,) a URDF's <limit lower> per configuration [rad or m], -inf where "
                             "none; empty without a URDF (not enforced by the dynamics)")
      .def_property_readonly("upper_limit", [](const PyScene& s) { return toArray(s.upperLimit); },
                             "(nq,) a URDF's <limit upper>, +inf where none; empty without a URDF")
      .def_property_readonly("effort_limit", [](const PyScene& s) { return toArray(s.effortLimit); },
                             "(nq,) a URDF's <limit effort> [N m or N], +inf where none; empty "
                             "without a URDF")
      .def_readonly("warnings", &PyScene::warnings,
                    "What was read but not modelled (e.g. URDF friction dropped by "
                    "ignore_friction), one line each naming file, line and value")
      .def("__repr__", [](const PyScene& s) { return "<trellis_mech.Scene '" + s.name + "'>"; });

  m.def("load_scene", [](const std::string& path) { return toPyScene(loadScene(path)); },
        py::arg("path"),
        "Reads a scene file (JSON, docs/scene_format.md). Raises ModelError (a ValueError) naming "
        "the element, field and value, also when the file cannot be read.");
  m.def("parse_scene",
        [](const std::string& text, const std::string& source) {
          return toPyScene(parseScene(text, source));
        },
        py::arg("text"), py::arg("source") = "<scene>",
        "Parses a scene from JSON text; `source` names it in messages. Raises ModelError.");

  // ---- Builder -------------------------------------------------------------------------------
  py::class_<Transform>(m, "Transform",
      "A frame's local transform to its parent: tx/ty/tz/rx/ry/rz with a constant value (float) or "
      "driven by a configuration variable (str, its name), or const_se3(4x4 matrix).")
      .def_static("tx", py::overload_cast<std::string>(&Transform::tx), py::arg("config"))
      .def_static("tx", py::overload_cast<double>(&Transform::tx), py::arg("value"))
      .def_static("ty", py::overload_cast<std::string>(&Transform::ty), py::arg("config"))
      .def_static("ty", py::overload_cast<double>(&Transform::ty), py::arg("value"))
      .def_static("tz", py::overload_cast<std::string>(&Transform::tz), py::arg("config"))
      .def_static("tz", py::overload_cast<double>(&Transform::tz), py::arg("value"))
      .def_static("rx", py::overload_cast<std::string>(&Transform::rx), py::arg("config"))
      .def_static("rx", py::overload_cast<double>(&Transform::rx), py::arg("angle"))
      .def_static("ry", py::overload_cast<std::string>(&Transform::ry), py::arg("config"))
      .def_static("ry", py::overload_cast<double>(&Transform::ry), py::arg("angle"))
      .def_static("rz", py::overload_cast<std::string>(&Transform::rz), py::arg("config"))
      .def_static("rz", py::overload_cast<double>(&Transform::rz), py::arg("angle"))
      .def_static("const_se3", &Transform::constSE3, py::arg("matrix"))
      .def_readonly("config", &Transform::config)
      .def_readonly("value", &Transform::value)
      .def_property_readonly("is_driven", &Transform::isDriven)
      .def("evaluate", [](const Transform& t, double q) { return toArray(t.evaluate(q).matrix()); },
           py::arg("q") = 0.0, "the 4x4 homogeneous matrix at coordinate value q");

  py::class_<Mass>(m, "Mass",
      "A point mass m at a frame's origin with rotational inertia (3x3, frame axes, about that point).")
      .def(py::init([](double mass, const Eigen::Matrix3d& inertia) {
             Mass ms;
             ms.m = mass;
             ms.inertia = inertia;
             return ms;
           }),
           py::arg("m"), py::arg("inertia") = Eigen::Matrix3d::Zero().eval())
      .def_readonly("m", &Mass::m)
      .def_property_readonly("inertia", [](const Mass& ms) { return toArray(ms.inertia); });

  py::class_<ModelBuilder>(m, "ModelBuilder",
      "Builds and validates a Model: every add_* checks its arguments at once and raises ModelError "
      "(a ValueError) naming the element, field and value; finalize() checks cross references.")
      .def(py::init<>())
      .def(py::init<std::string>(), py::arg("name"))
      .def("add_frame", &ModelBuilder::addFrame, py::arg("name"), py::arg("parent"),
           py::arg("transform"), py::arg("mass") = std::optional<Mass>{},
           "Adds frame `name` under `parent` ('world' or an earlier frame); returns the name.")
      .def("add_gravity", &ModelBuilder::addGravity, py::arg("g"), "g: (3,) acceleration")
      .def("add_linear_spring", &ModelBuilder::addLinearSpring, py::arg("frame1"),
           py::arg("frame2"), py::arg("k"), py::arg("x0"),
           "V = 1/2 k (|p1 - p2| - x0)^2 between two frame origins")
      .def("add_config_spring", &ModelBuilder::addConfigSpring, py::arg("config"), py::arg("k"),
           py::arg("q0"), "V = 1/2 k (q_i - q0)^2")
      .def("add_config_force", &ModelBuilder::addConfigForce, py::arg("config"), py::arg("input"),
           "Q[config] += u[input] (the input is created on first use)")
      .def("add_damping", &ModelBuilder::addDamping, py::arg("default_coefficient"),
           py::arg("coefficients") = std::map<std::string, double>{},
           "Q_i -= c_i dq_i with c_i = coefficients[config] if listed, else default_coefficient")
      .def("add_body_wrench", &ModelBuilder::addBodyWrench, py::arg("frame"), py::arg("wrench"),
           "wrench: 6 entries [fx, fy, fz, tx, ty, tz] in the frame's axes, each a float "
           "(constant) or a str (input name)")
      .def("add_tendon", &ModelBuilder::addTendon, py::arg("path"), py::arg("input"),
           "A cable through the origins of `path` (>= 2 frames) with tension u[input]")
      .def("add_distance_constraint", &ModelBuilder::addDistanceConstraint, py::arg("frame1"),
           py::arg("frame2"), py::arg("distance"), "h = |p1 - p2|^2 - d^2")
      .def("add_point_constraint", &ModelBuilder::addPointConstraint, py::arg("frame1"),
           py::arg("frame2"), py::arg("axis"), "h = (p1 - p2) . e_axis (axis 0, 1, 2: world x, y, z)")
      .def("add_point_on_plane_constraint", &ModelBuilder::addPointOnPlaneConstraint,
           py::arg("plane_frame"), py::arg("normal"), py::arg("point_frame"))
      .def("add_knife_edge_constraint", &ModelBuilder::addKnifeEdgeConstraint, py::arg("frame"),
           py::arg("axis"), "nonholonomic: the velocity of the frame origin along its axis is 0")
      .def("add_coordinate_coupling", &ModelBuilder::addCoordinateCoupling, py::arg("follower"),
           py::arg("leader"), py::arg("multiplier"), py::arg("offset") = 0.0,
           "h = q_follower - multiplier * q_leader - offset (a URDF <mimic>)")
      .def("finalize",
           [](const ModelBuilder& b) { return std::make_shared<Model>(b.finalize()); },
           "Validates cross references and returns the immutable Model (the builder stays usable).");

  // ---- Data and results ----------------------------------------------------------------------
  py::class_<DynamicsStatus>(m, "DynamicsStatus",
      "Outcome of a KKT solve [M A^T; A 0] (the Status shape of every result): code (str: ok, "
      "redundant_constraints, singular_mass_matrix, singular_constraints, non_finite), message, t, "
      "index, ok (qdd and the linearization are valid and determined), constraint_rank, "
      "constraint_conditioning; describe() and json() are the library's reports.")
      .def_property_readonly("code", [](const DynamicsStatus& s) { return std::string(s.name()); })
      .def_readonly("message", &DynamicsStatus::message)
      .def_readonly("t", &DynamicsStatus::t)
      .def_readonly("index", &DynamicsStatus::index)
      .def_readonly("constraint_rank", &DynamicsStatus::constraintRank)
      .def_readonly("constraint_conditioning", &DynamicsStatus::constraintConditioning)
      .def_property_readonly("ok", &DynamicsStatus::ok)
      .def("describe", &DynamicsStatus::describe)
      .def("json", &DynamicsStatus::json)
      .def("__repr__", [](const DynamicsStatus& s) { return "<DynamicsStatus " + s.describe() + ">"; });

  py::class_<Energy>(m, "Energy")
      .def_readonly("kinetic", &Energy::kinetic)
      .def_readonly("potential", &Energy::potential)
      .def_property_readonly("total", &Energy::total);

  using D = PyData;
  auto vec = [](Eigen::VectorXd Data::*member) {
    return [member](const D& d) { return toArray(d.data.*member); };
  };
  auto mat = [](Eigen::MatrixXd Data::*member) {
    return [member](const D& d) { return toArray(d.data.*member); };
  };
  py::class_<D>(m, "Data",
      "The preallocated workspace of a model: every compute_* function writes its results here "
      "and reuses its buffers (one Data per thread; a Data in use by another thread raises). The "
      "properties return copies (fresh arrays) of the latest results.")
      // none(false): Data(None) is a TypeError naming the signature, not a null model dereferenced.
      .def(py::init<ModelPtr>(), py::arg("model").none(false))
      .def_readonly("model", &D::model)
      .def_property_readonly("M", mat(&Data::M), "mass matrix (nq, nq)")
      .def_property_readonly("bias", vec(&Data::bias), "ID(q, dq, 0) - Q (nq,)")
      .def_property_readonly("qdd", vec(&Data::qdd), "forward dynamics qdd (nq,)")
      .def_property_readonly("lambda_", vec(&Data::lambda),
                             "constraint forces (nc,): M qdd = ... + A^T lambda")
      .def_property_readonly("constraint_value", vec(&Data::constraintValue), "h(q) (nc,)")
      .def_property_readonly("constraint_jacobian", mat(&Data::constraintJacobian), "A(q) (nc, nq)")
      .def_property_readonly("constraint_drift", vec(&Data::constraintDrift), "dA/dt dq (nc,)")
      .def_property_readonly("input_matrix", mat(&Data::inputMatrix), "dQ/du (nq, nu)")
      .def_property_readonly("A", mat(&Data::A), "dxdot/dx (nx, nx), x = [q; dq]")
      .def_property_readonly("B", mat(&Data::B), "dxdot/du (nx, nu)")
      .def_property_readonly("dqdd_dq", mat(&Data::dqdd_dq), "(nq, nq)")
      .def_property_readonly("dqdd_ddq", mat(&Data::dqdd_ddq), "(nq, nq)")
      .def_property_readonly("dqdd_du", mat(&Data::dqdd_du), "(nq, nu)")
      .def_property_readonly("dlambda_dx", mat(&Data::dlambda_dx), "dlambda/d[q; dq; u] (nc, nx+nu)")
      .def_property_readonly("tangent_basis", mat(&Data::tangentBasis),
                             "orthonormal basis T (nx, d) of the constraint manifold's tangent space")
      .def_property_readonly("reduced_A", mat(&Data::reducedA), "T^T A T (d, d)")
      .def_property_readonly("reduced_B", mat(&Data::reducedB), "T^T B (d, nu)")
      .def_property_readonly("status", [](const D& d) { return d.data.status; })
      .def_property_readonly("frame_poses", [](const D& d) {
            std::vector<py::array_t<double>> poses;
            for (const auto& g : d.data.framePose) poses.push_back(toArray(g.matrix()));
            return poses;
          }, "world pose of every frame (list of 4x4), after compute_kinematics")
      .def_property_readonly("frame_velocities", [](const D& d) {
            Eigen::MatrixXd v(d.data.frameVelocity.size(), 6);
            for (std::size_t i = 0; i < d.data.frameVelocity.size(); ++i) {
              v.row(static_cast<Eigen::Index>(i)) = d.data.frameVelocity[i].transpose();
            }
            return toArray(v);
          }, "body velocity [v_b, w_b] of every frame (nframes, 6), after compute_kinematics");

  // ---- Algorithms ----------------------------------------------------------------------------
  m.def("compute_kinematics",
        [](const Model& model, D& d, const RealVector<"q">& q, const RealVector<"dq">& dq) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadState(d, q, dq);
          computeKinematics(model, d.data, d.q, d.dq);
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"),
        "World pose and body velocity of every frame: data.frame_poses, data.frame_velocities.");
  m.def("compute_mass_matrix",
        [](const Model& model, D& d, const RealVector<"q">& q) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadVector(q, d.q, "q", "model.nq");
          computeMassMatrix(model, d.data, d.q);
          return toArray(d.data.M);
        },
        py::arg("model"), py::arg("data"), py::arg("q"),
        "M(q) (nq, nq), symmetric positive semidefinite (also in data.M).");
  m.def("compute_constraints",
        [](const Model& model, D& d, const RealVector<"q">& q, const RealVector<"dq">& dq) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadState(d, q, dq);
          computeConstraints(model, d.data, d.q, d.dq);
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"),
        "data.constraint_value h(q) (nc,), data.constraint_jacobian A(q) (nc, nq), "
        "data.constraint_drift dA/dt dq (nc,).");
  m.def("compute_input_matrix",
        [](const Model& model, D& d, const RealVector<"q">& q) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadVector(q, d.q, "q", "model.nq");
          computeInputMatrix(model, d.data, d.q);
          return toArray(d.data.inputMatrix);
        },
        py::arg("model"), py::arg("data"), py::arg("q"), "dQ/du (nq, nu) at q.");

  m.def("compute_dynamics",
        [](const Model& model, D& d, const RealVector<"q">& q, const RealVector<"dq">& dq, const RealVector<"u">& u,
           std::optional<py::array> qddOut, std::optional<py::array> lambdaOut) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadState(d, q, dq, u);
          std::optional<StridedMap> qddMap, lambdaMap;
          if (qddOut) qddMap.emplace(outputMap(*qddOut, model.nq(), -1, "qdd"));
          if (lambdaOut) lambdaMap.emplace(outputMap(*lambdaOut, model.nc(), -1, "lambda_"));
          {
            py::gil_scoped_release release;
            computeDynamics(model, d.data, d.q, d.dq, d.u);
          }
          if (qddMap) *qddMap = d.data.qdd;
          if (lambdaMap) *lambdaMap = d.data.lambda;
          return d.data.status;
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"), py::arg("u"),
        py::kw_only(), py::arg("qdd") = py::none(), py::arg("lambda_") = py::none(),
        (std::string(
             "Forward dynamics: solves [M A^T; A 0] [qdd; -lambda] = [Q - b; -dA/dt dq]. Results in "
             "data (qdd (nq,), lambda_ (nc,), M, bias, constraint terms) and, when given, written "
             "into the float64 arrays `qdd` (nq,) and `lambda_` (nc,) of any memory order. Returns "
             "the DynamicsStatus: a numerical failure is a status, not an exception.") +
         kStateArgs).c_str());

  m.def("compute_linearization",
        [](const Model& model, D& d, const RealVector<"q">& q, const RealVector<"dq">& dq, const RealVector<"u">& u,
           std::optional<py::array> aOut, std::optional<py::array> bOut) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadState(d, q, dq, u);
          const Eigen::Index nx = 2 * model.nq();
          std::optional<StridedMap> aMap, bMap;
          if (aOut) aMap.emplace(outputMap(*aOut, nx, nx, "A"));
          if (bOut) bMap.emplace(outputMap(*bOut, nx, model.nu(), "B"));
          {
            py::gil_scoped_release release;
            computeLinearization(model, d.data, d.q, d.dq, d.u);
          }
          if (aMap) *aMap = d.data.A;
          if (bMap) *bMap = d.data.B;
          return d.data.status;
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"), py::arg("u"),
        py::kw_only(), py::arg("A") = py::none(), py::arg("B") = py::none(),
        (std::string(
             "Exact linearization of xdot = [dq; qdd(q, dq, u)]: data.A = [[0, I], [dqdd/dq, "
             "dqdd/ddq]] (nx, nx), data.B = [[0], [dqdd/du]] (nx, nu), the blocks dqdd_dq, "
             "dqdd_ddq, dqdd_du, dlambda_dx, and everything compute_dynamics gives. When given, "
             "A and B are written into the caller's float64 arrays (nx, nx), (nx, nu) in any "
             "memory order (the hot-loop form: no allocation). Returns the DynamicsStatus; A, B "
             "are valid when status.ok.") +
         kStateArgs).c_str());

  m.def("compute_constraint_tangent_basis",
        [](const Model& model, D& d) {
          checkSameModel(model, d);
          DataGuard guard(d);
          return computeConstraintTangentBasis(model, d.data);
        },
        py::arg("model"), py::arg("data"),
        "Orthonormal basis T (nx, d) of the tangent space of {h(q) = 0, A(q) dq = 0} at the state "
        "of the last compute_linearization (data.tangent_basis), and data.reduced_A = T^T A T "
        "(d, d), data.reduced_B = T^T B (d, nu). Returns d = nx - rank(dPhi/dx); T = I without "
        "constraints.");

  m.def("compute_energy",
        [](const Model& model, D& d, const RealVector<"q">& q, const RealVector<"dq">& dq) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadState(d, q, dq);
          return computeEnergy(model, d.data, d.q, d.dq);
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"),
        "Kinetic energy 1/2 dq^T M dq and potential energy (gravity, springs).");
  m.def("compute_non_conservative_power",
        [](const Model& model, D& d, const RealVector<"q">& q, const RealVector<"dq">& dq, const RealVector<"u">& u) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadState(d, q, dq, u);
          return computeNonConservativePower(model, d.data, d.q, d.dq, d.u);
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"), py::arg("u"),
        "Q_nc^T dq: power of inputs, damping, wrenches and tendons.");

  // For python/bench_overhead.py: the C++ time of the same call, in this process — `repeats`
  // calls of computeLinearization in a C++ loop (GIL released), seconds per call.
  m.def("_time_linearization_loop",
        [](const Model& model, D& d, const RealVector<"q">& q, const RealVector<"dq">& dq, const RealVector<"u">& u,
           int repeats) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadState(d, q, dq, u);
          py::gil_scoped_release release;
          const auto start = std::chrono::steady_clock::now();
          for (int i = 0; i < repeats; ++i) computeLinearization(model, d.data, d.q, d.dq, d.u);
          return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() /
                 std::max(repeats, 1);
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"), py::arg("u"),
        py::arg("repeats"));
}

}  // namespace trellis::python
