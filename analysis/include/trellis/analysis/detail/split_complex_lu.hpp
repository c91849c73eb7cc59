// trellis/analysis/detail/split_complex_lu.hpp (internal: for trellis's own libraries, not an API)
// — LU with partial pivoting of a complex matrix held as its real and imaginary parts, for the
// complex stage system of Radau IIA (radau_tableau.hpp) in its two users: the simulator's stepper
// (analysis/src/radau_stepper.cpp) and the sampled-data discretization's frozen twin
// (control/src/sampled_lqr.cpp). The updates are real multiply-adds the compiler vectorizes, where
// std::complex's products (with their NaN/Inf branches) are not: 26×26 (the hand's halved complex
// system) 6.1 µs against 15.6 µs for Eigen's PartialPivLU<MatrixXcd>, the same pivots (the largest
// |z| of the column). Allocates only in resize().
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
  /// X ← M⁻¹ X for every column of X = Xr + i Xi (n rows each, any number of columns; the same
  /// arithmetic as solve() column by column), in place.
  void solve(Eigen::Ref<Eigen::MatrixXd> Xr, Eigen::Ref<Eigen::MatrixXd> Xi) const;

 private:
  /// The pivoted forward and back substitution of one column held as (xr, xi), in place.
  void substitute(double* xr, double* xi) const;

  Eigen::MatrixXd re_, im_;
  Eigen::VectorXi pivot_;
  Eigen::VectorXd xr_, xi_;
};

}  // namespace trellis::detail
