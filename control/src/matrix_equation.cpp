// matrix_equation.cpp — the report of a Lyapunov or Stein solution, and the first step both
// solvers share (matrix_equation_schur.hpp).
#include "trellis/control/matrix_equation.hpp"

#include "matrix_equation_schur.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <sstream>
#include <stdexcept>

namespace trellis {

std::string MatrixEquationSolution::describe() const {
  return status.describe() + " (n = " + std::to_string(X.rows()) + ")";
}

std::string MatrixEquationSolution::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["n"] = X.rows();
  return j.dump();
}

namespace detail {

void requireSquarePair(const char* who, const Eigen::MatrixXd& F, const Eigen::MatrixXd& C) {
  const Eigen::Index n = F.rows();
  if (F.cols() == n && C.rows() == n && C.cols() == n) return;
  std::ostringstream m;
  m << who << ": F and C must be square and of the same size, got F " << F.rows() << "x" << F.cols()
    << " and C " << C.rows() << "x" << C.cols();
  throw std::invalid_argument(m.str());
}

bool realSchurOrStatus(const char* who, const Eigen::MatrixXd& F, lapack::RealSchur& schur,
                       MatrixEquationSolution& out) {
  const int info = schur.compute(F);
  if (info == 0) return true;
  out.status.set(MatrixEquationCode::kNoConvergence,
                 info > F.rows() ? std::string(who) + ": F has a non-finite entry"
                                 : std::string(who) + ": the Schur form of F did not converge (LAPACK dgees INFO = " +
                                       std::to_string(info) + ")");
  return false;
}

}  // namespace detail
}  // namespace trellis
