// trellis/analysis/detail/shifted_solve.hpp (internal: for trellis's own libraries, not an API)
// — X ← (I − κA)⁻¹ X for the shifted systems of Radau IIA's stage equations (radau_tableau.hpp:
// a = T diag(γ0, μ, μ̄) T⁻¹, so a step of size h needs κ = γ0 h real and κ = μ h complex), every
// column of X, in its two users: the simulator's stepper (analysis/src/radau_stepper.cpp, one
// column: (σI − J) z = r is (I − κJ) z = κ r with κ = 1/σ) and the sampled-data discretization
// (control/src/sampled_lqr.cpp, nx + m columns).
//
// For a second-order A = [[0, I], [Aq, Av]] (x = [q; v], p = n/2 each) the rows
//   xq − κ xv = rq,  xv − κ (Aq xq + Av xv) = rv
// give (I − κAv − κ²Aq) xv = rv + κ Aq rq and xq = rq + κ xv: one p×p factorization instead of
// the n×n one (8× fewer flops) and half the substitution. The real solve is a SmallLu (row
// operations across all the columns: small_lu.hpp), the complex one keeps the matrix in split
// storage (split_complex_lu.hpp); the A_q products run through matmul (dense_kernels.hpp).
// Allocates only in resize() (and on a first call with another size or column count).
#pragma once

#include "trellis/analysis/detail/small_lu.hpp"
#include "trellis/analysis/detail/split_complex_lu.hpp"

#include <Eigen/Core>

#include <complex>

namespace trellis::detail {

class ShiftedSolve {
 public:
  /// The buffers for n×n matrices (halved when secondOrder) and `columns` right-hand sides.
  void resize(Eigen::Index n, bool secondOrder, Eigen::Index columns);
  /// Factor I − κA (A n×n; secondOrder: A = [[0, I], [Aq, Av]], its top rows not read).
  void factor(const Eigen::MatrixXd& A, double kappa, bool secondOrder);
  /// X ← (I − κA)⁻¹ X (n rows, any columns; non-finite where the matrix is singular).
  void solve(Eigen::Ref<Eigen::MatrixXd> X);

 private:
  bool secondOrder_ = false;
  double kappa_ = 0.0;
  Eigen::MatrixXd M_, Aq_, t_;
  SmallLu lu_;
};

class ComplexShiftedSolve {
 public:
  void resize(Eigen::Index n, bool secondOrder, Eigen::Index columns);  ///< as ShiftedSolve's
  /// Factor I − κA for a complex κ (as ShiftedSolve::factor).
  void factor(const Eigen::MatrixXd& A, std::complex<double> kappa, bool secondOrder);
  /// X ← (I − κA)⁻¹ X for X = Xr + i Xi (n rows each, any columns), in place.
  void solve(Eigen::Ref<Eigen::MatrixXd> Xr, Eigen::Ref<Eigen::MatrixXd> Xi);

 private:
  bool secondOrder_ = false;
  std::complex<double> kappa_;
  Eigen::MatrixXd Aq_, tr_, ti_;
  SplitComplexLu lu_;
};

}  // namespace trellis::detail
