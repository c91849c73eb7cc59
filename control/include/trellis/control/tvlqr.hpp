// trellis/control/tvlqr.hpp — the one entry point for time-varying LQR along a reference:
// constrained or not, continuous or sampled (zero-order hold at a rate).
//
//   TvlqrSolution sol = solveTvlqr(model, reference, weights, options);
//   if (!sol.ok()) … sol.status.describe();  sol.gains (K, m×2n, at sol.gains.times());  sol.S[k] (2n×2n)
//
// Continuous (options.sampleRate = 0): the Riccati ODE (riccati.hpp) — on the tangent space of the
// constraint manifold for a scene with constraints (manifold_lqr.hpp) — and K(t) tabulated at the
// reference's knots or every options.outputStep (sampling continuous gains: between rows they are
// interpolated linearly).
// Sampled (options.sampleRate = f > 0): the sampled-data LQR of sampled_lqr.hpp at t_k = t0 + k/f:
// the exact discretization of each interval of the (reduced) linearization, the cost of the
// held input, the recursion with the cross term; K_k at the sample times (the last row, at T,
// repeats the last sample's gain), S_k there. On a constrained scene the reduced system is that of
// the transported basis T(t) (z = T(t)ᵀδx), and K_k = Kr_k T(t_k)ᵀ, S_k = T(t_k) Sr_k T(t_k)ᵀ.
//
// Feed-forward of sampled gains (options.feedforward; GainSchedule::setFeedforward). K_k is exact
// for the hold, but u_ref(t_k) held over [t_k, t_{k+1}) is not the input that keeps the plant on
// the reference: with u_ref changing at rate u̇ the unperturbed loop leaves it by O(h² |B u̇|) per
// interval, which the feedback then chases (issue 27: 0.26 on a double pendulum on a cart at
// 100 Hz). kConsistent (the default) writes, per interval, the held input ū_k that carries
// x_ref(t_k) to x_ref(t_{k+1}) through the exact nonlinear dynamics as closely as one held input
// can, measured by the cost-to-go there:
//   ū_k = argmin_ū  d(ū)ᵀ S_{k+1} d(ū),   d(ū) = x(t_{k+1}; x(t_k) = x_ref(t_k), u ≡ ū) − x_ref(t_{k+1}).
// S_{k+1} is the metric the LQR itself puts on a deviation at t_{k+1} (unit-invariant: rescaling
// a state rescales S to match). From the interval average of u_ref (kAverage stops there: it is
// the minimizer of the input cost ∫ (ū − u_ref)ᵀR(ū − u_ref) ds for a constant R, and exact to
// O(h²) per interval in the defect against O(h) for u_ref(t_k)) a Gauss–Newton iteration
//   ū ← ū − (Γᵀ S Γ)⁺ Γᵀ S d(ū),   Γ = T(t_{k+1}) Γ_k  (the hold's exact input matrix of the
//                                                       sampled discretization, 2n × m),
// with d(ū) from the nonlinear plant (analysis's simulate, held ū, projected onto the
// constraints) and Γ_k as the Jacobian ∂d/∂ū: Γ_k is that Jacobian exactly along the reference
// with u_ref(s); along the held ū it differs by O(h·|ū − u_ref|), so the iteration (a chord
// method) converges linearly at that small rate, to the point where Γᵀ S d = 0 (the least-squares
// optimum up to the same order). With m < 2n a residual remains — what one held input cannot do
// (the reference's own curvature over the interval, and its collocation error): the solution
// reports its largest value, √(dᵀ S_{k+1} d), beside the same for u_ref(t_k). An interval with
// S_{k+1} = 0 (the last, when Qf = 0) keeps the average (nothing weighs its end state); an exactly
// constant stretch (a held pose) is solved once. kReference writes no feed-forward (the older
// behaviour: the simulator applies u_ref(t_k)).
//
// Infinite horizon (options.infiniteHorizon; a held pose only: every knot the same state at rest
// and the same input, constant weights): the terminal cost is the stationary cost-to-go S∞ of the
// linearization at the pose — the CARE's solution (continuous gains) or the DARE's of the exact
// sampled-data discretization with its cross term (sampled gains), on the tangent space of the
// constraint manifold when there are constraints (Sr∞, S∞ = T Sr∞ Tᵀ) — so Qf is replaced by S∞
// and the Riccati equation or recursion starts at its own fixed point: K(t) = K∞ all along, with
// no terminal layer (a finite-horizon gain ends in K(T) = R⁻¹BᵀQf, which can destabilize a loop
// that runs to T). The solution reports the LQR solve and the largest ‖K_k − K∞‖ / ‖K∞‖ over the
// rows (the integration's error; for sampled gains the last interval, when shorter than 1/f, has
// its own exact gain).
//
// The result is plain data (it owns the gains and S; no reference to the model).
#pragma once

#include "trellis/core/gain_schedule.hpp"
#include "trellis/control/manifold_lqr.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/control/sampled_lqr.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace trellis {

class Model;
class Trajectory;

/// The feed-forward written with sampled gains (file comment).
enum class SampledFeedforward {
  kReference,   ///< none: the controller applies u_ref(t_k) (the older behaviour)
  kAverage,     ///< ū_k = the average of u_ref over [t_k, t_{k+1}] (exact quadrature)
  kConsistent,  ///< ū_k carries x_ref(t_k) closest to x_ref(t_{k+1}) in the S_{k+1} metric
};

/// Names: reference, average, consistent.
inline EnumNameTable<SampledFeedforward> enumNames(SampledFeedforward) {
  static constexpr EnumName<SampledFeedforward> table[] = {{SampledFeedforward::kReference, "reference"},
                                                           {SampledFeedforward::kAverage, "average"},
                                                           {SampledFeedforward::kConsistent, "consistent"}};
  return table;
}

/// Options of the TV-LQR along a trajectory (solveTvlqr): continuous or zero-order-hold gains,
/// where they are tabulated, and the options of the solvers it uses.
struct TvlqrOptions {
  double sampleRate = 0.0;  ///< 0: continuous gains; > 0: zero-order-hold gains at this rate (Hz)
  double outputStep = 0.0;  ///< continuous only: tabulate K every outputStep from t0 (T included);
                            ///< 0: at the reference's knots (≥ 0)
  RiccatiOptions riccati;                 ///< the continuous solve
  SampledDiscretizationOptions sampled;   ///< the sampled discretization
  TangentTransportOptions transport;      ///< the tangent basis (scenes with constraints)
  /// Sampled only: the held feed-forward written beside K_k (file comment).
  SampledFeedforward feedforward = SampledFeedforward::kConsistent;
  int feedforwardIterations = 6;  ///< kConsistent: Gauss–Newton iterations per interval at most (≥ 1)
  /// Sampled: run the plant with u_ref(t_k) held over every interval, for
  /// TvlqrSolution::referenceDefect. With a feed-forward other than kReference it is what the
  /// feed-forward gains against the plain hold: one more plant run per interval, half of
  /// kAverage's runs, changing nothing else. With kReference these are the only plant runs (they
  /// also give feedforwardDefect and predictedDeviation): false then computes the gains alone,
  /// with no plant run, and the three are NaN ("not measured"). false: referenceDefect is NaN.
  bool measureHeldReference = true;
  /// Sampled only: threads for the feed-forward's plant runs (1..256). The sample intervals are
  /// independent (each starts on the reference and is weighed by the already solved S_{k+1}) and
  /// are gathered in order: the result is the same on any number of threads. The runs of every
  /// feed-forward but kConsistent need no gains: threads − 1 of them start beside the transport
  /// and the discretization, which run on the calling thread.
  int threads = 1;
  /// A held pose only: Qf := S∞ of the CARE (DARE when sampled) at the pose (file comment);
  /// weights.Qf is then not used. Throws std::invalid_argument for a reference that is not a held
  /// pose or time-varying weights.
  bool infiniteHorizon = false;
  /// Throws std::invalid_argument naming the field and its value.
  void validate() const;
};

/// Where a TV-LQR solve failed (status.message carries the inner solver's own report).
enum class TvlqrCode {
  kOk,
  kTransportFailure,       ///< the tangent basis transport failed (constrained scenes)
  kRiccatiFailure,         ///< the continuous Riccati solve failed (RiccatiSolution's status)
  kDiscretizationFailure,  ///< the sampled-data discretization failed
  kRecursionFailure,       ///< the sampled Riccati recursion failed
  kNonFinite,              ///< a tabulated K(t) or S(t) is not finite
  kIndefinite,             ///< S (Sr) has an eigenvalue below −1e-6·max|λ| (isSemidefiniteToRoundoff):
                           ///< the integration did not resolve the Riccati equation; gains are set
  kFeedforwardFailure,     ///< the plant's simulation over a sample interval failed (kConsistent)
  kNotSolved,              ///< a default-constructed solution (no solve ran)
};

/// Names: ok, transport_failure, riccati_failure, discretization_failure, recursion_failure,
/// non_finite, indefinite, feedforward_failure, not_solved.
inline EnumNameTable<TvlqrCode> enumNames(TvlqrCode) {
  static constexpr EnumName<TvlqrCode> table[] = {
      {TvlqrCode::kOk, "ok"},
      {TvlqrCode::kTransportFailure, "transport_failure"},
      {TvlqrCode::kRiccatiFailure, "riccati_failure"},
      {TvlqrCode::kDiscretizationFailure, "discretization_failure"},
      {TvlqrCode::kRecursionFailure, "recursion_failure"},
      {TvlqrCode::kNonFinite, "non_finite"},
      {TvlqrCode::kIndefinite, "indefinite"},
      {TvlqrCode::kFeedforwardFailure, "feedforward_failure"},
      {TvlqrCode::kNotSolved, "not_solved"}};
  return table;
}

/// The TV-LQR gains K(t) along a trajectory (on the constraint manifold's tangent space when the
/// scene has constraints), the cost-to-go S at the gains' times, and the solve's diagnostics.
struct TvlqrSolution {
  /// code; message (empty when ok; what failed, where, when); t: the failure's time when known;
  /// index unused. A default-constructed solution is kNotSolved.
  Status<TvlqrCode> status{TvlqrCode::kNotSolved, "no solve ran"};
  double sampleRate = 0.0;        ///< as requested (0 = continuous)
  bool constrained = false;       ///< solved on the tangent space of the constraint manifold
  ///@{
  /// The full state's size 2n and the inputs m.
  int nx = 0, nu = 0;
  ///@}
  int dimension = 0;              ///< d: tangent dimension (2n without constraints)
  /// K (m×2n) at its times, with the scene's column names and the sample rate set.
  GainSchedule gains;
  /// Full-state cost-to-go at gains.times() (2n×2n, symmetric PSD; rank ≤ d).
  std::vector<Eigen::MatrixXd> S;
  // Diagnostics.
  double seconds = 0.0;           ///< wall time of the solve
  long steps = 0;                 ///< CVODES internal steps (Riccati ODE, or all intervals)
  long rhsEvaluations = 0;        ///< right-hand sides evaluated by CVODES
  long linearizations = 0;        ///< sampled: evaluations of the (reduced) linearization
  long transportSteps = 0;        ///< basis transport steps (constrained)
  double maxBasisCorrection = 0.0;  ///< TangentBasisTrajectory::maxCorrection (constrained)
  ///@{
  /// The smallest and largest eigenvalue of S (of the reduced Sr when constrained) at
  /// gains.times() (continuous: the output grid; sampled: the samples). The continuous solve's
  /// per-step S ⪰ 0 check (RiccatiOptions::checkPositiveSemidefinite) covers the steps between.
  double minEigenvalueS = 0.0, maxEigenvalueS = 0.0;
  ///@}
  std::string method;             ///< "bdf", "adams", "factored" or "sampled-zoh"
  /// Sampled: the feed-forward written (options.feedforward) and, over the sample intervals, the
  /// largest defect √(dᵀ S_{k+1} d) it leaves (file comment) and the same for u_ref(t_k) held.
  SampledFeedforward feedforward = SampledFeedforward::kReference;
  double feedforwardDefect = 0.0;  ///< max_k √(dᵀ S_{k+1} d) with the feed-forward written
  double referenceDefect = 0.0;    ///< the same with u_ref(t_k) held (NaN: not measured, TvlqrOptions::measureHeldReference)
  long feedforwardSimulations = 0;  ///< plant simulations over one interval for the feed-forward
  /// Sampled: what the hold allows — the largest ‖e_k‖₂ (full state, the simulator's tracking
  /// error's norm) of the defects r_k left by the feed-forward written, propagated by the sampled
  /// closed loop of the linearization, e_{k+1} = (Φ_k − Γ_k K_k) e_k + r_k, e_0 = 0: to first order
  /// in r, the unperturbed sampled loop's deviation from the reference at the samples. With
  /// constraints, in the tangent coordinates between the projections of the reference onto the
  /// constraints, plus the reference's own distance from them, P(x_ref(t_k)) − x_ref(t_k).
  double predictedDeviation = 0.0;
  /// Empty, or (feedforward = kReference only, where the plant runs serve only the prediction)
  /// why a run failed: the gains stand, the defects and the prediction are NaN. With a
  /// feed-forward to compute, a failed run is the status kFeedforwardFailure instead.
  std::string predictionFailure;
  bool infiniteHorizon = false;      ///< solved with Qf = S∞ (options.infiniteHorizon)
  std::string infiniteHorizonSolve;  ///< the CARE's (DARE's) LqrResult::describe() line
  double maxGainDeviation = 0.0;     ///< infinite horizon: max_k ‖K_k − K∞‖_F / ‖K∞‖_F

  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// A few lines for people (what was solved, work, S's spectrum).
  std::string summary() const;
  /// One line: the status, the mode, the rows of K and the work.
  std::string describe() const;
  /// One JSON object (keys: status, ok, message, t, index, mode, sample_rate_hz, constrained, nx,
  /// nu, tangent_dimension, rows, t0, t1, seconds, steps, rhs_evaluations, linearizations,
  /// transport_steps, max_basis_correction, min_eigenvalue_S, max_eigenvalue_S, method, feedforward: reference|average|consistent or "none"
  /// for continuous gains, feedforward_defect, reference_defect, feedforward_simulations,
  /// predicted_deviation, prediction_failure, infinite_horizon, infinite_horizon_solve,
  /// max_gain_deviation).
  std::string json() const;
};

/// Throws std::invalid_argument / TrajectoryError for bad input (sizes, weights, options, a
/// reference not matching the model, or whose knot dynamics fail: a reference without state
/// derivatives gets them from computeDynamics, ReferenceEvaluator); numerical failure is in
/// the result's status, never thrown.
TvlqrSolution solveTvlqr(const Model& model, const Trajectory& reference, const LqrWeights& weights,
                         const TvlqrOptions& options = {});

/// The S ⪰ 0 test on a solution's spectrum (TvlqrSolution::minEigenvalueS, maxEigenvalueS): S is
/// a sum of positive semidefinite terms, so a clearly negative eigenvalue means the integration did
/// not resolve the Riccati equation. True when λmin ≥ −relativeSlack·max(|λmin|, |λmax|) and both
/// are finite (λmin = λmax = 0, "not tracked", passes).
bool isSemidefiniteToRoundoff(double minEigenvalue, double maxEigenvalue, double relativeSlack = 1e-6);

}  // namespace trellis
