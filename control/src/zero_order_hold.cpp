// zero_order_hold.cpp — exact ZOH discretization by one matrix exponential.
#include "trellis/control/zero_order_hold.hpp"

#include <unsupported/Eigen/MatrixFunctions>

#include <cmath>
#include <stdexcept>
#include <string>

namespace trellis {

using Eigen::MatrixXd;

DiscreteSystem discretizeZeroOrderHold(const MatrixXd& A, const MatrixXd& B, double h) {
  if (A.rows() != A.cols() || B.rows() != A.rows()) {
    throw std::invalid_argument("discretizeZeroOrderHold: A must be nxn and B nxm");
  }
  if (!(h > 0.0) || !std::isfinite(h)) {
    throw std::invalid_argument("discretizeZeroOrderHold: step h = " + std::to_string(h) +
                                " must be > 0 and finite");
  }
  const Eigen::Index n = A.rows(), m = B.cols();
  MatrixXd M = MatrixXd::Zero(n + m, n + m);
  M.topLeftCorner(n, n) = A * h;
  M.topRightCorner(n, m) = B * h;
  const MatrixXd E = M.exp();
  return {E.topLeftCorner(n, n), E.topRightCorner(n, m)};
}

}  // namespace trellis
