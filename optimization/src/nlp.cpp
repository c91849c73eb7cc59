// nlp.cpp — Ipopt's TNLP over a dense NlpProblem (nlp.hpp; Ipopt stays in src/).
#include "trellis/optimization/nlp.hpp"

#include <IpIpoptApplication.hpp>
#include <IpTNLP.hpp>

#include "ipopt_status.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace trellis {

namespace {

using Ipopt::Index;
using Ipopt::Number;

constexpr double kIpoptInfinity = 1e20;  // Ipopt reads bounds beyond ±1e19 as none

/// Forwards Ipopt's calls to the problem's two callbacks, evaluating each only once per x (Ipopt
/// asks f, ∇f, g and ∂g at the same point in separate calls). Nothing throws through Ipopt.
class DenseNlp : public Ipopt::TNLP {
 public:
  explicit DenseNlp(const NlpProblem& p) : p_(p), n_(p.lower.size()), m_(p.constraintLower.size()) {}

  bool get_nlp_info(Index& n, Index& m, Index& nnz_jac_g, Index& nnz_h_lag, IndexStyleEnum& style) override {
    n = static_cast<Index>(n_);
    m = static_cast<Index>(m_);
    nnz_jac_g = static_cast<Index>(n_ * m_);
    nnz_h_lag = 0;  // limited-memory quasi-Newton: eval_h is never called
    style = C_STYLE;
    return true;
  }
  bool get_bounds_info(Index, Number* xl, Number* xu, Index, Number* gl, Number* gu) override {
    for (Eigen::Index i = 0; i < n_; ++i) {
      xl[i] = std::max(p_.lower(i), -kIpoptInfinity);
      xu[i] = std::min(p_.upper(i), kIpoptInfinity);
    }
    for (Eigen::Index i = 0; i < m_; ++i) {
      gl[i] = std::max(p_.constraintLower(i), -kIpoptInfinity);
      gu[i] = std::min(p_.constraintUpper(i), kIpoptInfinity);
    }
    return true;
  }
  bool get_starting_point(Index, bool init_x, Number* x, bool, Number*, Number*, Index, bool, Number*) override {
    if (init_x) std::copy(p_.start.data(), p_.start.data() + n_, x);
    return true;
  }
  bool eval_f(Index, const Number* x, bool, Number& f) override {
    if (!objectiveAt(x)) return false;
    f = f_;
    return true;
  }
  bool eval_grad_f(Index, const Number* x, bool, Number* grad) override {
    if (!objectiveAt(x)) return false;
    std::copy(grad_.data(), grad_.data() + n_, grad);
    return true;
  }
  bool eval_g(Index, const Number* x, bool, Index, Number* g) override {
    if (!constraintsAt(x)) return false;
    std::copy(g_.data(), g_.data() + m_, g);
    return true;
  }
  bool eval_jac_g(Index, const Number* x, bool, Index, Index, Index* iRow, Index* jCol, Number* values) override {
    if (values == nullptr) {  // structure: dense, row by row
      Index k = 0;
      for (Eigen::Index i = 0; i < m_; ++i)
        for (Eigen::Index j = 0; j < n_; ++j) iRow[k] = static_cast<Index>(i), jCol[k++] = static_cast<Index>(j);
      return true;
    }
    if (!constraintsAt(x)) return false;
    Index k = 0;
    for (Eigen::Index i = 0; i < m_; ++i)
      for (Eigen::Index j = 0; j < n_; ++j) values[k++] = jac_(i, j);
    return true;
  }
  bool intermediate_callback(Ipopt::AlgorithmMode, Index iter, Number, Number, Number, Number, Number, Number,
                             Number, Number, Index, const Ipopt::IpoptData*, Ipopt::IpoptCalculatedQuantities*) override {
    iterations_ = iter;
    return error_.empty();
  }
  void finalize_solution(Ipopt::SolverReturn, Index n, const Number* x, const Number* zl, const Number* zu, Index m,
                         const Number*, const Number* lambda, Number, const Ipopt::IpoptData*,
                         Ipopt::IpoptCalculatedQuantities*) override {
    if (x) final_ = Eigen::Map<const Eigen::VectorXd>(x, n);
    if (zl) zl_ = Eigen::Map<const Eigen::VectorXd>(zl, n);
    if (zu) zu_ = Eigen::Map<const Eigen::VectorXd>(zu, n);
    if (lambda) lambda_ = Eigen::Map<const Eigen::VectorXd>(lambda, m);
  }

  Eigen::VectorXd final_, zl_, zu_, lambda_;
  int iterations_ = 0;
  long evaluations_ = 0;
  std::string error_;

 private:
  bool same(const Number* x, const Eigen::VectorXd& at, bool valid) const {
    return valid && std::equal(x, x + n_, at.data());
  }
  bool objectiveAt(const Number* x) {
    if (same(x, fAt_, fValid_)) return fOk_;
    fAt_ = Eigen::Map<const Eigen::VectorXd>(x, n_);
    grad_.resize(n_);
    fOk_ = call([&] { return p_.objective(fAt_, f_, grad_); }) && std::isfinite(f_) && grad_.allFinite();
    fValid_ = true;
    return fOk_;
  }
  bool constraintsAt(const Number* x) {
    if (same(x, gAt_, gValid_)) return gOk_;
    gAt_ = Eigen::Map<const Eigen::VectorXd>(x, n_);
    g_.resize(m_);
    jac_.resize(m_, n_);
    ++evaluations_;
    gOk_ = call([&] { return p_.constraints(gAt_, g_, jac_); }) && g_.allFinite() && jac_.allFinite() &&
           g_.size() == m_ && jac_.rows() == m_ && jac_.cols() == n_;
    gValid_ = true;
    return gOk_;
  }
  template <class F>
  bool call(F&& f) {
    try {
      return f();
    } catch (const std::exception& e) {
      error_ = std::string("a callback threw: ") + e.what();
    } catch (...) {
      error_ = "a callback threw";
    }
    return false;
  }

  const NlpProblem& p_;
  Eigen::Index n_, m_;
  Eigen::VectorXd fAt_, gAt_, grad_, g_;
  Eigen::MatrixXd jac_;
  double f_ = 0.0;
  bool fValid_ = false, fOk_ = false, gValid_ = false, gOk_ = false;
};

}  // namespace

NlpResult solveNlp(const NlpProblem& problem, const NlpOptions& options) {
  const Eigen::Index n = problem.lower.size(), m = problem.constraintLower.size();
  const auto bad = [](const std::string& what) { throw std::invalid_argument("solveNlp: " + what); };
  if (n == 0) bad("the problem has no variables");
  if (problem.upper.size() != n || problem.start.size() != n)
    bad("upper has " + std::to_string(problem.upper.size()) + " and start " + std::to_string(problem.start.size()) +
        " entries, lower " + std::to_string(n));
  if (problem.constraintUpper.size() != m)
    bad("constraintUpper has " + std::to_string(problem.constraintUpper.size()) + " entries, constraintLower " +
        std::to_string(m));
  for (Eigen::Index i = 0; i < n; ++i)
    if (!(problem.lower(i) <= problem.upper(i)))
      bad("variable " + std::to_string(i) + ": lower " + std::to_string(problem.lower(i)) + " > upper " +
          std::to_string(problem.upper(i)));
  for (Eigen::Index i = 0; i < m; ++i)
    if (!(problem.constraintLower(i) <= problem.constraintUpper(i)))
      bad("constraint " + std::to_string(i) + ": lower " + std::to_string(problem.constraintLower(i)) + " > upper " +
          std::to_string(problem.constraintUpper(i)));
  if (!problem.objective || !problem.constraints) bad("the objective or the constraints callback is empty");
  if (!(options.boundRelaxFactor >= 0.0)) bad("options.boundRelaxFactor = " + std::to_string(options.boundRelaxFactor) + " must be >= 0");

  const auto t0 = std::chrono::steady_clock::now();
  Ipopt::SmartPtr<DenseNlp> nlp = new DenseNlp(problem);
  Ipopt::SmartPtr<Ipopt::IpoptApplication> app = IpoptApplicationFactory();
  Ipopt::OptionsList& o = *app->Options();
  o.SetStringValue("sb", "yes");
  o.SetIntegerValue("print_level", options.printLevel);
  o.SetIntegerValue("max_iter", options.maxIterations);
  o.SetNumericValue("tol", options.tolerance);
  o.SetNumericValue("constr_viol_tol", options.constraintTolerance);
  o.SetNumericValue("max_cpu_time", options.maxCpuTime);
  o.SetStringValue("hessian_approximation", "limited-memory");
  o.SetIntegerValue("limited_memory_max_history", options.limitedMemorySize);
  o.SetStringValue("linear_solver", "mumps");
  o.SetNumericValue("bound_relax_factor", options.boundRelaxFactor);
  Ipopt::ApplicationReturnStatus status = app->Initialize("");  // "": no ipopt.opt is read
  if (status == Ipopt::Solve_Succeeded) status = app->OptimizeTNLP(Ipopt::SmartPtr<Ipopt::TNLP>(GetRawPtr(nlp)));

  NlpResult r;
  r.ipoptStatus = detail::applicationStatusName(status);
  r.status.code = detail::classify(status);
  r.iterations = nlp->iterations_;
  r.evaluations = nlp->evaluations_;
  r.x = nlp->final_.size() == n ? nlp->final_ : problem.start;
  r.constraintMultipliers = nlp->lambda_.size() == m ? nlp->lambda_ : Eigen::VectorXd::Zero(m);
  r.lowerBoundMultipliers = nlp->zl_.size() == n ? nlp->zl_ : Eigen::VectorXd::Zero(n);
  r.upperBoundMultipliers = nlp->zu_.size() == n ? nlp->zu_ : Eigen::VectorXd::Zero(n);
  Eigen::VectorXd grad(n);
  Eigen::MatrixXd jac(m, n);
  r.g = Eigen::VectorXd::Constant(m, std::numeric_limits<double>::quiet_NaN());
  r.objective = std::numeric_limits<double>::quiet_NaN();
  bool evaluated = false;
  try {
    problem.objective(r.x, r.objective, grad);
    Eigen::VectorXd g(m);
    evaluated = problem.constraints(r.x, g, jac);
    if (evaluated) r.g = g;
  } catch (...) {
    evaluated = false;
  }
  r.constraintViolation =
      m == 0 ? 0.0 : (problem.constraintLower - r.g).cwiseMax(r.g - problem.constraintUpper).cwiseMax(0.0).maxCoeff();
  if (!evaluated) r.constraintViolation = std::numeric_limits<double>::quiet_NaN();
  r.boundViolation = std::max(0.0, std::max((problem.lower - r.x).maxCoeff(), (r.x - problem.upper).maxCoeff()));
  r.solveTime = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Ipopt's success is checked here, at the returned x: f and g evaluate, and every row and bound
  // holds to constraintTolerance plus the relaxation Ipopt was allowed (bound_relax_factor ·
  // max(1, |bound|), as Ipopt relaxes). Otherwise the result is not ok, whatever Ipopt said.
  if (r.ok()) {
    const auto excess = [&](const Eigen::VectorXd& v, const Eigen::VectorXd& lo, const Eigen::VectorXd& hi) {
      double worst = 0.0;
      for (Eigen::Index i = 0; i < v.size(); ++i) {
        const auto allowed = [&](double b) {
          return options.constraintTolerance + options.boundRelaxFactor * std::max(1.0, std::abs(b));
        };
        worst = std::max({worst, lo(i) - v(i) - allowed(lo(i)), v(i) - hi(i) - allowed(hi(i))});
      }
      return worst;
    };
    if (!evaluated || !std::isfinite(r.objective)) {
      r.status.code = OptimizationCode::kFailed;
      r.status.message = "Ipopt: " + r.ipoptStatus + ", but the objective or the constraints do not evaluate at its x";
    } else if (const double e = std::max(excess(r.g, problem.constraintLower, problem.constraintUpper),
                                         excess(r.x, problem.lower, problem.upper));
               e > 0.0) {
      r.status.code = OptimizationCode::kFailed;
      r.status.message = "Ipopt: " + r.ipoptStatus + ", but its x violates a constraint or bound by " +
                         std::to_string(e) + " beyond the tolerance";
    }
    if (!r.ok()) return r;
  }
  if (!r.ok()) {
    r.status.message = "Ipopt: " + r.ipoptStatus + " after " + std::to_string(r.iterations) +
                       " iterations; constraint violation " + std::to_string(r.constraintViolation);
    if (!nlp->error_.empty()) r.status.message += "; " + nlp->error_;
  }
  return r;
}

}  // namespace trellis
