// trellis/control/matrix_equation.hpp — the result of a linear matrix equation (Lyapunov, Stein).
#pragma once

#include "trellis/core/status.hpp"

#include <Eigen/Core>

#include <string>

namespace trellis {

/// Why a linear matrix equation has no (unique) solution.
enum class MatrixEquationCode {
  kOk,
  kSingular,   ///< two eigenvalues of F make the operator singular (index: the Schur column)
  kNonFinite,  ///< the solution has a non-finite entry
  kNoConvergence,  ///< the Schur form of F did not converge (LAPACK dgees), or F is not finite
};
inline EnumNameTable<MatrixEquationCode> enumNames(MatrixEquationCode) {
  static constexpr EnumName<MatrixEquationCode> table[] = {
      {MatrixEquationCode::kOk, "ok"},
      {MatrixEquationCode::kSingular, "singular"},
      {MatrixEquationCode::kNonFinite, "non_finite"},
      {MatrixEquationCode::kNoConvergence, "no_convergence"}};
  return table;
}

/// X of a Lyapunov or Stein equation (n×n, symmetric) and the status. When not ok, X is empty and
/// status.index is the column of the Schur form where the substitution met a zero pivot.
struct MatrixEquationSolution {
  Status<MatrixEquationCode> status;  ///< kOk, kSingular (status.index: the Schur column), kNonFinite, kNoConvergence
  Eigen::MatrixXd X;                  ///< n×n symmetric solution; empty when not ok
  bool ok() const { return status.ok(); }  ///< status.ok()
  /// One line: the status (and n).
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "n"}.
  std::string json() const;
};

}  // namespace trellis
