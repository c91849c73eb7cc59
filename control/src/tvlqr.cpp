// tvlqr.cpp — solveTvlqr: the user entry point over the continuous (full-state or manifold)
// Riccati solve and the sampled-data recursion; summary and JSON of the result.
#include "trellis/control/tvlqr.hpp"

#include "reduced_problem.hpp"

#include "trellis/core/detail/report_json.hpp"

#include "trellis/analysis/simulation.hpp"
#include "trellis/control/care.hpp"
#include "trellis/control/dare.hpp"
#include "trellis/core/reference.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/core/model.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <system_error>
#include <thread>

namespace trellis {
namespace {

/// Where the reference is exactly constant: the start time of the stretch of knot intervals on which
/// its interpolant cannot move, for the sampled discretization (ConstantSpanCallback). A knot
/// interval is constant when its end knots have the same state and input and zero state derivatives
/// (and zero input derivatives under the cubic input rule): the cubic Hermite spline through
/// (x, 0), (x, 0) is x, and the linear input through u, u is u. Read off the reference's data,
/// never from samples of A(t).
class ConstantStretches {
 public:
  explicit ConstantStretches(const Trajectory& r) : times_(r.times()) {
    const int intervals = r.size() - 1;
    start_.assign(static_cast<std::size_t>(std::max(intervals, 0)), -1);
    for (int j = 0; j < intervals; ++j) {
      const bool atRest = r.stateDerivatives().col(j).isZero(0.0) && r.stateDerivatives().col(j + 1).isZero(0.0) &&
                          (!r.hasInputDerivatives() || (r.inputDerivatives().col(j).isZero(0.0) &&
                                                        r.inputDerivatives().col(j + 1).isZero(0.0)));
      const bool constant = atRest && r.states().col(j) == r.states().col(j + 1) &&
                            r.inputs().col(j) == r.inputs().col(j + 1);
      if (constant) start_[static_cast<std::size_t>(j)] = (j > 0 && start_[static_cast<std::size_t>(j - 1)] >= 0)
                                                            ? start_[static_cast<std::size_t>(j - 1)]
                                                            : j;
    }
  }
  /// The stretch's start time if [a, b] lies in one constant stretch, else NaN.
  double operator()(double a, double b) const {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    if (start_.empty() || a < times_(0) || b > times_(times_.size() - 1)) return nan;
    // Knot intervals [t_j, t_{j+1}] meeting (a, b): from the one holding a to the one holding b.
    const double* first = times_.data();
    const double* last = first + times_.size();
    const auto ja = std::max<std::ptrdiff_t>(std::upper_bound(first, last, a) - first - 1, 0);
    const auto jb = std::min<std::ptrdiff_t>(std::lower_bound(first, last, b) - first - 1,
                                             static_cast<std::ptrdiff_t>(start_.size()) - 1);
    const int s = start_[static_cast<std::size_t>(std::min(ja, static_cast<std::ptrdiff_t>(start_.size()) - 1))];
    if (s < 0) return nan;
    for (auto j = ja; j <= jb; ++j) {
      if (start_[static_cast<std::size_t>(j)] != s) return nan;
    }
    return times_(s);
  }

 private:
  Eigen::VectorXd times_;
  std::vector<int> start_;  // per knot interval: the first knot of its constant stretch, or −1
};

}  // namespace

void TvlqrOptions::validate() const {
  if (!(sampleRate >= 0.0) || !std::isfinite(sampleRate)) {
    throw std::invalid_argument("TvlqrOptions.sampleRate = " + std::to_string(sampleRate) +
                                " is invalid (0 for continuous gains, else finite and > 0)");
  }
  if (!(outputStep >= 0.0) || !std::isfinite(outputStep)) {
    throw std::invalid_argument("TvlqrOptions.outputStep = " + std::to_string(outputStep) +
                                " is invalid (must be finite and >= 0)");
  }
  if (threads < 1 || threads > 256) {
    throw std::invalid_argument("TvlqrOptions.threads = " + std::to_string(threads) + " is invalid (must be in 1..256)");
  }
  if (feedforwardIterations < 1) {
    throw std::invalid_argument("TvlqrOptions.feedforwardIterations = " + std::to_string(feedforwardIterations) +
                                " is invalid (must be >= 1)");
  }
  riccati.validate();
  sampled.validate();
  transport.validate();
}

namespace {

std::string fmt(double v, int digits = 6) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

Eigen::VectorXd outputGrid(const Trajectory& reference, double step) {
  if (step <= 0.0) return reference.times();
  // k·step from t0 (no accumulated round-off); T closes the grid unless a grid point is already
  // within a tiny fraction of a step of it.
  const double t0 = reference.startTime(), T = reference.endTime();
  std::vector<double> times;
  for (long k = 0;; ++k) {
    const double t = t0 + static_cast<double>(k) * step;
    if (t >= T - 1e-9 * step) break;
    times.push_back(t);
  }
  times.push_back(T);
  return Eigen::Map<Eigen::VectorXd>(times.data(), static_cast<Eigen::Index>(times.size()));
}

/// ∫_a^b u_ref(s) ds / (b − a): Simpson's rule on each piece between knots, exact for the linear
/// and the cubic Hermite input rules (both are polynomials of degree ≤ 3 on a piece).
Eigen::VectorXd intervalAverage(const Trajectory& reference, double a, double b, Eigen::VectorXd& x,
                                Eigen::VectorXd& u) {
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(reference.nu());
  const Eigen::VectorXd& knots = reference.times();
  double lo = a;
  const double* first = knots.data();
  const double* last = first + knots.size();
  for (const double* it = std::upper_bound(first, last, a);; ++it) {
    const double hi = (it == last || *it >= b) ? b : *it;
    if (hi > lo) {
      reference.evaluate(lo, x, u);
      sum += (hi - lo) / 6.0 * u;
      reference.evaluate(0.5 * (lo + hi), x, u);
      sum += (hi - lo) * 4.0 / 6.0 * u;
      reference.evaluate(hi, x, u);
      sum += (hi - lo) / 6.0 * u;
    }
    if (hi >= b) break;
    lo = hi;
  }
  return sum / (b - a);
}

}  // namespace

std::string TvlqrSolution::summary() const {
  std::ostringstream o;
  if (!ok()) {
    o << "tvlqr: FAILED: " << status.describe() << "\n";
    return o.str();
  }
  const int rows = gains.size();
  o << rows << " rows of K (" << nu << " x " << nx << ") on [" << fmt(gains.startTime()) << ", "
    << fmt(gains.endTime()) << "], "
    << (sampleRate > 0.0 ? "zero-order-hold gains for a controller sampling at " + fmt(sampleRate, 17) +
                               " Hz (apply at t0 + k/" + fmt(sampleRate, 17) + ", hold between samples)"
                         : std::string("continuous gains (K(t), linear between rows)"))
    << "\n";
  if (constrained) {
    o << "riccati: on the constraint manifold (tangent dimension " << dimension << " of " << nx
      << "; basis transport " << transportSteps << " steps, max correction " << fmt(maxBasisCorrection, 3)
      << ")\n";
  } else {
    o << "riccati: full state (no constraints)\n";
  }
  o << "riccati: " << method << ", " << steps << " steps, " << rhsEvaluations << " right-hand-side evaluations";
  if (sampleRate > 0.0) o << ", " << linearizations << " linearizations";
  o << ", " << fmt(seconds, 3) << " s\n";
  o << "S" << (constrained ? "r" : "") << ": min eigenvalue " << fmt(minEigenvalueS) << ", max eigenvalue "
    << fmt(maxEigenvalueS) << "\n";
  if (infiniteHorizon) {
    o << "infinite horizon: Qf = S_inf of the " << infiniteHorizonSolve << "; max |K_k - K_inf| / |K_inf| "
      << fmt(maxGainDeviation, 3) << " over the rows\n";
  }
  if (sampleRate > 0.0) {
    // kReference with no plant run (measureHeldReference false): the defects are not measured.
    const bool measured =
        !(feedforward == SampledFeedforward::kReference && predictionFailure.empty() && std::isnan(referenceDefect));
    if (feedforward == SampledFeedforward::kReference) {
      o << "feed-forward: none written (the controller applies u_ref(t_k), held); largest defect at the next sample "
        << "sqrt(d'S d) " << (measured ? fmt(referenceDefect, 3) : std::string("not measured (no plant runs)")) << "\n";
    } else {
      o << "feed-forward: " << toString(feedforward) << " (uff_k held with K_k); largest defect at the next sample "
        << "sqrt(d'S d) " << fmt(feedforwardDefect, 3) << " (u_ref(t_k) held: "
        << (std::isnan(referenceDefect) && predictionFailure.empty() ? std::string("not measured") : fmt(referenceDefect, 3)) << "), "
        << feedforwardSimulations << " plant runs\n";
    }
    if (!measured) {
      o << "what the hold allows: not predicted (no plant runs: feedforward reference, measureHeldReference false)\n";
    } else if (predictionFailure.empty()) {
      o << "what the hold allows: the defects left, propagated by the sampled closed loop, predict a largest "
        << "|x - x_ref| of " << fmt(predictedDeviation, 3) << " at the samples of the unperturbed loop (first order)\n";
    } else {
      o << "what the hold allows: not predicted (" << predictionFailure << ")\n";
    }
  }
  return o.str();
}

std::string TvlqrSolution::describe() const {
  std::string line = status.describe() + " (" + (sampleRate > 0.0 ? "sampled at " + fmt(sampleRate) + " Hz" : std::string("continuous"));
  line += constrained ? ", on the constraint manifold" : ", full state";
  line += ", " + std::to_string(gains.size()) + " rows of K, " + std::to_string(steps) + " steps, " + fmt(seconds, 3) + " s)";
  return line;
}

std::string TvlqrSolution::json() const {
  const bool have = gains.size() > 0;
  detail::ReportJson j = detail::statusJson(status);
  j["mode"] = sampleRate > 0.0 ? "sampled" : "continuous";
  j["sample_rate_hz"] = detail::toJson(sampleRate);
  j["constrained"] = constrained;
  j["nx"] = nx;
  j["nu"] = nu;
  j["tangent_dimension"] = dimension;
  j["rows"] = gains.size();
  j["t0"] = have ? detail::toJson(gains.startTime()) : detail::ReportJson(nullptr);
  j["t1"] = have ? detail::toJson(gains.endTime()) : detail::ReportJson(nullptr);
  j["seconds"] = detail::toJson(seconds);
  j["steps"] = steps;
  j["rhs_evaluations"] = rhsEvaluations;
  j["linearizations"] = linearizations;
  j["transport_steps"] = transportSteps;
  j["max_basis_correction"] = detail::toJson(maxBasisCorrection);
  j["min_eigenvalue_S"] = detail::toJson(minEigenvalueS);
  j["max_eigenvalue_S"] = detail::toJson(maxEigenvalueS);
  j["method"] = method;
  j["feedforward"] = sampleRate > 0.0 ? toString(feedforward) : "none";
  j["feedforward_defect"] = detail::toJson(feedforwardDefect);
  j["reference_defect"] = detail::toJson(referenceDefect);
  j["feedforward_simulations"] = feedforwardSimulations;
  j["predicted_deviation"] = detail::toJson(predictedDeviation);
  j["prediction_failure"] = predictionFailure;
  j["infinite_horizon"] = infiniteHorizon;
  j["infinite_horizon_solve"] = infiniteHorizonSolve;
  j["max_gain_deviation"] = detail::toJson(maxGainDeviation);
  return j.dump();
}

namespace {

/// options.infiniteHorizon (file comment): S∞ at the held pose, then the usual solve with Qf = S∞.
TvlqrSolution solveHeldInfiniteHorizon(const Model& model, const Trajectory& input, const LqrWeights& weights,
                                       const TvlqrOptions& options) {
  if (weights.Qfun || weights.Rfun) {
    throw std::invalid_argument("solveTvlqr: options.infiniteHorizon needs constant weights Q and R");
  }
  const int n = model.nq();
  for (Eigen::Index k = 0; k < input.size(); ++k) {
    const bool same = input.states().col(k) == input.states().col(0) && input.inputs().col(k) == input.inputs().col(0);
    if (!same || !input.states().col(k).tail(n).isZero(0.0)) {
      throw std::invalid_argument("solveTvlqr: options.infiniteHorizon needs a held pose (every knot the same state "
                                  "at rest and the same input); knot " + std::to_string(k) + " (t = " +
                                  fmt(input.times()(k), 17) + ") differs from knot 0 or moves");
    }
  }
  const ReferenceEvaluator checked(model, input);
  const Trajectory& reference = checked.trajectory();
  TvlqrSolution failed;
  failed.sampleRate = options.sampleRate;
  failed.constrained = model.nc() > 0;
  failed.infiniteHorizon = true;
  const TangentBasisTrajectory basis = transportTangentBasis(model, reference, options.transport);
  if (!basis.ok()) {
    failed.status.set(TvlqrCode::kTransportFailure, "the tangent basis transport failed: " + basis.status().message,
                      basis.status().t);
    return failed;
  }
  const detail::ReducedProblem problem = detail::makeReducedProblem(model, basis, weights);
  const double t0 = reference.startTime();
  Eigen::MatrixXd Ar, Br;
  const ReferenceStatus at = problem.linearization(t0, Ar, Br);
  if (!at.ok()) {
    failed.status.set(TvlqrCode::kRiccatiFailure, "the linearization at the held pose failed: " + at.message, t0);
    return failed;
  }
  Eigen::MatrixXd Qr = problem.weights.Q;
  if (problem.weights.Qfun) problem.weights.Qfun(t0, Qr);
  LqrResult lqr;
  if (options.sampleRate > 0.0) {
    SampledInterval iv;
    discretizeConstantInterval(Ar, Br, Qr, weights.R, std::min(1.0 / options.sampleRate, reference.endTime() - t0), iv);
    lqr = solveDare(iv.Phi, iv.Gamma, iv.Q, iv.R, iv.N);
  } else {
    lqr = solveCare(Ar, Br, Qr, weights.R);
  }
  if (!lqr.ok()) {
    failed.status.set(TvlqrCode::kRiccatiFailure,
                      std::string("the ") + (options.sampleRate > 0.0 ? "DARE" : "CARE") +
                          " at the held pose failed (no stationary gain: is the pose stabilizable?): " + lqr.describe(),
                      t0);
    return failed;
  }
  const Eigen::MatrixXd T = basis.basis(t0);
  LqrWeights held = weights;
  held.Qf = T * lqr.S * T.transpose();
  held.Qf = 0.5 * (held.Qf + held.Qf.transpose()).eval();
  TvlqrOptions inner = options;
  inner.infiniteHorizon = false;
  TvlqrSolution sol = solveTvlqr(model, input, held, inner);
  sol.infiniteHorizon = true;
  sol.infiniteHorizonSolve = std::string(options.sampleRate > 0.0 ? "DARE" : "CARE") + ": " + lqr.describe();
  if (sol.gains.size() > 0) {
    const Eigen::MatrixXd Kinf = lqr.K * T.transpose();
    for (const Eigen::MatrixXd& K : sol.gains.gains()) {
      sol.maxGainDeviation = std::max(sol.maxGainDeviation, (K - Kinf).norm() / Kinf.norm());
    }
  }
  return sol;
}

}  // namespace

TvlqrSolution solveTvlqr(const Model& model, const Trajectory& input, const LqrWeights& weights,
                         const TvlqrOptions& options) {
  options.validate();
  if (options.infiniteHorizon) return solveHeldInfiniteHorizon(model, input, weights, options);
  // Names checked, knot derivatives the reference's own or from the core's dynamics: one check,
  // and every solve below reads this copy.
  const ReferenceEvaluator checked(model, input);
  const Trajectory& reference = checked.trajectory();
  const int nx = reference.nx(), nu = reference.nu();
  if (nu == 0) throw std::invalid_argument("solveTvlqr: the model has no inputs: there is nothing to control");
  checkWeightMatrix(weights.Qf, "Qf", nx, false);
  if (!weights.Qfun) checkWeightMatrix(weights.Q, "Q", nx, false);
  if (!weights.Rfun) checkWeightMatrix(weights.R, "R", nu, true);

  TvlqrSolution sol;
  sol.sampleRate = options.sampleRate;
  sol.constrained = model.nc() > 0;
  sol.nx = nx;
  sol.nu = nu;
  sol.dimension = nx;
  const std::vector<std::string> stateNames = GainSchedule::stateNames(model.configNames());
  const auto start = std::chrono::steady_clock::now();
  auto finish = [&](Eigen::VectorXd times, std::vector<Eigen::MatrixXd> K) {
    sol.gains = GainSchedule(std::move(times), std::move(K));
    sol.gains.setColumnNames(model.inputNames(), stateNames);
    sol.gains.setSampleRate(options.sampleRate);
    sol.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    // S is a sum of positive semidefinite terms: a clearly negative eigenvalue means the
    // integration did not resolve the Riccati equation (not a result to hand out as ok).
    if (!isSemidefiniteToRoundoff(sol.minEigenvalueS, sol.maxEigenvalueS)) {
      std::ostringstream m;
      m << (sol.constrained ? "Sr" : "S") << " is indefinite beyond round-off: smallest eigenvalue "
        << fmt(sol.minEigenvalueS, 17) << ", largest " << fmt(sol.maxEigenvalueS, 17)
        << " (the integration did not resolve the Riccati equation; tighten rtol/atol)";
      sol.status.set(TvlqrCode::kIndefinite, m.str());
      return;
    }
    sol.status = {};
  };

  if (options.sampleRate == 0.0) {
    // Continuous: the Riccati ODE, on the tangent space when there are constraints.
    sol.method = toString(options.riccati.method);
    const Eigen::VectorXd times = outputGrid(reference, options.outputStep);
    std::vector<Eigen::MatrixXd> K;
    const RiccatiSolution* riccati = nullptr;
    std::optional<ManifoldRiccatiSolution> onManifold;
    std::optional<RiccatiSolution> fullState;
    // S's spectrum is taken below at the output grid, where S is formed anyway: the solve's own
    // tracking (an eigen-decomposition at every step, +38 % of the solve's CPU on the 20-link
    // chain) would only be read for the same two numbers. Its S ⪰ 0 check (a Cholesky per step)
    // stays on.
    RiccatiOptions riccatiOptions = options.riccati;
    riccatiOptions.trackEigenvalues = false;
    if (sol.constrained) {
      onManifold = solveManifoldRiccati(model, reference, weights, riccatiOptions, options.transport);
      sol.transportSteps = onManifold->basis.steps();
      sol.dimension = onManifold->dimension();
      riccati = &onManifold->reduced;
      if (!onManifold->ok()) {
        sol.status.set(onManifold->status.code == ManifoldRiccatiCode::kTransportFailure
                           ? TvlqrCode::kTransportFailure
                           : TvlqrCode::kRiccatiFailure,
                       "the Riccati solve failed: " + onManifold->status.describe(), onManifold->status.t);
        return sol;
      }
    } else {
      fullState = solveRiccati(model, reference, weights, riccatiOptions);
      riccati = &*fullState;
      if (!fullState->ok()) {
        sol.status.set(TvlqrCode::kRiccatiFailure, "the Riccati solve failed: " + fullState->status.describe(),
                       fullState->status.t);
        return sol;
      }
    }
    sol.steps = riccati->steps;
    sol.rhsEvaluations = riccati->rhsEvaluations;
    sol.minEigenvalueS = std::numeric_limits<double>::infinity();
    sol.maxEigenvalueS = -std::numeric_limits<double>::infinity();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(sol.dimension);
    // The grid lies inside [t0, T], where an ok solution has S and K: no query can fail.
    for (Eigen::Index k = 0; k < times.size(); ++k) {
      const double t = times(k);
      K.push_back(sol.constrained ? onManifold->K(t) : fullState->K(t));
      sol.S.push_back(sol.constrained ? onManifold->S(t) : fullState->S(t));
      if (!K.back().allFinite() || !sol.S.back().allFinite()) {
        sol.status.set(TvlqrCode::kNonFinite, "the gain K(t) or S(t) is not finite at t = " + fmt(t, 17), t,
                       static_cast<long>(k));
        sol.S.clear();
        return sol;
      }
      // Of the reduced Sr when constrained (the full S = T Sr Tᵀ has zeros off the tangent space).
      eig.compute(sol.constrained ? onManifold->reduced.S(t) : sol.S.back(), Eigen::EigenvaluesOnly);
      sol.minEigenvalueS = std::min(sol.minEigenvalueS, eig.eigenvalues()(0));
      sol.maxEigenvalueS = std::max(sol.maxEigenvalueS, eig.eigenvalues()(eig.eigenvalues().size() - 1));
    }
    if (sol.constrained) sol.maxBasisCorrection = onManifold->basis.maxCorrection();
    finish(times, std::move(K));
    return sol;
  }

  // Sampled: reduced system on the transported basis (T = I without constraints).
  sol.method = "sampled-zoh";
  sol.feedforward = options.feedforward;
  const Eigen::VectorXd times = sampleTimes(reference.startTime(), reference.endTime(), options.sampleRate);
  const std::size_t N = static_cast<std::size_t>(times.size() - 1);
  // Exactly constant stretches of the reference (a held pose) are discretized by the exponential;
  // not on a constrained scene (the transported basis T(t) is integrated, not constant by
  // construction) nor with time-varying weights.
  // The knots are where the reference's interpolant (so A(t)) may have a kink.
  SampledStructure structure;
  if (!sol.constrained && !weights.Qfun && !weights.Rfun) structure.constantOn = ConstantStretches(reference);
  structure.breakpoints.assign(reference.times().data(), reference.times().data() + reference.times().size());
  // Between knots the reference is polynomial and A, B its exact linearization: analytic there
  // unless a constraint basis is transported along it (its dense output has joints of its own).
  structure.smoothBetweenBreakpoints = !sol.constrained;

  // The plant runs of the held feed-forward (file comment): per interval the defect d_k that u_ref(t_k)
  // held leaves at t_{k+1}, and that of the written ū_k, in the metric of S_{k+1} once the gains
  // exist. Only kConsistent's iteration needs the gains (S_{k+1}, Γ_k) during its runs; every other
  // feed-forward's runs depend on the reference alone, so they start here, on threads − 1 workers
  // beside the transport and the discretization on this thread (which then joins them): the hand's
  // 400 runs took ~1.4 s after a ~1.2 s serial discretization on 2 threads.
  SimulationOptions base;
  // The plant runs keep kRtol when rtol is left to the integrator's default (Radau's is looser
  // because its estimate is; the plant's BDF estimate is not).
  base.rtol = options.sampled.rtol > 0.0 ? options.sampled.rtol : SampledDiscretizationOptions::kRtol;
  base.atol = options.sampled.atol;
  base.maxSteps = options.sampled.maxSteps;  // per interval, as for the discretization
  // BDF with the exact Jacobian: a held input is a "sampled" policy (∂u/∂x = 0, so ∂f/∂x = A),
  // one sample per run at its start. (Radau IIA, which needs no start-up, was measured in its
  // place: each run starts with the transient of its own input, so its steps are set by that,
  // not by the restart — the 6-link swing's gains 132 → 120 ms at 100 Hz but 35 → 38 ms at
  // 10 Hz, the hand's the same within noise; not taken.)
  base.method = IntegrationMethod::kBDF;
  // An exactly constant stretch is time-invariant: an interval of the same stretch and length
  // as an earlier one has its ū and defect (sourceOf). The lengths t_{k+1} − t_k of equal
  // intervals differ by rounding (~1e-16 h): equal within 1e-9 h (the sample grid's own
  // tolerance; ū moves by O(Δh) far below that).
  std::vector<std::size_t> sourceOf(N);
  {
    struct Source {
      double stretch, h;
      std::size_t k;
    };
    std::vector<Source> sources;  // one per distinct (stretch, length)
    for (std::size_t k = 0; k < N; ++k) {
      sourceOf[k] = k;
      if (!structure.constantOn) continue;
      const double a = times(static_cast<Eigen::Index>(k)), b = times(static_cast<Eigen::Index>(k + 1));
      const double stretch = structure.constantOn(a, b);
      if (std::isnan(stretch)) continue;
      const auto same = std::find_if(sources.begin(), sources.end(), [&](const Source& c) {
        return c.stretch == stretch && std::abs(c.h - (b - a)) <= 1e-9 * (b - a);
      });
      if (same != sources.end()) {
        sourceOf[k] = same->k;
      } else {
        sources.push_back({stretch, b - a, k});
      }
    }
  }
  std::vector<Eigen::VectorXd> offManifold(N + 1, Eigen::VectorXd::Zero(nx));  // P(x_ref(t_k)) − x_ref(t_k)
  // What each interval gives (the intervals are independent: each starts from the reference at
  // t_k), gathered in order below, so the gains, the feed-forward and every status are the same
  // on any number of threads and whether the runs started early or not.
  struct Outcome {
    Eigen::VectorXd u, defect;  // the held input written and the defect it leaves
    Eigen::VectorXd referenceDefect;  // the defect of u_ref(t_k) held
    long simulations = 0;
    bool failed = false;
    std::exception_ptr error;  // an exception thrown for this interval, rethrown in order
    std::string what;
    double t = 0.0;
  };
  std::vector<Outcome> outcomes(N);
  // Intervals are handed out in order; after a failure at k only the later ones are skipped,
  // so every interval before the first failure is computed (the gathering below needs them).
  std::atomic<std::size_t> next{0}, firstFailure{N};
  std::atomic<bool> abandon{false};  // the solve failed before the gathering: stop taking intervals
  const auto noteFailure = [&firstFailure](std::size_t k) {
    std::size_t seen = firstFailure.load();
    while (k < seen && !firstFailure.compare_exchange_weak(seen, k)) {
    }
  };
  // kConsistent's runs read the gains (set before its workers start).
  const std::vector<Eigen::MatrixXd>* gainS = nullptr;   // sol.S
  const std::vector<Eigen::MatrixXd>* basisAt = nullptr;  // T(t_k)
  const SampledDiscretization* discretization = nullptr;
  const auto worker = [&]() {
    Eigen::VectorXd xa(nx), xb(nx), ua(nu), ub(nu), dk(nx), held(nu);
    const Policy hold = [&held](double, const Eigen::VectorXd&, Eigen::VectorXd& u) { u = held; };
    SimulationOptions so = base;
    for (std::size_t k = next++; k < N; k = next++) {
      // A copy of a constant stretch's interval needs no run (constant stretches exist only
      // without constraints, so it has no projection offset either).
      if (abandon.load() || k > firstFailure.load() || sourceOf[k] != k) continue;
      Outcome& out = outcomes[k];
      try {
        const double a = times(static_cast<Eigen::Index>(k)), b = times(static_cast<Eigen::Index>(k + 1));
        reference.evaluate(a, xa, ua);
        Eigen::VectorXd ubar = intervalAverage(reference, a, b, xb, ub);
        reference.evaluate(b, xb, ub);
        if (sol.constrained) {
          // Between knots the reference's spline leaves the constraints by its interpolation error;
          // the plant's run starts from the projection of x_ref(t_k) (simulate projects it), so it
          // ends compared with the projection of x_ref(t_{k+1}): otherwise the mass-metric
          // projection's tangent part at the start would count as a defect every interval. The
          // offset P(x_ref) − x_ref is what no loop on the constraints can follow (the prediction
          // below adds it).
          const Eigen::VectorXd xa0 = xa, xb0 = xb;
          projectOntoConstraints(model, xa);
          projectOntoConstraints(model, xb);
          if (k == 0) offManifold[0] = xa - xa0;
          offManifold[k + 1] = xb - xb0;
        }
        so.sampleRate = 1.0 / (b - a);
        so.outputStep = b - a;
        // The defect dk of a held input v; false when the plant's run failed.
        auto defect = [&](const Eigen::VectorXd& v) {
          held = v;
          const SimulationResult run = simulate(model, xa, a, b, hold, so);
          ++out.simulations;
          if (!run.ok()) {
            out.failed = true;
            out.what = "the plant's run over the sample interval [" + fmt(a, 17) + ", " + fmt(b, 17) +
                       "] with a held input failed: " + run.status.describe();
            out.t = run.status.t;
            return false;
          }
          dk = run.trajectory.states().col(run.trajectory.size() - 1) - xb;
          return true;
        };
        if (options.feedforward == SampledFeedforward::kReference || options.measureHeldReference) {
          if (!defect(ua)) {
            noteFailure(k);
            continue;
          }
          out.referenceDefect = dk;
        }
        if (options.feedforward == SampledFeedforward::kReference) {
          ubar = ua;
        } else if (!defect(ubar)) {
          noteFailure(k);
          continue;
        }
        if (options.feedforward == SampledFeedforward::kConsistent) {
          // Gauss–Newton with Γ as ∂d/∂ū (chord method, file comment), damped in the metric of
          // the interval's input cost R_k (Levenberg–Marquardt, μ = 1e-3 σ_max, σ the generalized
          // eigenvalues of (ΓᵀSΓ, R_k): what a unit of input cost buys in cost-to-go). Directions
          // with σ ≪ μ — inputs that barely move the state, such as tendons pulling against each
          // other — then move by at most |d|_S/(2√μ) per step instead of |d|_S/√σ (measured on the
          // hand without it: held tensions of ±300 against |u_ref| ≤ 5.6); the fixed point
          // (Γᵀ S d = 0 in the directions that matter) is unchanged. A step that does not lower
          // dᵀSd is halved (at most 4 times), and none that lowers it ends the iteration.
          const Eigen::MatrixXd& W = (*gainS)[k + 1];
          const Eigen::MatrixXd G = (*basisAt)[k + 1] * discretization->intervals[k].Gamma;
          double f = dk.dot(W * dk);
          const Eigen::MatrixXd H = G.transpose() * W * G;
          const Eigen::MatrixXd& Rk = discretization->intervals[k].R;
          const Eigen::MatrixXd Hs = 0.5 * (H + H.transpose());
          const Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> sigma(Hs, 0.5 * (Rk + Rk.transpose()),
                                                                                Eigen::EigenvaluesOnly);
          const double mu = 1e-3 * std::max(sigma.eigenvalues().maxCoeff(), 0.0);
          const Eigen::LDLT<Eigen::MatrixXd> damped(Hs + mu * Rk);
          Eigen::VectorXd dBest = dk;
          // A defect within the plant runs' own accuracy (10 (atol + rtol |x|) per entry) is
          // resolved: further steps would chase the integration error (a held equilibrium).
          const auto resolved = [&](const Eigen::VectorXd& dv) {
            return (dv.array().abs() <= 10.0 * (so.atol + so.rtol * xb.array().abs())).all();
          };
          bool runFailed = false;
          for (int it = 0; it < options.feedforwardIterations && f > 0.0 && mu > 0.0 && !resolved(dBest); ++it) {
            const Eigen::VectorXd step = damped.solve(G.transpose() * (W * dBest));
            if (!step.allFinite() || step.isZero(0.0)) break;
            double scale = 1.0, fTrial = 0.0;
            bool lowered = false;
            Eigen::VectorXd trial;
            for (int halving = 0; halving <= 4 && !lowered; ++halving, scale *= 0.5) {
              trial = ubar - scale * step;
              if (!defect(trial)) {
                runFailed = true;
                break;
              }
              fTrial = dk.dot(W * dk);
              lowered = fTrial < f;
            }
            if (runFailed || !lowered) break;
            const bool stalled = fTrial > (1.0 - 1e-6) * f;  // no longer worth a run
            ubar = trial;
            f = fTrial;
            dBest = dk;
            if (stalled) break;
          }
          if (runFailed) {
            noteFailure(k);
            continue;
          }
          dk = dBest;
        }
        out.u = std::move(ubar);
        out.defect = dk;
      } catch (...) {
        out.error = std::current_exception();
        noteFailure(k);
      }
    }
  };
  const int threads = static_cast<int>(std::min<std::size_t>(static_cast<std::size_t>(options.threads), std::max<std::size_t>(N, 1)));
  // Workers take the next interval until none is left: fewer threads than asked (the system's
  // limit) only take longer. Leaving early (a failure below, an exception) abandons the runs not
  // yet started and joins the rest.
  struct Pool {
    std::vector<std::thread> threads;
    std::atomic<bool>& abandon;
    void start(int count, const std::function<void()>& work) {
      try {
        for (int t = 0; t < count; ++t) threads.emplace_back(work);
      } catch (const std::system_error&) {
      }
    }
    void join() {
      for (std::thread& t : threads) t.join();
      threads.clear();
    }
    ~Pool() {
      abandon = true;
      join();
    }
  } pool{{}, abandon};
  const std::function<void()> work = worker;
  // kReference without the held reference's runs: no plant run at all (the gains alone; the
  // defects and the prediction are not measured).
  const bool plantRuns = options.feedforward != SampledFeedforward::kReference || options.measureHeldReference;
  if (plantRuns && options.feedforward != SampledFeedforward::kConsistent) pool.start(threads - 1, work);

  const TangentBasisTrajectory basis = transportTangentBasis(model, reference, options.transport);
  sol.transportSteps = basis.steps();
  if (!basis.ok()) {
    sol.status.set(TvlqrCode::kTransportFailure, "the tangent basis transport failed: " + basis.status().message,
                   basis.status().t);
    return sol;
  }
  const int d = basis.dimension();
  sol.dimension = d;
  const detail::ReducedProblem problem = detail::makeReducedProblem(model, basis, weights);
  const SampledDiscretization disc =
      discretizeSampledData(times, d, nu, problem.linearization, problem.weights, options.sampled, structure);
  sol.steps = disc.steps;
  sol.rhsEvaluations = disc.rhsEvaluations;
  sol.linearizations = disc.linearizations;
  if (!disc.ok()) {
    sol.status.set(TvlqrCode::kDiscretizationFailure, disc.status.describe(), disc.status.t, disc.status.index);
    return sol;
  }
  // The sample times lie inside the basis's range (the transport covered the horizon).
  std::vector<Eigen::MatrixXd> Tk;
  for (Eigen::Index k = 0; k < times.size(); ++k) Tk.push_back(basis.basis(times(k)));
  const Eigen::MatrixXd Qfr = Tk.back().transpose() * weights.Qf * Tk.back();
  const SampledRiccatiRecursion rec = solveSampledRiccatiRecursion(disc.intervals, 0.5 * (Qfr + Qfr.transpose()));
  if (!rec.ok()) {
    sol.status.set(TvlqrCode::kRecursionFailure, rec.status.describe(), rec.status.t, rec.status.index);
    return sol;
  }
  std::vector<Eigen::MatrixXd> K;
  sol.minEigenvalueS = std::numeric_limits<double>::infinity();
  sol.maxEigenvalueS = -std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k <= N; ++k) {
    // K at T repeats the last sample's gain (the input is held over the last interval).
    K.push_back(rec.K[std::min(k, N - 1)] * Tk[k].transpose());
    Eigen::MatrixXd S = Tk[k] * rec.S[k] * Tk[k].transpose();
    sol.S.push_back(0.5 * (S + S.transpose()));
    const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(rec.S[k], Eigen::EigenvaluesOnly).eigenvalues();
    sol.minEigenvalueS = std::min(sol.minEigenvalueS, ev(0));
    sol.maxEigenvalueS = std::max(sol.maxEigenvalueS, ev(ev.size() - 1));
  }
  sol.maxBasisCorrection = sol.constrained ? basis.maxCorrection() : 0.0;
  // The held feed-forward (file comment), in the metric of S_{k+1} (set above), and the defect
  // r_k it leaves at each next sample (for every choice: u_ref(t_k) held too).
  std::vector<Eigen::VectorXd> uff, residual;
  if (!plantRuns) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    sol.predictedDeviation = sol.referenceDefect = sol.feedforwardDefect = nan;
  } else {
    gainS = &sol.S;
    basisAt = &Tk;
    discretization = &disc;
    if (options.feedforward == SampledFeedforward::kConsistent) pool.start(threads - 1, work);
    worker();
    pool.join();
    // In order: the first failure decides, as a serial loop would have stopped there.
    for (std::size_t k = 0; k < N; ++k) {
      const Outcome& out = outcomes[k];
      const Outcome& source = outcomes[sourceOf[k]];  // itself, or the first of its constant stretch
      sol.feedforwardSimulations += out.simulations;
      if (out.error) std::rethrow_exception(out.error);
      if (out.failed) {
        // With no feed-forward to compute the runs only serve the prediction: the gains stand.
        if (options.feedforward == SampledFeedforward::kReference) {
          sol.predictionFailure = out.what;
          break;
        }
        sol.status.set(TvlqrCode::kFeedforwardFailure,
                       out.what + " (feedforward = reference needs none of these runs; a looser sampled.rtol "
                                  "may help)",
                       out.t, static_cast<long>(k));
        return sol;
      }
      if (source.u.size() == 0) {  // not reached: intervals up to the first failure are computed
        sol.status.set(TvlqrCode::kFeedforwardFailure, "the feed-forward of interval " + std::to_string(k) +
                                                           " was not computed", times(static_cast<Eigen::Index>(k)),
                       static_cast<long>(k));
        return sol;
      }
      const Eigen::MatrixXd& W = sol.S[k + 1];
      if (out.referenceDefect.size() > 0)
        sol.referenceDefect = std::max(sol.referenceDefect, std::sqrt(std::max(out.referenceDefect.dot(W * out.referenceDefect), 0.0)));
      sol.feedforwardDefect = std::max(sol.feedforwardDefect, std::sqrt(std::max(source.defect.dot(W * source.defect), 0.0)));
      uff.push_back(source.u);
      residual.push_back(source.defect);
    }
    if (options.feedforward != SampledFeedforward::kReference && !options.measureHeldReference)
      sol.referenceDefect = std::numeric_limits<double>::quiet_NaN();  // no run held u_ref(t_k)
    if (!sol.predictionFailure.empty()) {
      const double nan = std::numeric_limits<double>::quiet_NaN();
      sol.predictedDeviation = sol.referenceDefect = sol.feedforwardDefect = nan;
      residual.clear();
    } else {
      uff.push_back(uff.back());  // the row at T repeats the last sample's
    }
    // What the hold allows: the residuals propagated by the sampled closed loop of the
    // linearization, z_{k+1} = (Φ_k − Γ_k K_k) z_k + T_{k+1}ᵀ r_k, z_0 = 0 (reduced coordinates;
    // T = I without constraints), e_k = T_k z_k + (P(x_ref(t_k)) − x_ref(t_k)) — to first order
    // in r the unperturbed loop's deviation at the samples (the loop follows the reference's
    // projection onto the constraints).
    Eigen::VectorXd z = Eigen::VectorXd::Zero(d);
    if (sol.predictionFailure.empty()) sol.predictedDeviation = offManifold[0].norm();
    for (std::size_t k = 0; k < residual.size(); ++k) {
      const SampledInterval& iv = disc.intervals[k];
      z = (iv.Phi * z - iv.Gamma * (rec.K[k] * z) + Tk[k + 1].transpose() * residual[k]).eval();
      sol.predictedDeviation = std::max(sol.predictedDeviation, (Tk[k + 1] * z + offManifold[k + 1]).norm());
    }
  }
  finish(times, std::move(K));
  if (sol.ok() && options.feedforward != SampledFeedforward::kReference) sol.gains.setFeedforward(std::move(uff));
  return sol;
}

bool isSemidefiniteToRoundoff(double minEigenvalue, double maxEigenvalue, double relativeSlack) {
  const double scale = std::max(std::abs(minEigenvalue), std::abs(maxEigenvalue));
  return std::isfinite(scale) && !(minEigenvalue < -relativeSlack * scale);
}

}  // namespace trellis
