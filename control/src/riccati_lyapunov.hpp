// riccati_lyapunov.hpp (private) — the Newton matrix of the Riccati equation, inverted.
//
// Inside BDF the Newton matrix I − γJ of dS/dτ acts on a symmetric E as E − γ(A_clᵀE + E A_cl).
// Solving (I − γJ) X = R is the Lyapunov equation FᵀX + XF = −R with F = γA_cl − ½I. With the
// real Schur form A_cl = Z T Zᵀ (factor(), O(nx³) once per Jacobian update; γ only rescales T)
// it is a Bartels–Stewart back substitution on quasi-triangular T (solve(), O(nx³) per call,
// no allocation): the exact preconditioner of the Krylov solver, or the linear solver itself
// (OdeLinearSolver::SystemSolve). The dense products (the two congruences, ~6 nx³ flops, and the
// rows above each column block of the substitution) and the substitution's dot products run
// through dense_kernels.hpp (AVX2+FMA when the CPU has it).
#pragma once

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include <vector>

namespace trellis::detail {

class SchurLyapunov {
 public:
  explicit SchurLyapunov(Eigen::Index n);
  /// Real Schur form of Acl; false if the QR iteration did not converge.
  bool factor(const Eigen::MatrixXd& Acl);
  /// X ← the symmetric solution of X − γ(A_clᵀX + X A_cl) = X (R in X on entry, symmetric).
  /// False if the equation is singular (an eigenvalue sum of F is zero) or the result not finite.
  bool solve(double gamma, Eigen::MatrixXd& X);

 private:
  Eigen::Index n_;
  Eigen::RealSchur<Eigen::MatrixXd> schur_;
  Eigen::MatrixXd Z_, Zt_, T_, TF_, C_, Y_;
  double gammaTF_ = 0.0;  // the γ of TF_ (re-formed only when γ changes)
  bool tfValid_ = false;
  std::vector<Eigen::Index> blockStart_;  // 1×1 and 2×2 diagonal blocks of T, and n at the end
};

}  // namespace trellis::detail
