// optimizer.cpp — Ipopt's TNLP over a Transcription (Ipopt stays in this file).
#include "trellis/optimization/optimizer.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/reference.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <IpIpoptApplication.hpp>
#include <IpIpoptCalculatedQuantities.hpp>
#include <IpIpoptData.hpp>
#include <IpTNLP.hpp>

#include "ipopt_status.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

void OptimizerOptions::validate() const {
  auto bad = [](const std::string& what) { throw std::invalid_argument("OptimizerOptions." + what); };
  if (printLevel < 0 || printLevel > 12) bad("printLevel = " + std::to_string(printLevel) + " must be in [0, 12]");
  if (maxIterations < 0) bad("maxIterations = " + std::to_string(maxIterations) + " must be >= 0");
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) bad("tolerance must be > 0 and finite");
  if (!(constraintTolerance > 0.0) || !std::isfinite(constraintTolerance)) {
    bad("constraintTolerance must be > 0 and finite");
  }
  if (!(maxCpuTime > 0.0)) bad("maxCpuTime must be > 0");
  if (limitedMemorySize < 1) bad("limitedMemorySize = " + std::to_string(limitedMemorySize) + " must be >= 1");
  if (threads < 1 || threads > Transcription::kMaxThreads) {
    bad("threads = " + std::to_string(threads) + " must be in 1.." + std::to_string(Transcription::kMaxThreads));
  }
  if (static_cast<int>(ordering) < 0 || static_cast<int>(ordering) > static_cast<int>(MumpsOrdering::kQamd)) {
    bad("ordering = " + std::to_string(static_cast<int>(ordering)) + " is not a MumpsOrdering");
  }
  if (!(consistencyTolerance > 0.0) || !std::isfinite(consistencyTolerance)) {
    bad("consistencyTolerance must be > 0 and finite");
  }
  if (maxRefinements < 0) bad("maxRefinements = " + std::to_string(maxRefinements) + " must be >= 0");
  if (maxKnots < 2) bad("maxKnots = " + std::to_string(maxKnots) + " must be >= 2");
  if (!(initialBarrier > 0.0) || !std::isfinite(initialBarrier)) bad("initialBarrier = " + std::to_string(initialBarrier) + " must be > 0 and finite");
  if (!(initialBoundPush > 0.0) || !(initialBoundPush < 1.0)) bad("initialBoundPush = " + std::to_string(initialBoundPush) + " must be in (0, 1)");
  if (!(warmStartBarrier > 0.0) || !std::isfinite(warmStartBarrier)) {
    bad("warmStartBarrier must be > 0 and finite");
  }
  if (maxSplit < 2) bad("maxSplit = " + std::to_string(maxSplit) + " must be >= 2");
  if (refinementBand < 0) bad("refinementBand = " + std::to_string(refinementBand) + " must be >= 0");
  if (!(refinementGrading == 0.0 || (refinementGrading > 1.0 && std::isfinite(refinementGrading)))) {
    bad("refinementGrading = " + std::to_string(refinementGrading) + " must be 0 (off) or > 1 and finite");
  }
  if (!(unresolvedDefect > 0.0)) {
    bad("unresolvedDefect must be > 0 (infinity: never refine everywhere)");
  }
}

namespace {

using Ipopt::Index;
using Ipopt::Number;

// Ipopt reads bounds beyond ±1e19 (nlp_lower/upper_bound_inf) as no bound.
constexpr double kIpoptInfinity = 1e20;

/// Where Ipopt starts: the primal point, and with `multipliers` the constraint multipliers and
/// the bound multipliers z_L, z_U (Ipopt's warm_start_init_point).
struct StartPoint {
  Eigen::VectorXd z, lambda, zLower, zUpper;
  bool multipliers = false;
};

/// Adds the wall time of its scope to `total` (the result's time split).
class Timer {
 public:
  explicit Timer(double& total) : total_(total), start_(std::chrono::steady_clock::now()) {}
  ~Timer() { total_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }
  Timer(const Timer&) = delete;
  Timer& operator=(const Timer&) = delete;

 private:
  double& total_;
  std::chrono::steady_clock::time_point start_;
};

/// The TNLP: forwards every evaluation to the Transcription and keeps the final iterate and
/// multipliers. Nothing may throw through Ipopt: evaluation failures return false (Ipopt then
/// shortens the step).
class CollocationNlp : public Ipopt::TNLP {
 public:
  CollocationNlp(Transcription& transcription, const OptimizerOptions& options, bool exactHessian,
                 StartPoint start)
      : t_(transcription), options_(options), exactHessian_(exactHessian), start_(std::move(start)) {
    t_.variableBounds(lower_, upper_);
    t_.constraintBounds(gLower_, gUpper_);
    finalZ_ = start_.z;
    finalLambda_ = Eigen::VectorXd::Zero(t_.numConstraints());
    finalZL_ = finalZU_ = Eigen::VectorXd::Zero(t_.numVariables());
  }

  bool get_nlp_info(Index& n, Index& m, Index& nnz_jac_g, Index& nnz_h_lag,
                    IndexStyleEnum& index_style) override {
    n = t_.numVariables();
    m = t_.numConstraints();
    nnz_jac_g = static_cast<Index>(t_.jacobianRows().size());
    // Limited-memory quasi-Newton: eval_h is never called.
    nnz_h_lag = exactHessian_ ? static_cast<Index>(t_.hessianRows().size()) : 0;
    index_style = C_STYLE;
    return true;
  }

  bool get_bounds_info(Index n, Number* x_l, Number* x_u, Index m, Number* g_l,
                       Number* g_u) override {
    for (Index i = 0; i < n; ++i) {
      x_l[i] = std::max(lower_(i), -kIpoptInfinity);
      x_u[i] = std::min(upper_(i), kIpoptInfinity);
    }
    // Equalities g(z) = 0, and the constraint-force rows between their bounds.
    for (Index i = 0; i < m; ++i) {
      g_l[i] = std::max(gLower_(i), -kIpoptInfinity);
      g_u[i] = std::min(gUpper_(i), kIpoptInfinity);
    }
    return true;
  }

  bool get_starting_point(Index n, bool init_x, Number* x, bool init_z, Number* z_L, Number* z_U,
                          Index m, bool init_lambda, Number* lambda) override {
    if ((init_z || init_lambda) && !start_.multipliers) return false;
    if (init_x) std::copy(start_.z.data(), start_.z.data() + n, x);
    if (init_z) {
      std::copy(start_.zLower.data(), start_.zLower.data() + n, z_L);
      std::copy(start_.zUpper.data(), start_.zUpper.data() + n, z_U);
    }
    if (init_lambda) std::copy(start_.lambda.data(), start_.lambda.data() + m, lambda);
    return true;
  }

  bool eval_f(Index, const Number* x, bool, Number& obj_value) override {
    const Timer timer(evaluationTime_);
    return t_.evalCost(x, obj_value);
  }
  bool eval_grad_f(Index, const Number* x, bool, Number* grad_f) override {
    const Timer timer(evaluationTime_);
    return t_.evalCostGradient(x, grad_f);
  }
  bool eval_g(Index, const Number* x, bool, Index, Number* g) override {
    const Timer timer(evaluationTime_);
    return noteFailure(t_.evalConstraints(x, g));
  }
  bool eval_jac_g(Index, const Number* x, bool, Index, Index nele_jac, Index* iRow, Index* jCol,
                  Number* values) override {
    if (values == nullptr) {  // structure call
      const std::vector<int>& rows = t_.jacobianRows();
      const std::vector<int>& cols = t_.jacobianCols();
      for (Index k = 0; k < nele_jac; ++k) {
        iRow[k] = rows[k];
        jCol[k] = cols[k];
      }
      return true;
    }
    const Timer timer(evaluationTime_);
    return noteFailure(t_.evalJacobian(x, values));
  }
  bool eval_h(Index, const Number* x, bool, Number obj_factor, Index, const Number* lambda, bool,
              Index nele_hess, Index* iRow, Index* jCol, Number* values) override {
    if (values == nullptr) {  // structure call (lower triangle)
      const std::vector<int>& rows = t_.hessianRows();
      const std::vector<int>& cols = t_.hessianCols();
      for (Index k = 0; k < nele_hess; ++k) {
        iRow[k] = rows[k];
        jCol[k] = cols[k];
      }
      return true;
    }
    const Timer timer(evaluationTime_), hessianTimer(hessianTime_);
    return noteFailure(t_.evalHessian(x, obj_factor, lambda, values));
  }

  bool intermediate_callback(Ipopt::AlgorithmMode mode, Index iter, Number obj_value,
                             Number inf_pr, Number inf_du, Number, Number, Number, Number, Number alpha_pr,
                             Index, const Ipopt::IpoptData*,
                             Ipopt::IpoptCalculatedQuantities*) override {
    iterations_ = iter;
    if (!options_.onIteration) return true;
    IterationInfo info;
    info.iteration = iter;
    info.cost = obj_value;
    info.constraintViolation = inf_pr;
    info.dualInfeasibility = inf_du;
    info.stepSize = alpha_pr;
    info.restoration = mode == Ipopt::RestorationPhaseMode;
    try {
      return options_.onIteration(info);
    } catch (...) {
      callbackError_ = "the onIteration callback threw; the solve was stopped";
      return false;
    }
  }

  void finalize_solution(Ipopt::SolverReturn, Index n, const Number* x, const Number* z_L,
                         const Number* z_U, Index m, const Number*, const Number* lambda, Number,
                         const Ipopt::IpoptData*, Ipopt::IpoptCalculatedQuantities*) override {
    if (x != nullptr) finalZ_ = Eigen::Map<const Eigen::VectorXd>(x, n);
    haveFinal_ = x != nullptr;
    if (z_L != nullptr) finalZL_ = Eigen::Map<const Eigen::VectorXd>(z_L, n);
    if (z_U != nullptr) finalZU_ = Eigen::Map<const Eigen::VectorXd>(z_U, n);
    if (lambda != nullptr) finalLambda_ = Eigen::Map<const Eigen::VectorXd>(lambda, m);
  }

  const Eigen::VectorXd& finalVariables() const { return finalZ_; }
  const Eigen::VectorXd& finalLambda() const { return finalLambda_; }
  const Eigen::VectorXd& finalLowerMultipliers() const { return finalZL_; }
  const Eigen::VectorXd& finalUpperMultipliers() const { return finalZU_; }
  bool haveFinal() const { return haveFinal_; }
  int iterations() const { return iterations_; }
  double evaluationTime() const { return evaluationTime_; }  ///< wall seconds inside the evaluations
  double hessianTime() const { return hessianTime_; }        ///< of which the Hessian's
  const std::string& evaluationError() const { return evaluationError_; }
  const std::string& callbackError() const { return callbackError_; }

 private:
  bool noteFailure(bool ok) {
    if (!ok) evaluationError_ = t_.lastError();
    return ok;
  }

  Transcription& t_;
  const OptimizerOptions& options_;
  bool exactHessian_;
  StartPoint start_;
  Eigen::VectorXd lower_, upper_, gLower_, gUpper_, finalZ_, finalLambda_, finalZL_, finalZU_;
  bool haveFinal_ = false;
  int iterations_ = 0;
  double evaluationTime_ = 0.0, hessianTime_ = 0.0;
  std::string evaluationError_, callbackError_;
};

}  // namespace

namespace {

/// The τ of every point (knots, and for Hermite–Simpson the interval midpoints, in time order)
/// and its quadrature weight over T (Simpson Δτ/6, 4Δτ/6, Δτ/6; trapezoid Δτ/2, Δτ/2).
void pointFractions(const Eigen::VectorXd& tau, bool hs, Eigen::VectorXd& s, Eigen::VectorXd& w) {
  const int N = static_cast<int>(tau.size());
  const int P = hs ? 2 * N - 1 : N;
  s.resize(P);
  w = Eigen::VectorXd::Zero(P);
  const double c = hs ? 1.0 / 6.0 : 0.5;
  for (int k = 0; k < N; ++k) {
    const int p = hs ? 2 * k : k;
    s(p) = tau(k);
    if (k > 0) w(p) += c * (tau(k) - tau(k - 1));
    if (k + 1 < N) w(p) += c * (tau(k + 1) - tau(k));
    if (hs && k + 1 < N) {
      s(p + 1) = 0.5 * (tau(k) + tau(k + 1));
      w(p + 1) = 4.0 / 6.0 * (tau(k + 1) - tau(k));
    }
  }
}

/// Linear interpolation of the columns of `values` (at the increasing abscissae `at`) at x.
template <class Out>
void interpolateColumns(const Eigen::VectorXd& at, const Eigen::MatrixXd& values, double x, Out&& out) {
  const int n = static_cast<int>(at.size());
  if (n == 1 || x <= at(0)) {
    out = values.col(0);
    return;
  }
  if (x >= at(n - 1)) {
    out = values.col(n - 1);
    return;
  }
  const int k = static_cast<int>(std::upper_bound(at.data(), at.data() + n, x) - at.data()) - 1;
  const double a = (x - at(k)) / (at(k + 1) - at(k));
  out = (1.0 - a) * values.col(k) + a * values.col(k + 1);
}

/// The previous round's solution carried onto a refined mesh (the new knots subdivide the old
/// intervals): `z` from the new transcription's guess (the old solution's Hermite spline, refine()),
/// and the multipliers by what they approximate. The Simpson (trapezoid) multipliers λ_S
/// approximate the costate (∂L/∂x_b = λ_S,k − λ_S,k+1 + O(h)), so they are interpolated in
/// time between interval centres; the Hermite and input-row multipliers balance O(h) terms
/// (∂L/∂x_m = λ_H − 4h/6 f_xᵀ λ_S + …) and the bound multipliers of a point balance its
/// quadrature-weighted gradient, so those are interpolated as densities (divided by h, or by the
/// point's weight) and multiplied back on the new mesh. Knot-row multipliers are interpolated
/// between knots; the slack's and T's bound multipliers keep their values.
StartPoint carryOver(const Transcription& now, const OptimalControlProblem& before, const OptimizationResult& r) {
  StartPoint start;
  start.z = now.initialGuess();
  const OptimalControlProblem& p = now.problem();
  // The implicit form's layout (q̈, λ per point, its rows) is not carried: a cold start from the
  // previous solution's trajectory (the refined problem's initial guess).
  if (p.dynamics == DynamicsForm::kImplicit || before.dynamics == DynamicsForm::kImplicit) return start;
  // Radau's layout (3 points and 3nx + 2m rows per interval) is not carried either: a cold start.
  if (p.method == CollocationMethod::kRadau || before.method == CollocationMethod::kRadau) return start;
  const bool hs = p.method == CollocationMethod::kHermiteSimpson;
  const int nx = p.nx(), m = p.nu(), nc = p.model->nc();
  const int rowsPer = hs ? 2 * nx + m : nx;
  const Eigen::VectorXd tauOld = before.meshFractions(), tauNew = p.meshFractions();
  const int No = static_cast<int>(tauOld.size()), Nn = static_cast<int>(tauNew.size());
  const int F = now.forceRowsPerPoint();
  const int Pn0 = hs ? 2 * Nn - 1 : Nn, Po0 = hs ? 2 * No - 1 : No;
  const int knotRows = nc > 0 ? (now.numConstraints() - (Nn - 1) * rowsPer - Pn0 * F) / Nn : 0;
  if (r.constraintMultipliers.size() != (No - 1) * rowsPer + No * knotRows + Po0 * F ||
      r.lowerBoundMultipliers.size() != r.variables.size() || !r.constraintMultipliers.allFinite()) {
    return start;  // nothing usable to carry (Ipopt returned no multipliers)
  }
  // Interval quantities at the old centres, as densities where they scale with h.
  Eigen::VectorXd centres(No - 1);
  Eigen::MatrixXd intervalValues(rowsPer, No - 1);
  for (int k = 0; k + 1 < No; ++k) {
    const double dt = tauOld(k + 1) - tauOld(k);
    centres(k) = 0.5 * (tauOld(k) + tauOld(k + 1));
    intervalValues.col(k) = r.constraintMultipliers.segment(k * rowsPer, rowsPer);
    if (hs) intervalValues.col(k).tail(nx + m) /= dt;
  }
  start.lambda = Eigen::VectorXd::Zero(now.numConstraints());
  for (int k = 0; k + 1 < Nn; ++k) {
    const double dt = tauNew(k + 1) - tauNew(k);
    auto seg = start.lambda.segment(k * rowsPer, rowsPer);
    interpolateColumns(centres, intervalValues, 0.5 * (tauNew(k) + tauNew(k + 1)), seg);
    if (hs) seg.tail(nx + m) *= dt;
  }
  if (knotRows > 0) {
    Eigen::MatrixXd knotValues(knotRows, No);
    for (int k = 0; k < No; ++k) {
      knotValues.col(k) = r.constraintMultipliers.segment((No - 1) * rowsPer + k * knotRows, knotRows);
    }
    for (int k = 0; k < Nn; ++k) {
      auto seg = start.lambda.segment((Nn - 1) * rowsPer + k * knotRows, knotRows);
      interpolateColumns(tauOld, knotValues, tauNew(k), seg);
    }
  }
  // Bound multipliers of the point variables, and the multipliers of the constraint-force rows,
  // as densities over the quadrature weight.
  Eigen::VectorXd sOld, wOld, sNew, wNew;
  pointFractions(tauOld, hs, sOld, wOld);
  pointFractions(tauNew, hs, sNew, wNew);
  if (F > 0) {
    const int oldStart = (No - 1) * rowsPer + No * knotRows, newStart = now.forceRow(0);
    Eigen::MatrixXd density(F, Po0);
    for (int q = 0; q < Po0; ++q) density.col(q) = r.constraintMultipliers.segment(oldStart + q * F, F) / wOld(q);
    for (int q = 0; q < Pn0; ++q) {
      auto seg = start.lambda.segment(newStart + q * F, F);
      interpolateColumns(sOld, density, sNew(q), seg);
      seg *= wNew(q);
    }
  }
  const int stride = nx + m;
  const int Po = static_cast<int>(sOld.size()), Pn = static_cast<int>(sNew.size());
  start.zLower = Eigen::VectorXd::Zero(now.numVariables());
  start.zUpper = Eigen::VectorXd::Zero(now.numVariables());
  for (Eigen::VectorXd* out : {&start.zLower, &start.zUpper}) {
    const Eigen::VectorXd& old = out == &start.zLower ? r.lowerBoundMultipliers : r.upperBoundMultipliers;
    Eigen::MatrixXd density(stride, Po);
    for (int q = 0; q < Po; ++q) density.col(q) = old.segment(q * stride, stride) / wOld(q);
    for (int q = 0; q < Pn; ++q) {
      auto seg = out->segment(q * stride, stride);
      interpolateColumns(sOld, density, sNew(q), seg);
      seg *= wNew(q);
    }
    if (now.horizonIndex() >= 0) (*out)(now.horizonIndex()) = old(old.size() - 1);
  }
  start.multipliers = true;
  return start;
}

/// One Ipopt solve of `problem` (no check, no refinement): the fields of OptimizationResult that
/// describe the solve; `result.message` gets Ipopt's part of the story. With `previous` (the
/// last round's problem and result) the solve is warm-started from it (carryOver).
OptimizationResult solveOnce(const OptimalControlProblem& problem, const OptimizerOptions& options,
                             const OptimalControlProblem* previousProblem = nullptr,
                             const OptimizationResult* previous = nullptr) {
  Transcription transcription(problem, options.derivatives);  // validates the problem
  transcription.setThreads(options.threads);

  HessianMode hessian = options.hessian.value_or(problem.hessian);
  std::string hessianNote;
  if (hessian == HessianMode::kExact && !transcription.hessianAvailable()) {
    hessian = HessianMode::kLimitedMemory;
    hessianNote = "L-BFGS used: " + transcription.hessianUnavailableReason();
  }
  const bool warm = options.warmStart && previous != nullptr && previousProblem != nullptr;
  StartPoint start;
  if (warm) {
    start = carryOver(transcription, *previousProblem, *previous);
  } else {
    start.z = transcription.initialGuess();
  }
  Ipopt::SmartPtr<CollocationNlp> nlp =
      new CollocationNlp(transcription, options, hessian == HessianMode::kExact, start);
  Ipopt::SmartPtr<Ipopt::IpoptApplication> app = IpoptApplicationFactory();
  Ipopt::OptionsList& o = *app->Options();
  o.SetStringValue("sb", "yes");  // no banner
  o.SetIntegerValue("print_level", options.printLevel);
  o.SetIntegerValue("max_iter", options.maxIterations);
  o.SetNumericValue("tol", options.tolerance);
  o.SetNumericValue("constr_viol_tol", options.constraintTolerance);
  o.SetNumericValue("max_cpu_time", options.maxCpuTime);
  if (hessian == HessianMode::kExact) {
    o.SetStringValue("hessian_approximation", "exact");
  } else {
    o.SetStringValue("hessian_approximation", "limited-memory");
    o.SetIntegerValue("limited_memory_max_history", options.limitedMemorySize);
    // The L-BFGS Hessian σI + V Vᵀ makes each step a low-rank update of the KKT system. Ipopt's
    // default (Sherman–Morrison) pays 2·history extra MUMPS solves per iteration, and MUMPS's
    // per-call overhead dominates on these small systems; "extended" factorizes the KKT matrix
    // bordered by V once: the cart-pole swing-up (25 knots) takes half the CPU time, same iterates.
    o.SetStringValue("limited_memory_aug_solver", "extended");
  }
  o.SetStringValue("linear_solver", "mumps");
  {
    // ICNTL(7) codes: 0 AMD, 2 AMF, 3 SCOTCH, 4 PORD, 5 METIS, 6 QAMD, 7 automatic.
    constexpr int kCode[] = {7, 0, 2, 3, 4, 5, 6};
    o.SetIntegerValue("mumps_pivot_order", kCode[static_cast<int>(options.ordering)]);
  }
  if (!warm) {
    o.SetNumericValue("mu_init", options.initialBarrier);
    o.SetNumericValue("bound_push", options.initialBoundPush);
    o.SetNumericValue("bound_frac", std::min(0.5, options.initialBoundPush));
  }
  if (warm && start.multipliers) {
    // The carried point is close to the refined problem's solution: start there with the
    // multipliers, pushed only slightly off the bounds, and a small barrier parameter (a large
    // μ_init would first pull the iterate back to the centre of the bounds).
    o.SetStringValue("warm_start_init_point", "yes");
    o.SetNumericValue("warm_start_bound_push", 1e-9);
    o.SetNumericValue("warm_start_bound_frac", 1e-9);
    o.SetNumericValue("warm_start_slack_bound_push", 1e-9);
    o.SetNumericValue("warm_start_slack_bound_frac", 1e-9);
    o.SetNumericValue("warm_start_mult_bound_push", 1e-9);
    o.SetNumericValue("mu_init", options.warmStartBarrier);
  }

  OptimizationResult result;
  result.hessian = hessian;
  // "": no ipopt.opt from the working directory, so a solve depends only on its arguments.
  Ipopt::ApplicationReturnStatus status = app->Initialize("");
  if (status == Ipopt::Solve_Succeeded) status = app->OptimizeTNLP(nlp);

  result.ipoptStatus = detail::applicationStatusName(status);
  result.status.code = detail::classify(status);
  result.iterations = nlp->iterations();
  result.variables = nlp->finalVariables();
  result.evaluationTime = nlp->evaluationTime();
  result.hessianTime = nlp->hessianTime();
  result.constraintMultipliers = nlp->finalLambda();
  result.lowerBoundMultipliers = nlp->finalLowerMultipliers();
  result.upperBoundMultipliers = nlp->finalUpperMultipliers();
  const double* z = result.variables.data();
  result.horizon = transcription.horizon(z);
  transcription.evalCost(z, result.cost);
  Eigen::VectorXd g(transcription.numConstraints());
  std::ostringstream message;
  if (transcription.evalConstraints(z, g.data())) {
    Eigen::VectorXd gLower, gUpper;  // violation beyond each row's bounds (0 = 0 for equalities)
    transcription.constraintBounds(gLower, gUpper);
    result.constraintViolation =
        g.size() > 0 ? (gLower - g).cwiseMax(g - gUpper).cwiseMax(0.0).maxCoeff() : 0.0;
  } else {
    result.constraintViolation = std::numeric_limits<double>::quiet_NaN();
  }
  Eigen::VectorXd lower, upper;
  transcription.variableBounds(lower, upper);
  result.boundViolation = std::max(0.0, std::max((lower - result.variables).maxCoeff(),
                                                 (result.variables - upper).maxCoeff()));
  result.maxSlack = transcription.maxSlack(z);
  result.dynamicsEvaluations = transcription.dynamicsEvaluations();
  result.linearizationEvaluations = transcription.linearizationEvaluations();
  result.secondOrderEvaluations = transcription.secondOrderEvaluations();
  result.mesh = problem.meshFractions();
  std::string trajectoryError;
  try {
    result.trajectory = transcription.trajectory(z);
  } catch (const std::exception& e) {  // a non-finite last iterate: report, do not throw
    trajectoryError = e.what();
  }
  result.midpointStates = transcription.midpointStates(z);
  result.midpointInputs = transcription.midpointInputs(z);

  if (!result.ok()) {
    message << "Ipopt: " << result.ipoptStatus << " after " << result.iterations << " iterations, cost "
            << result.cost << ", constraint violation " << result.constraintViolation;
    if (result.status.code == OptimizationCode::kInfeasible) {
      message << ": Ipopt converged to a point of local infeasibility; the bounds, boundary states "
                 "and horizon admit no trajectory it can find (the last iterate is returned)";
    } else {
      message << "; the last iterate is returned";
    }
    if (!nlp->haveFinal()) message << "; Ipopt returned no iterate (the initial guess is returned)";
    if (!nlp->evaluationError().empty()) message << "; last evaluation failure: " << nlp->evaluationError();
    if (!nlp->callbackError().empty()) message << "; " << nlp->callbackError();
    if (!trajectoryError.empty()) message << "; no trajectory: " << trajectoryError;
  }
  result.status.message = message.str();
  result.hessianNote = hessianNote;
  return result;
}

std::string fmt(double v) {
  std::ostringstream s;
  s.precision(3);
  s << v;
  return s.str();
}

/// The slack's share of each interval's defect relative to the check's state scale (N − 1
/// entries, zeros without constraints); sets r.maxSlackDefect and r.worstSlackInterval.
Eigen::VectorXd measureSlack(const OptimalControlProblem& problem, const OptimizerOptions& options,
                             OptimizationResult& r) {
  Eigen::VectorXd share = Eigen::VectorXd::Zero(problem.knots - 1);
  r.maxSlackDefect = 0.0;
  r.worstSlackInterval = -1;
  if (problem.model->nc() == 0 || r.consistency.stateScale.size() == 0) return share;
  Transcription t(problem, options.derivatives);
  const Eigen::MatrixXd slack = t.slackContributions(r.variables.data());
  for (int k = 0; k < slack.cols(); ++k) {
    share(k) = slack.col(k).cwiseAbs().cwiseQuotient(r.consistency.stateScale).maxCoeff();
    if (share(k) > r.maxSlackDefect || r.worstSlackInterval < 0) {
      r.maxSlackDefect = share(k);
      r.worstSlackInterval = k;
    }
  }
  return share;
}

/// The refined mesh and a warm start on it (file comment of optimizer.hpp). Returns false when
/// the knot limit would be exceeded.
bool refine(OptimalControlProblem& problem, const OptimizationResult& r, const Eigen::VectorXd& errors,
            const OptimizerOptions& options) {
  const Eigen::VectorXd& tau = r.mesh;
  const std::vector<int> parts = refinementSplits(tau, errors, problem.method, options);
  std::vector<double> mesh{0.0};
  for (int k = 0; k + 1 < tau.size(); ++k) {
    for (int j = 1; j <= parts[k]; ++j) {
      mesh.push_back(j == parts[k] ? tau(k + 1) : tau(k) + (tau(k + 1) - tau(k)) * j / parts[k]);
    }
  }
  const int N = static_cast<int>(mesh.size());
  if (N > options.maxKnots || N == tau.size()) return false;
  // The solution as every reader sees it (knot derivatives from the dynamics), sampled on the new mesh.
  ReferenceOptions readers;
  readers.stateDerivatives = ReferenceOptions::StateDerivatives::kFromDynamics;
  ReferenceEvaluator previous(*problem.model, r.trajectory, readers);
  Eigen::VectorXd times(N);
  Eigen::MatrixXd states(problem.nx(), N), inputs(problem.nu(), N);
  for (int k = 0; k < N; ++k) {
    times(k) = r.horizon * mesh[k];
    previous.evaluate(std::min(times(k), previous.endTime()));
    states.col(k) = previous.x();
    inputs.col(k) = previous.u();
  }
  const Trajectory guess(problem.model->configNames(), problem.model->inputNames(), times, states, inputs);
  problem.initialGuess = ReferenceEvaluator(*problem.model, guess, readers).trajectory();
  problem.knots = N;
  problem.mesh = Eigen::Map<const Eigen::VectorXd>(mesh.data(), N);
  if (problem.freeHorizon()) problem.horizon = std::clamp(r.horizon, problem.minHorizon, problem.maxHorizon);
  return true;
}

}  // namespace

std::vector<int> refinementSplits(const Eigen::VectorXd& mesh, const Eigen::VectorXd& intervalDefects,
                                  CollocationMethod method, const OptimizerOptions& options) {
  options.validate();
  const int n = static_cast<int>(intervalDefects.size());
  if (mesh.size() != n + 1) {
    throw std::invalid_argument("refinementSplits: mesh has " + std::to_string(mesh.size()) +
                                " points for " + std::to_string(n) + " interval defects (expected " +
                                std::to_string(n + 1) + ")");
  }
  for (int k = 0; k < n; ++k) {
    if (!(mesh(k + 1) > mesh(k))) {
      throw std::invalid_argument("refinementSplits: mesh(" + std::to_string(k + 1) + ") = " + fmt(mesh(k + 1)) +
                                  " must be > mesh(" + std::to_string(k) + ") = " + fmt(mesh(k)));
    }
  }
  for (int k = 0; k < n; ++k) {
    if (!(intervalDefects(k) >= 0.0)) {  // NaN or negative: no defect to size a split by
      throw std::invalid_argument("refinementSplits: intervalDefects(" + std::to_string(k) + ") = " +
                                  fmt(intervalDefects(k)) + " must be >= 0");
    }
  }
  const double tol = options.consistencyTolerance;
  const double order = method == CollocationMethod::kTrapezoidal ? 3.0 : 5.0;  // p + 1 (Radau IIA: 6, taken as 5)
  std::vector<int> parts(n, 1);
  // 1. By the defect's order: ε ∝ h^(p+1), so M parts bring ε to ε / M^(p+1) ≤ tol/2.
  for (int k = 0; k < n; ++k) {
    if (intervalDefects(k) > tol) {
      const int m = static_cast<int>(std::ceil(std::pow(intervalDefects(k) / (0.5 * tol), 1.0 / order)));
      parts[k] = std::clamp(m, 2, options.maxSplit);
    }
  }
  // 2. Unresolved: a defect that is a sizeable share of the state's range says the motion is not
  // resolved at all (the order model does not hold, and the re-optimized motion is free to go
  // anywhere): every interval is halved.
  const bool unresolved = n > 0 && intervalDefects.maxCoeff() > options.unresolvedDefect;
  // 3. The safety band: the re-optimized motion moves its fast phase into the neighbours of the
  // intervals that were split, so those are halved too.
  std::vector<int> out = parts;
  for (int k = 0; k < n; ++k) {
    if (unresolved) out[k] = std::max(out[k], 2);
    if (parts[k] < 2) continue;
    const int from = std::max(0, k - options.refinementBand), to = std::min(n - 1, k + options.refinementBand);
    for (int j = from; j <= to; ++j) out[j] = std::max(out[j], 2);
  }
  // 4. Grading (opt-in): neighbouring new widths differ by at most the factor ρ (a forward and a
  // backward sweep, each interval still at most maxSplit parts), so no coarse interval sits next
  // to a fine one for a moving fast phase to settle in.
  if (options.refinementGrading > 0.0) {
    const double rho = options.refinementGrading;
    auto width = [&](int j) { return (mesh(j + 1) - mesh(j)) / out[j]; };
    for (int pass = 0; pass < 2; ++pass) {
      for (int step = 0; step + 1 < n; ++step) {
        const int j = pass == 0 ? step + 1 : n - 2 - step, i = pass == 0 ? j - 1 : j + 1;
        const double limit = rho * width(i);
        if (width(j) > limit * (1.0 + 1e-12)) {
          const int m = static_cast<int>(std::ceil((mesh(j + 1) - mesh(j)) / limit - 1e-9));
          out[j] = std::max(out[j], std::min(options.maxSplit, m));
        }
      }
    }
  }
  return out;
}

OptimizationResult optimizeTrajectory(const OptimalControlProblem& input,
                                      const OptimizerOptions& options) {
  options.validate();
  input.validate();
  OptimalControlProblem problem = input;
  ConsistencyOptions check;
  check.tolerance = options.consistencyTolerance;
  const auto start = std::chrono::steady_clock::now();
  const std::clock_t cpuStart = std::clock();
  OptimizationResult result;
  int iterations = 0;
  long dynamics = 0, linearizations = 0, secondOrder = 0;
  double evaluationTime = 0.0, hessianTime = 0.0, checkTime = 0.0;
  std::vector<RefinementRound> rounds;
  OptimalControlProblem previousProblem;
  for (int round = 0;; ++round) {
    const auto roundStart = std::chrono::steady_clock::now();
    if (round == 0) {
      result = solveOnce(problem, options);
    } else {
      OptimizationResult previous = std::move(result);
      result = solveOnce(problem, options, &previousProblem, &previous);
    }
    iterations += result.iterations;
    dynamics += result.dynamicsEvaluations;
    linearizations += result.linearizationEvaluations;
    secondOrder += result.secondOrderEvaluations;
    evaluationTime += result.evaluationTime;
    hessianTime += result.hessianTime;
    RefinementRound info;
    info.knots = problem.knots;
    info.iterations = result.iterations;
    info.hessian = result.hessian;
    info.ipoptStatus = result.ipoptStatus;
    info.maxDefect = std::numeric_limits<double>::quiet_NaN();
    info.maxSlackDefect = std::numeric_limits<double>::quiet_NaN();
    bool consistent = false;
    Eigen::VectorXd errors;
    if (result.ok() && result.trajectory.size() > 0) {
      const Timer timer(checkTime);
      result.consistency = checkConsistency(*problem.model, result.trajectory, check);
      const Eigen::VectorXd slackShare = measureSlack(problem, options, result);
      info.maxDefect = result.consistency.maxDefect;
      info.maxSlackDefect = result.maxSlackDefect;
      consistent = result.consistency.ok() && result.maxSlackDefect <= options.consistencyTolerance;
      if (result.consistency.checked()) errors = result.consistency.intervalDefects.cwiseMax(slackShare);
    }
    info.solveTime = std::chrono::duration<double>(std::chrono::steady_clock::now() - roundStart).count();
    rounds.push_back(info);
    if (!result.ok() || consistent) break;
    // Ipopt converged but the result is not consistent: refine or report.
    previousProblem = problem;
    const bool canRefine = round < options.maxRefinements && errors.size() > 0 &&
                           refine(problem, result, errors, options);
    if (!canRefine) {
      result.status.code = OptimizationCode::kInconsistent;
      std::ostringstream m;
      m << "Ipopt: " << result.ipoptStatus << ", " << problem.knots << " knots after " << round
        << " refinement round(s): ";
      if (result.consistency.status.code == ConsistencyCode::kInconsistent && result.consistency.worstInterval >= 0) {
        result.status.index = result.consistency.worstInterval;
        result.status.t = result.trajectory.times()(result.consistency.worstInterval);
      } else if (result.worstSlackInterval >= 0) {
        result.status.index = result.worstSlackInterval;
        result.status.t = result.trajectory.times()(result.worstSlackInterval);
      }
      if (!result.consistency.checked()) {
        m << "the consistency check could not run: " << result.consistency.status.message;
      } else if (!result.consistency.ok()) {
        m << result.consistency.status.message;
      } else {
        m << "the closed-chain slack carries " << fmt(result.maxSlackDefect)
          << " of the state's range (tolerance " << fmt(options.consistencyTolerance)
          << ") on interval " << result.worstSlackInterval << " [" 
          << fmt(result.trajectory.times()(result.worstSlackInterval)) << ", "
          << fmt(result.trajectory.times()(result.worstSlackInterval + 1)) << "]";
      }
      if (round >= options.maxRefinements) {
        m << " (refinement limit " << options.maxRefinements << " reached)";
      } else {
        m << " (the knot limit " << options.maxKnots << " would be exceeded)";
      }
      m << "; the last solution is returned";
      result.status.message = m.str();
      break;
    }
  }
  result.iterations = iterations;
  result.dynamicsEvaluations = dynamics;
  result.linearizationEvaluations = linearizations;
  result.secondOrderEvaluations = secondOrder;
  result.evaluationTime = evaluationTime;
  result.hessianTime = hessianTime;
  result.checkTime = checkTime;
  result.rounds = std::move(rounds);
  result.solveTime = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  result.solveCpuTime = static_cast<double>(std::clock() - cpuStart) / CLOCKS_PER_SEC;
  if (result.ok()) result.status.message.clear();
  return result;
}

std::string OptimizationResult::describe() const {
  std::ostringstream s;
  s << status.describe() << " (Ipopt: " << ipoptStatus << ", " << iterations << " iterations in "
    << rounds.size() << " round(s), " << trajectory.size() << " knots, cost " << formatStatusNumber(cost)
    << ", constraint violation " << fmt(constraintViolation) << ", consistency defect "
    << (consistency.checked() ? fmt(consistency.maxDefect) : std::string("not checked"));
  if (worstSlackInterval >= 0) s << ", slack share " << fmt(maxSlackDefect);
  s << ", " << toString(hessian) << " Hessian, " << fmt(solveTime) << " s)";
  if (!hessianNote.empty()) s << "; " << hessianNote;
  return s.str();
}

std::string OptimizationResult::json() const {
  detail::ReportJson j = detail::statusJson(status);
  using detail::toJson;
  j["ipopt_status"] = ipoptStatus;
  j["iterations"] = iterations;
  j["cost"] = toJson(cost);
  j["constraint_violation"] = toJson(constraintViolation);
  j["bound_violation"] = toJson(boundViolation);
  j["max_slack"] = toJson(maxSlack);
  j["horizon"] = toJson(horizon);
  j["knots"] = trajectory.size();
  j["hessian"] = toString(hessian);
  if (!hessianNote.empty()) j["hessian_note"] = hessianNote;
  // null when the check did not run (Ipopt failed first, or an interval could not be
  // integrated): a 0 would claim a consistency nobody measured.
  j["consistency_defect"] = consistency.checked() ? toJson(consistency.maxDefect) : detail::ReportJson(nullptr);
  j["consistency_checked"] = consistency.checked();
  if (consistency.checked() && consistency.worstInterval >= 0) {
    j["consistency_where"] = {{"state", consistency.worstStateName},
                              {"interval", consistency.worstInterval},
                              {"time", toJson(consistency.worstTime)}};
  }
  if (worstSlackInterval >= 0) j["slack_defect"] = toJson(maxSlackDefect);
  j["refinement_rounds"] = rounds.empty() ? 0 : rounds.size() - 1;
  detail::ReportJson list = detail::ReportJson::array();
  for (const RefinementRound& r : rounds) {
    list.push_back({{"knots", r.knots},
                    {"iterations", r.iterations},
                    {"defect", toJson(r.maxDefect)},
                    {"hessian", toString(r.hessian)}});
  }
  j["rounds"] = std::move(list);
  j["solve_time_ms"] = toJson(1e3 * solveTime);
  j["solve_cpu_time_ms"] = toJson(1e3 * solveCpuTime);
  j["evaluation_time_ms"] = toJson(1e3 * evaluationTime);
  j["hessian_time_ms"] = toJson(1e3 * hessianTime);
  j["check_time_ms"] = toJson(1e3 * checkTime);
  return j.dump();
}

}  // namespace trellis
