// trellis/control/lyapunov.hpp — the continuous Lyapunov equation Fᵀ X + X F + C = 0.
#pragma once

#include "trellis/control/matrix_equation.hpp"

#include <Eigen/Core>

namespace trellis {

/// Solves Fᵀ X + X F + C = 0 (F n×n with no eigenvalue pair λ_i + λ̄_j = 0, C n×n symmetric) by
/// LAPACK's real Schur form F = U T Uᵀ (dgees) and the quasi-triangular Sylvester solve
/// Tᵀ Y + Y T = −Uᵀ C U (dtrsyl; Bartels–Stewart), O(n³); X = U Y Uᵀ, symmetric. Throws
/// std::invalid_argument when F or C is not square or their sizes differ. A singular equation
/// (eigenvalues with |λ_i + conj(λ_j)| ≤ 1e3·eps·max(1, ‖T‖_F); index: the first such Schur column j)
/// is the status kSingular, a Schur form that did not converge or a non-finite F kNoConvergence,
/// never thrown.
MatrixEquationSolution solveLyapunov(const Eigen::MatrixXd& F, const Eigen::MatrixXd& C);

}  // namespace trellis
