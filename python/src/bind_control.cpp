// python/src/bind_control.cpp — trellis::control: trajectories, gain schedules, CARE/DARE and the
// discrete recursion, controllability, TV-LQR (full state and on the constraint manifold) and
// closed-loop simulation.
//
// Lifetimes: RiccatiSolution, TangentBasisTrajectory and ManifoldRiccatiSolution are plain data
// (they keep no reference to the Model); the py::keep_alive on the functions returning them is
// harmless and kept for older results. The unified, plain-data TV-LQR (solveTvlqr) is bound in
// bind_tvlqr.cpp when its header exists.
#include "common.hpp"
#include "control_common.hpp"
#include "options.hpp"

#include "trellis/control/controllability.hpp"
#include "trellis/core/gain_schedule.hpp"
#include "trellis/control/lqr.hpp"
#include "trellis/control/manifold_lqr.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/analysis/simulation.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/core/data.hpp"

#include <algorithm>
#include <atomic>
#include <thread>

namespace trellis::python {

namespace {

/// A weight given as a number (w·I), a 1-D array of n entries (its diagonal) or an n×n matrix.
Eigen::MatrixXd weightMatrix(const py::object& w, Eigen::Index n, const char* name) {
  if (py::isinstance<py::float_>(w) || py::isinstance<py::int_>(w)) {
    return w.cast<double>() * Eigen::MatrixXd::Identity(n, n);
  }
  const auto a = py::array_t<double, py::array::forcecast>::ensure(w);
  if (!a) throw std::invalid_argument(std::string(name) + ": expected a number or a float array");
  if (a.ndim() == 0) return a.data()[0] * Eigen::MatrixXd::Identity(n, n);  // NumPy scalar
  if (a.ndim() == 1) {
    checkSize(a.shape(0), n, name, "diagonal entries");
    Eigen::VectorXd d(n);
    for (Eigen::Index i = 0; i < n; ++i) d(i) = a.at(i);
    return d.asDiagonal();
  }
  if (a.ndim() == 2 && a.shape(0) == n && a.shape(1) == n) {
    Eigen::MatrixXd W(n, n);
    for (Eigen::Index i = 0; i < n; ++i) {
      for (Eigen::Index j = 0; j < n; ++j) W(i, j) = a.at(i, j);
    }
    return W;
  }
  throw std::invalid_argument(std::string(name) + ": expected a number, " + std::to_string(n) +
                              " diagonal entries or a " + std::to_string(n) + "x" +
                              std::to_string(n) + " matrix");
}

/// Gains as one (N, m, nx) array → the vector the C++ takes.
std::vector<Eigen::MatrixXd> gainsFromArray(const py::array_t<double, py::array::forcecast>& g) {
  if (g.ndim() != 3) {
    throw std::invalid_argument("gains: expected an array of shape (N, nu, nx), got " +
                                std::to_string(g.ndim()) + " dimensions");
  }
  std::vector<Eigen::MatrixXd> gains(g.shape(0), Eigen::MatrixXd(g.shape(1), g.shape(2)));
  auto r = g.unchecked<3>();
  for (py::ssize_t k = 0; k < g.shape(0); ++k) {
    for (py::ssize_t i = 0; i < g.shape(1); ++i) {
      for (py::ssize_t j = 0; j < g.shape(2); ++j) gains[k](i, j) = r(k, i, j);
    }
  }
  return gains;
}

/// Runs f with the GIL released (the long solves).
template <class F>
auto withoutGil(F&& f) {
  py::gil_scoped_release release;
  return f();
}

/// A Python policy u = policy(t, x) as the C++ Policy; called with the GIL held. A Python error
/// becomes a C++ exception with its message (the simulator reports it as POLICY_FAILURE).
/// The std::function holds a pointer to the caller's py::function (alive for the whole call), so
/// copies made by the simulator without the GIL never touch a Python reference count.
/// A KeyboardInterrupt (Ctrl-C while the policy runs) sets *interrupted: the caller raises it
/// again after the simulation stops, instead of a POLICY_FAILURE status the script would go past.
Policy pythonPolicy(const py::function& policy, Eigen::Index nu, std::atomic<bool>* interrupted) {
  return [fn = &policy, nu, interrupted](double t, const Eigen::VectorXd& x, Eigen::VectorXd& u) {
    py::gil_scoped_acquire acquire;
    try {
      const auto result = py::array_t<double, py::array::forcecast>::ensure((*fn)(t, toArray(x)));
      if (!result || result.ndim() > 1 || result.size() != nu) {
        throw std::runtime_error("policy: expected " + std::to_string(nu) + " inputs");
      }
      for (Eigen::Index i = 0; i < nu; ++i) u(i) = result.data()[i];
    } catch (py::error_already_set& e) {
      if (e.matches(PyExc_KeyboardInterrupt)) interrupted->store(true);
      throw std::runtime_error(std::string("policy raised ") + e.what());
    }
  };
}

}  // namespace

LqrWeights makeWeights(const py::object& Q, const py::object& R, const py::object& Qf,
                       Eigen::Index nx, Eigen::Index nu) {
  LqrWeights w;
  w.Q = weightMatrix(Q, nx, "Q");
  w.R = weightMatrix(R, nu, "R");
  w.Qf = Qf.is_none() ? w.Q : weightMatrix(Qf, nx, "Qf");
  return w;
}

void bindControl(py::module_& m) {
  // ---- Trajectory ----------------------------------------------------------------------------
  py::class_<Trajectory>(m, "Trajectory",
      "A nominal trajectory: knot times (N,), states x = [q; dq] (nx, N) — column k is the state "
      "at t_k, the layout of scipy's solve_ivp — and inputs u (nu, N). Between knots the state is "
      "a cubic Hermite spline (knot derivatives [dq; qdd] from the dynamics) and the input is "
      "piecewise linear, or the cubic Hermite spline through (u_k, du_k) when input derivatives are set. "
      "CSV layout: t, <configs>, d<configs>, <inputs>[, rate_<inputs>].")
      .def(py::init<std::vector<std::string>, std::vector<std::string>, Eigen::VectorXd,
                    Eigen::MatrixXd, Eigen::MatrixXd>(),
           py::arg("config_names"), py::arg("input_names"), py::arg("times"), py::arg("states"),
           py::arg("inputs"),
           "times (N,) strictly increasing; states (2n, N); inputs (m, N). Raises TrajectoryError.")
      .def_static("for_model",
                  [](const Model& model, Eigen::VectorXd times, Eigen::MatrixXd states,
                     std::optional<Eigen::MatrixXd> inputs) {
                    Eigen::MatrixXd u = inputs ? *inputs : Eigen::MatrixXd::Zero(model.nu(), times.size());
                    return Trajectory(model.configNames(), model.inputNames(), std::move(times),
                                      std::move(states), std::move(u));
                  },
                  py::arg("model"), py::arg("times"), py::arg("states"), py::arg("inputs") = py::none(),
                  "A trajectory with the model's names; inputs default to zeros (nu, N).")
      .def_static("read_csv", &Trajectory::readCsvFile, py::arg("path"),
                  "Reads the CSV layout; raises TrajectoryError naming row and column.")
      .def("write_csv", &Trajectory::writeCsvFile, py::arg("path"),
           "Writes the CSV layout with 17 significant digits (exact round trip).")
      .def_property_readonly("nq", &Trajectory::nq)
      .def_property_readonly("nx", &Trajectory::nx)
      .def_property_readonly("nu", &Trajectory::nu)
      .def("__len__", &Trajectory::size)
      .def_property_readonly("start_time", &Trajectory::startTime)
      .def_property_readonly("end_time", &Trajectory::endTime)
      .def_property_readonly("times", [](const Trajectory& t) { return toArray(t.times()); }, "(N,)")
      .def_property_readonly("states", [](const Trajectory& t) { return toArray(t.states()); }, "(nx, N)")
      .def_property_readonly("inputs", [](const Trajectory& t) { return toArray(t.inputs()); }, "(nu, N)")
      .def_property_readonly("config_names", &Trajectory::configNames)
      .def_property_readonly("input_names", &Trajectory::inputNames)
      .def_property_readonly("has_state_derivatives", &Trajectory::hasStateDerivatives)
      .def_property_readonly("state_derivatives", [](const Trajectory& t) -> py::object {
            if (!t.hasStateDerivatives()) return py::none();
            return toArray(t.stateDerivatives());
          }, "(nx, N) or None")
      .def("check_compatible", &Trajectory::checkCompatible, py::arg("model"),
           "Raises TrajectoryError unless the names equal the model's, in order.")
      .def("compute_state_derivatives",
           [](Trajectory& t, const Model& model) {
             Data data(model);
             t.computeStateDerivatives(model, data);
           },
           py::arg("model"), "[dq; qdd] at every knot from the forward dynamics.")
      .def("set_state_derivatives", &Trajectory::setStateDerivatives, py::arg("state_derivatives"),
           "(nx, N)")
      .def("set_input_derivatives", &Trajectory::setInputDerivatives, py::arg("input_derivatives"),
           "(nu, N): the input becomes the cubic Hermite spline through (u_k, du_k).")
      .def("clear_input_derivatives", &Trajectory::clearInputDerivatives, "Back to the linear input rule.")
      .def_property_readonly("has_input_derivatives", &Trajectory::hasInputDerivatives)
      .def_property_readonly("input_derivatives", [](const Trajectory& t) -> py::object {
            if (!t.hasInputDerivatives()) return py::none();
            return toArray(t.inputDerivatives());
          }, "(nu, N) or None")
      .def("evaluate",
           [](const Trajectory& tr, double t) {
             Eigen::VectorXd x, u;
             tr.evaluate(t, x, u);
             return py::make_tuple(toArray(x), toArray(u));
           },
           py::arg("t"), "(x (nx,), u (nu,)) at time t; needs state derivatives.")
      .def("sample",
           [](const Trajectory& tr, const Eigen::VectorXd& times) {
             Eigen::MatrixXd X(tr.nx(), times.size()), U(tr.nu(), times.size());
             Eigen::VectorXd x(tr.nx()), u(tr.nu());
             for (Eigen::Index k = 0; k < times.size(); ++k) {
               tr.evaluate(times(k), x, u);
               X.col(k) = x;
               U.col(k) = u;
             }
             return py::make_tuple(toArray(X), toArray(U));
           },
           py::arg("times"), "(X (nx, K), U (nu, K)) at K times.")
      .def("__repr__", [](const Trajectory& t) {
        return "<trellis_mech.Trajectory: " + std::to_string(t.size()) + " knots, nx=" +
               std::to_string(t.nx()) + ", nu=" + std::to_string(t.nu()) + ">";
      });

  // ---- GainSchedule --------------------------------------------------------------------------
  py::class_<GainSchedule>(m, "GainSchedule",
      "Feedback gains K(t) (nu, nx) at ascending times, linear in between; u = u_ref - K (x - x_ref). "
      "As arrays: times (N,), gains (N, nu, nx). CSV: t, K_i_j (row-major).")
      .def(py::init([](Eigen::VectorXd times, const py::array_t<double, py::array::forcecast>& gains) {
             return GainSchedule(std::move(times), gainsFromArray(gains));
           }),
           py::arg("times"), py::arg("gains"),
           "times (N,) strictly increasing; gains (N, nu, nx). Raises TrajectoryError.")
      .def_static("read_csv", &GainSchedule::readCsvFile, py::arg("path"))
      .def("write_csv", &GainSchedule::writeCsvFile, py::arg("path"))
      .def_static("sample",
                  [](const py::function& gain, const Eigen::VectorXd& times) {
                    return GainSchedule::sample(
                        [&](double t) { return gain(t).cast<Eigen::MatrixXd>(); }, times);
                  },
                  py::arg("gain"), py::arg("times"),
                  "Samples a Python function K(t) -> (nu, nx) at the times.")
      .def_property_readonly("nu", &GainSchedule::nu)
      .def_property_readonly("nx", &GainSchedule::nx)
      .def("__len__", &GainSchedule::size)
      .def_property_readonly("start_time", &GainSchedule::startTime)
      .def_property_readonly("end_time", &GainSchedule::endTime)
      .def_property_readonly("times", [](const GainSchedule& g) { return toArray(g.times()); })
      .def_property_readonly("gains", [](const GainSchedule& g) {
            return toArray3(g.gains(), g.nu(), g.nx());
          }, "(N, nu, nx)")
      .def("evaluate", [](const GainSchedule& g, double t) { return toArray(g.evaluate(t)); },
           py::arg("t"), "K(t) (nu, nx) by linear interpolation")
      .def("__repr__", [](const GainSchedule& g) {
        return "<trellis_mech.GainSchedule: " + std::to_string(g.size()) + " times, K " +
               std::to_string(g.nu()) + "x" + std::to_string(g.nx()) + ">";
      });

  // ---- CARE / DARE ---------------------------------------------------------------------------
  py::enum_<LqrStatus>(m, "LqrStatus")
      .value("OK", LqrStatus::kOk)
      .value("NOT_STABILIZABLE", LqrStatus::kNotStabilizable)
      .value("NO_STABILIZING_SOLUTION", LqrStatus::kNoStabilizingSolution)
      .value("NO_CONVERGENCE", LqrStatus::kNoConvergence);

  py::class_<CareOptions>(m, "CareOptions", "Options of solve_care / solve_dare (keywords).")
      .def(py::init(&makeFromKwargs<CareOptions>))
      .def_readwrite("max_iterations", &CareOptions::maxIterations)
      .def_readwrite("tolerance", &CareOptions::tolerance)
      .def_readwrite("refinement_steps", &CareOptions::refinementSteps)
      .def_readwrite("residual_tolerance", &CareOptions::residualTolerance)
      .def_readwrite("stabilizability_tolerance", &CareOptions::stabilizabilityTolerance);

  py::class_<LqrResult>(m, "LqrResult",
      "S (nx, nx), K (nu, nx), status (LqrStatus) and message, residual, iterations, "
      "closed_loop_eigenvalues (complex, of A - BK or Ad - Bd K).")
      .def_readonly("status", &LqrResult::status)
      .def_readonly("message", &LqrResult::message)
      .def_property_readonly("S", [](const LqrResult& r) { return toArray(r.S); })
      .def_property_readonly("K", [](const LqrResult& r) { return toArray(r.K); })
      .def_readonly("residual", &LqrResult::residual)
      .def_readonly("iterations", &LqrResult::iterations)
      .def_property_readonly("closed_loop_eigenvalues",
                             [](const LqrResult& r) { return toArrayComplex(r.closedLoopEigenvalues); })
      .def_property_readonly("ok", &LqrResult::ok)
      .def("__repr__", [](const LqrResult& r) {
        return std::string("<LqrResult ") + toString(r.status) +
               (r.message.empty() ? "" : ": " + r.message) + ">";
      });

  m.def("solve_care",
        [](const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
           const Eigen::MatrixXd& R, const std::optional<CareOptions>& options) {
          return withoutGil([&] { return solveCare(A, B, Q, R, options.value_or(CareOptions{})); });
        },
        py::arg("A"), py::arg("B"), py::arg("Q"), py::arg("R"), py::kw_only(),
        py::arg("options") = py::none(),
        "Continuous algebraic Riccati equation A^T S + S A - S B R^-1 B^T S + Q = 0 (A (nx, nx), "
        "B (nx, nu), Q (nx, nx) PSD, R (nu, nu) PD); K = R^-1 B^T S. Bad sizes or weights raise "
        "ValueError; numerical failure and non-stabilizability are the result's status.");
  m.def("solve_dare",
        [](const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
           const Eigen::MatrixXd& R, const std::optional<CareOptions>& options) {
          return withoutGil([&] { return solveDare(A, B, Q, R, options.value_or(CareOptions{})); });
        },
        py::arg("Ad"), py::arg("Bd"), py::arg("Q"), py::arg("R"), py::kw_only(),
        py::arg("options") = py::none(),
        "Discrete algebraic Riccati equation S = Ad^T S Ad - Ad^T S Bd (R + Bd^T S Bd)^-1 Bd^T S Ad + Q; "
        "K = (R + Bd^T S Bd)^-1 Bd^T S Ad.");
  m.def("solve_lyapunov",
        [](const Eigen::MatrixXd& F, const Eigen::MatrixXd& C) {
          // The library returns a singular equation as a status; Python keeps raising it.
          MatrixEquationSolution sol = solveLyapunov(F, C);
          if (!sol.ok()) throw std::runtime_error(sol.status.message);
          return sol.X;
        },
        py::arg("F"), py::arg("C"),
        "X with F^T X + X F + C = 0 (Bartels-Stewart); raises NumericalError when singular.");
  m.def("discretize_zero_order_hold",
        [](const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, double h) {
          const DiscreteSystem s = discretizeZeroOrderHold(A, B, h);
          // e^(A h) overflows for a large step (|λ| h beyond ~709): an error, never NaN arrays.
          if (!s.Ad.allFinite() || !s.Bd.allFinite()) {
            throw std::runtime_error("discretize_zero_order_hold: e^(A h) is not finite at h = " + std::to_string(h) +
                                     " (the step is too large for this A: |eigenvalue| * h overflows)");
          }
          return py::make_tuple(toArray(s.Ad), toArray(s.Bd));
        },
        py::arg("A"), py::arg("B"), py::arg("h"),
        "(Ad, Bd): Ad = e^(A h), Bd = int_0^h e^(A s) ds B (exact zero-order hold). Raises "
        "NumericalError when the exponential overflows (a step too large for A).");
  m.def("solve_discrete_riccati_recursion",
        [](const Eigen::MatrixXd& Ad, const Eigen::MatrixXd& Bd, const Eigen::MatrixXd& Q,
           const Eigen::MatrixXd& R, const Eigen::MatrixXd& Qf, int N) {
          const DiscreteRiccatiRecursion r =
              withoutGil([&] { return solveDiscreteRiccatiRecursion(Ad, Bd, Q, R, Qf, N); });
          return py::make_tuple(toArray3(r.S, Ad.rows(), Ad.cols()),
                                toArray3(r.K, Bd.cols(), Ad.cols()));
        },
        py::arg("Ad"), py::arg("Bd"), py::arg("Q"), py::arg("R"), py::arg("Qf"), py::arg("N"),
        "Finite-horizon discrete LQR over N steps: (S (N+1, nx, nx), K (N, nu, nx)) with S_N = Qf, "
        "K_k = (R + Bd^T S_{k+1} Bd)^-1 Bd^T S_{k+1} Ad, S_k = Q + Ad^T S_{k+1} (Ad - Bd K_k).");

  // ---- Controllability -----------------------------------------------------------------------
  py::class_<ControllabilityReport>(m, "ControllabilityReport",
      "Rank of the scaled Krylov matrix [B, (A/a) B, ..., (A/a)^(d-1) B] against d.")
      .def_readonly("dimension", &ControllabilityReport::dimension)
      .def_readonly("rank", &ControllabilityReport::rank)
      .def_readonly("smallest_singular_value", &ControllabilityReport::smallestSingularValue)
      .def_readonly("largest_singular_value", &ControllabilityReport::largestSingularValue)
      .def_readonly("scale", &ControllabilityReport::scale)
      .def_property_readonly("singular_values",
                             [](const ControllabilityReport& r) { return toArray(r.singularValues); })
      .def_readonly("ok", &ControllabilityReport::ok)
      .def_readonly("message", &ControllabilityReport::message)
      .def_property_readonly("controllable", &ControllabilityReport::controllable)
      .def("__repr__", [](const ControllabilityReport& r) {
        return "<ControllabilityReport rank " + std::to_string(r.rank) + " of " +
               std::to_string(r.dimension) + (r.controllable() ? " (controllable)>" : ">");
      });
  m.def("compute_controllability", &computeControllability, py::arg("A"), py::arg("B"),
        py::arg("relative_tolerance") = 1e-10, "Controllability of (A (d, d), B (d, nu)).");
  m.def("compute_controllability_at",
        [](const Model& model, PyData& d, const VectorRef& q, const VectorRef& dq,
           const VectorRef& u, double tol) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadVector(q, d.q, "q", "model.nq");
          loadVector(dq, d.dq, "dq", "model.nq");
          loadVector(u, d.u, "u", "model.nu");
          return computeControllabilityAt(model, d.data, d.q, d.dq, d.u, tol);
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"), py::arg("u"),
        py::arg("relative_tolerance") = 1e-10,
        "Linearization at x = [q; dq], u, reduced to the constraint tangent space, then its "
        "controllability. Raises NumericalError if the dynamics fail there.");
  m.def("controllability_at_knots",
        [](const Model& model, const Trajectory& t, double tol) {
          return withoutGil([&] { return controllabilityAtKnots(model, t, tol); });
        },
        py::arg("model"), py::arg("trajectory"), py::arg("relative_tolerance") = 1e-10,
        "compute_controllability_at every knot (a failing knot: ok False and a message).");

  py::class_<GramianReport>(m, "GramianReport",
      "Reduced reachability Gramian W (d, d) over [t0, t1] on the transported tangent basis.")
      .def_property_readonly("W", [](const GramianReport& r) { return toArray(r.W); })
      .def_readonly("min_eigenvalue", &GramianReport::minEigenvalue)
      .def_readonly("max_eigenvalue", &GramianReport::maxEigenvalue)
      .def_readonly("ok", &GramianReport::ok)
      .def_readonly("message", &GramianReport::message)
      .def_readonly("dimension", &GramianReport::dimension)
      .def("controllable", &GramianReport::controllable, py::arg("relative_tolerance") = 1e-10);

  // ---- Riccati (TV-LQR) ----------------------------------------------------------------------
  py::enum_<RiccatiMethod>(m, "RiccatiMethod")
      .value("BDF", RiccatiMethod::kBDF)
      .value("ADAMS", RiccatiMethod::kAdams)
      .value("FACTORED", RiccatiMethod::kFactored);
  py::enum_<RiccatiLinearSolver>(m, "RiccatiLinearSolver")
      .value("AUTO", RiccatiLinearSolver::kAuto)
      .value("DENSE", RiccatiLinearSolver::kDense)
      .value("KRYLOV", RiccatiLinearSolver::kKrylov)
      .value("LYAPUNOV", RiccatiLinearSolver::kLyapunov);
  py::enum_<RiccatiStatus>(m, "RiccatiStatus")
      .value("OK", RiccatiStatus::kOk)
      .value("INTEGRATOR_FAILURE", RiccatiStatus::kIntegratorFailure)
      .value("NON_FINITE", RiccatiStatus::kNonFinite)
      .value("BLOW_UP", RiccatiStatus::kBlowUp)
      .value("CALLBACK_FAILURE", RiccatiStatus::kCallbackFailure)
      .value("INDEFINITE", RiccatiStatus::kIndefinite);
  py::enum_<TangentTransport>(m, "TangentTransport")
      .value("INTEGRATED", TangentTransport::kIntegrated)
      .value("PROJECTED", TangentTransport::kProjected);

  py::class_<RiccatiOptions>(m, "RiccatiOptions", "Options of the Riccati integration (keywords).")
      .def(py::init(&makeFromKwargs<RiccatiOptions>))
      .def_readwrite("rtol", &RiccatiOptions::rtol)
      .def_readwrite("atol", &RiccatiOptions::atol)
      .def_readwrite("method", &RiccatiOptions::method)
      .def_readwrite("max_steps", &RiccatiOptions::maxSteps)
      .def_readwrite("max_norm", &RiccatiOptions::maxNorm)
      .def_readwrite("initial_step", &RiccatiOptions::initialStep)
      .def_readwrite("max_step", &RiccatiOptions::maxStep)
      .def_readwrite("linear_solver", &RiccatiOptions::linearSolver)
      .def_readwrite("exact_jacobian", &RiccatiOptions::exactJacobian)
      .def_readwrite("track_eigenvalues", &RiccatiOptions::trackEigenvalues)
      .def_readwrite("krylov_preconditioner", &RiccatiOptions::krylovPreconditioner)
      .def_readwrite("factored_qf_shift", &RiccatiOptions::factoredQfShift)
      .def("validate", &RiccatiOptions::validate);

  py::class_<TangentTransportOptions>(m, "TangentTransportOptions",
      "How the tangent basis T(t) is carried along the reference (keywords).")
      .def(py::init(&makeFromKwargs<TangentTransportOptions>))
      .def_readwrite("method", &TangentTransportOptions::method)
      .def_readwrite("substeps", &TangentTransportOptions::substeps)
      .def_readwrite("rtol", &TangentTransportOptions::rtol)
      .def_readwrite("atol", &TangentTransportOptions::atol)
      .def_readwrite("max_steps", &TangentTransportOptions::maxSteps);

  m.def("compute_controllability_gramian",
        [](const Model& model, const Trajectory& reference, std::optional<double> t0,
           std::optional<double> t1, const std::optional<TangentTransportOptions>& transport) {
          return withoutGil([&] {
            return computeControllabilityGramian(model, reference, t0.value_or(reference.startTime()),
                                                 t1.value_or(reference.endTime()),
                                                 transport.value_or(TangentTransportOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::arg("t0") = py::none(), py::arg("t1") = py::none(),
        py::kw_only(), py::arg("transport") = py::none(),
        "Reduced reachability Gramian W(t0, t1) = int Phi_r(t1, s) Br Br^T Phi_r^T ds (d, d) along "
        "the reference (default: its whole span); numerical failure is in ok / message.");

  py::class_<RiccatiSolution>(m, "RiccatiSolution",
      "The TV-LQR solution: S(t) (nx, nx) from -dS/dt = A^T S + S A - S B R^-1 B^T S + Q, "
      "S(T) = Qf, and K(t) = R^-1 B(t)^T S(t) (nu, nx). Keeps its model alive. K and S are not "
      "thread safe (they share one workspace).")
      .def_readonly("status", &RiccatiSolution::status)
      .def_readonly("message", &RiccatiSolution::message)
      .def_readonly("failure_time", &RiccatiSolution::failureTime)
      .def_readonly("failure_norm", &RiccatiSolution::failureNorm)
      .def_readonly("steps", &RiccatiSolution::steps)
      .def_readonly("rhs_evaluations", &RiccatiSolution::rhsEvaluations)
      .def_readonly("jacobian_evaluations", &RiccatiSolution::jacobianEvaluations)
      .def_readonly("linear_iterations", &RiccatiSolution::linearIterations)
      .def_readonly("preconditioner_solves", &RiccatiSolution::preconditionerSolves)
      .def_readonly("min_eigenvalue", &RiccatiSolution::minEigenvalue)
      .def_readonly("max_eigenvalue", &RiccatiSolution::maxEigenvalue)
      .def_property_readonly("ok", &RiccatiSolution::ok)
      .def_property_readonly("nx", &RiccatiSolution::nx)
      .def_property_readonly("nu", &RiccatiSolution::nu)
      .def_property_readonly("start_time", &RiccatiSolution::startTime)
      .def_property_readonly("end_time", &RiccatiSolution::endTime)
      .def_property_readonly("valid_from", &RiccatiSolution::validFrom)
      .def_property_readonly("step_times", &RiccatiSolution::stepTimes)
      .def("S", [](const RiccatiSolution& s, double t) { return toArray(s.S(t)); }, py::arg("t"))
      .def("K", [](const RiccatiSolution& s, double t) { return toArray(s.K(t)); }, py::arg("t"))
      .def("gain_schedule",
           [](const RiccatiSolution& s, const Eigen::VectorXd& times) {
             return GainSchedule::sample([&](double t) { return s.K(t); }, times);
           },
           py::arg("times"), "K sampled at the times, as a GainSchedule.")
      .def("__repr__", [](const RiccatiSolution& s) {
        return std::string("<RiccatiSolution ") + toString(s.status) +
               (s.message.empty() ? "" : ": " + s.message) + ", " + std::to_string(s.steps) +
               " steps>";
      });

  py::class_<TangentBasisTrajectory>(m, "TangentBasisTrajectory",
      "T(t) (nx, d): an orthonormal basis of the constraint manifold's tangent space, transported "
      "along the reference. Keeps its model alive.")
      .def_property_readonly("dimension", &TangentBasisTrajectory::dimension)
      .def_property_readonly("nx", &TangentBasisTrajectory::nx)
      .def_property_readonly("ok", &TangentBasisTrajectory::ok)
      .def_property_readonly("message", &TangentBasisTrajectory::message)
      .def_property_readonly("valid_until", &TangentBasisTrajectory::validUntil)
      .def_property_readonly("steps", &TangentBasisTrajectory::steps)
      .def_property_readonly("max_correction", &TangentBasisTrajectory::maxCorrection)
      .def("basis", [](const TangentBasisTrajectory& b, double t) { return toArray(b.basis(t)); },
           py::arg("t"), "T(t) (nx, d)")
      .def("reduced_linearization",
           [](const TangentBasisTrajectory& b, const Model& model, double t) {
             Eigen::MatrixXd T, Ar, Br;
             b.reducedLinearization(model, t, T, Ar, Br);
             return py::make_tuple(toArray(T), toArray(Ar), toArray(Br));
           },
           py::arg("model"), py::arg("t"),
           "(T (nx, d), Ar = T^T A T (d, d), Br = T^T B (d, nu)) at t, with T corrected onto the "
           "exact tangent space of the model at x_ref(t)");
  m.def("transport_tangent_basis",
        [](const Model& model, const Trajectory& reference,
           const std::optional<TangentTransportOptions>& options) {
          return withoutGil([&] {
            return transportTangentBasis(model, reference, options.value_or(TangentTransportOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::kw_only(), py::arg("options") = py::none(),
        py::keep_alive<0, 1>(), "T(t) along the reference (which needs state derivatives).");

  py::class_<ManifoldRiccatiSolution>(m, "ManifoldRiccatiSolution",
      "TV-LQR on the constraint manifold: `reduced` (RiccatiSolution on z, d states) and `basis` "
      "(T(t)); K(t) = Kr(t) T(t)^T (nu, nx), S(t) = T Sr T^T. Keeps its model alive.")
      .def_readonly("reduced", &ManifoldRiccatiSolution::reduced)
      .def_readonly("basis", &ManifoldRiccatiSolution::basis)
      .def_property_readonly("ok", &ManifoldRiccatiSolution::ok)
      .def_property_readonly("message", &ManifoldRiccatiSolution::message)
      .def_property_readonly("nx", &ManifoldRiccatiSolution::nx)
      .def_property_readonly("dimension", &ManifoldRiccatiSolution::dimension)
      .def("S", [](const ManifoldRiccatiSolution& s, double t) { return toArray(s.S(t)); }, py::arg("t"))
      .def("K", [](const ManifoldRiccatiSolution& s, double t) { return toArray(s.K(t)); }, py::arg("t"))
      .def("gain_schedule",
           [](const ManifoldRiccatiSolution& s, const Eigen::VectorXd& times) {
             return GainSchedule::sample([&](double t) { return s.K(t); }, times);
           },
           py::arg("times"), "K sampled at the times, as a GainSchedule.")
      .def("__repr__", [](const ManifoldRiccatiSolution& s) {
        return std::string("<ManifoldRiccatiSolution ") + (s.ok() ? "ok" : "FAILED: " + s.message()) +
               ", d=" + std::to_string(s.dimension()) + ">";
      });

  m.def("solve_riccati",
        [](const Model& model, const Trajectory& reference, const py::object& Q, const py::object& R,
           const py::object& Qf, const std::optional<RiccatiOptions>& options) {
          const LqrWeights w = makeWeights(Q, R, Qf, 2 * model.nq(), model.nu());
          return withoutGil([&] {
            return solveRiccati(model, reference, w, options.value_or(RiccatiOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::kw_only(), py::arg("Q"), py::arg("R"),
        py::arg("Qf") = py::none(), py::arg("options") = py::none(), py::keep_alive<0, 1>(),
        "Full-state TV-LQR along the reference (state derivatives needed): minimizes "
        "J = int dx^T Q dx + du^T R du dt + dx(T)^T Qf dx(T) for dxdot = A(t) dx + B(t) du. "
        "Weights: a number (times I), a diagonal (1-D) or a matrix; Qf defaults to Q. For a model "
        "with constraints use solve_manifold_riccati. Numerical failure is the status.");
  m.def("solve_manifold_riccati",
        [](const Model& model, const Trajectory& reference, const py::object& Q, const py::object& R,
           const py::object& Qf, const std::optional<RiccatiOptions>& options,
           const std::optional<TangentTransportOptions>& transport) {
          const LqrWeights w = makeWeights(Q, R, Qf, 2 * model.nq(), model.nu());
          return withoutGil([&] {
            return solveManifoldRiccati(model, reference, w, options.value_or(RiccatiOptions{}),
                                        transport.value_or(TangentTransportOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::kw_only(), py::arg("Q"), py::arg("R"),
        py::arg("Qf") = py::none(), py::arg("options") = py::none(),
        py::arg("transport") = py::none(), py::keep_alive<0, 1>(),
        "TV-LQR on the constraint manifold: full-state weights reduced with T(t), Riccati on "
        "z = T^T dx (d states); K(t) = Kr T^T. Numerical failure is in ok / message.");

  // ---- Simulation ----------------------------------------------------------------------------
  py::enum_<ConstraintHandling>(m, "ConstraintHandling")
      .value("NONE", ConstraintHandling::kNone)
      .value("PROJECT", ConstraintHandling::kProject);
  py::enum_<IntegrationMethod>(m, "IntegrationMethod")
      .value("ADAMS", IntegrationMethod::kAdams)
      .value("BDF", IntegrationMethod::kBDF);
  py::enum_<SimulationStatus>(m, "SimulationStatus")
      .value("OK", SimulationStatus::kOk)
      .value("INTEGRATOR_FAILURE", SimulationStatus::kIntegratorFailure)
      .value("DYNAMICS_FAILURE", SimulationStatus::kDynamicsFailure)
      .value("NON_FINITE", SimulationStatus::kNonFinite)
      .value("POLICY_FAILURE", SimulationStatus::kPolicyFailure)
      .value("CONSTRAINT_DRIFT", SimulationStatus::kConstraintDrift);

  py::class_<SimulationOptions>(m, "SimulationOptions",
      "Options of the CVODES simulation (keywords): rtol, atol, max_steps, sample_rate (0: "
      "continuous feedback; f > 0: sampled at f Hz with zero-order hold), input_lower / "
      "input_upper (nu,) box, output_step, constraints (ConstraintHandling), method, max_step, "
      "breakpoints, projection_iterations, drift_tolerance (0: 10 (atol + rtol); projection above "
      "it), exact_jacobian (BDF: exact A - B S K, else difference quotients).")
      .def(py::init(&makeFromKwargs<SimulationOptions>))
      .def_readwrite("rtol", &SimulationOptions::rtol)
      .def_readwrite("atol", &SimulationOptions::atol)
      .def_readwrite("max_steps", &SimulationOptions::maxSteps)
      .def_readwrite("sample_rate", &SimulationOptions::sampleRate)
      .def_readwrite("input_lower", &SimulationOptions::inputLower)
      .def_readwrite("input_upper", &SimulationOptions::inputUpper)
      .def_readwrite("output_step", &SimulationOptions::outputStep)
      .def_readwrite("constraints", &SimulationOptions::constraints)
      .def_readwrite("method", &SimulationOptions::method)
      .def_readwrite("max_step", &SimulationOptions::maxStep)
      .def_readwrite("breakpoints", &SimulationOptions::breakpoints)
      .def_readwrite("projection_iterations", &SimulationOptions::projectionIterations)
      .def_readwrite("drift_tolerance", &SimulationOptions::driftTolerance)
      .def_readwrite("exact_jacobian", &SimulationOptions::exactJacobian)
      .def("validate", &SimulationOptions::validate);

  py::class_<SimulationResult>(m, "SimulationResult",
      "The simulated trajectory (x, applied u at the output times) with status and diagnostics.")
      .def_readonly("status", &SimulationResult::status)
      .def_readonly("message", &SimulationResult::message)
      .def_readonly("failure_time", &SimulationResult::failureTime)
      .def_property_readonly("failure_state",
                             [](const SimulationResult& r) { return toArray(r.failureState); })
      .def_readonly("trajectory", &SimulationResult::trajectory)
      .def_property_readonly("tracking_error",
                             [](const SimulationResult& r) { return toArray(r.trackingError); },
                             "|x(t_k) - x_ref(t_k)| per output time")
      .def_property_readonly("constraint_drift",
                             [](const SimulationResult& r) { return toArray(r.constraintDrift); })
      .def_readonly("max_constraint_drift", &SimulationResult::maxConstraintDrift)
      .def_readonly("saturated_samples", &SimulationResult::saturatedSamples)
      .def_readonly("control_samples", &SimulationResult::controlSamples)
      .def_readonly("saturated_fraction", &SimulationResult::saturatedFraction)
      .def_readonly("steps", &SimulationResult::steps)
      .def_readonly("rhs_evaluations", &SimulationResult::rhsEvaluations)
      .def_readonly("linear_rhs_evaluations", &SimulationResult::linearRhsEvaluations,
                    "right-hand sides spent on difference-quotient Jacobians (0 with exact ones)")
      .def_readonly("jacobian_evaluations", &SimulationResult::jacobianEvaluations)
      .def_readonly("restarts", &SimulationResult::restarts)
      .def_readonly("projections", &SimulationResult::projections)
      .def_property_readonly("ok", &SimulationResult::ok)
      .def("__repr__", [](const SimulationResult& r) {
        return std::string("<SimulationResult ") + toString(r.status) +
               (r.message.empty() ? "" : ": " + r.message) + ", " +
               std::to_string(r.trajectory.size()) + " points>";
      });

  m.def("simulate",
        [](const Model& model, const VectorRef& x0, double t0, double t1, const py::function& policy,
           const std::optional<SimulationOptions>& options, const Trajectory* reference) {
          const Eigen::VectorXd x = x0;
          std::atomic<bool> interrupted{false};
          const Policy p = pythonPolicy(policy, model.nu(), &interrupted);
          auto result = withoutGil([&] {
            return trellis::simulate(model, x, t0, t1, p, options.value_or(SimulationOptions{}),
                                     reference);
          });
          if (interrupted.load()) {
            PyErr_SetNone(PyExc_KeyboardInterrupt);
            throw py::error_already_set();
          }
          return result;
        },
        py::arg("model"), py::arg("x0"), py::arg("t0"), py::arg("t1"), py::arg("policy"),
        py::kw_only(), py::arg("options") = py::none(), py::arg("reference") = py::none(),
        "xdot = [dq; qdd(q, dq, sat(u))] from x(t0) = x0 (nx,) to t1 with u = policy(t, x) (a "
        "Python callable returning (nu,)); an exception in the policy is status POLICY_FAILURE.");
  m.def("simulate_closed_loop",
        [](const Model& model, const Trajectory& reference, const GainSchedule& gains,
           const VectorRef& x0, const std::optional<SimulationOptions>& options) {
          const Eigen::VectorXd x = x0;
          return withoutGil([&] {
            return simulateClosedLoop(model, reference, gains, x, options.value_or(SimulationOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::arg("gains"), py::arg("x0"), py::kw_only(),
        py::arg("options") = py::none(),
        "u = u_ref(t) - K(t) (x - x_ref(t)) over the reference's span from x0 (nx,).");
  m.def("simulate_closed_loop_many",
        [](const Model& model, const Trajectory& reference, const GainSchedule& gains,
           const Eigen::MatrixXd& x0s, const std::optional<SimulationOptions>& options, int threads) {
          checkSize(x0s.cols(), 2 * model.nq(), "x0s columns", "model.nx");
          std::vector<Eigen::VectorXd> starts;
          for (Eigen::Index k = 0; k < x0s.rows(); ++k) starts.push_back(x0s.row(k).transpose());
          const SimulationOptions opts = options.value_or(SimulationOptions{});
          std::vector<SimulationResult> results;
          {
            py::gil_scoped_release release;
            results = simulateBatch(model, reference, gains, starts, opts, threads);
          }
          return results;
        },
        py::arg("model"), py::arg("reference"), py::arg("gains"), py::arg("x0s"), py::kw_only(),
        py::arg("options") = py::none(), py::arg("threads") = 0,
        "simulate_closed_loop from each row of x0s (K, nx), on `threads` threads (0: one per "
        "core) without the GIL; returns K SimulationResults in order.");
  m.def("simulate_open_loop",
        [](const Model& model, const Trajectory& reference, const VectorRef& x0,
           const std::optional<SimulationOptions>& options) {
          const Eigen::VectorXd x = x0;
          return withoutGil([&] {
            return simulateOpenLoop(model, reference, x, options.value_or(SimulationOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::arg("x0"), py::kw_only(),
        py::arg("options") = py::none(), "u = u_ref(t) over the reference's span.");

  py::class_<ConstraintProjection>(m, "ConstraintProjection")
      .def_readonly("drift_before", &ConstraintProjection::driftBefore)
      .def_readonly("drift_after", &ConstraintProjection::driftAfter)
      .def_readonly("iterations", &ConstraintProjection::iterations);
  m.def("project_onto_constraints",
        [](const Model& model, const VectorRef& x, int maxIterations) {
          Eigen::VectorXd y = x;
          const ConstraintProjection p = projectOntoConstraints(model, y, maxIterations);
          return py::make_tuple(toArray(y), p);
        },
        py::arg("model"), py::arg("x"), py::arg("max_iterations") = 10,
        "(x projected onto h(q) = 0, A(q) dq = 0 in the mass-matrix metric, ConstraintProjection).");
}

}  // namespace trellis::python
