// trellis/core/reference.hpp — a trajectory bound to a model: the reference x(t), u(t), ẋ(t) and
// the exact linearization A(t), B(t) at any t, after one check.
//
// Everything that follows a reference (TV-LQR, the tangent-basis transport, the closed loop, the
// consistency check, the optimizer's mesh refinement) needs the same sequence: check that the
// trajectory's names are the model's, give it knot derivatives ẋ_k from the core's dynamics,
// then at each t interpolate (trajectory.hpp's rule: cubic Hermite state; linear or, with input
// derivatives, cubic Hermite input) and call computeLinearization at (x(t), u(t)). The evaluator
// does the checks once in its constructor and owns what the queries need:
//   - its copy of the trajectory (with state derivatives), so it does not depend on the caller's;
//   - a Data workspace for the model, so a query allocates nothing (tests/core/no_malloc);
//   - the buffers x, u, ẋ it answers in.
// It keeps a pointer to the Model (like an algorithm's arguments, the model must outlive it). One
// evaluator per thread: queries write its buffers.
//
// It is THE way to evaluate along a reference: the Riccati solve's A(t), B(t)
// (makeTrajectoryLinearization), the tangent-basis transport and the reduced linearization on the
// constraint manifold (linearizeWithTangentBasis), the consistency check and the TV-LQR entry all
// go through it. A failure of the dynamics at a query is a returned Status, never thrown.
#pragma once

#include "trellis/core/data.hpp"
#include "trellis/core/status.hpp"
#include "trellis/core/trajectory.hpp"

#include <Eigen/Core>

#include <string>

namespace trellis {

class Model;

/// Why a query along the reference failed.
enum class ReferenceCode {
  kOk,
  kLinearizationFailed,  ///< computeLinearization's status was not ok (singular M, constraints)
  kNonFinite,            ///< A or B has a non-finite entry
  kTangentRankChanged,   ///< the constraint tangent space changed dimension (the rank of the
                         ///< constraints changed; index: the new dimension)
  kOffConstraints,       ///< a knot violates a constraint (checkReferenceOnConstraints)
  kBasisDrift,           ///< a transported tangent basis no longer spans the tangent space
                         ///< (control's ReducedLinearization)
};
inline EnumNameTable<ReferenceCode> enumNames(ReferenceCode) {
  static constexpr EnumName<ReferenceCode> table[] = {
      {ReferenceCode::kOk, "ok"},
      {ReferenceCode::kLinearizationFailed, "linearization_failed"},
      {ReferenceCode::kNonFinite, "non_finite"},
      {ReferenceCode::kTangentRankChanged, "tangent_rank_changed"},
      {ReferenceCode::kOffConstraints, "off_constraints"},
      {ReferenceCode::kBasisDrift, "basis_drift"}};
  return table;
}

/// A query's outcome: ok, or the time t and what failed there (the message names t and the core's
/// status message: "linearization failed at t = …: …").
using ReferenceStatus = Status<ReferenceCode>;

/// How a ReferenceEvaluator prepares its trajectory.
struct ReferenceOptions {
  /// Where the knot derivatives ẋ_k come from.
  ///  kFromDynamics: ẋ_k = [q̇_k; q̈(q_k, q̇_k, u_k)] by computeDynamics at every knot (the meaning
  ///                 of a trajectory file; supplied derivatives are replaced);
  ///  kKeepSupplied: the trajectory's own (setStateDerivatives, e.g. a designed motion's exact
  ///                 q̈) when it has them, else from the dynamics as above.
  ///  kRequireSupplied: the trajectory's own; a trajectory without them is refused
  ///                 (std::logic_error "<caller>: the trajectory has no state derivatives (call
  ///                 computeStateDerivatives)"): for solvers whose reference was prepared before.
  enum class StateDerivatives { kFromDynamics, kKeepSupplied, kRequireSupplied };
  StateDerivatives stateDerivatives = StateDerivatives::kKeepSupplied;  ///< see StateDerivatives
  int minimumKnots = 1;  ///< fewer knots are refused (a reference to follow needs 2)
  /// Names the caller in the messages of a refusal ("transportTangentBasis: …").
  std::string caller = "reference";
};

/// The verdict of checkReferenceOnConstraints: ok, or the first violation (status.index: the
/// knot, status.t: its time, status.message: a sentence naming the constraint and the values).
struct ReferenceConstraintCheck {
  ReferenceStatus status;  ///< ok, or kind, knot (index), time (t) and message of the first violation
  int constraint = -1;     ///< the violated row (Model::constraints() index)
  bool position = true;    ///< h(q) (true) or A(q) q̇ (false) is off
  double value = 0.0;      ///< h(q) or A(q) q̇ there
  double scale = 0.0;      ///< the size of the compared terms (see below)
  double tolerance = 0.0;  ///< the relative tolerance used
  bool ok() const { return status.ok(); }  ///< every knot on the constraints
};

/// Is every knot of `trajectory` on the constraints of `model` (names must match: else
/// TrajectoryError)? A reference off the constraint manifold has no meaningful linearization and
/// would be tracked with a drift as large as its violation. Each residual is measured against the
/// size of the terms it compares, so that changing the model's units (lengths scaled by any s)
/// leaves the verdict unchanged:
///  - velocity row: |A_r q̇| ≤ tol · max(‖A_r‖ ‖q̇‖, ℓ_r / T), T the reference's duration and ℓ_r
///    the row's own size in h's units (2ℓ² for a distance, L otherwise): a knot at rest is not held
///    to the rounding of a zero velocity;
///  - distance row, h = ‖d‖² − ℓ²: |h| ≤ tol · (‖d‖² + ℓ²) = tol · (h + 2ℓ²);
///  - point and point-on-plane rows (h a length): |h| ≤ tol · max(L, ‖A_r‖ ‖q‖), L the model's
///    length scale (the largest joint offset, frame offset or constraint point; lengths scale it
///    like h), ‖A_r‖ ‖q‖ the size of the motion's contribution;
///  - knife edges are velocity rows only.
/// A model without constraints is ok. Bad input throws; a violation is the returned verdict.
ReferenceConstraintCheck checkReferenceOnConstraints(const Model& model, const Trajectory& trajectory,
                                                     double tolerance = 1e-6);

/// A reference trajectory prepared for queries at any time t: x(t), u(t), ẋ(t) by the
/// trajectory's interpolation rule (trajectory.hpp), the exact linearization A(t), B(t) and the
/// constraint tangent basis there, into buffers sized once (no allocation per query). One per
/// thread; the model must outlive it.
class ReferenceEvaluator {
 public:
  /// Checks, once: the configuration and input names equal the model's (in order), at least
  /// options.minimumKnots knots, and the knot derivatives (computeDynamics at every knot unless
  /// kept). Throws TrajectoryError naming the mismatch, or the knot and time where the dynamics
  /// failed. (The knot values are finite by construction of a Trajectory.)
  ReferenceEvaluator(const Model& model, Trajectory trajectory, const ReferenceOptions& options = {});

  const Model& model() const { return *model_; }  ///< the model it was made for
  const Trajectory& trajectory() const { return trajectory_; }  ///< with state derivatives
  int nq() const { return trajectory_.nq(); }                   ///< n
  int nx() const { return trajectory_.nx(); }                   ///< 2n
  int nu() const { return trajectory_.nu(); }                   ///< m
  double startTime() const { return trajectory_.startTime(); }  ///< t_0 [s]
  double endTime() const { return trajectory_.endTime(); }      ///< t_{N−1} [s]

  /// x(t), u(t) and the spline's ẋ(t) into x(), u(), xdot(). Throws std::out_of_range outside
  /// [t_0, t_{N-1}] (a relative slack of 1e-12 is clamped). No allocation.
  void evaluate(double t);
  /// evaluate(t), then the exact A(t) = ∂f/∂x, B(t) = ∂f/∂u at (x(t), u(t)) by computeLinearization
  /// into A(), B() (and everything else data() holds: M, the constraint Jacobian, ...). A failure of
  /// the dynamics is the returned status naming t, never thrown. No allocation when ok.
  ReferenceStatus linearize(double t);
  /// linearize(t), then the orthonormal basis Tc (2n×d_c) of the constraint tangent space at x(t)
  /// (computeConstraintTangentBasis; T = I without constraints) into tangentBasis(). With
  /// expectedDimension ≥ 0, a different d_c is the status kTangentRankChanged naming t and both
  /// dimensions. No allocation when ok and d_c is unchanged.
  ReferenceStatus linearizeWithTangentBasis(double t, Eigen::Index expectedDimension = -1);

  const Eigen::VectorXd& x() const { return x_; }        ///< 2n: x(t) of the last query
  const Eigen::VectorXd& u() const { return u_; }        ///< m: u(t)
  const Eigen::VectorXd& xdot() const { return xdot_; }  ///< 2n: the spline's dx/dt at t
  const Eigen::MatrixXd& A() const { return data_.A; }   ///< 2n×2n, valid after linearize ok
  const Eigen::MatrixXd& B() const { return data_.B; }   ///< 2n×m
  /// 2n×d_c, valid after linearizeWithTangentBasis ok.
  const Eigen::MatrixXd& tangentBasis() const { return data_.tangentBasis; }
  /// Number of linearizations (dynamics evaluations) so far.
  long linearizations() const { return linearizations_; }
  ///@{
  /// The workspace of the last query (its results: M, λ, the constraint Jacobian, ...).
  Data& data() { return data_; }
  const Data& data() const { return data_; }
  ///@}

 private:
  const Model* model_;
  Trajectory trajectory_;
  Data data_;
  Eigen::VectorXd x_, u_, xdot_, q_, dq_;
  long linearizations_ = 0;
};

}  // namespace trellis
