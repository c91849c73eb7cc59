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

/// Options of the TV-LQR along a trajectory (solveTvlqr): continuous or zero-order-hold gains,
/// where they are tabulated, and the options of the solvers it uses.
struct TvlqrOptions {
  double sampleRate = 0.0;  ///< 0: continuous gains; > 0: zero-order-hold gains at this rate (Hz)
  double outputStep = 0.0;  ///< continuous only: tabulate K every outputStep from t0 (T included);
                            ///< 0: at the reference's knots (≥ 0)
  RiccatiOptions riccati;                 ///< the continuous solve
  SampledDiscretizationOptions sampled;   ///< the sampled discretization
  TangentTransportOptions transport;      ///< the tangent basis (scenes with constraints)
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
  kNotSolved,              ///< a default-constructed solution (no solve ran)
};

/// Names: ok, transport_failure, riccati_failure, discretization_failure, recursion_failure,
/// non_finite, indefinite, not_solved.
inline EnumNameTable<TvlqrCode> enumNames(TvlqrCode) {
  static constexpr EnumName<TvlqrCode> table[] = {
      {TvlqrCode::kOk, "ok"},
      {TvlqrCode::kTransportFailure, "transport_failure"},
      {TvlqrCode::kRiccatiFailure, "riccati_failure"},
      {TvlqrCode::kDiscretizationFailure, "discretization_failure"},
      {TvlqrCode::kRecursionFailure, "recursion_failure"},
      {TvlqrCode::kNonFinite, "non_finite"},
      {TvlqrCode::kIndefinite, "indefinite"},
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
  /// The smallest and largest eigenvalue of S (of the reduced Sr when constrained) over the solve.
  double minEigenvalueS = 0.0, maxEigenvalueS = 0.0;
  ///@}
  std::string method;             ///< "bdf", "adams", "factored" or "sampled-zoh"

  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// A few lines for people (what was solved, work, S's spectrum).
  std::string summary() const;
  /// One line: the status, the mode, the rows of K and the work.
  std::string describe() const;
  /// One JSON object (keys: status, ok, message, t, index, mode, sample_rate_hz, constrained, nx,
  /// nu, tangent_dimension, rows, t0, t1, seconds, steps, rhs_evaluations, linearizations,
  /// transport_steps, max_basis_correction, min_eigenvalue_S, max_eigenvalue_S, method).
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
