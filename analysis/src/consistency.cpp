// consistency.cpp — the a-posteriori check of consistency.hpp, integrated with the module's one
// ODE driver (ode_driver.hpp): Radau IIA with the core's exact Jacobian by default (Adams or BDF
// on request), per-component absolute tolerances scaled to the state's range, a restart at every
// knot.
#include "trellis/analysis/consistency.hpp"

#include "trellis/analysis/detail/ode_driver.hpp"
#include "trellis/core/detail/report_json.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"
#include "trellis/core/reference.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

void ConsistencyOptions::validate() const {
  auto positive = [](double v, const char* name) {
    if (!(v > 0.0) || !std::isfinite(v)) {
      throw std::invalid_argument(std::string("ConsistencyOptions.") + name + " = " +
                                  std::to_string(v) + " must be > 0 and finite");
    }
  };
  positive(tolerance, "tolerance");
  positive(rtol, "rtol");
  positive(atolFraction, "atolFraction");
  if (!(rangeFloor >= 0.0) || !std::isfinite(rangeFloor)) {
    throw std::invalid_argument("ConsistencyOptions.rangeFloor must be >= 0 and finite");
  }
  if (maxStepsPerInterval < 1) throw std::invalid_argument("ConsistencyOptions.maxStepsPerInterval must be >= 1");
  if (method != IntegrationMethod::kAdams && method != IntegrationMethod::kBDF && method != IntegrationMethod::kRadau) {
    throw std::invalid_argument("ConsistencyOptions.method = " + std::to_string(static_cast<int>(method)) +
                                " is not adams, bdf or radau");
  }
}

namespace {

/// ẋ = [q̇; q̈(q, q̇, u(t))] with u(t) by the trajectory's input rule (linear, or cubic Hermite
/// with rates). A failure is recoverable (CVODES retries with a smaller step); the first one of
/// an interval is kept in `failure` (the driver clears it at every start).
class Integrand final : public detail::OdeSystem {
 public:
  Integrand(const Model& m, ReferenceEvaluator& r) : model_(m), reference_(r), data_(m), q_(m.nq()), dq_(m.nq()) {}

  int rhs(double t, detail::ConstVectorMap y, detail::VectorMap ydot) override {
    const int n = model_.nq();
    if (!at(t, y)) return 1;
    const DynamicsStatus status = computeDynamics(model_, data_, q_, dq_, reference_.u());
    if (!status.ok() || !data_.qdd.allFinite()) return failed(t, "the dynamics", status, "non-finite q''");
    ydot.head(n) = dq_;
    ydot.tail(n) = data_.qdd;
    return 0;
  }

  // J = ∂f/∂x = [[0, I], [∂q̈/∂q, ∂q̈/∂q̇]] at u(t): the core's exact linearization (u depends on t
  // only). Its failure is the integrator's (reported with the interval).
  bool hasJacobian() const override { return true; }
  bool secondOrder() const override { return true; }
  int jacobian(double t, detail::ConstVectorMap y, detail::ConstVectorMap, detail::MatrixMap J) override {
    if (!at(t, y)) return 1;
    const DynamicsStatus status = computeLinearization(model_, data_, q_, dq_, reference_.u());
    if (!status.ok() || !data_.A.allFinite()) return failed(t, "the linearization", status, "non-finite A");
    J = data_.A;
    return 0;
  }

 private:
  /// q, q̇ from y and u(t) from the reference; false (failure set) for a non-finite state.
  bool at(double t, detail::ConstVectorMap y) {
    const int n = model_.nq();
    q_ = y.head(n);
    dq_ = y.tail(n);
    if (!q_.allFinite() || !dq_.allFinite()) {
      if (failure.empty()) failure = "the state became non-finite at t = " + std::to_string(t);
      return false;
    }
    reference_.evaluate(std::clamp(t, reference_.startTime(), reference_.endTime()));
    return true;
  }
  /// The first failure of an interval, kept (what failed, and why); 1: recoverable.
  int failed(double t, const char* what, const DynamicsStatus& status, const char* nonFinite) {
    if (failure.empty()) {
      failure = std::string(what) + " failed at t = " + std::to_string(t) + ": " +
                (status.message.empty() ? std::string(nonFinite) : status.message);
    }
    return 1;
  }

  const Model& model_;
  ReferenceEvaluator& reference_;
  Data data_;
  Eigen::VectorXd q_, dq_;
};

std::string formatNumber(double v) {
  std::ostringstream s;
  s.precision(3);
  s << v;
  return s.str();
}

}  // namespace

ConsistencyResult checkConsistency(const Model& model, const Trajectory& input,
                                   const ConsistencyOptions& options) {
  options.validate();
  input.checkCompatible(model);
  ConsistencyResult result;
  result.tolerance = options.tolerance;
  const int n = model.nq(), nx = 2 * n, N = input.size();
  if (N < 2) throw TrajectoryError("checkConsistency: the trajectory needs at least 2 knots");

  // The readers' reference: knot derivatives ẋ_k = [q̇_k; q̈_k] from the core (the Hermite
  // spline's slopes), the file's input rule. A knot where the dynamics fail is the verdict.
  Trajectory withDerivatives = input;
  {
    Data data(model);
    const DynamicsStatus st = withDerivatives.tryComputeStateDerivatives(model, data);
    if (!st.ok()) {
      result.status.set(ConsistencyCode::kDynamicsFailure,
                        "not checked: the dynamics fail at knot " + std::to_string(st.index) + ": " +
                            st.name() + ": " + st.message,
                        st.t, st.index);
      return result;
    }
  }
  ReferenceOptions checks;
  checks.stateDerivatives = ReferenceOptions::StateDerivatives::kKeepSupplied;
  ReferenceEvaluator reference(model, std::move(withDerivatives), checks);
  const Trajectory& trajectory = reference.trajectory();

  // Scales s_i (file comment).
  const Eigen::MatrixXd& X = trajectory.states();
  const Eigen::VectorXd range = X.rowwise().maxCoeff() - X.rowwise().minCoeff();
  result.stateScale.resize(nx);
  const double rq = range.head(n).maxCoeff(), rv = range.tail(n).maxCoeff();
  for (int i = 0; i < nx; ++i) {
    result.stateScale(i) = std::max({range(i), options.rangeFloor * (i < n ? rq : rv), 1e-12});
  }

  Integrand integrand(model, reference);
  // The driver's step budget restarts at every start(): maxStepsPerInterval per interval.
  const bool adams = options.method == IntegrationMethod::kAdams;
  detail::OdeOptions ode = detail::makeOdeOptions(
      "checkConsistency",
      adams ? detail::OdeMethod::Adams
            : options.method == IntegrationMethod::kBDF ? detail::OdeMethod::Bdf : detail::OdeMethod::Radau,
      adams ? detail::OdeLinearSolver::FixedPoint : detail::OdeLinearSolver::Dense, options.rtol,
      detail::OdeOptions{}.atol, options.maxStepsPerInterval);
  ode.atolVector = options.atolFraction * result.stateScale;
  detail::OdeDriver driver(integrand, nx, ode);

  result.intervalDefects = Eigen::VectorXd::Zero(N - 1);
  Eigen::VectorXd e(nx), y(nx);
  bool integrated = true;
  for (int k = 0; k + 1 < N && integrated; ++k) {
    const double ta = trajectory.times()(k), tb = trajectory.times()(k + 1), tm = 0.5 * (ta + tb);
    driver.start(ta, X.col(k));
    double interval = 0.0;
    for (int stage = 0; stage < 2; ++stage) {
      const double target = stage == 0 ? tm : tb;
      // Steps towards the knot tb (never beyond it); the midpoint from the dense output.
      detail::OdeStatus st;
      while (driver.time() < target && st.ok()) st = driver.step(tb);
      if (!st.ok()) {
        integrated = false;
        result.status.set(ConsistencyCode::kIntegratorFailure,
                          "not checked: the integration of interval " + std::to_string(k) + " [" +
                              formatNumber(ta) + ", " + formatNumber(tb) + "] failed at t = " +
                              formatNumber(st.t) + ": " + st.message,
                          st.t, k);
        break;
      }
      if (stage == 0) {
        if (!driver.interpolate(tm, 0, y)) {
          throw std::logic_error("checkConsistency: no dense output at the midpoint of interval " +
                                 std::to_string(k));
        }
        reference.evaluate(tm);
        e = y - reference.x();
      } else {
        e = driver.state() - X.col(k + 1);
      }
      const Eigen::VectorXd relative = e.cwiseAbs().cwiseQuotient(result.stateScale);
      int i = 0;
      const double d = relative.maxCoeff(&i);
      interval = std::max(interval, d);
      if (d > result.maxDefect || result.worstInterval < 0) {
        result.maxDefect = d;
        result.worstInterval = k;
        result.worstTime = target;
        result.worstAtMidpoint = stage == 0;
        result.worstState = i;
      }
    }
    if (integrated) result.intervalDefects(k) = interval;
  }
  const detail::OdeStats stats = driver.stats();
  result.steps = stats.steps;
  result.rhsEvaluations = stats.rhsEvaluations;
  result.jacobianEvaluations = stats.jacobianEvaluations;
  if (!integrated) return result;
  const int i = result.worstState;
  result.worstStateName = i < n ? trajectory.configNames()[i] : "d" + trajectory.configNames()[i - n];
  const bool consistent = result.maxDefect <= options.tolerance;
  std::ostringstream m;
  m << (consistent ? "consistent" : "inconsistent") << ": worst defect "
    << formatNumber(result.maxDefect) << " of the state's range (tolerance "
    << formatNumber(options.tolerance) << ") in '" << result.worstStateName << "' on interval "
    << result.worstInterval << " [" << formatNumber(trajectory.times()(result.worstInterval)) << ", "
    << formatNumber(trajectory.times()(result.worstInterval + 1)) << "], "
    << (result.worstAtMidpoint ? "at its midpoint t = " : "at its end t = ")
    << formatNumber(result.worstTime);
  if (consistent) {
    result.status.set(ConsistencyCode::kOk, m.str());
  } else {
    result.status.set(ConsistencyCode::kInconsistent, m.str(), result.worstTime, result.worstInterval);
  }
  return result;
}

std::string ConsistencyResult::describe() const { return status.describe(); }

std::string ConsistencyResult::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["tolerance"] = detail::toJson(tolerance);
  j["max_defect"] = checked() ? detail::toJson(maxDefect) : detail::ReportJson(nullptr);
  j["worst_interval"] = checked() ? detail::ReportJson(worstInterval) : detail::ReportJson(nullptr);
  j["worst_time"] = checked() ? detail::toJson(worstTime) : detail::ReportJson(nullptr);
  j["worst_at_midpoint"] = worstAtMidpoint;
  j["worst_state"] = worstStateName;
  j["steps"] = steps;
  j["rhs_evaluations"] = rhsEvaluations;
  j["jacobian_evaluations"] = jacobianEvaluations;
  return j.dump();
}

}  // namespace trellis
