// python/src/bind_controllability.cpp — control/controllability.hpp: the rank test at a point (or
// at every knot) and the reachability Gramian along a trajectory. Numerical failure (the dynamics
// at a point, the transport, CVODES) is the report's status, never an exception.
#include "common.hpp"
#include "control_common.hpp"
#include "options.hpp"

#include "trellis/control/controllability.hpp"
#include "trellis/core/trajectory.hpp"

#include <optional>
#include <string>

namespace trellis::python {

void bindControllability(py::module_& m) {
  bindStatus<ControllabilityCode>(m, "ControllabilityStatus",
      "Status of a controllability report (code: ok, linearization_failed, transport_failure, "
      "integrator_failure, not_computed).");

  py::class_<ControllabilityReport>(m, "ControllabilityReport",
      "Rank of the scaled Krylov matrix [B, (A/a) B, ..., (A/a)^(d-1) B] against d.")
      .def_readonly("status", &ControllabilityReport::status)
      .def_property_readonly("ok", &ControllabilityReport::ok)
      .def_readonly("dimension", &ControllabilityReport::dimension)
      .def_readonly("rank", &ControllabilityReport::rank)
      .def_readonly("smallest_singular_value", &ControllabilityReport::smallestSingularValue)
      .def_readonly("largest_singular_value", &ControllabilityReport::largestSingularValue)
      .def_readonly("scale", &ControllabilityReport::scale)
      .def_property_readonly("singular_values",
                             [](const ControllabilityReport& r) { return toArray(r.singularValues); })
      .def_property_readonly("controllable", &ControllabilityReport::controllable)
      .def("describe", &ControllabilityReport::describe)
      .def("json", &ControllabilityReport::json)
      .def("__repr__", [](const ControllabilityReport& r) { return "<ControllabilityReport " + r.describe() + ">"; });
  m.def("compute_controllability",
        [](const RealMatrix<"A">& A, const RealMatrix<"B">& B, double tol) {
          return computeControllability(A, B, tol);
        },
        py::arg("A"), py::arg("B"), py::arg("relative_tolerance") = 1e-10,
        "Controllability of (A (d, d), B (d, nu)).");
  m.def("compute_controllability_at",
        [](const Model& model, PyData& d, const RealVector<"q">& q, const RealVector<"dq">& dq,
           const RealVector<"u">& u, double tol) {
          checkSameModel(model, d);
          DataGuard guard(d);
          loadVector(q, d.q, "q", "model.nq");
          loadVector(dq, d.dq, "dq", "model.nq");
          loadVector(u, d.u, "u", "model.nu");
          return computeControllabilityAt(model, d.data, d.q, d.dq, d.u, tol);
        },
        py::arg("model"), py::arg("data"), py::arg("q"), py::arg("dq"), py::arg("u"),
        py::arg("relative_tolerance") = 1e-10,
        "Linearization at x = [q; dq], u, reduced to the constraint tangent space, then its "
        "controllability. If the dynamics fail there, the status is 'linearization_failed'.");
  m.def("controllability_at_knots",
        [](const Model& model, const Trajectory& t, double tol) {
          return withoutGil([&] { return controllabilityAtKnots(model, t, tol); });
        },
        py::arg("model"), py::arg("trajectory"), py::arg("relative_tolerance") = 1e-10,
        "compute_controllability_at every knot (a failing knot: its status names the knot, t and "
        "index).");

  py::class_<GramianReport>(m, "GramianReport",
      "Reduced reachability Gramian W (d, d) over [t0, t1] on the transported tangent basis.")
      .def_readonly("status", &GramianReport::status)
      .def_property_readonly("ok", &GramianReport::ok)
      .def_property_readonly("W", [](const GramianReport& r) { return toArray(r.W); })
      .def_readonly("min_eigenvalue", &GramianReport::minEigenvalue)
      .def_readonly("max_eigenvalue", &GramianReport::maxEigenvalue)
      .def_readonly("dimension", &GramianReport::dimension)
      .def_readonly("steps", &GramianReport::steps)
      .def("controllable", &GramianReport::controllable, py::arg("relative_tolerance") = 1e-10)
      .def("describe", &GramianReport::describe)
      .def("json", &GramianReport::json)
      .def("__repr__", [](const GramianReport& r) { return "<GramianReport " + r.describe() + ">"; });
  m.def("compute_controllability_gramian",
        [](const Model& model, const Trajectory& reference, std::optional<double> t0,
           std::optional<double> t1, const std::optional<TangentTransportOptions>& transport) {
          return withoutGil([&] {
            return computeControllabilityGramian(model, reference, t0.value_or(reference.startTime()),
                                                 t1.value_or(reference.endTime()),
                                                 transport.value_or(TangentTransportOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::arg("t0") = py::none(), py::arg("t1") = py::none(),
        py::kw_only(), py::arg("transport") = py::none(),
        "Reduced reachability Gramian W(t0, t1) = int Phi_r(t1, s) Br Br^T Phi_r^T ds (d, d) along "
        "the reference (default: its whole span); numerical failure is the status.");
}

}  // namespace trellis::python
