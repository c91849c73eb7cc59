// matrix_equation_schur.hpp (private) — the first step of solveLyapunov and solveStein: check
// that F and C are square and of one size (std::invalid_argument naming the solver otherwise),
// then F = U T Uᵀ by LAPACK's real Schur form; a Schur form that fails (no convergence, or a
// non-finite entry of F) becomes the solution's kNoConvergence status, named by the solver.
#pragma once

#include "lapack.hpp"
#include "trellis/control/matrix_equation.hpp"

namespace trellis::detail {

/// Throws std::invalid_argument("WHO: F and C must be square and of the same size, got …")
/// unless F and C are square and of one size.
void requireSquarePair(const char* who, const Eigen::MatrixXd& F, const Eigen::MatrixXd& C);

/// Computes `schur` of F and returns true; when dgees fails, sets out.status to kNoConvergence
/// with WHO's message (a non-finite entry of F, or the QR iteration's INFO) and returns false.
bool realSchurOrStatus(const char* who, const Eigen::MatrixXd& F, lapack::RealSchur& schur,
                       MatrixEquationSolution& out);

}  // namespace trellis::detail
