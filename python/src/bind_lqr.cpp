// python/src/bind_lqr.cpp — the time-invariant control headers: algebraic_riccati.hpp (care.hpp,
// dare.hpp: LqrResult), lyapunov.hpp (MatrixEquationSolution), zero_order_hold.hpp and
// discrete_riccati_recursion.hpp. Matrix arguments are RealMatrix<"name">: a complex array is a
// TypeError naming the argument.
#include "common.hpp"
#include "control_common.hpp"
#include "options.hpp"

#include "trellis/control/discrete_riccati_recursion.hpp"
#include "trellis/control/lqr.hpp"
#include "trellis/control/lyapunov.hpp"
#include "trellis/control/zero_order_hold.hpp"

#include <optional>
#include <string>

namespace trellis::python {

void bindLqr(py::module_& m) {
  bindStatus<LqrCode>(m, "LqrStatus", "Status of solve_care / solve_dare (code: ok, not_stabilizable, "
                                      "no_stabilizing_solution, no_convergence).");
  bindStatus<MatrixEquationCode>(m, "MatrixEquationStatus",
                                 "Status of solve_lyapunov (code: ok, singular, non_finite, no_convergence).");

  py::class_<CareOptions>(m, "CareOptions", "Options of solve_care / solve_dare (keywords).")
      .def(py::init(&makeFromKwargs<CareOptions>))
      .def_readwrite("max_iterations", &CareOptions::maxIterations)
      .def_readwrite("tolerance", &CareOptions::tolerance)
      .def_readwrite("refinement_steps", &CareOptions::refinementSteps)
      .def_readwrite("residual_tolerance", &CareOptions::residualTolerance)
      .def_readwrite("stabilizability_tolerance", &CareOptions::stabilizabilityTolerance);

  py::class_<LqrResult>(m, "LqrResult",
      "S (nx, nx), K (nu, nx), status (LqrStatus), residual, iterations, closed_loop_eigenvalues "
      "(complex, of A - BK or Ad - Bd K); describe() and json() are the library's reports.")
      .def_readonly("status", &LqrResult::status)
      .def_property_readonly("ok", &LqrResult::ok)
      .def_property_readonly("S", [](const LqrResult& r) { return toArray(r.S); })
      .def_property_readonly("K", [](const LqrResult& r) { return toArray(r.K); })
      .def_readonly("residual", &LqrResult::residual)
      .def_readonly("iterations", &LqrResult::iterations)
      .def_readonly("refinement_steps", &LqrResult::refinementSteps)
      .def_property_readonly("closed_loop_eigenvalues",
                             [](const LqrResult& r) { return toArrayComplex(r.closedLoopEigenvalues); })
      .def("describe", &LqrResult::describe)
      .def("json", &LqrResult::json)
      .def("__repr__", [](const LqrResult& r) { return "<LqrResult " + r.describe() + ">"; });

  m.def("solve_care",
        [](const RealMatrix<"A">& A, const RealMatrix<"B">& B, const RealMatrix<"Q">& Q,
           const RealMatrix<"R">& R, const std::optional<CareOptions>& options) {
          return withoutGil([&] { return solveCare(A, B, Q, R, options.value_or(CareOptions{})); });
        },
        py::arg("A"), py::arg("B"), py::arg("Q"), py::arg("R"), py::kw_only(),
        py::arg("options") = py::none(),
        "Continuous algebraic Riccati equation A^T S + S A - S B R^-1 B^T S + Q = 0 (A (nx, nx), "
        "B (nx, nu), Q (nx, nx), R (nu, nu) PD); K = R^-1 B^T S. Bad sizes or weights raise "
        "ValueError; numerical failure and non-stabilizability are the result's status.");
  m.def("solve_dare",
        [](const RealMatrix<"Ad">& A, const RealMatrix<"Bd">& B, const RealMatrix<"Q">& Q,
           const RealMatrix<"R">& R, const std::optional<CareOptions>& options) {
          return withoutGil([&] { return solveDare(A, B, Q, R, options.value_or(CareOptions{})); });
        },
        py::arg("Ad"), py::arg("Bd"), py::arg("Q"), py::arg("R"), py::kw_only(),
        py::arg("options") = py::none(),
        "Discrete algebraic Riccati equation S = Ad^T S Ad - Ad^T S Bd (R + Bd^T S Bd)^-1 Bd^T S Ad + Q; "
        "K = (R + Bd^T S Bd)^-1 Bd^T S Ad.");

  py::class_<MatrixEquationSolution>(m, "MatrixEquationSolution",
      "X (n, n) of a Lyapunov equation and its status (MatrixEquationStatus); X is empty when not ok.")
      .def_readonly("status", &MatrixEquationSolution::status)
      .def_property_readonly("ok", &MatrixEquationSolution::ok)
      .def_property_readonly("X", [](const MatrixEquationSolution& s) { return toArray(s.X); })
      .def("describe", &MatrixEquationSolution::describe)
      .def("json", &MatrixEquationSolution::json)
      .def("__repr__", [](const MatrixEquationSolution& s) { return "<MatrixEquationSolution " + s.describe() + ">"; });
  m.def("solve_lyapunov",
        [](const RealMatrix<"F">& F, const RealMatrix<"C">& C) { return solveLyapunov(F, C); },
        py::arg("F"), py::arg("C"),
        "X with F^T X + X F + C = 0 (Bartels-Stewart); a singular equation is the status "
        "(code 'singular'), not an exception.");
  m.def("discretize_zero_order_hold",
        [](const RealMatrix<"A">& A, const RealMatrix<"B">& B, double h) {
          const DiscreteSystem s = discretizeZeroOrderHold(A, B, h);
          // e^(A h) overflows for a large step (|λ| h beyond ~709): an error, never NaN arrays.
          if (!s.Ad.allFinite() || !s.Bd.allFinite()) {
            throw std::runtime_error("discretize_zero_order_hold: e^(A h) is not finite at h = " + std::to_string(h) +
                                     " (the step is too large for this A: |eigenvalue| * h overflows)");
          }
          return py::make_tuple(toArray(s.Ad), toArray(s.Bd));
        },
        py::arg("A"), py::arg("B"), py::arg("h"),
        "(Ad, Bd): Ad = e^(A h), Bd = int_0^h e^(A s) ds B (exact zero-order hold). Raises "
        "NumericalError when the exponential overflows (a step too large for A).");
  m.def("solve_discrete_riccati_recursion",
        [](const RealMatrix<"Ad">& Ad, const RealMatrix<"Bd">& Bd, const RealMatrix<"Q">& Q,
           const RealMatrix<"R">& R, const RealMatrix<"Qf">& Qf, int N) {
          const DiscreteRiccatiRecursion r =
              withoutGil([&] { return solveDiscreteRiccatiRecursion(Ad, Bd, Q, R, Qf, N); });
          return py::make_tuple(toArray3(r.S, Ad.value.rows(), Ad.value.cols()),
                                toArray3(r.K, Bd.value.cols(), Ad.value.cols()));
        },
        py::arg("Ad"), py::arg("Bd"), py::arg("Q"), py::arg("R"), py::arg("Qf"), py::arg("N"),
        "Finite-horizon discrete LQR over N steps: (S (N+1, nx, nx), K (N, nu, nx)) with S_N = Qf, "
        "K_k = (R + Bd^T S_{k+1} Bd)^-1 Bd^T S_{k+1} Ad, S_k = Q + Ad^T S_{k+1} (Ad - Bd K_k).");
}

}  // namespace trellis::python
