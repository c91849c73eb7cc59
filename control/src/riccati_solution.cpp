// riccati_solution.cpp — S(t) and K(t) from the stored steps of a Riccati solve.
#include "riccati_packing.hpp"
#include "trellis/control/riccati.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace trellis {

double RiccatiSolution::validFrom() const {
  return steps_.empty() ? tf_ : tf_ - steps_.back().tau;
}

std::vector<double> RiccatiSolution::stepTimes() const {
  std::vector<double> t;
  t.reserve(steps_.size());
  for (auto it = steps_.rbegin(); it != steps_.rend(); ++it) t.push_back(tf_ - it->tau);
  return t;
}

std::vector<int> RiccatiSolution::stepOrders() const {
  std::vector<int> q;
  q.reserve(steps_.size());
  for (auto it = steps_.rbegin(); it != steps_.rend(); ++it) {
    q.push_back(static_cast<int>(it->D.cols()) - 1);
  }
  return q;
}

// The step's interpolating polynomial Σ D_k (τ − τ_k)ᵏ / k! (CVODES's own dense output), in S or
// in its factor U (then S = UᵀU, symmetric PSD by construction).
void RiccatiSolution::S(double t, Eigen::MatrixXd& out) const {
  if (steps_.empty()) throw std::out_of_range("RiccatiSolution: empty solution");
  const double tauMax = steps_.back().tau;
  double tau = tf_ - t;
  const double slack = 1e-12 * std::max({1.0, std::abs(t0_), std::abs(tf_)});
  if (!(tau >= -slack && tau <= tauMax + slack)) {
    std::ostringstream m;
    m << "RiccatiSolution: t = " << t << " is outside [" << tf_ - tauMax << ", " << tf_ << "]";
    throw std::out_of_range(m.str());
  }
  tau = std::clamp(tau, 0.0, tauMax);
  // First stored step with τ_k ≥ τ; its polynomial covers [τ_{k-1}, τ_k].
  const auto it = std::lower_bound(steps_.begin(), steps_.end(), tau,
                                   [](const Step& s, double v) { return s.tau < v; });
  const Step& st = *it;
  const double dt = tau - st.tau;
  const Eigen::Index q = st.D.cols() - 1;
  Eigen::VectorXd y = st.D.col(q);  // Horner
  for (Eigen::Index k = q; k-- > 0;) y = st.D.col(k) + (dt / static_cast<double>(k + 1)) * y;
  out.resize(nx_, nx_);
  if (st.factored) {
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
