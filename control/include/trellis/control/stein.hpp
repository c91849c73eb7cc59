// trellis/control/stein.hpp — the Stein (discrete Lyapunov) equation Fᵀ X F − X + C = 0.
#pragma once

#include "trellis/control/matrix_equation.hpp"

#include <Eigen/Core>

namespace trellis {

/// Solves Fᵀ X F − X + C = 0 (F n×n with no eigenvalue pair λ_i λ̄_j = 1, C n×n symmetric) by
/// LAPACK's real Schur form (dgees), made complex triangular by one plane rotation per 2×2 block,
/// and column-wise back substitution, O(n³); X is symmetric. Throws std::invalid_argument when F or
/// C is not square or their sizes differ. A singular equation (a pivot T_jj conj(T_ii) − 1 at
/// rounding level, ≤ 1e3·eps·max(1, ‖T‖²)) is the status kSingular, a Schur form that did not
/// converge or a non-finite F kNoConvergence, never thrown.
MatrixEquationSolution solveStein(const Eigen::MatrixXd& F, const Eigen::MatrixXd& C);

}  // namespace trellis
