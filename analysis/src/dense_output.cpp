// dense_output.cpp — storing and evaluating the step polynomials of an integration.
#include "trellis/analysis/dense_output.hpp"

#include <algorithm>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace trellis {

void DenseOutput::append(double s, Eigen::MatrixXd D) {
  if (D.cols() < 1 || (!empty() && D.rows() != dimension()) || (!empty() && s < ends_.back())) {
    std::ostringstream m;
    m << "DenseOutput::append: step at s = " << s << " with " << D.rows() << "x" << D.cols()
      << " coefficients after " << size() << " steps";
    if (!empty()) m << " (dimension " << dimension() << ", last end " << ends_.back() << ")";
    m << " — needs ascending ends, the same dimension and at least one column";
    throw std::invalid_argument(m.str());
  }
  ends_.push_back(s);
  coefficients_.push_back(std::move(D));
}

void DenseOutput::clear() {
  ends_.clear();
  coefficients_.clear();
}

void DenseOutput::reserve(std::size_t steps) {
  ends_.reserve(steps);
  coefficients_.reserve(steps);
}

double DenseOutput::front() const {
  if (empty()) throw std::out_of_range("DenseOutput: empty");
  return ends_.front();
}

double DenseOutput::back() const {
  if (empty()) throw std::out_of_range("DenseOutput: empty");
  return ends_.back();
}

std::size_t DenseOutput::locate(double s) const {
  if (empty()) throw std::out_of_range("DenseOutput: empty");
  const auto it = std::lower_bound(ends_.begin(), ends_.end(), s);
  return it == ends_.end() ? ends_.size() - 1 : static_cast<std::size_t>(it - ends_.begin());
}

void DenseOutput::evaluate(double s, Eigen::Ref<Eigen::VectorXd> out) const {
  const std::size_t k = locate(s);
  const Eigen::MatrixXd& D = coefficients_[k];
  const double ds = s - ends_[k];
  const Eigen::Index q = D.cols() - 1;
  // Horner: y = D_0 + ds (D_1 + ds/2 (D_2 + … (ds/q) D_q)).
  out = D.col(q);
  for (Eigen::Index j = q; j-- > 0;) out = D.col(j) + (ds / static_cast<double>(j + 1)) * out;
}

}  // namespace trellis
