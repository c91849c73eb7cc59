// matrix_equation.cpp — the report of a Lyapunov or Stein solution.
#include "trellis/control/matrix_equation.hpp"

#include "trellis/core/detail/report_json.hpp"

namespace trellis {

std::string MatrixEquationSolution::describe() const {
  return status.describe() + " (n = " + std::to_string(X.rows()) + ")";
}

std::string MatrixEquationSolution::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["n"] = X.rows();
  return j.dump();
}

}  // namespace trellis
