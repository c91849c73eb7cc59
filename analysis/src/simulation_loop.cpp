// simulation_loop.cpp — the simulator's event loop: integrate from event to event with the one
// CVODES driver (exactly to the stop events, dense output elsewhere), measure the drift and
// project above the tolerance, sample the held input, run the step check, record the outputs (see
// simulation.hpp).
#include "constraint_drift.hpp"
#include "trellis/analysis/detail/ode_driver.hpp"
#include "simulation_events.hpp"
#include "simulation_run.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/model.hpp"

#include <memory>
#include <stdexcept>
#include <string>

namespace trellis::detail {

namespace {

/// Radau (radau_stepper.hpp): its own halved solves, the exact Jacobian required. BDF's Newton
/// solves: by the system's structure where its Jacobian is known (ClosedLoopSystem::
/// preconditionerSolve: one n×n LU), else dense with CVODES's difference quotient. Adams:
/// fixed-point iterations.
OdeOptions integratorOptions(const SimulationOptions& options, const ClosedLoopSystem& system) {
  if (options.method == IntegrationMethod::kRadau) {
    if (!system.hasJacobian()) {
      throw std::invalid_argument(
          "SimulationOptions.method = radau needs the exact Jacobian: a continuous Policy has no known "
          "∂π/∂x and exactJacobian = false asks for a difference quotient (use bdf or adams there)");
    }
    OdeOptions ode = makeOdeOptions("closed-loop simulation", OdeMethod::Radau, OdeLinearSolver::Dense,
                                    options.rtol, options.atol, options.maxSteps, options.maxStep);
    ode.newtonTolerance = options.newtonTolerance;
    return ode;
  }
  const bool bdf = options.method == IntegrationMethod::kBDF;
  const OdeLinearSolver solver = !bdf                         ? OdeLinearSolver::FixedPoint
                                 : system.hasPreconditioner() ? OdeLinearSolver::SystemSolve
                                                              : OdeLinearSolver::Dense;
  OdeOptions ode = makeOdeOptions("closed-loop simulation", bdf ? OdeMethod::Bdf : OdeMethod::Adams, solver,
                                  options.rtol, options.atol, options.maxSteps, options.maxStep);
  ode.exactJacobian = options.exactJacobian;
  return ode;
}

/// SimulationOptions::stepCheck at one point (simulation.hpp, "Step check"): the input applied
/// there, the dynamics at (x, u) in a Data of its own (the right-hand side's stays untouched), then
/// the check. Allocates only in the constructor (and for a failure's text).
class StepChecker {
 public:
  StepChecker(const Model& model, const SimulationOptions& options)
      : model_(model), check_(options.stepCheck), data_(model), n_(model.nq()), sampled_(options.sampleRate > 0.0),
        q_(n_), dq_(n_), u_(model.nu()), noLambda_() {}

  /// Checks (t, x) of `system`'s loop; false with code and what set on a violation or failure.
  bool check(double t, const Eigen::VectorXd& x, ClosedLoopSystem& system, SimulationCode& code,
             std::string& what) {
    ++count;
    bool clipped = false;
    if (sampled_) {
      u_ = system.heldInput();
    } else if (!system.control(t, x, u_, clipped)) {
      code = system.failStatus;
      what = system.failMessage;
      return false;
    }
    // λ of the right-hand side's own evaluation at this very point when there is one (Radau's
    // step end), else computeDynamics here: the same function of (x, u) either way.
    const Eigen::VectorXd* lambda = system.lambdaAt(t, x, u_);
    if (!lambda) {
      q_ = x.head(n_);
      dq_ = x.tail(n_);
      const DynamicsStatus st = computeDynamics(model_, data_, q_, dq_, u_);
      if (!st.ok()) {
        code = st.code == DynamicsStatus::Code::kNonFinite ? SimulationCode::kNonFinite
                                                            : SimulationCode::kDynamicsFailure;
        what = "computeDynamics failed at the step check: " + st.message;
        return false;
      }
      lambda = &data_.lambda;
    }
    try {
      what = check_(t, x, u_, model_.nc() > 0 ? *lambda : noLambda_);
    } catch (const std::exception& e) {
      what = std::string("the step check threw: ") + e.what();
    } catch (...) {
      what = "the step check threw an unknown exception";
    }
    if (what.empty()) return true;
    code = SimulationCode::kCheckFailed;
    what = "step check: " + what;
    return false;
  }

  long count = 0;  ///< points checked

 private:
  const Model& model_;
  const StepCheck& check_;
  Data data_;
  int n_;
  bool sampled_;
  Eigen::VectorXd q_, dq_, u_, noLambda_;
};

}  // namespace

SimulationResult runSimulation(const Model& model, const Eigen::VectorXd& x0, double t0, double t1,
                               const InputLaw& law, const SimulationOptions& options,
                               const Trajectory* reference) {
  const std::vector<SimulationEvent> events = simulationEvents(t0, t1, options, reference);
  const int m = model.nu(), nx = 2 * model.nq();
  const bool constrained = model.nc() > 0;
  const bool projecting = constrained && options.constraints == ConstraintHandling::kProject;
  const bool sampled = options.sampleRate > 0.0;
  // Drift is integration error: a few times the tolerances' size is what one interval may add.
  const double driftTolerance =
      options.driftTolerance > 0.0 ? options.driftTolerance : 10.0 * (options.atol + options.rtol);

  long outputs = 0;
  for (const SimulationEvent& e : events) outputs += e.output ? 1 : 0;
  SimulationRecord record;
  record.times.reserve(static_cast<std::size_t>(outputs));
  record.states.resize(nx, outputs);
  record.inputs.resize(m, outputs);
  record.drift = Eigen::VectorXd::Zero(outputs);
  record.tracking.resize(reference ? outputs : 0);

  SimulationResult result;
  ClosedLoopSystem system(model, law, options);
  OdeDriver driver(system, nx, integratorOptions(options, system));
  std::unique_ptr<ConstraintDrift> monitor;
  if (constrained) monitor = std::make_unique<ConstraintDrift>(model, options.projectionIterations);
  std::unique_ptr<StepChecker> checker;
  if (options.stepCheck) checker = std::make_unique<StepChecker>(model, options);
  std::string checkMessage;
  SimulationCode checkCode = SimulationCode::kOk;

  auto setFailure = [&](SimulationCode s, double t, const Eigen::VectorXd& state,
                        const std::string& what) {
    result.status.set(s, "simulation stopped at t = " + formatTime(t) + ", x = " + formatVector(state) + ": " + what, t);
    result.failureState = state;
  };

  Eigen::VectorXd x = x0, xr(nx), ur(m), u(m), y(nx), xs(nx);
  // The state x at the integrator's current time (the integrator holds x or x − x_ref, see
  // closed_loop_system.hpp).
  auto integratorState = [&]() {
    Eigen::VectorXd state(nx);
    system.toState(driver.time(), driver.state(), state);
    return state;
  };
  long steps = 0;
  double stopTime = t0;  // the next stop event: the integrator never steps past it
  for (std::size_t e = 0; e < events.size(); ++e) {
    const SimulationEvent& ev = events[e];
    const double te = ev.t;
    // 1. the state at te: step until the integrator passes te, then its dense output
    if (e > 0) {
      bool failed = false;
      // Failures count per event interval: a run creeping towards a point beyond which the
      // right-hand side fails takes ever smaller successful steps, each with a few failures.
      system.resetCallState();
      while (driver.time() < te) {
        if (steps >= options.maxSteps) {
          setFailure(SimulationCode::kIntegratorFailure, driver.time(),
                     integratorState(),
                     "more than maxSteps = " + std::to_string(options.maxSteps) + " internal steps");
          failed = true;
          break;
        }
        const OdeStatus st = driver.step(stopTime);
        if (!st.ok()) {
          if (system.failed && st.callbackFailed()) {
            setFailure(system.failStatus, system.failTime, system.failState, st.message);
          } else {
            std::string what = st.message;
            if (st.tooMuchWork())
              what = "more than maxSteps = " + std::to_string(options.maxSteps) +
                     " internal steps; " + what;
            if (system.failed) what += " (last right-hand-side failure: " + system.failMessage + ")";
            setFailure(SimulationCode::kIntegratorFailure, st.t, integratorState(),
                       what);
          }
          failed = true;
          break;
        }
        ++steps;
        if (checker) {  // every accepted step's end (file comment of simulation.hpp)
          system.toState(driver.time(), driver.state(), xs);
          if (!checker->check(driver.time(), xs, system, checkCode, checkMessage)) {
            setFailure(checkCode, driver.time(), xs, checkMessage);
            failed = true;
            break;
          }
        }
      }
      if (failed) break;
      if (driver.time() == te) {
        system.toState(te, driver.state(), x);
      } else if (driver.interpolate(te, 0, y)) {
        system.toState(te, y, x);
      } else {
        setFailure(SimulationCode::kIntegratorFailure, te, integratorState(),
                   "the dense output is not available at t = " + formatTime(te));
        break;
      }
      if (!x.allFinite()) {
        setFailure(SimulationCode::kNonFinite, te, x, "the state became non-finite");
        break;
      }
    }
    // 2. drift (before projecting); projection where it exceeds the tolerance
    double d = 0.0;
    bool projected = false;
    if (constrained && (ev.output || ev.stop)) {
      d = monitor->drift(x);
      result.maxConstraintDrift = std::max(result.maxConstraintDrift, d);
    }
    if (projecting && d > driftTolerance) {
      const ConstraintProjection p = monitor->project(x);
      ++result.projections;
      projected = true;
      if (!x.allFinite()) {
        setFailure(SimulationCode::kNonFinite, te, x,
                   "the constraint projection produced a non-finite state");
        break;
      }
      if (!(p.driftAfter <= driftTolerance)) {
        setFailure(SimulationCode::kConstraintDrift, te, x,
                   "the constraint drift " + formatTime(p.driftBefore) + " is still " +
                       formatTime(p.driftAfter) + " after projection (" +
                       std::to_string(p.iterations) + " Newton steps), above the tolerance " +
                       formatTime(driftTolerance));
        break;
      }
    }
    // 3. a new sample of the held input
    if (ev.sample) {
      bool clipped = false;
      if (!system.sample(te, x, clipped)) {
        setFailure(system.failStatus, te, x, system.failMessage);
        break;
      }
      ++result.controlSamples;
      if (clipped) ++result.saturatedSamples;
    }
    // 3b. the step check where the integration (re)starts: t0, and after a new sample or a
    // projection (u or x jumped; the last step's end was checked before the jump)
    if (checker && (e == 0 || projected || (ev.stop && e + 1 < events.size()))) {
      if (!checker->check(te, x, system, checkCode, checkMessage)) {
        setFailure(checkCode, te, x, checkMessage);
        break;
      }
    }
    // 4. output
    if (ev.output) {
      const auto k = static_cast<Eigen::Index>(record.times.size());
      if (sampled) {
        u = system.heldInput();
      } else {
        bool clipped = false;
        if (!system.control(te, x, u, clipped)) {
          setFailure(system.failStatus, te, x, system.failMessage);
          break;
        }
        ++result.controlSamples;
        if (clipped) ++result.saturatedSamples;
      }
      record.times.push_back(te);
      record.states.col(k) = x;
      record.inputs.col(k) = u;
      record.drift(k) = d;
      if (reference) {
        reference->evaluate(te, xr, ur);
        record.tracking(k) = (x - xr).norm();
      }
    }
    if (e + 1 == events.size()) break;
    // 5. (re)start where the right-hand side jumps (a sample, a breakpoint) or the state did
    if (e == 0 || ev.stop || projected) {
      system.toIntegrator(te, x, y);
      driver.start(te, y);
      std::size_t next = e + 1;
      while (!events[next].stop) ++next;  // the last event (t1) is a stop
      stopTime = events[next].t;
    }
  }

  const OdeStats s = driver.stats();
  result.steps = s.steps;
  result.rhsEvaluations = s.rhsEvaluations;
  result.linearRhsEvaluations = s.linearRhsEvaluations;
  result.jacobianEvaluations = s.jacobianEvaluations + system.structuredJacobians();
  result.restarts = s.restarts;
  result.checks = checker ? checker->count : 0;
  assembleResult(model, record, reference != nullptr, result);
  return result;
}

}  // namespace trellis::detail
