// consistency.cpp — the a-posteriori check of consistency.hpp (CVODES stays in this file).
#include "trellis/control/consistency.hpp"

#include "sundials_raii.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/model.hpp"
#include "trellis/core/reference.hpp"

#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
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
}

namespace {

/// The right-hand side's state: the model, the reference (for its input rule) and scratch.
struct Integrand {
  const Model& model;
  ReferenceEvaluator& reference;
  Data data;
  Eigen::VectorXd q, dq;
  std::string failure;  // the first failure inside the current CVode call

  Integrand(const Model& m, ReferenceEvaluator& r) : model(m), reference(r), data(m), q(m.nq()), dq(m.nq()) {}

  static int rhs(double t, N_Vector yv, N_Vector ydotv, void* user) {
    auto& s = *static_cast<Integrand*>(user);
    const int n = s.model.nq();
    const double* y = N_VGetArrayPointer(yv);
    s.q = Eigen::Map<const Eigen::VectorXd>(y, n);
    s.dq = Eigen::Map<const Eigen::VectorXd>(y + n, n);
    if (!s.q.allFinite() || !s.dq.allFinite()) {
      if (s.failure.empty()) s.failure = "the state became non-finite at t = " + std::to_string(t);
      return 1;
    }
    // The trajectory's rule for the input between knots (linear, or cubic Hermite with rates).
    s.reference.evaluate(std::clamp(t, s.reference.startTime(), s.reference.endTime()));
    const DynamicsStatus status = computeDynamics(s.model, s.data, s.q, s.dq, s.reference.u());
    if (!status.ok() || !s.data.qdd.allFinite()) {
      if (s.failure.empty()) {
        s.failure = "the dynamics failed at t = " + std::to_string(t) + ": " +
                    (status.message.empty() ? std::string("non-finite q''") : status.message);
      }
      return 1;  // recoverable: CVODES retries with a smaller step
    }
    double* out = N_VGetArrayPointer(ydotv);
    Eigen::Map<Eigen::VectorXd>(out, n) = s.dq;
    Eigen::Map<Eigen::VectorXd>(out + n, n) = s.data.qdd;
    return 0;
  }

  static void errorHandler(int code, const char* module, const char* function, char* msg, void* user) {
    auto& s = *static_cast<Integrand*>(user);
    if (code < 0 && s.failure.empty()) s.failure = std::string(module) + "::" + function + ": " + msg;
  }
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

  // The readers' reference: knot derivatives from the core (Hermite spline), the file's input
  // rule. (Names and knot count are checked above, so a refusal here is the dynamics at a knot.)
  std::optional<ReferenceEvaluator> reference;
  try {
    ReferenceOptions checks;
    checks.stateDerivatives = ReferenceOptions::StateDerivatives::kFromDynamics;
    reference.emplace(model, input, checks);
  } catch (const TrajectoryError& e) {
    result.message = std::string("not checked: ") + e.what();
    return result;
  }
  const Trajectory& trajectory = reference->trajectory();

  // Scales s_i (file comment).
  const Eigen::MatrixXd& X = trajectory.states();
  const Eigen::VectorXd range = X.rowwise().maxCoeff() - X.rowwise().minCoeff();
  result.stateScale.resize(nx);
  const double rq = range.head(n).maxCoeff(), rv = range.tail(n).maxCoeff();
  for (int i = 0; i < nx; ++i) {
    result.stateScale(i) = std::max({range(i), options.rangeFloor * (i < n ? rq : rv), 1e-12});
  }

  Integrand integrand(model, *reference);
  detail::CvodeSession cv;
  cv.context.reset(detail::createContext());
  SUNContext ctx = cv.context.get();
  cv.y.reset(N_VNew_Serial(nx, ctx));
  detail::Vector atol(N_VNew_Serial(nx, ctx));
  if (!cv.y || !atol) throw std::runtime_error("checkConsistency: N_VNew_Serial failed");
  Eigen::Map<Eigen::VectorXd> y(N_VGetArrayPointer(cv.y.get()), nx);
  Eigen::Map<Eigen::VectorXd>(N_VGetArrayPointer(atol.get()), nx) = options.atolFraction * result.stateScale;
  cv.cvode.reset(CVodeCreate(CV_ADAMS, ctx));
  void* mem = cv.cvode.get();
  if (!mem) throw std::runtime_error("checkConsistency: CVodeCreate failed");
  auto check = [&](int flag, const char* call) {
    if (flag < 0) {
      throw std::runtime_error(std::string("checkConsistency: ") + call + " failed with flag " +
                               std::to_string(flag) + ": " + integrand.failure);
    }
  };
  y = X.col(0);
  check(CVodeSetErrHandlerFn(mem, &Integrand::errorHandler, &integrand), "CVodeSetErrHandlerFn");
  check(CVodeInit(mem, &Integrand::rhs, trajectory.startTime(), cv.y.get()), "CVodeInit");
  check(CVodeSVtolerances(mem, options.rtol, atol.get()), "CVodeSVtolerances");
  check(CVodeSetUserData(mem, &integrand), "CVodeSetUserData");
  check(CVodeSetMaxNumSteps(mem, options.maxStepsPerInterval), "CVodeSetMaxNumSteps");
  cv.nonlinearSolver.reset(SUNNonlinSol_FixedPoint(cv.y.get(), 0, ctx));
  if (!cv.nonlinearSolver) throw std::runtime_error("checkConsistency: fixed-point solver");
  check(CVodeSetNonlinearSolver(mem, cv.nonlinearSolver.get()), "CVodeSetNonlinearSolver");

  result.intervalDefects = Eigen::VectorXd::Zero(N - 1);
  Eigen::VectorXd e(nx);
  result.integrated = true;
  for (int k = 0; k + 1 < N; ++k) {
    const double ta = trajectory.times()(k), tb = trajectory.times()(k + 1), tm = 0.5 * (ta + tb);
    y = X.col(k);
    integrand.failure.clear();
    if (k > 0) check(CVodeReInit(mem, ta, cv.y.get()), "CVodeReInit");
    check(CVodeSetStopTime(mem, tb), "CVodeSetStopTime");
    double interval = 0.0;
    for (int stage = 0; stage < 2; ++stage) {
      const double target = stage == 0 ? tm : tb;
      double tret = ta;
      const int flag = CVode(mem, target, cv.y.get(), &tret, CV_NORMAL);
      if (flag < 0) {
        result.integrated = false;
        result.worstInterval = k;
        result.worstTime = tret;
        result.message = "not checked: the integration of interval " + std::to_string(k) + " [" +
                         formatNumber(ta) + ", " + formatNumber(tb) + "] failed at t = " +
                         formatNumber(tret) + " (" + CVodeGetReturnFlagName(flag) + "): " +
                         integrand.failure;
        break;
      }
      if (stage == 0) {
        reference->evaluate(tm);
        e = y - reference->x();
      } else {
        e = y - X.col(k + 1);
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
    long v = 0;
    if (CVodeGetNumSteps(mem, &v) >= 0) result.steps += v;
    if (CVodeGetNumRhsEvals(mem, &v) >= 0) result.rhsEvaluations += v;
    if (!result.integrated) return result;
    result.intervalDefects(k) = interval;
  }
  const int i = result.worstState;
  result.worstStateName = i < n ? trajectory.configNames()[i] : "d" + trajectory.configNames()[i - n];
  result.consistent = result.maxDefect <= options.tolerance;
  std::ostringstream m;
  m << (result.consistent ? "consistent" : "inconsistent") << ": worst defect "
    << formatNumber(result.maxDefect) << " of the state's range (tolerance "
    << formatNumber(options.tolerance) << ") in '" << result.worstStateName << "' on interval "
    << result.worstInterval << " [" << formatNumber(trajectory.times()(result.worstInterval)) << ", "
    << formatNumber(trajectory.times()(result.worstInterval + 1)) << "], "
    << (result.worstAtMidpoint ? "at its midpoint t = " : "at its end t = ")
    << formatNumber(result.worstTime);
  result.message = m.str();
  return result;
}

}  // namespace trellis
