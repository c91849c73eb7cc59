// lyapunov.cpp — Fᵀ X + X F + C = 0 by the real Schur form (Bartels–Stewart, LAPACK dgees + dtrsyl).
#include "trellis/control/lyapunov.hpp"

#include "lapack.hpp"
#include "matrix_equation_schur.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

namespace trellis {

using Eigen::Index;
using Eigen::MatrixXd;

MatrixEquationSolution solveLyapunov(const MatrixXd& F, const MatrixXd& C) {
  const Index n = F.rows();
  detail::requireSquarePair("solveLyapunov", F, C);
  MatrixEquationSolution out;
  if (n == 0) return out;
  // F = U T Uᵀ (T quasi-triangular), X = U Y Uᵀ: Tᵀ Y + Y T = −Uᵀ C U, a triangular Sylvester
  // equation (dtrsyl). Its operator has the eigenvalues λ_i + λ_j.
  detail::lapack::RealSchur schur(n, true);
  if (!detail::realSchurOrStatus("solveLyapunov", F, schur, out)) return out;
  // Singular when some λ_i + conj(λ_j) is at rounding level (the same test, and the same first
  // Schur column j in the status, as a pivot test of a complex column-by-column substitution).
  const double tiny =
      1e3 * std::numeric_limits<double>::epsilon() * std::max(1.0, schur.T().norm());
  for (Index j = 0; j < n; ++j) {
    const std::complex<double> lj(schur.wr()(j), schur.wi()(j));
    for (Index i = 0; i < n; ++i) {
      if (std::abs(std::complex<double>(schur.wr()(i), -schur.wi()(i)) + lj) <= tiny) {
        out.status.set(MatrixEquationCode::kSingular,
                       "solveLyapunov: singular equation (eigenvalues of F with lambda_i + "
                       "conj(lambda_j) = 0)",
                       std::numeric_limits<double>::quiet_NaN(), static_cast<long>(j));
        return out;
      }
    }
  }
  const MatrixXd& U = schur.U();
  MatrixXd Y = -(U.transpose() * (C * U));
  double scale = 1.0;
  if (detail::lapack::solveSchurLyapunov(schur.T(), Y, scale) != 0) {
    out.status.set(MatrixEquationCode::kSingular,
                   "solveLyapunov: singular equation (LAPACK dtrsyl perturbed eigenvalues of F "
                   "with lambda_i + lambda_j = 0)",
                   std::numeric_limits<double>::quiet_NaN(), 0L);
    return out;
  }
  MatrixXd X = U * ((Y / scale) * U.transpose());
  out.X = 0.5 * (X + X.transpose());
  if (!out.X.allFinite()) {
    out.X.resize(0, 0);
    out.status.set(MatrixEquationCode::kNonFinite, "solveLyapunov: the solution is not finite");
  }
  return out;
}

}  // namespace trellis
