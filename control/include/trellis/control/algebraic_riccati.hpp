// trellis/control/algebraic_riccati.hpp — what the algebraic Riccati solvers (care.hpp, dare.hpp)
// share: the problem, the status, the options and the result.
//
// Continuous: ẋ = A x + B u, J = ∫ xᵀQx + 2xᵀNu + uᵀRu dt. The stabilizing solution S of the CARE
//   AᵀS + SA − (SB + N) R⁻¹ (BᵀS + Nᵀ) + Q = 0
// gives u = −K x, K = R⁻¹ (BᵀS + Nᵀ), with A − BK Hurwitz.
// Discrete: x_{k+1} = Ad x_k + Bd u_k, J = Σ x_kᵀQx_k + 2x_kᵀNu_k + u_kᵀRu_k. The DARE
//   S = AdᵀS Ad − (AdᵀS Bd + N)(R + BdᵀS Bd)⁻¹(BdᵀS Ad + Nᵀ) + Q
// gives K = (R + BdᵀS Bd)⁻¹ (BdᵀS Ad + Nᵀ), with Ad − Bd K Schur stable.
//
// Sizes: A, Ad nx×nx; B, Bd nx×m; Q nx×nx symmetric; N nx×m (absent = 0); R m×m symmetric PD.
// Q (and Q − N R⁻¹ Nᵀ) need not be PSD: the solvers return the stabilizing solution whenever one
// exists (then it is unique). Bad sizes or weights throw std::invalid_argument.
//
// Right or refused. An ok result has (1) a stable closed loop (max Re λ(A − BK) < 0, resp.
// max |λ(Ad − Bd K)| < 1) and (2) a residual that no diagonal scaling of states or inputs can hide:
//   residual = max_ij |Res_ij| / max(√(T_ii T_jj), T_ij),
// T the sum of the entrywise absolute values of the terms of the equation (|Aᵀ||S| + |S||A| + ...).
// Under x = D z (D diagonal), Res and T both become D·D, so the measure is unchanged; a large block
// cannot mask a wrong small one. Otherwise the status says why, with the eigenvalue and its margin:
// an uncontrollable mode outside the stability region (left-eigenvector test), a Hamiltonian
// (symplectic pencil) eigenvalue on the imaginary axis (unit circle), or the residual reached.
//
// Method. Inputs are scaled to unit diag R (powers of 2), R = LLᵀ, and B̂ = B L⁻ᵀ, N̂ = N L⁻ᵀ,
// G = B̂B̂ᵀ, A − B̂N̂ᵀ, Q − N̂N̂ᵀ are formed in extended precision (long double), so the accuracy is
// not limited by cond(R)·1e-16. The states are then scaled (powers of 2, x = D z) to balance the
// Hamiltonian [[A, −G], [−Q, −Aᵀ]]: D minimizes the sum of squares of its off-diagonal entries plus
// a weak pull of each diag(Q, G) toward |A_ii| (a convex problem in log D, coordinate descent).
// CARE: scaled sign function of the balanced Hamiltonian (LAPACK's LU inverse), then
// Newton–Kleinman steps (Lyapunov solves on LAPACK's real Schur form). DARE:
// structure-preserving doubling stopped when every entry has converged relative to √(S_ii S_jj)
// and the doubled transition has decayed, ‖A_k‖_F ≤ √tol ‖A_0‖_F (the per-entry test alone stops
// early when modes of very different scales mix), then Newton (Hewer) steps (Stein solves on
// LAPACK's Schur form). The closed-loop eigenvalues are LAPACK's (dgees). Stabilizability is diagnosed only when the solve fails (a successful
// solve proves it), in O(n³): one complex Schur form of A and a left eigenvector per unstable mode.
#pragma once

#include "trellis/core/status.hpp"

#include <Eigen/Core>

#include <string>

namespace trellis {

enum class LqrCode {
  kOk,
  kNotStabilizable,         ///< an eigenvalue of A with Re ≥ 0 (|λ| ≥ 1) is uncontrollable
  kNoStabilizingSolution,   ///< Hamiltonian eigenvalue on the imaginary axis (pencil: unit circle)
  kNoConvergence,           ///< iteration limit reached, residual above tolerance, or unstable
                            ///< closed loop without an identified cause
};

/// Names: ok, not_stabilizable, no_stabilizing_solution, no_convergence.
inline EnumNameTable<LqrCode> enumNames(LqrCode) {
  static constexpr EnumName<LqrCode> table[] = {
      {LqrCode::kOk, "ok"},
      {LqrCode::kNotStabilizable, "not_stabilizable"},
      {LqrCode::kNoStabilizingSolution, "no_stabilizing_solution"},
      {LqrCode::kNoConvergence, "no_convergence"}};
  return table;
}

/// Options of solveCare and solveDare (the name is historical: both take them).
struct CareOptions {
  int maxIterations = 100;        ///< sign-function (or doubling) iterations
  double tolerance = 1e-12;       ///< change that stops the iteration (DARE: per entry, rel. to √(S_ii S_jj))
  int refinementSteps = 3;        ///< at most this many Newton steps (kept only while they reduce the residual)
  double residualTolerance = 1e-10;  ///< scale-invariant residual (see above) accepted for ok
  /// ‖wᴴB̂‖ / (‖w‖‖B̂‖) at or below this (w a left eigenvector of A for an unstable λ): uncontrollable
  double stabilizabilityTolerance = 1e-10;
  bool balance = true;            ///< scale states to balance the Hamiltonian (off: D = I)
};

/// The stabilizing solution S of the CARE / DARE (file comment), the gain K, and the checks that
/// make it ok: a stable closed loop and a scale-invariant residual below tolerance.
struct LqrResult {
  /// code, message (empty when ok: the eigenvalue and its margin, or the residual reached);
  /// t and index unused.
  Status<LqrCode> status;
  Eigen::MatrixXd S;              ///< nx×nx symmetric (PSD when Q − N R⁻¹ Nᵀ is PSD)
  Eigen::MatrixXd K;              ///< m×nx
  double residual = 0.0;          ///< scale-invariant relative residual (see above)
  int iterations = 0;             ///< sign / doubling iterations
  int refinementSteps = 0;        ///< Newton steps kept
  Eigen::VectorXcd closedLoopEigenvalues;  ///< of A − BK (Ad − Bd K)
  Eigen::VectorXd stateScaling;   ///< the balancing D (x = D z), powers of 2
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// One line: the status, then the residual, iterations and Newton steps.
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "nx", "nu", "residual", "iterations",
  /// "refinement_steps", "max_real_closed_loop", "max_abs_closed_loop", "S", "K"}.
  std::string json() const;
};

}  // namespace trellis
