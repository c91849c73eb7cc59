// riccati_solution.cpp — S(t) and K(t) from the stored steps of a Riccati solve.
#include "riccati_packing.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace trellis {

std::string RiccatiSolution::describe() const {
  return status.describe() + " (" + std::to_string(steps) + " steps, " +
         std::to_string(rhsEvaluations) + " right-hand sides, S eigenvalues in [" +
         formatStatusNumber(minEigenvalue) + ", " + formatStatusNumber(maxEigenvalue) + "]" +
         (lowOrderRetry ? ", redone at BDF order <= 2" : "") + ")";
}

std::string RiccatiSolution::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["nx"] = nx_;
  j["nu"] = nu_;
  j["t0"] = detail::toJson(t0_);
  j["t1"] = detail::toJson(tf_);
  j["valid_from"] = detail::toJson(validFrom());
  j["steps"] = steps;
  j["rhs_evaluations"] = rhsEvaluations;
  j["jacobian_evaluations"] = jacobianEvaluations;
  j["linear_iterations"] = linearIterations;
  j["newton_iterations"] = newtonIterations;
  j["linearizations"] = linearizations;
  j["failure_norm"] = detail::toJson(failureNorm);
  j["indefinite_ratio"] = detail::toJson(indefiniteRatio);
  j["switched_to_plain_at"] = detail::toJson(switchedToPlainAt);
  j["min_eigenvalue_S"] = detail::toJson(minEigenvalue);
  j["max_eigenvalue_S"] = detail::toJson(maxEigenvalue);
  j["low_order_retry"] = lowOrderRetry;
  return j.dump();
}

double RiccatiSolution::validFrom() const {
  return steps_.empty() ? tf_ : tf_ - steps_.back();
}

std::vector<double> RiccatiSolution::stepTimes() const {
  std::vector<double> t;
  t.reserve(steps_.size());
  for (std::size_t i = steps_.size(); i-- > 0;) t.push_back(tf_ - steps_.end(i));
  return t;
}

std::vector<int> RiccatiSolution::stepOrders() const {
  std::vector<int> q;
  q.reserve(steps_.size());
  for (std::size_t i = steps_.size(); i-- > 0;) q.push_back(steps_.order(i));
  return q;
}

// The step's interpolating polynomial (CVODES's own dense output, DenseOutput), in S or in its
// factor U (then S = UᵀU, symmetric PSD by construction).
void RiccatiSolution::S(double t, Eigen::MatrixXd& out) const {
  if (steps_.empty()) throw std::out_of_range("RiccatiSolution: empty solution");
  const double tauMax = steps_.back();
  double tau = tf_ - t;
  const double slack = 1e-12 * std::max({1.0, std::abs(t0_), std::abs(tf_)});
  if (!(tau >= -slack && tau <= tauMax + slack)) {
    std::ostringstream m;
    m << "RiccatiSolution: t = " << t << " is outside [" << tf_ - tauMax << ", " << tf_ << "]";
    throw std::out_of_range(m.str());
  }
  tau = std::clamp(tau, 0.0, tauMax);
  Eigen::VectorXd y(steps_.dimension());
  steps_.evaluate(tau, y);
  out.resize(nx_, nx_);
  if (steps_.locate(tau) < factoredSteps_) {
    Eigen::MatrixXd U = Eigen::MatrixXd::Zero(nx_, nx_);
    detail::unpackUpper(y.data(), nx_, U);
    out.noalias() = U.transpose() * U;
  } else {
    detail::unpackSymmetric(y.data(), nx_, out);
  }
}

Eigen::MatrixXd RiccatiSolution::S(double t) const {
  Eigen::MatrixXd out;
  S(t, out);
  return out;
}

Eigen::MatrixXd RiccatiSolution::K(double t) const {
  const Eigen::MatrixXd St = S(t);  // checks the range
  const auto n = static_cast<std::ptrdiff_t>(gainTimes_.size());
  if (n == 0) throw std::out_of_range("RiccatiSolution::K: no stored gain nodes");
  if (n == 1) return gainNodes_[0] * St;
  // The four nearest nodes (fewer when there are fewer): Lagrange cubic in t.
  const auto it = std::lower_bound(gainTimes_.begin(), gainTimes_.end(), t);
  const std::ptrdiff_t hi = std::clamp<std::ptrdiff_t>(it - gainTimes_.begin(), 1, n - 1);
  const std::ptrdiff_t first =
      std::clamp<std::ptrdiff_t>(hi - 2, 0, std::max<std::ptrdiff_t>(0, n - 4));
  const std::ptrdiff_t last = std::min<std::ptrdiff_t>(first + 3, n - 1);
  auto at = [](std::ptrdiff_t i) { return static_cast<std::size_t>(i); };
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(nu_, nx_);
  for (std::ptrdiff_t i = first; i <= last; ++i) {
    if (t == gainTimes_[at(i)]) return gainNodes_[at(i)] * St;
    double w = 1.0;
    for (std::ptrdiff_t j = first; j <= last; ++j) {
      if (j != i) w *= (t - gainTimes_[at(j)]) / (gainTimes_[at(i)] - gainTimes_[at(j)]);
    }
    G += w * gainNodes_[at(i)];
  }
  return G * St;
}

}  // namespace trellis
