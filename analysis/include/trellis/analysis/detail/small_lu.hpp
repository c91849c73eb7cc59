// trellis/analysis/detail/small_lu.hpp (internal: for trellis's own libraries, not an API)
// — LU with partial pivoting (LAPACK's getrf/getrs: the pivot is the column's largest |a_ik|) of
// a small dense real matrix, solved for all the columns of a right-hand side at once. Its users
// are the Radau stage systems: the shifted solves (shifted_solve.hpp: the simulator's stepper and
// the sampled discretization's filters and twin) and the sampled discretization's halved stage
// system (n = 3p, nx + m columns).
//
// Why not Eigen's PartialPivLU: at these sizes (n ≈ 6…60, a few to ~80 columns) its triangular
// solves go through the blocked trsm/gebp machinery (packing, blocking set-up) and cost several
// times the flops they do. Here the factor and the right-hand side are held row-major, so each
// elimination (row_i −= l_ik row_k) is one contiguous multiply-add across all the columns; with
// AVX2+FMA (chosen once at run time like matmul's kernel in dense_kernels.hpp) the pivot row of up
// to 32 columns is held in registers, so the eliminations of one step do not wait on each other
// (a chunk-at-a-time order waited on each pivot row's store: 11 % of the sampled discretization's
// time in 7 % of its instructions). Same pivots and the same operations per entry as the textbook
// algorithm; results equal to Eigen's up to rounding.
// Allocates only in resize() (and on a first call with another size or more columns).
#pragma once

#include <Eigen/Core>

namespace trellis::detail {

class SmallLu {
 public:
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

  /// Buffers for an n×n matrix and up to `columns` right-hand sides.
  void resize(Eigen::Index n, Eigen::Index columns = 1);
  /// Factor M (n×n, column-major; resized here if n changed), or Mᵀ when `transposed`. A zero
  /// pivot is not an error: the solves then return non-finite entries (the callers' finiteness
  /// checks see them).
  void factor(const Eigen::Ref<const Eigen::MatrixXd>& M, bool transposed = false);
  /// X ← M⁻¹ X (n rows, any number of columns; column-major with any outer stride), in place.
  void solve(Eigen::Ref<Eigen::MatrixXd> X);
  Eigen::Index size() const { return lu_.rows(); }  ///< n

 private:
  RowMatrix lu_;          ///< L (unit, strictly below) and U, row-major, rows in pivoted order
  Eigen::VectorXi perm_;  ///< row i of the factored P M is row perm_[i] of M
  RowMatrix x_;           ///< the right-hand side, row-major in pivoted order
};

}  // namespace trellis::detail
