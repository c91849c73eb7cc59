// lapack.hpp (private) — the LAPACK routines control/ calls, in one place, behind Eigen types.
//
// Why LAPACK: at n ≥ 100 the algebraic Riccati solvers spend their time in dense factorizations
// (the sign iteration's 2n×2n inverse, the Schur forms of the Newton steps' closed loops, the
// closed-loop eigenvalues). LAPACK's are blocked (its Schur form also uses multishift QR with
// aggressive early deflation), so that they run at the speed of the BLAS they are linked with;
// Eigen's Schur forms are unblocked, and its products are compiled for baseline x86-64.
// The Fortran symbols are declared in lapack.cpp only (the Fortran calling convention: every
// argument by address, each CHARACTER argument followed by its hidden length). Every function
// returns LAPACK's INFO: 0 on success, > 0 a numerical failure the caller turns into a status,
// < 0 a bad argument (a bug here: std::logic_error is thrown instead).
#pragma once

#include <Eigen/Core>

#include <vector>

namespace trellis::detail::lapack {

/// In-place inverse of a square matrix by LU with partial pivoting (dgetrf, then dgetri). The pivot
/// indices and dgetri's workspace are sized at construction, so invert() allocates nothing.
class LuInverse {
 public:
  /// Workspace for n×n matrices (dgetri's optimal size, queried once).
  explicit LuInverse(Eigen::Index n);
  /// Z ← Z⁻¹. logAbsDet ← Σ log|U_ii| of the factor (also when the inverse is not formed).
  /// Returns dgetrf's INFO: k > 0 when U_kk is exactly zero (Z is left factored, not inverted);
  /// also k > 0 when U_kk is not finite.
  int invert(Eigen::MatrixXd& Z, double& logAbsDet);

 private:
  int n_;
  std::vector<int> ipiv_;
  std::vector<double> work_;
};

/// Real Schur form F = U T Uᵀ (dgees, no reordering): T quasi-upper-triangular with 1×1 and 2×2
/// diagonal blocks (each 2×2 block a complex pair, standardized: equal diagonal entries and
/// off-diagonal entries of opposite signs), U orthogonal; the eigenvalues in diagonal order.
/// Workspace sized at construction; compute() allocates nothing.
class RealSchur {
 public:
  /// Workspace for n×n matrices; vectors = false skips U (eigenvalues and T only).
  RealSchur(Eigen::Index n, bool vectors);
  /// Factors F (n×n). Returns dgees's INFO: k in 1…n when the QR iteration did not converge
  /// (T, U and the eigenvalues are then not valid), n + 1 when F has a non-finite entry.
  int compute(const Eigen::MatrixXd& F);
  const Eigen::MatrixXd& T() const { return T_; }  ///< quasi-upper-triangular T
  const Eigen::MatrixXd& U() const { return U_; }  ///< orthogonal U (empty if vectors = false)
  const Eigen::VectorXd& wr() const { return wr_; }  ///< real parts of the eigenvalues
  const Eigen::VectorXd& wi() const { return wi_; }  ///< imaginary parts (pairs ±, positive first)

 private:
  int n_;
  bool vectors_;
  Eigen::MatrixXd T_, U_;
  Eigen::VectorXd wr_, wi_;
  std::vector<double> work_;
};

/// Triangular Sylvester equation with quasi-triangular T (a real Schur factor, n×n):
///   Tᵀ Y + Y T = s·C  (dtrsyl, TRANA = 'T', TRANB = 'N', ISGN = +1),
/// Y overwriting C (n×n) and s ∈ (0, 1] the scale dtrsyl chose to avoid overflow. Returns INFO:
/// 1 when T and −T have (nearly) common eigenvalues and dtrsyl perturbed them (the equation is
/// singular to working precision).
int solveSchurLyapunov(const Eigen::MatrixXd& T, Eigen::MatrixXd& C, double& scale);

}  // namespace trellis::detail::lapack
