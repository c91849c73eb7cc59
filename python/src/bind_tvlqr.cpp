// python/src/bind_tvlqr.cpp — control/tvlqr.hpp, the one TV-LQR entry (solveTvlqr: continuous or
// sampled with zero-order hold, on the constraint manifold when the model has constraints), with
// the options it takes from riccati.hpp, sampled_lqr.hpp and manifold_lqr.hpp, and the tangent
// basis of manifold_lqr.hpp (transport_tangent_basis). The result is plain data: the gain
// schedule, S (N, nx, nx) at its times (time first), the status and diagnostics.
#include "common.hpp"
#include "control_common.hpp"
#include "options.hpp"

#include "trellis/control/manifold_lqr.hpp"
#include "trellis/control/tvlqr.hpp"
#include "trellis/core/model.hpp"
#include "trellis/core/trajectory.hpp"

#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>

namespace trellis::python {

void bindTvlqr(py::module_& m) {
  py::enum_<RiccatiMethod>(m, "RiccatiMethod")
      .value("BDF", RiccatiMethod::kBDF)
      .value("ADAMS", RiccatiMethod::kAdams)
      .value("FACTORED", RiccatiMethod::kFactored);
  py::enum_<RiccatiLinearSolver>(m, "RiccatiLinearSolver")
      .value("AUTO", RiccatiLinearSolver::kAuto)
      .value("DENSE", RiccatiLinearSolver::kDense)
      .value("KRYLOV", RiccatiLinearSolver::kKrylov)
      .value("LYAPUNOV", RiccatiLinearSolver::kLyapunov);
  py::enum_<SampledIntegrator>(m, "SampledIntegrator")
      .value("MAGNUS", SampledIntegrator::kMagnus)
      .value("RADAU", SampledIntegrator::kRadau)
      .value("BDF", SampledIntegrator::kBdf);
  py::enum_<SampledFeedforward>(m, "SampledFeedforward",
      "The feed-forward written with sampled gains: REFERENCE (none: u_ref(t_k) held), AVERAGE "
      "(the interval average of u_ref), CONSISTENT (the held input that carries x_ref(t_k) closest "
      "to x_ref(t_k+1) through the exact dynamics, in the metric of S_k+1; the default).")
      .value("REFERENCE", SampledFeedforward::kReference)
      .value("AVERAGE", SampledFeedforward::kAverage)
      .value("CONSISTENT", SampledFeedforward::kConsistent);
  py::enum_<TangentTransport>(m, "TangentTransport")
      .value("INTEGRATED", TangentTransport::kIntegrated)
      .value("PROJECTED", TangentTransport::kProjected);

  py::class_<RiccatiOptions>(m, "RiccatiOptions", "Options of the Riccati integration (keywords).")
      .def(py::init(&makeFromKwargs<RiccatiOptions>))
      .def_readwrite("rtol", &RiccatiOptions::rtol)
      .def_readwrite("atol", &RiccatiOptions::atol)
      .def_readwrite("method", &RiccatiOptions::method)
      .def_readwrite("max_steps", &RiccatiOptions::maxSteps)
      .def_readwrite("max_norm", &RiccatiOptions::maxNorm)
      .def_readwrite("max_order", &RiccatiOptions::maxOrder)
      .def_readwrite("initial_step", &RiccatiOptions::initialStep)
      .def_readwrite("max_step", &RiccatiOptions::maxStep)
      .def_readwrite("linear_solver", &RiccatiOptions::linearSolver)
      .def_readwrite("exact_jacobian", &RiccatiOptions::exactJacobian)
      .def_readwrite("track_eigenvalues", &RiccatiOptions::trackEigenvalues)
      .def_readwrite("krylov_preconditioner", &RiccatiOptions::krylovPreconditioner)
      .def_readwrite("factored_qf_shift", &RiccatiOptions::factoredQfShift)
      .def("validate", &RiccatiOptions::validate);

  py::class_<TangentTransportOptions>(m, "TangentTransportOptions",
      "How the tangent basis T(t) is carried along the reference (keywords).")
      .def(py::init(&makeFromKwargs<TangentTransportOptions>))
      .def_readwrite("method", &TangentTransportOptions::method)
      .def_readwrite("substeps", &TangentTransportOptions::substeps)
      .def_readwrite("rtol", &TangentTransportOptions::rtol)
      .def_readwrite("atol", &TangentTransportOptions::atol)
      .def_readwrite("max_steps", &TangentTransportOptions::maxSteps);

  py::class_<SampledDiscretizationOptions>(m, "SampledDiscretizationOptions",
      "The exact interval discretization (keywords): integrator (SampledIntegrator.RADAU, the "
      "default; MAGNUS for non-stiff systems; BDF: CVODES per interval), rtol, atol (BDF only), "
      "max_steps, and "
      "exact_constant_intervals (default True: intervals where the reference is exactly constant, "
      "e.g. a held pose, by the exact block exponential instead of the integration), "
      "interpolate_linearization (default True: with RADAU along an unconstrained reference, A(t), "
      "B(t) between knots from a checked Chebyshev interpolant of exact linearizations, to 1e-12 "
      "of their balanced scale, else exact).")
      .def(py::init(&makeFromKwargs<SampledDiscretizationOptions>))
      .def_readwrite("integrator", &SampledDiscretizationOptions::integrator)
      .def_readwrite("rtol", &SampledDiscretizationOptions::rtol)
      .def_readwrite("atol", &SampledDiscretizationOptions::atol)
      .def_readwrite("max_steps", &SampledDiscretizationOptions::maxSteps)
      .def_readwrite("exact_constant_intervals", &SampledDiscretizationOptions::exactConstantIntervals)
      .def_readwrite("interpolate_linearization", &SampledDiscretizationOptions::interpolateLinearization);

  py::class_<TvlqrOptions>(m, "TvlqrOptions",
      "Options of solve_tvlqr (keywords): sample_rate (0: continuous; f > 0: zero-order hold at f "
      "Hz), output_step (continuous: tabulate K every output_step; 0: at the knots), riccati "
      "(RiccatiOptions), sampled (SampledDiscretizationOptions), transport (TangentTransportOptions), "
      "feedforward (SampledFeedforward, sampled only), feedforward_iterations, measure_held_reference "
      "(sampled: also run u_ref(t_k) held, for reference_defect; with feedforward reference, False "
      "runs no plant at all: the gains alone), threads (sampled: the "
      "feed-forward's plant runs; the same result on any count), infinite_horizon (a held "
      "pose only: Qf = S_inf of the CARE, or of the DARE when sampled).")
      .def(py::init(&makeFromKwargs<TvlqrOptions>))
      .def_readwrite("feedforward", &TvlqrOptions::feedforward)
      .def_readwrite("feedforward_iterations", &TvlqrOptions::feedforwardIterations)
      .def_readwrite("measure_held_reference", &TvlqrOptions::measureHeldReference)
      .def_readwrite("threads", &TvlqrOptions::threads)
      .def_readwrite("infinite_horizon", &TvlqrOptions::infiniteHorizon)
      .def_readwrite("sample_rate", &TvlqrOptions::sampleRate)
      .def_readwrite("output_step", &TvlqrOptions::outputStep)
      .def_readwrite("riccati", &TvlqrOptions::riccati)
      .def_readwrite("sampled", &TvlqrOptions::sampled)
      .def_readwrite("transport", &TvlqrOptions::transport)
      .def("validate", &TvlqrOptions::validate);

  bindStatus<TvlqrCode>(m, "TvlqrStatus",
      "Status of solve_tvlqr (code: ok, transport_failure, riccati_failure, discretization_failure, "
      "recursion_failure, non_finite, indefinite, feedforward_failure, not_solved); the message carries the inner "
      "solver's report.");

  py::class_<TvlqrSolution>(m, "TvlqrSolution",
      "Plain data (owns its arrays; no reference to the model): status (TvlqrStatus), ok, gains "
      "(GainSchedule, K (nu, nx) at its times), S (N, nx, nx) at the same times, and diagnostics; "
      "describe(), summary() and json() are the library's reports.")
      .def_readonly("status", &TvlqrSolution::status)
      .def_property_readonly("ok", &TvlqrSolution::ok)
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
      .def_readonly("feedforward", &TvlqrSolution::feedforward)
      .def_readonly("prediction_failure", &TvlqrSolution::predictionFailure,
                    "feedforward = REFERENCE only: why a plant run failed (the gains stand; the "
                    "prediction is NaN), else empty")
      .def_readonly("infinite_horizon", &TvlqrSolution::infiniteHorizon)
      .def_readonly("infinite_horizon_solve", &TvlqrSolution::infiniteHorizonSolve)
      .def_readonly("max_gain_deviation", &TvlqrSolution::maxGainDeviation,
                    "infinite horizon: max_k |K_k - K_inf|_F / |K_inf|_F")
      .def_readonly("feedforward_defect", &TvlqrSolution::feedforwardDefect,
                    "largest sqrt(d^T S_k+1 d) left at the next sample by the feed-forward written")
      .def_readonly("reference_defect", &TvlqrSolution::referenceDefect,
                    "the same for u_ref(t_k) held (NaN: not measured, TvlqrOptions.measure_held_reference)")
      .def_readonly("feedforward_simulations", &TvlqrSolution::feedforwardSimulations)
      .def_readonly("predicted_deviation", &TvlqrSolution::predictedDeviation,
                    "what the hold allows: the defects propagated by the sampled closed loop, the "
                    "largest |x - x_ref| at the samples of the unperturbed loop (first order)")
      .def("K", [](const TvlqrSolution& s, double t) { return toArray(s.gains.evaluate(t)); }, py::arg("t"),
           "K(t) (nu, nx) from the gain schedule (its interpolation rule)")
      .def("describe", &TvlqrSolution::describe)
      .def("summary", &TvlqrSolution::summary)
      .def("json", &TvlqrSolution::json)
      .def("__repr__", [](const TvlqrSolution& s) { return "<TvlqrSolution " + s.describe() + ">"; });

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
          return withoutGil([&] { return solveTvlqr(model, reference, w, o); });
        },
        py::arg("model"), py::arg("reference"), py::kw_only(), py::arg("Q"), py::arg("R"),
        py::arg("Qf") = py::none(), py::arg("options") = py::none(),
        "TV-LQR along the reference, continuous (Riccati ODE) or sampled at options.sample_rate "
        "with zero-order hold, on the constraint manifold when the model has constraints: "
        "minimizes int dx^T Q dx + du^T R du dt + dx(T)^T Qf dx(T). Weights: a number (times I), a "
        "diagonal or a matrix (a complex array is a TypeError naming it); Qf defaults to Q. "
        "Returns plain data; numerical failure is the status. Releases the GIL.");

  bindStatus<TransportCode>(m, "TransportStatus",
      "Status of transport_tangent_basis (code: ok, dynamics_failure, integrator_failure, "
      "non_finite, turned_too_fast, not_transported; t: where it stopped).");
  py::class_<TangentBasisTrajectory>(m, "TangentBasisTrajectory",
      "T(t) (nx, d): an orthonormal basis of the constraint manifold's tangent space, transported "
      "along the reference (plain data). status / valid_until report a transport that stopped "
      "early (has_basis is False when it failed at t0 already).")
      .def_property_readonly("dimension", &TangentBasisTrajectory::dimension)
      .def_property_readonly("nx", &TangentBasisTrajectory::nx)
      .def_property_readonly("status", &TangentBasisTrajectory::status)
      .def_property_readonly("ok", &TangentBasisTrajectory::ok)
      .def("describe", &TangentBasisTrajectory::describe)
      .def("json", &TangentBasisTrajectory::json)
      .def_property_readonly("has_basis", &TangentBasisTrajectory::hasBasis)
      .def_property_readonly("valid_until", &TangentBasisTrajectory::validUntil)
      .def_property_readonly("steps", &TangentBasisTrajectory::steps)
      .def_property_readonly("max_correction", &TangentBasisTrajectory::maxCorrection)
      .def("basis", [](const TangentBasisTrajectory& b, double t) { return toArray(b.basis(t)); },
           py::arg("t"), "T(t) (nx, d)")
      .def("reduced_linearization",
           [](const TangentBasisTrajectory& b, const Model& model, double t) {
             Eigen::MatrixXd T, Ar, Br;
             b.reducedLinearization(model, t, T, Ar, Br);
             return py::make_tuple(toArray(T), toArray(Ar), toArray(Br));
           },
           py::arg("model"), py::arg("t"),
           "(T (nx, d), Ar = T^T A T (d, d), Br = T^T B (d, nu)) at t, with T corrected onto the "
           "exact tangent space of the model at x_ref(t)");
  m.def("transport_tangent_basis",
        [](const Model& model, const Trajectory& reference,
           const std::optional<TangentTransportOptions>& options) {
          return withoutGil([&] {
            return transportTangentBasis(model, reference, options.value_or(TangentTransportOptions{}));
          });
        },
        py::arg("model"), py::arg("reference"), py::kw_only(), py::arg("options") = py::none(),
        "T(t) along the reference (which needs state derivatives).");
}

}  // namespace trellis::python
