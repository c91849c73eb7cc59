// trellis/analysis/detail/split_complex_lu.hpp (internal: for trellis's own libraries, not an API)
// — LU with partial pivoting of a complex matrix held as its real and imaginary parts, for the
// complex stage system of Radau IIA (radau_tableau.hpp) in its two users: the simulator's stepper
// (analysis/src/radau_stepper.cpp) and the sampled-data discretization's frozen twin
// (control/src/sampled_lqr.cpp). The updates are real multiply-adds the compiler vectorizes, where
// std::complex's products (with their NaN/Inf branches) are not: 26×26 (the hand's halved complex
// system) 6.1 µs against 15.6 µs for Eigen's PartialPivLU<MatrixXcd>, the same pivots (the largest
// |z| of the column). Allocates only in resize() (and in the first solve of more columns).
#pragma once

#include <Eigen/Core>

namespace trellis::detail {

class SplitComplexLu {
 public:
  void resize(Eigen::Index n);
  /// The matrix to factor: fill re() and im(), then factor() (in place).
  Eigen::MatrixXd& re() { return re_; }
  Eigen::MatrixXd& im() { return im_; }  ///< see re()
  void factor();
  /// x ← M⁻¹ x (non-finite where a pivot is zero: the caller's finiteness checks see it).
  void solve(Eigen::VectorXcd& x);
  /// X ← M⁻¹ X for every column of X = Xr + i Xi (n rows each, any number of columns), in place:
  /// one column as solve(); 2…32 columns with AVX2+FMA as row operations across all of them on a
  /// row-major copy (the pivot row in registers: small_lu.hpp says why), equal to the column-by-
  /// column solve up to rounding (its multiply-adds fused).
  void solve(Eigen::Ref<Eigen::MatrixXd> Xr, Eigen::Ref<Eigen::MatrixXd> Xi);

 private:
  /// The pivoted forward and back substitution of one column held as (xr, xi), in place.
  void substitute(double* xr, double* xi) const;

  Eigen::MatrixXd re_, im_;
  Eigen::VectorXi pivot_;  ///< LAPACK's: row k swapped with row pivot_[k], in order
  Eigen::VectorXi perm_;   ///< their product: row i of P M is row perm_[i] of M
  Eigen::VectorXd xr_, xi_;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rowsR_, rowsI_;  ///< solve()'s copy
};

}  // namespace trellis::detail
