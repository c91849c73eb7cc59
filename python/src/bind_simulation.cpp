// python/src/bind_simulation.cpp — analysis/simulation.hpp: the closed loop (a Python policy, a
// gain schedule along a reference, many starts on threads), the open loop and the constraint
// projection. Trajectories come back time first (N, nx), like every array of samples.
#include "common.hpp"
#include "control_common.hpp"
#include "options.hpp"

#include "trellis/analysis/simulation.hpp"
#include "trellis/core/gain_schedule.hpp"
#include "trellis/core/trajectory.hpp"

#include <atomic>
#include <optional>
#include <string>
#include <vector>

namespace trellis::python {

namespace {

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

void bindSimulation(py::module_& m) {
  // ---- Simulation ----------------------------------------------------------------------------
  py::enum_<ConstraintHandling>(m, "ConstraintHandling")
      .value("NONE", ConstraintHandling::kNone)
      .value("PROJECT", ConstraintHandling::kProject);
  py::enum_<IntegrationMethod>(m, "IntegrationMethod")
      .value("ADAMS", IntegrationMethod::kAdams)
      .value("BDF", IntegrationMethod::kBDF)
      .value("RADAU", IntegrationMethod::kRadau);
  bindStatus<SimulationCode>(m, "SimulationStatus",
      "Status of a simulation (code: ok, integrator_failure, dynamics_failure, non_finite, "
      "policy_failure, constraint_drift, check_failed); t: the time of the failure.");

  py::class_<SimulationOptions> simulationOptions(m, "SimulationOptions",
      "Options of the CVODES simulation (keywords): rtol, atol, max_steps, sample_rate (0: "
      "continuous feedback; f > 0: sampled at f Hz with zero-order hold), input_lower / "
      "input_upper (nu,) box, output_step, constraints (ConstraintHandling), method, max_step, "
      "breakpoints, projection_iterations, drift_tolerance (0: 10 (atol + rtol); projection above "
      "it), exact_jacobian (BDF: exact A - B S K, else difference quotients), newton_tolerance (Radau: "
      "Newton's stopping test in units of the step's tolerance; 0: RADAU5's default).");
  simulationOptions
      .def(py::init(&makeFromKwargs<SimulationOptions>))
      .def_readwrite("rtol", &SimulationOptions::rtol)
      .def_readwrite("atol", &SimulationOptions::atol)
      .def_readwrite("max_steps", &SimulationOptions::maxSteps)
      .def_readwrite("sample_rate", &SimulationOptions::sampleRate)
      .def_readwrite("output_step", &SimulationOptions::outputStep)
      .def_readwrite("constraints", &SimulationOptions::constraints)
      .def_readwrite("method", &SimulationOptions::method)
      .def_readwrite("max_step", &SimulationOptions::maxStep)
      .def_readwrite("breakpoints", &SimulationOptions::breakpoints)
      .def_readwrite("projection_iterations", &SimulationOptions::projectionIterations)
      .def_readwrite("drift_tolerance", &SimulationOptions::driftTolerance)
      .def_readwrite("exact_jacobian", &SimulationOptions::exactJacobian)
      .def_readwrite("newton_tolerance", &SimulationOptions::newtonTolerance)
      .def("validate", &SimulationOptions::validate);
  realArrayProperty(simulationOptions, "input_lower", &SimulationOptions::inputLower,
                    "(nu,) lower bounds on the applied input (empty: none); copied in and out");
  realArrayProperty(simulationOptions, "input_upper", &SimulationOptions::inputUpper,
                    "(nu,) upper bounds (empty: none)");

  py::class_<SimulationResult>(m, "SimulationResult",
      "The simulated trajectory (x, applied u at the output times) with status and diagnostics.")
      .def_readonly("status", &SimulationResult::status)
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
      .def_readonly("checks", &SimulationResult::checks,
                    "points where the C++ SimulationOptions.stepCheck ran (not bound in Python: 0)")
      .def_property_readonly("ok", &SimulationResult::ok)
      .def("describe", &SimulationResult::describe)
      .def("json", &SimulationResult::json)
      .def("__repr__", [](const SimulationResult& r) { return "<SimulationResult " + r.describe() + ">"; });

  m.def("simulate",
        [](const Model& model, const RealVector<"x0">& x0, double t0, double t1, const py::function& policy,
           const std::optional<SimulationOptions>& options, const Trajectory* reference) {
          const Eigen::VectorXd x = x0.ref;
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
        "Python callable returning (nu,)); an exception in the policy is the status 'policy_failure'.");
  m.def("simulate_closed_loop",
        [](const Model& model, const Trajectory& reference, const GainSchedule& gains,
           const RealVector<"x0">& x0, const std::optional<SimulationOptions>& options) {
          const Eigen::VectorXd x = x0.ref;
          return withoutGil([&] {
            return simulateClosedLoop(model, reference, gains, x, options.value_or(SimulationOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::arg("gains"), py::arg("x0"), py::kw_only(),
        py::arg("options") = py::none(),
        "u = u_ref(t) - K(t) (x - x_ref(t)) over the reference's span from x0 (nx,).");
  m.def("simulate_closed_loop_many",
        [](const Model& model, const Trajectory& reference, const GainSchedule& gains,
           const RealMatrix<"x0s">& x0arg, const std::optional<SimulationOptions>& options, int threads) {
          const Eigen::MatrixXd& x0s = x0arg;
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
        [](const Model& model, const Trajectory& reference, const RealVector<"x0">& x0,
           const std::optional<SimulationOptions>& options) {
          const Eigen::VectorXd x = x0.ref;
          return withoutGil([&] {
            return simulateOpenLoop(model, reference, x, options.value_or(SimulationOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::arg("x0"), py::kw_only(),
        py::arg("options") = py::none(), "u = u_ref(t) over the reference's span.");

  bindStatus<ProjectionCode>(m, "ProjectionStatus",
      "Status of a constraint projection (code: ok, not_converged, non_finite).");
  py::class_<ConstraintProjection>(m, "ConstraintProjection",
      "drift_before, drift_after (max(|h|, |A dq|)), iterations, and the projection's status.")
      .def_readonly("status", &ConstraintProjection::status)
      .def_property_readonly("ok", &ConstraintProjection::ok)
      .def_readonly("drift_before", &ConstraintProjection::driftBefore)
      .def_readonly("drift_after", &ConstraintProjection::driftAfter)
      .def_readonly("iterations", &ConstraintProjection::iterations)
      .def("describe", &ConstraintProjection::describe)
      .def("json", &ConstraintProjection::json)
      .def("__repr__", [](const ConstraintProjection& p) { return "<ConstraintProjection " + p.describe() + ">"; });
  m.def("project_onto_constraints",
        [](const Model& model, const RealVector<"x">& x, int maxIterations) {
          Eigen::VectorXd y = x.ref;
          const ConstraintProjection p = projectOntoConstraints(model, y, maxIterations);
          return py::make_tuple(toArray(y), p);
        },
        py::arg("model"), py::arg("x"), py::arg("max_iterations") = 10,
        "(x projected onto h(q) = 0, A(q) dq = 0 in the mass-matrix metric, ConstraintProjection).");
}

}  // namespace trellis::python
