// trellis/control/zero_order_hold.hpp — exact zero-order-hold discretization of ẋ = A x + B u.
#pragma once

#include <Eigen/Core>

namespace trellis {

/// Exact zero-order-hold discretization at step h > 0:
/// exp([[A, B], [0, 0]] h) = [[Ad, Bd], [0, I]], Ad = e^{Ah}, Bd = ∫₀ʰ e^{As} ds B.
struct DiscreteSystem {
  ///@{
  /// Ad (nx×nx) and Bd (nx×m): x_{k+1} = Ad x_k + Bd u_k with u held over the step.
  Eigen::MatrixXd Ad, Bd;
  ///@}
};
/// The discretization above of A (nx×nx), B (nx×m) at step h [s] (> 0), by one matrix exponential
/// of the (nx+m)×(nx+m) block matrix. Throws std::invalid_argument for bad sizes or h ≤ 0.
DiscreteSystem discretizeZeroOrderHold(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, double h);

}  // namespace trellis
