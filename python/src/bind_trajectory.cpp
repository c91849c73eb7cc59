// python/src/bind_trajectory.cpp — core/trajectory.hpp and core/gain_schedule.hpp: a nominal
// trajectory and a tabulated gain K(t), as NumPy arrays with time first (the package's one axis
// rule: arrays of samples are shaped (N, ...), row k at time t_k).
#include "common.hpp"
#include "control_common.hpp"

#include "trellis/core/gain_schedule.hpp"
#include "trellis/core/trajectory.hpp"

#include <optional>
#include <string>
#include <vector>

namespace trellis::python {

namespace {

/// (N, cols) from Python (time first) → the C++ layout (cols, N); complex is refused.
Eigen::MatrixXd timeFirst(const py::object& a, const char* name, Eigen::Index cols, const char* colsName) {
  refuseComplex(a, name, "a real (float64) array (N, ...)");
  const auto arr = py::array_t<double, py::array::forcecast>::ensure(a);
  if (!arr || arr.ndim() != 2 || arr.shape(1) != cols) {
    std::string got = arr ? std::to_string(arr.ndim()) + "-D" : std::string("not an array");
    if (arr && arr.ndim() == 2) got = "(" + std::to_string(arr.shape(0)) + ", " + std::to_string(arr.shape(1)) + ")";
    throw std::invalid_argument(std::string(name) + ": expected shape (N, " + std::to_string(cols) + ") (time first, " +
                                colsName + " columns), got " + got);
  }
  Eigen::MatrixXd out(cols, arr.shape(0));
  auto r = arr.unchecked<2>();
  for (py::ssize_t k = 0; k < arr.shape(0); ++k) {
    for (py::ssize_t i = 0; i < cols; ++i) out(i, k) = r(k, i);
  }
  return out;
}

/// The C++ (rows, N) → a fresh (N, rows) array.
py::array_t<double> timeFirstArray(const Eigen::MatrixXd& m) { return toArray(Eigen::MatrixXd(m.transpose())); }

Trajectory makeTrajectory(std::vector<std::string> configs, std::vector<std::string> inputs,
                          const RealVector<"times">& times, const py::object& states, const py::object& us) {
  const Eigen::Index nx = 2 * static_cast<Eigen::Index>(configs.size());
  const Eigen::Index nu = static_cast<Eigen::Index>(inputs.size());
  Eigen::MatrixXd X = timeFirst(states, "states", nx, "nx = 2 nq");
  Eigen::MatrixXd U = us.is_none() ? Eigen::MatrixXd::Zero(nu, times.size()) : timeFirst(us, "inputs", nu, "nu");
  return Trajectory(std::move(configs), std::move(inputs), Eigen::VectorXd(times.ref), std::move(X), std::move(U));
}

}  // namespace

void bindTrajectory(py::module_& m) {
  py::class_<Trajectory>(m, "Trajectory",
      "A nominal trajectory: knot times (N,), states x = [q; dq] (N, nx) — row k is the state at "
      "t_k — and inputs u (N, nu). Between knots the state is a cubic Hermite spline (knot "
      "derivatives [dq; qdd] from the dynamics) and the input is piecewise linear, or the cubic "
      "Hermite spline through (u_k, du_k) when input derivatives are set. CSV layout: t, "
      "<configs>, d<configs>, <inputs>[, rate_<inputs>].")
      .def(py::init(&makeTrajectory), py::arg("config_names"), py::arg("input_names"), py::arg("times"),
           py::arg("states"), py::arg("inputs") = py::none(),
           "times (N,) strictly increasing; states (N, nx); inputs (N, nu) (default zeros). Raises "
           "TrajectoryError.")
      .def_static("for_model",
                  [](const Model& model, const RealVector<"times">& times, const py::object& states,
                     const py::object& inputs) {
                    return makeTrajectory(model.configNames(), model.inputNames(), times, states, inputs);
                  },
                  py::arg("model"), py::arg("times"), py::arg("states"), py::arg("inputs") = py::none(),
                  "A trajectory with the model's names: states (N, nx), inputs (N, nu) (default zeros).")
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
      .def_property_readonly("states", [](const Trajectory& t) { return timeFirstArray(t.states()); }, "(N, nx)")
      .def_property_readonly("inputs", [](const Trajectory& t) { return timeFirstArray(t.inputs()); }, "(N, nu)")
      .def_property_readonly("config_names", &Trajectory::configNames)
      .def_property_readonly("input_names", &Trajectory::inputNames)
      .def_property_readonly("has_state_derivatives", &Trajectory::hasStateDerivatives)
      .def_property_readonly("state_derivatives", [](const Trajectory& t) -> py::object {
            if (!t.hasStateDerivatives()) return py::none();
            return timeFirstArray(t.stateDerivatives());
          }, "(N, nx) or None")
      .def("check_compatible", &Trajectory::checkCompatible, py::arg("model"),
           "Raises TrajectoryError unless the names equal the model's, in order.")
      .def("compute_state_derivatives",
           [](Trajectory& t, const Model& model) {
             Data data(model);
             t.computeStateDerivatives(model, data);
           },
           py::arg("model"), "[dq; qdd] at every knot from the forward dynamics.")
      .def("set_state_derivatives",
           [](Trajectory& t, const py::object& d) { t.setStateDerivatives(timeFirst(d, "state_derivatives", t.nx(), "nx")); },
           py::arg("state_derivatives"), "(N, nx)")
      .def("set_input_derivatives",
           [](Trajectory& t, const py::object& d) { t.setInputDerivatives(timeFirst(d, "input_derivatives", t.nu(), "nu")); },
           py::arg("input_derivatives"), "(N, nu): the input becomes the cubic Hermite spline through (u_k, du_k).")
      .def("clear_input_derivatives", &Trajectory::clearInputDerivatives, "Back to the linear input rule.")
      .def_property_readonly("has_input_derivatives", &Trajectory::hasInputDerivatives)
      .def_property_readonly("input_derivatives", [](const Trajectory& t) -> py::object {
            if (!t.hasInputDerivatives()) return py::none();
            return timeFirstArray(t.inputDerivatives());
          }, "(N, nu) or None")
      .def("evaluate",
           [](const Trajectory& tr, double t) {
             Eigen::VectorXd x, u;
             tr.evaluate(t, x, u);
             return py::make_tuple(toArray(x), toArray(u));
           },
           py::arg("t"), "(x (nx,), u (nu,)) at time t; needs state derivatives.")
      .def("sample",
           [](const Trajectory& tr, const RealVector<"times">& timesArg) {
             const VectorRef& times = timesArg;
             Eigen::MatrixXd X(times.size(), tr.nx()), U(times.size(), tr.nu());
             Eigen::VectorXd x(tr.nx()), u(tr.nu());
             for (Eigen::Index k = 0; k < times.size(); ++k) {
               tr.evaluate(times(k), x, u);
               X.row(k) = x.transpose();
               U.row(k) = u.transpose();
             }
             return py::make_tuple(toArray(X), toArray(U));
           },
           py::arg("times"), "(X (K, nx), U (K, nu)) at K times.")
      .def("__repr__", [](const Trajectory& t) {
        return "<trellis_mech.Trajectory: " + std::to_string(t.size()) + " knots, nx=" +
               std::to_string(t.nx()) + ", nu=" + std::to_string(t.nu()) + ">";
      });

  py::class_<GainSchedule>(m, "GainSchedule",
      "Feedback gains K(t) (nu, nx) at ascending times, linear in between; u = u_ref - K (x - x_ref). "
      "As arrays: times (N,), gains (N, nu, nx). CSV: t, K_<input>_<state> (row-major).")
      .def(py::init([](const RealVector<"times">& times, const py::object& gains) {
             return GainSchedule(Eigen::VectorXd(times.ref), gainsFromArray(gains));
           }),
           py::arg("times"), py::arg("gains"),
           "times (N,) strictly increasing; gains (N, nu, nx). Raises TrajectoryError.")
      .def_static("read_csv", &GainSchedule::readCsvFile, py::arg("path"))
      .def("write_csv", &GainSchedule::writeCsvFile, py::arg("path"))
      .def_static("sample",
                  [](const py::function& gain, const RealVector<"times">& times) {
                    return GainSchedule::sample(
                        [&](double t) {
                          const py::object K = gain(t);
                          refuseComplex(K, "gain(t)", "a real (nu, nx) matrix");
                          return K.cast<Eigen::MatrixXd>();
                        },
                        Eigen::VectorXd(times.ref));
                  },
                  py::arg("gain"), py::arg("times"),
                  "Samples a Python function K(t) -> (nu, nx) at the times.")
      .def_property_readonly("nu", &GainSchedule::nu)
      .def_property_readonly("nx", &GainSchedule::nx)
      .def("__len__", &GainSchedule::size)
      .def_property_readonly("start_time", &GainSchedule::startTime)
      .def_property_readonly("end_time", &GainSchedule::endTime)
      .def_property_readonly("times", [](const GainSchedule& g) { return toArray(g.times()); }, "(N,)")
      .def_property_readonly("gains", [](const GainSchedule& g) {
            return toArray3(g.gains(), g.nu(), g.nx());
          }, "(N, nu, nx)")
      .def_property("sample_rate", &GainSchedule::sampleRate, &GainSchedule::setSampleRate,
                    "0: continuous gains; f > 0: zero-order-hold gains for a controller sampling at f Hz")
      .def_property_readonly("is_sampled", &GainSchedule::isSampled)
      .def_property_readonly("column_names", &GainSchedule::columnNames,
                             "K[<input>|<state>], row-major (older files: K_<input>_<state>)")
      .def_property_readonly("has_feedforward", &GainSchedule::hasFeedforward)
      .def_property_readonly(
          "feedforward",
          [](const GainSchedule& g) -> py::object {
            if (!g.hasFeedforward()) return py::none();
            Eigen::MatrixXd u(g.size(), g.nu());
            for (int k = 0; k < g.size(); ++k) u.row(k) = g.feedforward()[static_cast<std::size_t>(k)].transpose();
            return toArray(u);
          },
          "(N, nu) held feed-forward uff_k of sampled gains (the sampled controller applies "
          "u_k = uff_k - K_k (x(t_k) - x_ref(t_k)), held), or None (then u_ref(t_k))")
      .def("set_feedforward",
           [](GainSchedule& g, const RealMatrix<"uff">& uff) {
             const Eigen::MatrixXd& u = uff.value;
             if (u.rows() != g.size() || u.cols() != g.nu()) {
               throw std::invalid_argument("set_feedforward: uff is (" + std::to_string(u.rows()) + ", " +
                                           std::to_string(u.cols()) + "), expected (N, nu) = (" +
                                           std::to_string(g.size()) + ", " + std::to_string(g.nu()) + ")");
             }
             std::vector<Eigen::VectorXd> rows;
             for (Eigen::Index k = 0; k < u.rows(); ++k) rows.push_back(u.row(k).transpose());
             g.setFeedforward(std::move(rows));
           },
           py::arg("uff"), "Sets the held feed-forward (N, nu) of sampled gains (raises ValueError "
           "unless sampled, the shape matches and every entry is finite).")
      .def("set_column_names", &GainSchedule::setColumnNames, py::arg("input_names"), py::arg("state_names"))
      .def("evaluate", [](const GainSchedule& g, double t) { return toArray(g.evaluate(t)); },
           py::arg("t"), "K(t) (nu, nx) by the schedule's interpolation rule")
      .def("__repr__", [](const GainSchedule& g) {
        return "<trellis_mech.GainSchedule: " + std::to_string(g.size()) + " times, K " +
               std::to_string(g.nu()) + "x" + std::to_string(g.nx()) + ">";
      });

  m.def("check_gain_schedule_applies", &checkGainScheduleApplies, py::arg("gains"), py::arg("model"),
        py::arg("reference"), py::arg("sample_rate") = 0.0, py::arg("source") = "gains",
        "The library's applicability check before a closed-loop simulation (as `trellis simulate` "
        "does): raises TrajectoryError when the gains' columns do not match the model, sampled "
        "gains are applied continuously or at another rate, their samples do not line up with the "
        "reference's start, or they do not cover its span; returns a note (str, empty when none) "
        "when continuous gains are sampled at sample_rate.");
}

}  // namespace trellis::python
