// stein.cpp — Fᵀ X F − X + C = 0 by a complex Schur form (LAPACK's real one, made triangular).
#include "trellis/control/stein.hpp"

#include "lapack.hpp"
#include "matrix_equation_schur.hpp"
#include "schur_substitution.hpp"

#include <algorithm>
#include <complex>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

namespace trellis {

using Eigen::Index;
using Eigen::MatrixXcd;
using Eigen::MatrixXd;
using Complex = std::complex<double>;

namespace {

/// The real Schur form F = U T Uᵀ made complex upper triangular, F = Uc Tc Ucᴴ: each 2×2 block
/// T(k:k+1, k:k+1) (a standardized pair a ± ib, b² = −T(k,k+1)·T(k+1,k)) is rotated by the unitary
/// G = [c −s; s c̄] whose first column (c, s) is the unit eigenvector of the block for μ = a + ib,
/// ∝ (μ − T(k+1,k+1), T(k+1,k)): then (GᴴTG)(k+1, k) = 0. The rotations act on disjoint planes
/// and leave the other blocks' entries alone, so their order is free. O(n²) per block.
void triangularize(const MatrixXd& T, const MatrixXd& U, MatrixXcd& Tc, MatrixXcd& Uc) {
  const Index n = T.rows();
  Tc = T.cast<Complex>();
  Uc = U.cast<Complex>();
  for (Index k = 0; k + 1 < n; ++k) {
    if (T(k + 1, k) == 0.0) continue;
    const double a = 0.5 * (T(k, k) + T(k + 1, k + 1));
    const double b = std::sqrt(std::abs(T(k, k + 1) * T(k + 1, k)));
    const Complex v0 = Complex(a - T(k + 1, k + 1), b);
    const double v1 = T(k + 1, k), r = std::hypot(std::abs(v0), v1);
    const Complex c = v0 / r, cc = std::conj(c);
    const double s = v1 / r;
    for (Index j = k; j < n; ++j) {  // rows k, k+1 ← Gᴴ rows
      const Complex x = Tc(k, j), y = Tc(k + 1, j);
      Tc(k, j) = cc * x + s * y;
      Tc(k + 1, j) = -s * x + c * y;
    }
    for (Index i = 0; i <= k + 1; ++i) {  // columns k, k+1 ← columns G
      const Complex x = Tc(i, k), y = Tc(i, k + 1);
      Tc(i, k) = c * x + s * y;
      Tc(i, k + 1) = -s * x + cc * y;
    }
    for (Index i = 0; i < n; ++i) {
      const Complex x = Uc(i, k), y = Uc(i, k + 1);
      Uc(i, k) = c * x + s * y;
      Uc(i, k + 1) = -s * x + cc * y;
    }
    Tc(k + 1, k) = 0.0;
    ++k;  // the block's second column
  }
}

}  // namespace

MatrixEquationSolution solveStein(const MatrixXd& F, const MatrixXd& C) {
  const Index n = F.rows();
  detail::requireSquarePair("solveStein", F, C);
  MatrixEquationSolution out;
  if (n == 0) return out;
  detail::lapack::RealSchur schur(n, true);
  if (!detail::realSchurOrStatus("solveStein", F, schur, out)) return out;
  // F = U T Uᴴ, X = U Y Uᴴ: Tᴴ Y T − Y + Uᴴ C U = 0, solved column by column:
  // (T_jj Tᴴ − I) Y_j = −C̃_j − Tᴴ Σ_{k<j} Y_k T_kj  (lower triangular).
  MatrixXcd T, Uc;
  triangularize(schur.T(), schur.U(), T, Uc);
  const MatrixXcd Ct = Uc.adjoint() * C.cast<Complex>() * Uc;
  const MatrixXcd Th = T.adjoint();
  Eigen::VectorXcd acc(n);
  const double tiny =
      1e3 * std::numeric_limits<double>::epsilon() * std::max(1.0, T.norm() * T.norm());
  return detail::substituteColumns(
      Uc, tiny, "solveStein", "lambda_i conj(lambda_j) = 1",
      [&](Index j, const MatrixXcd& Y, MatrixXcd& L, Eigen::VectorXcd& rhs) {
        acc.setZero();
        for (Index k = 0; k < j; ++k) acc += Y.col(k) * T(k, j);
        rhs = -Ct.col(j) - Th.triangularView<Eigen::Lower>() * acc;
        L = T(j, j) * Th;
        L.diagonal().array() -= 1.0;
      });
}

}  // namespace trellis
