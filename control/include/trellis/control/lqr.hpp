// trellis/control/lqr.hpp — infinite-horizon LQR (CARE, DARE), zero-order-hold discretization and
// the finite-horizon discrete Riccati recursion.
//
// Continuous: ẋ = A x + B u, J = ∫ xᵀQx + uᵀRu dt. The stabilizing solution S of the CARE
//   AᵀS + SA − S B R⁻¹ Bᵀ S + Q = 0
// gives u = −K x, K = R⁻¹ Bᵀ S, with A − BK Hurwitz.
// Discrete: x_{k+1} = Ad x_k + Bd u_k, J = Σ x_kᵀQx_k + u_kᵀRu_k. The DARE
//   S = AdᵀS Ad − AdᵀS Bd (R + BdᵀS Bd)⁻¹ BdᵀS Ad + Q
// gives K = (R + BdᵀS Bd)⁻¹ BdᵀS Ad, with Ad − Bd K Schur stable.
//
// Sizes: A, Ad nx×nx; B, Bd nx×m; Q nx×nx symmetric PSD; R m×m symmetric PD. Bad sizes or weights
// throw std::invalid_argument (see checkWeightMatrix); numerical failure and a system that is not
// stabilizable are reported in the result's status, with a message.
#pragma once

#include <Eigen/Core>

#include <functional>
#include <string>
#include <vector>

namespace trellis {

enum class LqrStatus {
  kOk,
  kNotStabilizable,         ///< an eigenvalue of A with Re ≥ 0 (|λ| ≥ 1) is uncontrollable (PBH)
  kNoStabilizingSolution,   ///< the Hamiltonian has eigenvalues on the boundary ((A, Q) not detectable)
  kNoConvergence,           ///< iteration limit reached or residual above tolerance
};

const char* toString(LqrStatus status);

struct CareOptions {
  int maxIterations = 100;        ///< sign-function (or doubling) iterations
  double tolerance = 1e-12;       ///< relative change that stops the iteration
  int refinementSteps = 2;        ///< Newton (Kleinman) steps after the sign function (CARE only)
  double residualTolerance = 1e-8;  ///< relative residual ‖Res‖/(‖Q‖ + ‖AᵀS‖·2 + ‖SGS‖) accepted
  double stabilizabilityTolerance = 1e-10;  ///< σ_min[A − λI, B] / ‖[A, B]‖ below this: uncontrollable
};

struct LqrResult {
  LqrStatus status = LqrStatus::kOk;
  std::string message;            ///< empty when ok
  Eigen::MatrixXd S;              ///< nx×nx symmetric PSD
  Eigen::MatrixXd K;              ///< m×nx
  double residual = 0.0;          ///< relative residual of the Riccati equation
  int iterations = 0;
  Eigen::VectorXcd closedLoopEigenvalues;  ///< of A − BK (Ad − Bd K)
  bool ok() const { return status == LqrStatus::kOk; }
};

/// Continuous algebraic Riccati equation by the matrix sign function of the Hamiltonian
/// H = [[A, −BR⁻¹Bᵀ], [−Q, −Aᵀ]] with determinant scaling, then Newton–Kleinman refinement.
LqrResult solveCare(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const CareOptions& options = {});

/// Discrete algebraic Riccati equation by the structure-preserving doubling algorithm.
LqrResult solveDare(const Eigen::MatrixXd& Ad, const Eigen::MatrixXd& Bd, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const CareOptions& options = {});

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
