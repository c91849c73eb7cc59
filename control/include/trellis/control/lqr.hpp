// trellis/control/lqr.hpp — infinite-horizon LQR (CARE, DARE), zero-order-hold discretization and
// the finite-horizon discrete Riccati recursion.
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
// CARE: scaled sign function of the balanced Hamiltonian, then Newton–Kleinman steps. DARE:
// structure-preserving doubling stopped when every entry has converged relative to √(S_ii S_jj)
// and the doubled transition has decayed, ‖A_k‖_F ≤ √tol ‖A_0‖_F (the per-entry test alone stops
// early when modes of very different scales mix), then Newton (Hewer) steps. Stabilizability is diagnosed only when the solve fails (a successful
// solve proves it), in O(n³): one complex Schur form of A and a left eigenvector per unstable mode.
#pragma once

#include <Eigen/Core>

#include <complex>
#include <functional>
#include <string>
#include <vector>

namespace trellis {

enum class LqrStatus {
  kOk,
  kNotStabilizable,         ///< an eigenvalue of A with Re ≥ 0 (|λ| ≥ 1) is uncontrollable
  kNoStabilizingSolution,   ///< Hamiltonian eigenvalue on the imaginary axis (pencil: unit circle)
  kNoConvergence,           ///< iteration limit reached, residual above tolerance, or unstable
                            ///< closed loop without an identified cause
};

const char* toString(LqrStatus status);

struct CareOptions {
  int maxIterations = 100;        ///< sign-function (or doubling) iterations
  double tolerance = 1e-12;       ///< change that stops the iteration (DARE: per entry, rel. to √(S_ii S_jj))
  int refinementSteps = 3;        ///< at most this many Newton steps (kept only while they reduce the residual)
  double residualTolerance = 1e-10;  ///< scale-invariant residual (see above) accepted for ok
  /// ‖wᴴB̂‖ / (‖w‖‖B̂‖) at or below this (w a left eigenvector of A for an unstable λ): uncontrollable
  double stabilizabilityTolerance = 1e-10;
  bool balance = true;            ///< scale states to balance the Hamiltonian (off: D = I)
};

struct LqrResult {
  LqrStatus status = LqrStatus::kOk;
  std::string message;            ///< empty when ok
  Eigen::MatrixXd S;              ///< nx×nx symmetric (PSD when Q − N R⁻¹ Nᵀ is PSD)
  Eigen::MatrixXd K;              ///< m×nx
  double residual = 0.0;          ///< scale-invariant relative residual (see above)
  int iterations = 0;             ///< sign / doubling iterations
  int refinementSteps = 0;        ///< Newton steps kept
  Eigen::VectorXcd closedLoopEigenvalues;  ///< of A − BK (Ad − Bd K)
  Eigen::VectorXd stateScaling;   ///< the balancing D (x = D z), powers of 2
  bool ok() const { return status == LqrStatus::kOk; }
};

/// Continuous algebraic Riccati equation (see the file comment), without / with cross term N.
LqrResult solveCare(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const CareOptions& options = {});
LqrResult solveCare(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const Eigen::MatrixXd& N,
                    const CareOptions& options = {});

/// Discrete algebraic Riccati equation (see the file comment), without / with cross term N.
LqrResult solveDare(const Eigen::MatrixXd& Ad, const Eigen::MatrixXd& Bd, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const CareOptions& options = {});
LqrResult solveDare(const Eigen::MatrixXd& Ad, const Eigen::MatrixXd& Bd, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const Eigen::MatrixXd& N,
                    const CareOptions& options = {});

/// Stabilizability of (A, B) in O(n³): one complex Schur form A = U T Uᴴ; for every eigenvalue
/// outside the stability region (continuous: Re λ ≥ −1e-8|λ|; discrete: |λ| ≥ 1 − 1e-8) a left
/// eigenvector w from the triangular T, and the margin ‖wᴴB‖ / (‖w‖‖B‖) (the sine of the angle
/// between w and range B; invariant under input scaling). Margin ≤ tolerance: not stabilizable.
/// Repeated unstable eigenvalues (where one left eigenvector does not span the eigenspace) are also
/// checked by the PBH singular value σ_min[A − λI, B] / ‖[A, B]‖. The solvers apply it to the
/// balanced problem; callers with badly scaled data should balance first.
struct StabilizabilityCheck {
  bool stabilizable = true;
  std::complex<double> eigenvalue{0.0, 0.0};  ///< the least controllable unstable eigenvalue
  double margin = 1.0;                        ///< its controllability margin (1 if none unstable)
  std::string message;                        ///< empty when stabilizable
};
StabilizabilityCheck checkStabilizability(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B,
                                          bool discrete, double tolerance = 1e-10);

/// Solves the Stein (discrete Lyapunov) equation Fᵀ X F − X + C = 0 (no eigenvalue pair of F with
/// λ_i λ̄_j = 1, C symmetric) by a complex Schur form; X symmetric. Throws std::runtime_error if
/// the equation is singular.
Eigen::MatrixXd solveStein(const Eigen::MatrixXd& F, const Eigen::MatrixXd& C);

/// Solves the Lyapunov equation Fᵀ X + X F + C = 0 (F nx×nx with no eigenvalue pair λ_i + λ̄_j = 0,
/// C symmetric) by a complex Schur form (Bartels–Stewart); X is symmetric. Throws
/// std::runtime_error if the equation is singular.
Eigen::MatrixXd solveLyapunov(const Eigen::MatrixXd& F, const Eigen::MatrixXd& C);

/// Exact zero-order-hold discretization at step h > 0:
/// exp([[A, B], [0, 0]] h) = [[Ad, Bd], [0, I]], Ad = e^{Ah}, Bd = ∫₀ʰ e^{As} ds B.
struct DiscreteSystem {
  Eigen::MatrixXd Ad, Bd;
};
DiscreteSystem discretizeZeroOrderHold(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, double h);

/// Finite-horizon discrete LQR over N steps: S_N = Qf,
///   K_k = (R + BdᵀS_{k+1}Bd)⁻¹ BdᵀS_{k+1}Ad,  S_k = Q + AdᵀS_{k+1}(Ad − Bd K_k),  k = N−1 … 0
/// (S_k symmetrized at every step). S has N+1 entries, K has N.
struct DiscreteRiccatiRecursion {
  std::vector<Eigen::MatrixXd> S, K;
};
DiscreteRiccatiRecursion solveDiscreteRiccatiRecursion(const Eigen::MatrixXd& Ad,
                                                       const Eigen::MatrixXd& Bd,
                                                       const Eigen::MatrixXd& Q,
                                                       const Eigen::MatrixXd& R,
                                                       const Eigen::MatrixXd& Qf, int N);
/// Time-varying variant: system(k, Ad, Bd) writes the step-k matrices (they arrive sized nx×nx, nx×m).
DiscreteRiccatiRecursion solveDiscreteRiccatiRecursion(
    const std::function<void(int k, Eigen::MatrixXd& Ad, Eigen::MatrixXd& Bd)>& system, int nx,
    int nu, const Eigen::MatrixXd& Q, const Eigen::MatrixXd& R, const Eigen::MatrixXd& Qf, int N);

}  // namespace trellis
