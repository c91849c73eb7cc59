// trellis/control/lyapunov.hpp — the continuous Lyapunov equation Fᵀ X + X F + C = 0.
#pragma once

#include "trellis/control/matrix_equation.hpp"

#include <Eigen/Core>

namespace trellis {

/// Solves Fᵀ X + X F + C = 0 (F n×n with no eigenvalue pair λ_i + λ̄_j = 0, C n×n symmetric) by a
/// complex Schur form F = U T Uᴴ and column-wise back substitution (Bartels–Stewart), O(n³); X is
/// symmetric. Throws std::invalid_argument when F or C is not square or their sizes differ. A
/// singular equation (a pivot T_ii + conj(T_jj) at rounding level, ≤ 1e3·eps·max(1, ‖T‖)) is the
/// status kSingular, never thrown.
MatrixEquationSolution solveLyapunov(const Eigen::MatrixXd& F, const Eigen::MatrixXd& C);

}  // namespace trellis
