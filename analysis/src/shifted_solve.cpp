// analysis/src/shifted_solve.cpp — trellis/analysis/detail/shifted_solve.hpp.
#include "trellis/analysis/detail/shifted_solve.hpp"

#include "trellis/analysis/detail/dense_kernels.hpp"

namespace trellis::detail {

void ShiftedSolve::resize(Eigen::Index n, bool secondOrder, Eigen::Index columns) {
  const Eigen::Index m = secondOrder ? n / 2 : n;
  M_.resize(m, m);
  Aq_.resize(n / 2, n / 2);
  t_.resize(m, columns);
  lu_.resize(m, columns);
}

void ShiftedSolve::factor(const Eigen::MatrixXd& A, double kappa, bool secondOrder) {
  secondOrder_ = secondOrder;
  kappa_ = kappa;
  const Eigen::Index n = A.rows(), p = n / 2;
  if (secondOrder) {
    Aq_ = A.bottomLeftCorner(p, p);
    M_ = (-kappa) * A.bottomRightCorner(p, p) - (kappa * kappa) * Aq_;
  } else {
    M_ = (-kappa) * A;
  }
  M_.diagonal().array() += 1.0;
  lu_.factor(M_);
}

void ShiftedSolve::solve(Eigen::Ref<Eigen::MatrixXd> X) {
  if (!secondOrder_) {
    lu_.solve(X);
    return;
  }
  const Eigen::Index p = Aq_.rows(), cols = X.cols();
  t_.resize(p, cols);
  matmul(p, cols, p, 1.0, Aq_.data(), p, X.data(), X.outerStride(), false, t_.data(), p, false);
  X.bottomRows(p) += kappa_ * t_;
  lu_.solve(X.bottomRows(p));
  X.topRows(p) += kappa_ * X.bottomRows(p);
}

void ComplexShiftedSolve::resize(Eigen::Index n, bool secondOrder, Eigen::Index columns) {
  lu_.resize(secondOrder ? n / 2 : n);
  Aq_.resize(n / 2, n / 2);
  tr_.resize(n / 2, columns);
  ti_.resize(n / 2, columns);
}

void ComplexShiftedSolve::factor(const Eigen::MatrixXd& A, std::complex<double> kappa, bool secondOrder) {
  secondOrder_ = secondOrder;
  kappa_ = kappa;
  const Eigen::Index n = A.rows(), p = n / 2;
  if (secondOrder) {
    // I − κAv − κ²Aq, real and imaginary parts.
    Aq_ = A.bottomLeftCorner(p, p);
    const std::complex<double> k2 = kappa * kappa;
    lu_.resize(p);
    lu_.re() = (-kappa.real()) * A.bottomRightCorner(p, p) - k2.real() * Aq_;
    lu_.im() = (-kappa.imag()) * A.bottomRightCorner(p, p) - k2.imag() * Aq_;
  } else {
    lu_.resize(n);
    lu_.re() = (-kappa.real()) * A;
    lu_.im() = (-kappa.imag()) * A;
  }
  lu_.re().diagonal().array() += 1.0;
  lu_.factor();
}

void ComplexShiftedSolve::solve(Eigen::Ref<Eigen::MatrixXd> Xr, Eigen::Ref<Eigen::MatrixXd> Xi) {
  if (!secondOrder_) {
    lu_.solve(Xr, Xi);
    return;
  }
  const Eigen::Index p = Aq_.rows(), cols = Xr.cols();
  const double kr = kappa_.real(), ki = kappa_.imag();
  tr_.resize(p, cols);
  ti_.resize(p, cols);
  // rv + κ Aq rq, with Aq rq as two real products.
  matmul(p, cols, p, 1.0, Aq_.data(), p, Xr.data(), Xr.outerStride(), false, tr_.data(), p, false);
  matmul(p, cols, p, 1.0, Aq_.data(), p, Xi.data(), Xi.outerStride(), false, ti_.data(), p, false);
  Xr.bottomRows(p) += kr * tr_ - ki * ti_;
  Xi.bottomRows(p) += kr * ti_ + ki * tr_;
  lu_.solve(Xr.bottomRows(p), Xi.bottomRows(p));
  // xq = rq + κ xv.
  Xr.topRows(p) += kr * Xr.bottomRows(p) - ki * Xi.bottomRows(p);
  Xi.topRows(p) += kr * Xi.bottomRows(p) + ki * Xr.bottomRows(p);
}

}  // namespace trellis::detail
