// python/src/bind_tvlqr.cpp — the unified, plain-data TV-LQR (solveTvlqr: continuous or sampled
// with zero-order hold, constrained or not), when the control library has it
// (trellis/control/tvlqr.hpp, branch i10-sampled). Without that header this file binds nothing
// and trellis_mech.HAS_SOLVE_TVLQR is False; the older solve_riccati / solve_manifold_riccati
// (bind_control.cpp) stay available either way.
#include "common.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#if __has_include("trellis/control/tvlqr.hpp")
#include "control_common.hpp"
#include "options.hpp"

#include "trellis/core/trajectory.hpp"
#include "trellis/control/tvlqr.hpp"
#include "trellis/core/model.hpp"

namespace trellis::python {

void bindTvlqr(py::module_& m) {
  m.attr("HAS_SOLVE_TVLQR") = true;

  // The gain schedule's sample rate and column names (added with solveTvlqr).
  auto schedule = py::reinterpret_borrow<py::class_<GainSchedule>>(m.attr("GainSchedule"));
  schedule
      .def_property("sample_rate", &GainSchedule::sampleRate, &GainSchedule::setSampleRate,
                    "0: continuous gains; f > 0: zero-order-hold gains for a controller sampling at f Hz")
      .def_property_readonly("is_sampled", &GainSchedule::isSampled)
      .def_property_readonly("column_names", &GainSchedule::columnNames, "K_<input>_<state>, row-major")
      .def("set_column_names", &GainSchedule::setColumnNames, py::arg("input_names"),
           py::arg("state_names"));

  py::class_<SampledDiscretizationOptions>(m, "SampledDiscretizationOptions",
      "CVODES tolerances of the exact interval discretization (keywords: rtol, atol, max_steps).")
      .def(py::init(&makeFromKwargs<SampledDiscretizationOptions>))
      .def_readwrite("rtol", &SampledDiscretizationOptions::rtol)
      .def_readwrite("atol", &SampledDiscretizationOptions::atol)
      .def_readwrite("max_steps", &SampledDiscretizationOptions::maxSteps);

  py::class_<TvlqrOptions>(m, "TvlqrOptions",
      "Options of solve_tvlqr (keywords): sample_rate (0: continuous; f > 0: zero-order hold at f "
      "Hz), output_step (continuous: tabulate K every output_step; 0: at the knots), riccati "
      "(RiccatiOptions), sampled (SampledDiscretizationOptions), transport (TangentTransportOptions).")
      .def(py::init(&makeFromKwargs<TvlqrOptions>))
      .def_readwrite("sample_rate", &TvlqrOptions::sampleRate)
      .def_readwrite("output_step", &TvlqrOptions::outputStep)
      .def_readwrite("riccati", &TvlqrOptions::riccati)
      .def_readwrite("sampled", &TvlqrOptions::sampled)
      .def_readwrite("transport", &TvlqrOptions::transport)
      .def("validate", &TvlqrOptions::validate);

  py::class_<TvlqrSolution>(m, "TvlqrSolution",
      "Plain data (owns its arrays; no reference to the model): ok, message, gains (GainSchedule, "
      "K (nu, nx) at its times), S (N, nx, nx) at the same times, and diagnostics.")
      .def_readonly("ok", &TvlqrSolution::ok)
      .def_readonly("message", &TvlqrSolution::message)
      .def_readonly("sample_rate", &TvlqrSolution::sampleRate)
      .def_readonly("constrained", &TvlqrSolution::constrained)
      .def_readonly("nx", &TvlqrSolution::nx)
      .def_readonly("nu", &TvlqrSolution::nu)
      .def_readonly("dimension", &TvlqrSolution::dimension)
      .def_readonly("gains", &TvlqrSolution::gains)
      .def_property_readonly("S", [](const TvlqrSolution& s) { return toArray3(s.S, s.nx, s.nx); },
                             "(N, nx, nx) at gains.times")
      .def_readonly("seconds", &TvlqrSolution::seconds)
      .def_readonly("steps", &TvlqrSolution::steps)
      .def_readonly("rhs_evaluations", &TvlqrSolution::rhsEvaluations)
      .def_readonly("linearizations", &TvlqrSolution::linearizations)
      .def_readonly("transport_steps", &TvlqrSolution::transportSteps)
      .def_readonly("max_basis_correction", &TvlqrSolution::maxBasisCorrection)
      .def_readonly("min_eigenvalue_S", &TvlqrSolution::minEigenvalueS)
      .def_readonly("max_eigenvalue_S", &TvlqrSolution::maxEigenvalueS)
      .def_readonly("method", &TvlqrSolution::method)
      .def("summary", &TvlqrSolution::summary)
      .def("json", &TvlqrSolution::json)
      .def("__repr__", [](const TvlqrSolution& s) {
        return std::string("<TvlqrSolution ") + (s.ok ? "ok" : "FAILED: " + s.message) + ", " +
               s.method + ">";
      });

  m.def("solve_tvlqr",
        [](const Model& model, const Trajectory& reference, const py::object& Q, const py::object& R,
           const py::object& Qf, const std::optional<TvlqrOptions>& options) {
          const LqrWeights w = makeWeights(Q, R, Qf, 2 * model.nq(), model.nu());
          const TvlqrOptions o = options.value_or(TvlqrOptions{});
          // The grids an option implies are bounded before any is allocated, as on the command
          // line (`trellis gains`: 1e6 output rows): the count is computed in double, never wrapped.
          constexpr double kMaxGridPoints = 1e6;
          const double span = reference.endTime() - reference.startTime();
          const auto bound = [&](const char* option, double step, const char* what) {
            const double points = std::floor(span / step) + 2.0;
            if (!(points <= kMaxGridPoints)) {
              throw std::invalid_argument("solve_tvlqr: options." + std::string(option) + " gives a step of " +
                                          std::to_string(step) + " s over " + std::to_string(span) + " s: " +
                                          std::to_string(points) + " " + what + "; the limit is 1000000");
            }
          };
          if (o.sampleRate > 0.0) bound("sample_rate", 1.0 / o.sampleRate, "samples");
          if (o.outputStep > 0.0) bound("output_step", o.outputStep, "output rows");
          py::gil_scoped_release release;
          return solveTvlqr(model, reference, w, o);
        },
        py::arg("model"), py::arg("reference"), py::kw_only(), py::arg("Q"), py::arg("R"),
        py::arg("Qf") = py::none(), py::arg("options") = py::none(),
        "TV-LQR along the reference (state derivatives needed), continuous (Riccati ODE) or "
        "sampled at options.sample_rate with zero-order hold, on the constraint manifold when the "
        "model has constraints: minimizes int dx^T Q dx + du^T R du dt + dx(T)^T Qf dx(T). Weights: "
        "a number (times I), a diagonal or a matrix; Qf defaults to Q. Returns plain data; "
        "numerical failure is ok = False with a message. Releases the GIL.");
}

}  // namespace trellis::python

#else

namespace trellis::python {
void bindTvlqr(py::module_& m) { m.attr("HAS_SOLVE_TVLQR") = false; }
}  // namespace trellis::python

#endif
