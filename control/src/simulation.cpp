// simulation.cpp — nonlinear open/closed-loop simulation with CVODES (SUNDIALS stays here).
#include "trellis/control/simulation.hpp"

#include "sundials_raii.hpp"
#include "trellis/control/tvlqr.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/model.hpp"

#include <cvodes/cvodes_ls.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include <Eigen/Cholesky>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>

namespace trellis {

const char* toString(SimulationStatus status) {
  switch (status) {
    case SimulationStatus::kOk:
      return "ok";
    case SimulationStatus::kIntegratorFailure:
      return "integrator failure";
    case SimulationStatus::kDynamicsFailure:
      return "dynamics failure";
    case SimulationStatus::kNonFinite:
      return "non-finite";
    case SimulationStatus::kPolicyFailure:
      return "policy failure";
  }
  return "unknown";
}

const char* toString(IntegrationMethod method) {
  return method == IntegrationMethod::kAdams ? "adams" : "bdf";
}

IntegrationMethod parseIntegrationMethod(const std::string& text) {
  if (text == "adams") return IntegrationMethod::kAdams;
  if (text == "bdf") return IntegrationMethod::kBDF;
  throw std::invalid_argument("'" + text + "' is not one of adams, bdf");
}

std::string simulationJson(const SimulationResult& r) {
  std::ostringstream o;
  const Trajectory& tr = r.trajectory;
  const bool have = tr.size() > 0;
  const Eigen::VectorXd& e = r.trackingError;
  Eigen::Index worst = 0;
  if (e.size() > 0) e.maxCoeff(&worst);
  o << "{\"ok\": " << (r.ok() ? "true" : "false") << ", \"status\": " << jsonString(toString(r.status))
    << ", \"message\": " << jsonString(r.message) << ", \"rows\": " << tr.size()
    << ", \"t0\": " << (have ? jsonNumber(tr.startTime()) : "null")
    << ", \"t1\": " << (have ? jsonNumber(tr.endTime()) : "null")
    << ", \"tracking_error_initial\": " << (e.size() > 0 ? jsonNumber(e(0)) : "null")
    << ", \"tracking_error_final\": " << (e.size() > 0 ? jsonNumber(e(e.size() - 1)) : "null")
    << ", \"tracking_error_max\": " << (e.size() > 0 ? jsonNumber(e(worst)) : "null")
    << ", \"tracking_error_max_time\": " << (e.size() > 0 && have ? jsonNumber(tr.times()(worst)) : "null")
    << ", \"max_constraint_drift\": " << jsonNumber(r.maxConstraintDrift)
    << ", \"saturated_samples\": " << r.saturatedSamples << ", \"control_samples\": " << r.controlSamples
    << ", \"saturated_fraction\": " << jsonNumber(r.saturatedFraction) << ", \"steps\": " << r.steps
    << ", \"rhs_evaluations\": " << r.rhsEvaluations << ", \"restarts\": " << r.restarts
    << ", \"projections\": " << r.projections << "}";
  return o.str();
}

void SimulationOptions::validate() const {
  auto bad = [](const std::string& field, double v, const char* rule) {
    std::ostringstream m;
    m << "SimulationOptions." << field << " = " << v << " must be " << rule;
    throw std::invalid_argument(m.str());
  };
  if (!(rtol > 0.0) || !std::isfinite(rtol)) bad("rtol", rtol, "> 0 and finite");
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol, "> 0 and finite");
  if (maxSteps <= 0) bad("maxSteps", static_cast<double>(maxSteps), "> 0");
  if (!(sampleRate >= 0.0) || !std::isfinite(sampleRate))
    bad("sampleRate", sampleRate, ">= 0 and finite");
  if (!(outputStep >= 0.0) || !std::isfinite(outputStep))
    bad("outputStep", outputStep, ">= 0 and finite");
  if (!(maxStep >= 0.0) || !std::isfinite(maxStep)) bad("maxStep", maxStep, ">= 0 and finite");
  if (projectionIterations < 1) {
    bad("projectionIterations", projectionIterations, ">= 1");
  }
  for (std::size_t k = 0; k < breakpoints.size(); ++k) {
    if (!std::isfinite(breakpoints[k]))
      bad("breakpoints[" + std::to_string(k) + "]", breakpoints[k], "finite");
  }
  if (inputLower.size() != 0 && inputUpper.size() != 0 && inputLower.size() != inputUpper.size()) {
    std::ostringstream m;
    m << "SimulationOptions.inputLower has size " << inputLower.size()
      << " but SimulationOptions.inputUpper has size " << inputUpper.size();
    throw std::invalid_argument(m.str());
  }
  for (Eigen::Index i = 0; i < inputLower.size(); ++i) {
    if (std::isnan(inputLower(i)) || inputLower(i) == std::numeric_limits<double>::infinity()) {
      bad("inputLower[" + std::to_string(i) + "]", inputLower(i), "a number < +inf");
    }
  }
  for (Eigen::Index i = 0; i < inputUpper.size(); ++i) {
    if (std::isnan(inputUpper(i)) || inputUpper(i) == -std::numeric_limits<double>::infinity()) {
      bad("inputUpper[" + std::to_string(i) + "]", inputUpper(i), "a number > -inf");
    }
    if (i < inputLower.size() && !(inputLower(i) <= inputUpper(i))) {
      std::ostringstream m;
      m << "SimulationOptions.inputLower[" << i << "] = " << inputLower(i)
        << " is greater than SimulationOptions.inputUpper[" << i << "] = " << inputUpper(i);
      throw std::invalid_argument(m.str());
    }
  }
}

namespace {

std::string formatVector(const Eigen::VectorXd& v) {
  std::ostringstream m;
  m.precision(10);
  m << "[";
  for (Eigen::Index i = 0; i < v.size(); ++i) m << (i ? ", " : "") << v(i);
  m << "]";
  return m.str();
}

std::string formatTime(double t) {
  std::ostringstream m;
  m.precision(12);
  m << t;
  return m.str();
}

/// Workspace and algorithm of the constraint projection (see simulation.hpp). Its own Data, so
/// the simulator's buffers are untouched.
class ConstraintProjector {
 public:
  explicit ConstraintProjector(const Model& model)
      : model_(model),
        data_(model),
        n_(model.nq()),
        nc_(model.nc()),
        q_(n_),
        dq_(n_),
        r_(nc_),
        w_(n_),
        qSaved_(n_),
        llt_(n_) {
    for (int r = 0; r < nc_; ++r) {
      if (model.constraints()[r].holonomic()) holonomicRows_.push_back(r);
    }
    const auto nh = static_cast<Eigen::Index>(holonomicRows_.size());
    rh_.resize(nh);
    GhT_.resize(n_, nh);
    GT_.resize(n_, nc_);
  }

  /// max(|h(q)|∞, |A q̇|∞) at x (0 without constraints).
  double drift(const Eigen::VectorXd& x) {
    if (nc_ == 0) return 0.0;
    q_ = x.head(n_);
    dq_ = x.tail(n_);
    return driftAtCurrent();
  }

  ConstraintProjection project(Eigen::VectorXd& x, int maxIterations) {
    ConstraintProjection p;
    if (nc_ == 0) return p;
    p.driftBefore = drift(x);  // leaves h, A at q in data_
    computeMassMatrix(model_, data_, q_);
    llt_.compute(data_.M);
    metric_ = llt_.info() == Eigen::Success && data_.M.allFinite();

    // Positions: Gauss–Newton on the holonomic rows with a minimum-W-norm step.
    if (!holonomicRows_.empty()) {
      double previous = std::numeric_limits<double>::infinity();
      for (int it = 0; it <= maxIterations; ++it) {
        if (it > 0) computeConstraints(model_, data_, q_, dq_);
        for (std::size_t k = 0; k < holonomicRows_.size(); ++k) {
          rh_(static_cast<Eigen::Index>(k)) = data_.constraintValue(holonomicRows_[k]);
        }
        const double residual = rh_.cwiseAbs().maxCoeff();
        if (!std::isfinite(residual) || residual > previous) {  // the last step made it worse
          if (it > 0) q_ = qSaved_;
          break;
        }
        if (residual == 0.0 || residual > 0.5 * previous || it == maxIterations) break;
        previous = residual;
        for (std::size_t k = 0; k < holonomicRows_.size(); ++k) {
          GhT_.col(static_cast<Eigen::Index>(k)) =
              data_.constraintJacobian.row(holonomicRows_[k]).transpose();
        }
        minimumNormStep(GhT_, rh_, codH_);
        qSaved_ = q_;
        q_ -= w_;
        p.iterations = it + 1;
      }
      computeConstraints(model_, data_, q_, dq_);
    }

    // Velocities: M-orthogonal projection onto A q̇ = 0.
    r_.noalias() = data_.constraintJacobian * dq_;
    GT_ = data_.constraintJacobian.transpose();
    minimumNormStep(GT_, r_, cod_);
    dq_ -= w_;

    x.head(n_) = q_;
    x.tail(n_) = dq_;
    p.driftAfter = driftAtCurrent();
    return p;
  }

 private:
  double driftAtCurrent() {
    computeConstraints(model_, data_, q_, dq_);
    r_.noalias() = data_.constraintJacobian * dq_;
    double d = 0.0;
    if (nc_ > 0)
      d = std::max(data_.constraintValue.cwiseAbs().maxCoeff(), r_.cwiseAbs().maxCoeff());
    return std::isfinite(d) ? d : std::numeric_limits<double>::infinity();
  }

  // w_ = the step δ of least δᵀMδ (least |δ| if M is not positive definite) with J δ = rhs, given
  // Jᵀ in JT (overwritten): with M = L Lᵀ and G = J L⁻ᵀ, δ = L⁻ᵀ G⁺ rhs.
  void minimumNormStep(Eigen::MatrixXd& JT, const Eigen::VectorXd& rhs,
                       Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd>& cod) {
    if (metric_) llt_.matrixL().solveInPlace(JT);  // JT ← L⁻¹ Jᵀ = Gᵀ
    cod.compute(JT.transpose());
    w_ = cod.solve(rhs);
    if (metric_) llt_.matrixU().solveInPlace(w_);  // δ = L⁻ᵀ w
  }

  const Model& model_;
  Data data_;
  int n_, nc_;
  std::vector<int> holonomicRows_;
  Eigen::VectorXd q_, dq_, r_, rh_, w_, qSaved_;
  Eigen::MatrixXd GhT_, GT_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
  bool metric_ = false;
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod_, codH_;
};

/// Everything the CVODES right-hand side needs, allocated once.
struct Simulator {
  const Model& model;
  const Policy& policy;
  int n, m;
  Data data;
  Eigen::VectorXd x, q, dq, u, uHeld, lower, upper;
  bool sampled = false;
  bool bounded = false;
  // The last failure inside the current CVode call (reset before each call).
  bool failed = false;
  // Right-hand-side failures are first reported as recoverable (CVODES retries with a smaller
  // step, which helps when only a trial point was bad). After kMaxRecoverableFailures in one
  // CVode call — typically the integrator creeping towards a point beyond which the dynamics or
  // the policy are invalid — or after a policy exception, every further call fails
  // unrecoverably until the CVode call returns. (SUNDIALS 6.4's fixed-point solver, used with
  // Adams, treats even a negative return as a convergence failure; a sticky failure turns that
  // into CV_CONV_FAILURE after a few attempts instead of a crawl through maxSteps.)
  static constexpr int kMaxRecoverableFailures = 10;
  int failuresThisCall = 0;
  bool aborted = false;
  SimulationStatus failStatus = SimulationStatus::kOk;
  double failTime = 0.0;
  Eigen::VectorXd failState;
  std::string failMessage, cvodeMessage;

  Simulator(const Model& mdl, const Policy& pol, const SimulationOptions& opt)
      : model(mdl),
        policy(pol),
        n(mdl.nq()),
        m(mdl.nu()),
        data(mdl),
        x(2 * n),
        q(n),
        dq(n),
        u(m),
        uHeld(m),
        lower(Eigen::VectorXd::Constant(m, -std::numeric_limits<double>::infinity())),
        upper(Eigen::VectorXd::Constant(m, std::numeric_limits<double>::infinity())),
        sampled(opt.sampleRate > 0.0) {
    if (opt.inputLower.size() == m) lower = opt.inputLower;
    if (opt.inputUpper.size() == m) upper = opt.inputUpper;
    bounded = opt.inputLower.size() > 0 || opt.inputUpper.size() > 0;
    u.setZero();
    uHeld.setZero();
  }

  // Keeps the LAST failure of a CVode call: after a recoverable failure CVODES retries with ever
  // smaller steps, so the last failing point is the closest to where the integration stuck.
  void fail(SimulationStatus s, double t, const Eigen::VectorXd& state, std::string message) {
    failed = true;
    failStatus = s;
    failTime = t;
    failState = state;
    failMessage = std::move(message);
  }

  /// out = sat(π(t, xs)); false (failure recorded) if the policy throws or returns a bad u.
  bool control(double t, const Eigen::VectorXd& xs, Eigen::VectorXd& out, bool& clipped) {
    try {
      policy(t, xs, out);
    } catch (const std::exception& e) {
      fail(SimulationStatus::kPolicyFailure, t, xs, std::string("the policy threw: ") + e.what());
      return false;
    } catch (...) {
      fail(SimulationStatus::kPolicyFailure, t, xs, "the policy threw an unknown exception");
      return false;
    }
    if (out.size() != m) {
      fail(SimulationStatus::kPolicyFailure, t, xs,
           "the policy returned u of size " + std::to_string(out.size()) + ", expected " +
               std::to_string(m));
      return false;
    }
    if (!out.allFinite()) {
      fail(SimulationStatus::kNonFinite, t, xs,
           "the policy returned a non-finite input u = " + formatVector(out));
      return false;
    }
    clipped = false;
    if (bounded) {
      for (int i = 0; i < m; ++i) {
        if (out(i) < lower(i)) {
          out(i) = lower(i);
          clipped = true;
        } else if (out(i) > upper(i)) {
          out(i) = upper(i);
          clipped = true;
        }
      }
    }
    return true;
  }

  void resetCallState() {
    failed = false;
    aborted = false;
    failuresThisCall = 0;
    cvodeMessage.clear();
  }

  int failureReturn() {
    if (failStatus == SimulationStatus::kPolicyFailure ||
        ++failuresThisCall >= kMaxRecoverableFailures) {
      aborted = true;
    }
    return aborted ? -1 : 1;
  }

  // ẋ = [q̇; q̈(q, q̇, u)].
  static int rhs(double t, N_Vector yv, N_Vector ydotv, void* user) {
    auto& s = *static_cast<Simulator*>(user);
    if (s.aborted) return -1;
    const Eigen::Index nx = 2 * s.n;
    s.x = Eigen::Map<const Eigen::VectorXd>(N_VGetArrayPointer(yv), nx);
    if (!s.x.allFinite()) {
      s.fail(SimulationStatus::kNonFinite, t, s.x, "the state became non-finite");
      return s.failureReturn();
    }
    if (s.sampled) {
      s.u = s.uHeld;
    } else {
      bool clipped = false;
      if (!s.control(t, s.x, s.u, clipped)) return s.failureReturn();
    }
    s.q = s.x.head(s.n);
    s.dq = s.x.tail(s.n);
    computeDynamics(s.model, s.data, s.q, s.dq, s.u);
    const DynamicsStatus& st = s.data.status;
    if (!st.ok()) {
      s.fail(st.code == DynamicsStatus::Code::kNonFinite ? SimulationStatus::kNonFinite
                                                         : SimulationStatus::kDynamicsFailure,
             t, s.x, "computeDynamics failed: " + st.message);
      return s.failureReturn();
    }
    Eigen::Map<Eigen::VectorXd> out(N_VGetArrayPointer(ydotv), nx);
    out.head(s.n) = s.dq;
    out.tail(s.n) = s.data.qdd;
    return 0;
  }

  static void errorHandler(int code, const char* module, const char* function, char* msg,
                           void* user) {
    auto& s = *static_cast<Simulator*>(user);
    if (code < 0) s.cvodeMessage = std::string(module) + "::" + function + ": " + msg;
  }
};

struct Event {
  double t;
  bool output = false;   // record x, u here
  bool restart = false;  // a kink or a projection point: the integration ends and restarts here
  bool sample = false;   // a new held input is computed here
};

}  // namespace

ConstraintProjection projectOntoConstraints(const Model& model, Eigen::VectorXd& x,
                                            int maxIterations) {
  if (x.size() != 2 * model.nq()) {
    throw std::invalid_argument("projectOntoConstraints: x has size " + std::to_string(x.size()) +
                                ", expected 2n = " + std::to_string(2 * model.nq()));
  }
  if (maxIterations < 1) {
    throw std::invalid_argument("projectOntoConstraints: maxIterations = " +
                                std::to_string(maxIterations) + " must be >= 1");
  }
  ConstraintProjector projector(model);
  return projector.project(x, maxIterations);
}

SimulationResult simulate(const Model& model, const Eigen::VectorXd& x0, double t0, double t1,
                          const Policy& policy, const SimulationOptions& options,
                          const Trajectory* reference) {
  options.validate();
  const int n = model.nq(), m = model.nu(), nx = 2 * n;
  if (!policy) throw std::invalid_argument("simulate: empty policy");
  if (!std::isfinite(t0) || !std::isfinite(t1) || !(t0 < t1)) {
    throw std::invalid_argument("simulate: need finite t0 < t1, got t0 = " + formatTime(t0) +
                                ", t1 = " + formatTime(t1));
  }
  if (x0.size() != nx) {
    throw std::invalid_argument("simulate: x0 has size " + std::to_string(x0.size()) +
                                ", expected 2n = " + std::to_string(nx));
  }
  for (Eigen::Index i = 0; i < nx; ++i) {
    if (!std::isfinite(x0(i))) {
      throw std::invalid_argument("simulate: x0[" + std::to_string(i) +
                                  "] = " + std::to_string(x0(i)) + " is not finite");
    }
  }
  for (const auto* bound : {&options.inputLower, &options.inputUpper}) {
    if (bound->size() != 0 && bound->size() != m) {
      throw std::invalid_argument(std::string("simulate: SimulationOptions.") +
                                  (bound == &options.inputLower ? "inputLower" : "inputUpper") +
                                  " has size " + std::to_string(bound->size()) +
                                  ", expected the model's " + std::to_string(m) +
                                  " inputs (or empty)");
    }
  }
  const double scale = std::max({1.0, std::abs(t0), std::abs(t1)});
  const double mergeTol = 1e-10 * scale;
  Trajectory referenceCopy;
  if (reference) {
    reference->checkCompatible(model);
    if (reference->startTime() > t0 + 1e-12 * scale || reference->endTime() < t1 - 1e-12 * scale) {
      throw std::invalid_argument("simulate: the reference covers [" +
                                  formatTime(reference->startTime()) + ", " +
                                  formatTime(reference->endTime()) + "], which does not contain [" +
                                  formatTime(t0) + ", " + formatTime(t1) + "]");
    }
    if (!reference->hasStateDerivatives()) {
      referenceCopy = *reference;
      Data d(model);
      referenceCopy.computeStateDerivatives(model, d);
      reference = &referenceCopy;
    }
  } else if (options.outputStep == 0.0) {
    throw std::invalid_argument(
        "simulate: SimulationOptions.outputStep = 0 (output at the reference's knots) needs a "
        "reference; give outputStep > 0");
  }

  // Event lists are materialized: refuse grids that would not fit in memory.
  constexpr double kMaxEvents = 1e7;
  if (options.outputStep > 0.0 && (t1 - t0) / options.outputStep > kMaxEvents) {
    throw std::invalid_argument("simulate: SimulationOptions.outputStep = " +
                                formatTime(options.outputStep) + " gives more than 1e7 outputs");
  }
  if (options.sampleRate > 0.0 && (t1 - t0) * options.sampleRate > kMaxEvents) {
    throw std::invalid_argument("simulate: SimulationOptions.sampleRate = " +
                                formatTime(options.sampleRate) + " gives more than 1e7 samples");
  }

  // ---- Event times ------------------------------------------------------------------------------
  const bool constrained = model.nc() > 0;
  const bool projecting = constrained && options.constraints == ConstraintHandling::kProject;
  const bool sampled = options.sampleRate > 0.0;
  std::vector<Event> events;
  auto inside = [&](double t) { return t > t0 + mergeTol && t < t1 - mergeTol; };
  events.push_back({t0, true, true, sampled});
  events.push_back({t1, true, true, false});
  if (options.outputStep > 0.0) {
    for (long k = 1;; ++k) {
      const double t = t0 + static_cast<double>(k) * options.outputStep;
      if (!inside(t)) break;
      events.push_back({t, true, projecting, false});
    }
  } else {  // the knots, which the loop below also makes restart points
    for (Eigen::Index k = 0; k < reference->size(); ++k) {
      const double t = reference->times()(k);
      if (inside(t)) events.push_back({t, true, false, false});
    }
  }
  if (reference) {
    for (Eigen::Index k = 0; k < reference->size(); ++k) {
      if (inside(reference->times()(k)))
        events.push_back({reference->times()(k), false, true, false});
    }
  }
  for (double t : options.breakpoints) {
    if (inside(t)) events.push_back({t, false, true, false});
  }
  if (sampled) {
    const double h = 1.0 / options.sampleRate;
    for (long k = 1;; ++k) {
      const double t = t0 + static_cast<double>(k) * h;
      if (!inside(t)) break;
      events.push_back({t, false, true, true});
    }
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const Event& a, const Event& b) { return a.t < b.t; });
  std::vector<Event> merged;
  for (const Event& e : events) {
    if (!merged.empty() && e.t - merged.back().t <= mergeTol) {
      Event& last = merged.back();
      last.output |= e.output;
      last.restart |= e.restart;
      last.sample |= e.sample;
    } else {
      merged.push_back(e);
    }
  }
  merged.front().t = t0;
  merged.back().t = t1;  // t1 may have merged into an earlier time within the tolerance
  for (Event& e : merged) {
    if (e.output && projecting) e.restart = true;
  }

  // ---- Outputs ----------------------------------------------------------------------------------
  const auto nOut =
      std::count_if(merged.begin(), merged.end(), [](const Event& e) { return e.output; });
  std::vector<double> outTimes;
  outTimes.reserve(static_cast<std::size_t>(nOut));
  Eigen::MatrixXd outStates(nx, nOut), outInputs(m, nOut);
  Eigen::VectorXd drift = Eigen::VectorXd::Zero(nOut), tracking(reference ? nOut : 0);
  Eigen::VectorXd xr(nx), ur(m);

  SimulationResult result;
  Simulator sim(model, policy, options);
  std::unique_ptr<ConstraintProjector> projector;
  if (constrained) projector = std::make_unique<ConstraintProjector>(model);

  // ---- CVODES -----------------------------------------------------------------------------------
  detail::CvodeSession cv;
  cv.context.reset(detail::createContext());
  SUNContext ctx = cv.context.get();
  cv.y.reset(N_VNew_Serial(nx, ctx));
  if (!cv.y) throw std::runtime_error("simulate: N_VNew_Serial failed");
  double* y = N_VGetArrayPointer(cv.y.get());
  Eigen::Map<Eigen::VectorXd> yMap(y, nx);
  const bool bdf = options.method == IntegrationMethod::kBDF;
  cv.cvode.reset(CVodeCreate(bdf ? CV_BDF : CV_ADAMS, ctx));
  void* mem = cv.cvode.get();
  if (!mem) throw std::runtime_error("simulate: CVodeCreate failed");
  auto check = [&](int flag, const char* call) {
    if (flag < 0) {
      throw std::runtime_error(std::string("simulate: ") + call + " failed with flag " +
                               std::to_string(flag) + ": " + sim.cvodeMessage);
    }
  };
  check(CVodeSetErrHandlerFn(mem, &Simulator::errorHandler, &sim), "CVodeSetErrHandlerFn");
  yMap = x0;
  check(CVodeInit(mem, &Simulator::rhs, t0, cv.y.get()), "CVodeInit");
  check(CVodeSStolerances(mem, options.rtol, options.atol), "CVodeSStolerances");
  check(CVodeSetUserData(mem, &sim), "CVodeSetUserData");
  if (options.maxStep > 0) check(CVodeSetMaxStep(mem, options.maxStep), "CVodeSetMaxStep");
  if (bdf) {
    cv.jacobian.reset(SUNDenseMatrix(nx, nx, ctx));
    cv.linearSolver.reset(SUNLinSol_Dense(cv.y.get(), cv.jacobian.get(), ctx));
    if (!cv.jacobian || !cv.linearSolver) throw std::runtime_error("simulate: dense solver");
    check(CVodeSetLinearSolver(mem, cv.linearSolver.get(), cv.jacobian.get()),
          "CVodeSetLinearSolver");
  } else {
    cv.nonlinearSolver.reset(SUNNonlinSol_FixedPoint(cv.y.get(), 0, ctx));
    if (!cv.nonlinearSolver) throw std::runtime_error("simulate: fixed-point solver");
    check(CVodeSetNonlinearSolver(mem, cv.nonlinearSolver.get()), "CVodeSetNonlinearSolver");
  }

  // CVodeReInit resets CVODES' counters: collect them before each restart and at the end.
  auto harvestCounters = [&]() {
    long v = 0;
    if (CVodeGetNumSteps(mem, &v) >= 0) result.steps += v;
    if (CVodeGetNumRhsEvals(mem, &v) >= 0) result.rhsEvaluations += v;
    if (bdf && CVodeGetNumLinRhsEvals(mem, &v) >= 0) result.rhsEvaluations += v;
  };
  auto setFailure = [&](SimulationStatus s, double t, const Eigen::VectorXd& state,
                        const std::string& what) {
    result.status = s;
    result.failureTime = t;
    result.failureState = state;
    result.message =
        "simulation stopped at t = " + formatTime(t) + ", x = " + formatVector(state) + ": " + what;
  };

  Eigen::VectorXd x = x0;
  bool initialized = false;
  for (std::size_t e = 0; e < merged.size(); ++e) {
    const Event& ev = merged[e];
    const double te = ev.t;
    // 1. drift (before projecting), projection
    double d = 0.0;
    if (constrained && (ev.output || projecting)) {
      d = projector->drift(x);
      result.maxConstraintDrift = std::max(result.maxConstraintDrift, d);
    }
    if (projecting) {
      projector->project(x, options.projectionIterations);
      ++result.projections;
      if (!x.allFinite()) {
        setFailure(SimulationStatus::kNonFinite, te, x,
                   "the constraint projection produced a non-finite state");
        break;
      }
    }
    // 2. a new sample of the held input
    sim.failed = false;
    if (ev.sample) {
      bool clipped = false;
      if (!sim.control(te, x, sim.uHeld, clipped)) {
        setFailure(sim.failStatus, te, x, sim.failMessage);
        break;
      }
      ++result.controlSamples;
      if (clipped) ++result.saturatedSamples;
    }
    // 3. output
    if (ev.output) {
      const auto k = static_cast<Eigen::Index>(outTimes.size());
      outTimes.push_back(te);
      outStates.col(k) = x;
      drift(k) = d;
      if (sampled) {
        outInputs.col(k) = sim.uHeld;
      } else {
        bool clipped = false;
        if (!sim.control(te, x, sim.u, clipped)) {
          outTimes.pop_back();
          setFailure(sim.failStatus, te, x, sim.failMessage);
          break;
        }
        outInputs.col(k) = sim.u;
        ++result.controlSamples;
        if (clipped) ++result.saturatedSamples;
      }
      if (reference) {
        reference->evaluate(te, xr, ur);
        tracking(k) = (x - xr).norm();
      }
    }
    if (e + 1 == merged.size()) break;
    // 4. (re)start at a kink, a sample or a projected state; the stop time is the next restart
    if (!initialized || ev.restart) {
      yMap = x;
      // Also on the first event: CVodeInit copied the unprojected x0 into CVODES' history, and
      // x may have been projected since.
      if (initialized) {
        harvestCounters();
        ++result.restarts;
      }
      check(CVodeReInit(mem, te, cv.y.get()), "CVodeReInit");
      initialized = true;
      std::size_t next = e + 1;
      while (next + 1 < merged.size() && !merged[next].restart) ++next;
      check(CVodeSetStopTime(mem, merged[next].t), "CVodeSetStopTime");
    }
    // 5. integrate to the next event within the remaining step budget
    long stepsNow = 0;
    CVodeGetNumSteps(mem, &stepsNow);
    const long remaining = options.maxSteps - (result.steps + stepsNow);
    const double tnext = merged[e + 1].t;
    if (remaining <= 0) {
      setFailure(SimulationStatus::kIntegratorFailure, te, x,
                 "more than maxSteps = " + std::to_string(options.maxSteps) + " internal steps");
      break;
    }
    check(CVodeSetMaxNumSteps(mem, remaining), "CVodeSetMaxNumSteps");
    sim.resetCallState();
    double tret = te;
    const int flag = CVode(mem, tnext, cv.y.get(), &tret, CV_NORMAL);
    if (flag < 0) {
      char* name = CVodeGetReturnFlagName(flag);
      std::ostringstream what;
      const bool callbackFlag = flag == CV_RHSFUNC_FAIL || flag == CV_FIRST_RHSFUNC_ERR ||
                                flag == CV_REPTD_RHSFUNC_ERR || flag == CV_UNREC_RHSFUNC_ERR ||
                                flag == CV_CONV_FAILURE || flag == CV_LSETUP_FAIL ||
                                flag == CV_LSOLVE_FAIL || flag == CV_NLS_FAIL;
      if (sim.failed && callbackFlag) {
        what << sim.failMessage << "; ";
      } else if (flag == CV_TOO_MUCH_WORK) {
        what << "more than maxSteps = " << options.maxSteps << " internal steps; ";
      }
      what << "CVODES " << (name ? name : "error") << " (" << flag << ")";
      if (!sim.cvodeMessage.empty()) what << ": " << sim.cvodeMessage;
      if (sim.failed && !callbackFlag)
        what << " (last right-hand-side failure: " << sim.failMessage << ")";
      std::free(name);
      if (sim.failed && callbackFlag) {
        setFailure(sim.failStatus, sim.failTime, sim.failState, what.str());
      } else {
        double tcur = tret;
        CVodeGetCurrentTime(mem, &tcur);
        setFailure(SimulationStatus::kIntegratorFailure, tcur, Eigen::VectorXd(yMap), what.str());
      }
      break;
    }
    x = yMap;
    if (!x.allFinite()) {
      setFailure(SimulationStatus::kNonFinite, tret, x, "the state became non-finite");
      break;
    }
  }
  harvestCounters();

  // ---- Result -----------------------------------------------------------------------------------
  const auto recorded = static_cast<Eigen::Index>(outTimes.size());
  if (recorded > 0) {
    const Eigen::VectorXd times = Eigen::Map<const Eigen::VectorXd>(outTimes.data(), recorded);
    result.trajectory = Trajectory(model.configNames(), model.inputNames(), times,
                                   outStates.leftCols(recorded), outInputs.leftCols(recorded));
    Eigen::MatrixXd xdot(nx, recorded);
    bool derivativesOk = true;
    for (Eigen::Index k = 0; k < recorded && derivativesOk; ++k) {
      sim.q = outStates.col(k).head(n);
      sim.dq = outStates.col(k).tail(n);
      sim.u = outInputs.col(k);
      derivativesOk = computeDynamics(model, sim.data, sim.q, sim.dq, sim.u).ok();
      xdot.col(k).head(n) = sim.dq;
      xdot.col(k).tail(n) = sim.data.qdd;
    }
    if (derivativesOk && xdot.allFinite()) result.trajectory.setStateDerivatives(std::move(xdot));
  }
  result.constraintDrift = drift.head(recorded);
  result.trackingError = tracking.head(reference ? recorded : 0);
  result.saturatedFraction =
      result.controlSamples > 0
          ? static_cast<double>(result.saturatedSamples) / result.controlSamples
          : 0.0;
  return result;
}

namespace {

void checkGainsCover(const Trajectory& reference, const GainSchedule& gains) {
  if (gains.size() == 0) throw std::invalid_argument("simulateClosedLoop: empty gain schedule");
  if (gains.nu() != reference.nu() || gains.nx() != reference.nx()) {
    std::ostringstream m;
    m << "simulateClosedLoop: gains are " << gains.nu() << "x" << gains.nx()
      << ", expected m x 2n = " << reference.nu() << "x" << reference.nx();
    throw std::invalid_argument(m.str());
  }
  const double slack =
      1e-12 * std::max({1.0, std::abs(reference.startTime()), std::abs(reference.endTime())});
  if (gains.startTime() > reference.startTime() + slack ||
      gains.endTime() < reference.endTime() - slack) {
    throw std::invalid_argument("simulateClosedLoop: the gain schedule covers [" +
                                formatTime(gains.startTime()) + ", " + formatTime(gains.endTime()) +
                                "], the reference needs [" + formatTime(reference.startTime()) +
                                ", " + formatTime(reference.endTime()) + "]");
  }
}

}  // namespace

SimulationResult simulateClosedLoop(const Model& model, const Trajectory& reference,
                                    const GainSchedule& gains, const Eigen::VectorXd& x0,
                                    const SimulationOptions& options) {
  reference.checkCompatible(model);
  checkGainsCover(reference, gains);
  // The policy owns a copy of the reference (with state derivatives) and its scratch buffers.
  struct State {
    Trajectory reference;
    GainSchedule gains;
    Eigen::VectorXd xr, ur, dx;
    Eigen::MatrixXd K;
  };
  auto st = std::make_shared<State>(
      State{reference, gains, Eigen::VectorXd(reference.nx()), Eigen::VectorXd(reference.nu()),
            Eigen::VectorXd(reference.nx()), Eigen::MatrixXd(gains.nu(), gains.nx())});
  if (!st->reference.hasStateDerivatives()) {
    Data d(model);
    st->reference.computeStateDerivatives(model, d);
  }
  const Policy policy = [st](double t, const Eigen::VectorXd& x, Eigen::VectorXd& u) {
    st->reference.evaluate(t, st->xr, st->ur);
    st->gains.evaluate(t, st->K);
    st->dx = x - st->xr;
    u = st->ur;
    u.noalias() -= st->K * st->dx;
  };
  SimulationOptions opt = options;
  opt.breakpoints.insert(opt.breakpoints.end(), gains.times().data(),
                         gains.times().data() + gains.size());
  return simulate(model, x0, st->reference.startTime(), st->reference.endTime(), policy, opt,
                  &st->reference);
}

SimulationResult simulateOpenLoop(const Model& model, const Trajectory& reference,
                                  const Eigen::VectorXd& x0, const SimulationOptions& options) {
  reference.checkCompatible(model);
  struct State {
    Trajectory reference;
    Eigen::VectorXd xr;
  };
  auto st = std::make_shared<State>(State{reference, Eigen::VectorXd(reference.nx())});
  if (!st->reference.hasStateDerivatives()) {
    Data d(model);
    st->reference.computeStateDerivatives(model, d);
  }
  const Policy policy = [st](double t, const Eigen::VectorXd&, Eigen::VectorXd& u) {
    st->reference.evaluate(t, st->xr, u);
  };
  return simulate(model, x0, st->reference.startTime(), st->reference.endTime(), policy, options,
                  &st->reference);
}

}  // namespace trellis
