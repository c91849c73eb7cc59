// schur_substitution.hpp (private) — the column substitution of the Stein solve (the Lyapunov
// solve uses LAPACK's dtrsyl instead): in the complex Schur basis F = U T Uᴴ, X = U Y Uᴴ, the
// equation becomes one lower-triangular system per column of Y,
//   L_j Y_j = r_j   (Stein: L_j = T_jj Tᴴ − I; a Lyapunov equation would have L_j = Tᴴ + T_jj I),
// solved for j = 0, 1, …, n−1 (r_j uses the columns before j). A pivot |L_j(i, i)| at rounding
// level (≤ tiny) makes the equation singular: the status kSingular with index j, never a throw.
#pragma once

#include "trellis/control/matrix_equation.hpp"

#include <Eigen/Core>

#include <complex>
#include <limits>
#include <string>

namespace trellis::detail {

/// column(j, Y, L, r) writes L_j (n×n, lower triangular part read) and r_j from Y's first j
/// columns; then Y_j = L_j⁻¹ r_j. Returns X = sym(Re(U Y Uᴴ)), or the singular / non-finite status
/// (`what` names the solver in the message, `singular` says which eigenvalue pairs are excluded).
template <class Column>
MatrixEquationSolution substituteColumns(const Eigen::MatrixXcd& U, double tiny, const char* what,
                                         const char* singular, Column&& column) {
  const Eigen::Index n = U.rows();
  MatrixEquationSolution out;
  Eigen::MatrixXcd Y(n, n), L(n, n);
  Eigen::VectorXcd rhs(n);
  for (Eigen::Index j = 0; j < n; ++j) {
    column(j, Y, L, rhs);
    for (Eigen::Index i = 0; i < n; ++i) {
      if (std::abs(L(i, i)) <= tiny) {
        out.status.set(MatrixEquationCode::kSingular,
                       std::string(what) + ": singular equation (eigenvalues of F with " + singular + ")",
                       std::numeric_limits<double>::quiet_NaN(), static_cast<long>(j));
        return out;
      }
    }
    Y.col(j) = L.triangularView<Eigen::Lower>().solve(rhs);
  }
  const Eigen::MatrixXd X = (U * Y * U.adjoint()).real();
  out.X = 0.5 * (X + X.transpose());
  if (!out.X.allFinite()) {
    out.X.resize(0, 0);
    out.status.set(MatrixEquationCode::kNonFinite, std::string(what) + ": the solution is not finite");
  }
  return out;
}

}  // namespace trellis::detail
