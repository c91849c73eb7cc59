// lyapunov.cpp — Fᵀ X + X F + C = 0 by a complex Schur form (Bartels–Stewart).
#include "trellis/control/lyapunov.hpp"

#include "schur_substitution.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <complex>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

using Eigen::MatrixXcd;
using Eigen::MatrixXd;

MatrixEquationSolution solveLyapunov(const MatrixXd& F, const MatrixXd& C) {
  const Eigen::Index n = F.rows();
  if (F.cols() != n || C.rows() != n || C.cols() != n) {
    std::ostringstream m;
    m << "solveLyapunov: F and C must be square and of the same size, got F " << F.rows() << "x"
      << F.cols() << " and C " << C.rows() << "x" << C.cols();
    throw std::invalid_argument(m.str());
  }
  // F = U T Uᴴ, X = U Y Uᴴ: Tᴴ Y + Y T + Uᴴ C U = 0, solved column by column:
  // (Tᴴ + T_jj I) Y_j = −C̃_j − Σ_{k<j} Y_k T_kj  (lower triangular).
  Eigen::ComplexSchur<MatrixXcd> schur(F.cast<std::complex<double>>());
  const MatrixXcd& T = schur.matrixT();
  const MatrixXcd Ct = schur.matrixU().adjoint() * C.cast<std::complex<double>>() * schur.matrixU();
  const MatrixXcd Th = T.adjoint();  // lower triangular
  const double tiny = 1e3 * std::numeric_limits<double>::epsilon() * std::max(1.0, T.norm());
  return detail::substituteColumns(
      schur.matrixU(), tiny, "solveLyapunov", "lambda_i + conj(lambda_j) = 0",
      [&](Eigen::Index j, const MatrixXcd& Y, MatrixXcd& L, Eigen::VectorXcd& rhs) {
        rhs = -Ct.col(j);
        for (Eigen::Index k = 0; k < j; ++k) rhs -= Y.col(k) * T(k, j);
        L = Th;
        L.diagonal().array() += T(j, j);
      });
}

}  // namespace trellis
