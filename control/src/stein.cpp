// stein.cpp — Fᵀ X F − X + C = 0 by a complex Schur form.
#include "trellis/control/stein.hpp"

#include "schur_substitution.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <complex>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

using Eigen::Index;
using Eigen::MatrixXcd;
using Eigen::MatrixXd;
using Complex = std::complex<double>;

MatrixEquationSolution solveStein(const MatrixXd& F, const MatrixXd& C) {
  const Index n = F.rows();
  if (F.cols() != n || C.rows() != n || C.cols() != n) {
    std::ostringstream m;
    m << "solveStein: F and C must be square and of the same size, got F " << F.rows() << "x"
      << F.cols() << " and C " << C.rows() << "x" << C.cols();
    throw std::invalid_argument(m.str());
  }
  // F = U T Uᴴ, X = U Y Uᴴ: Tᴴ Y T − Y + Uᴴ C U = 0, solved column by column:
  // (T_jj Tᴴ − I) Y_j = −C̃_j − Tᴴ Σ_{k<j} Y_k T_kj  (lower triangular).
  Eigen::ComplexSchur<MatrixXcd> schur(F.cast<Complex>());
  const MatrixXcd& T = schur.matrixT();
  const MatrixXcd Ct = schur.matrixU().adjoint() * C.cast<Complex>() * schur.matrixU();
  const MatrixXcd Th = T.adjoint();
  Eigen::VectorXcd acc(n);
  const double tiny =
      1e3 * std::numeric_limits<double>::epsilon() * std::max(1.0, T.norm() * T.norm());
  return detail::substituteColumns(
      schur.matrixU(), tiny, "solveStein", "lambda_i conj(lambda_j) = 1",
      [&](Index j, const MatrixXcd& Y, MatrixXcd& L, Eigen::VectorXcd& rhs) {
        acc.setZero();
        for (Index k = 0; k < j; ++k) acc += Y.col(k) * T(k, j);
        rhs = -Ct.col(j) - Th.triangularView<Eigen::Lower>() * acc;
        L = T(j, j) * Th;
        L.diagonal().array() -= 1.0;
      });
}

}  // namespace trellis
