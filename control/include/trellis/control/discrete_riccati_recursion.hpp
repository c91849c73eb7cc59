// trellis/control/discrete_riccati_recursion.hpp — the finite-horizon discrete LQR: the Riccati difference equation.
#pragma once

#include <Eigen/Core>

#include <functional>
#include <vector>

namespace trellis {

/// Finite-horizon discrete LQR over N steps: S_N = Qf,
///   K_k = (R + BdᵀS_{k+1}Bd)⁻¹ BdᵀS_{k+1}Ad,  S_k = Q + AdᵀS_{k+1}(Ad − Bd K_k),  k = N−1 … 0
/// (S_k symmetrized at every step). S has N+1 entries, K has N.
struct DiscreteRiccatiRecursion {
  ///@{
  /// S_0 … S_N (nx×nx each, symmetric) and K_0 … K_{N−1} (m×nx each).
  std::vector<Eigen::MatrixXd> S, K;
  ///@}
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
