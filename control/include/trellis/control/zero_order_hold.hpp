// trellis/control/zero_order_hold.hpp — exact zero-order-hold discretization of ẋ = A x + B u.
#pragma once

#include <Eigen/Core>

namespace trellis {

/// Exact zero-order-hold discretization at step h > 0:
/// exp([[A, B], [0, 0]] h) = [[Ad, Bd], [0, I]], Ad = e^{Ah}, Bd = ∫₀ʰ e^{As} ds B.
struct DiscreteSystem {
  Eigen::MatrixXd Ad, Bd;
};
DiscreteSystem discretizeZeroOrderHold(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, double h);

}  // namespace trellis
