// trellis/analysis/simulation.hpp — open- and closed-loop simulation of the NONLINEAR plant.
//
// The state x = [q; q̇] (2n) evolves by ẋ = f(t, x) = [q̇; q̈(q, q̇, u)], q̈ from computeDynamics
// (the KKT solve that enforces A q̈ + Ȧ q̇ = 0), integrated through the one ODE driver: SUNDIALS
// CVODES (Adams, BDF) or trellis's three-stage Radau IIA (IntegrationMethod::kRadau). The input comes from a policy u = π(t, x) (m), clipped to the box
// [inputLower, inputUpper]:
//  - continuous feedback (sampleRate = 0): u(t) = sat(π(t, x(t))) inside every right-hand side;
//  - sampled feedback (sampleRate = f > 0): u_k = sat(π(s_k, x(s_k))) at s_k = t0 + k/f, held
//    constant (zero-order hold) on [s_k, s_{k+1}).
// The closed loop about a reference (x_ref, u_ref) with a gain schedule K(t) is the policy
//   π(t, x) = u_ref(t) − K(t) (x − x_ref(t)),
// except for sampled gains with a held feed-forward (GainSchedule::hasFeedforward), sampled at
// their rate: there u_k = ū_k − K_k (x(s_k) − x_ref(s_k)), ū_k the input that carries the
// reference over the hold (u_ref(s_k) would leave a drift of O(h·|u̇_ref|) per interval);
// the open loop π(t, x) = u_ref(t). x_ref is the reference's cubic Hermite spline, u_ref and K are
// interpolated by Trajectory::evaluate and GainSchedule::evaluate (continuous in t).
//
// Jacobian (BDF, Radau). The Newton matrix needs ∂f/∂x. For the closed loop it is exact:
//   ∂f/∂x = A(x, u) − B(x, u) S K(t),   S = diag(s_i), s_i = 0 where u_i is clipped, else 1,
// with A, B from computeLinearization at the current state and input (a clipped input does not
// move with x). Sampled and open loops have ∂u/∂x = 0, so ∂f/∂x = A. A generic Policy has no
// known ∂π/∂x: there, and with SimulationOptions::exactJacobian = false, CVODES forms the
// difference quotient (2n extra right-hand sides per Jacobian, counted in
// SimulationResult::linearRhsEvaluations).
//
// Deviation coordinates. For the open and closed loop about a reference (simulateOpenLoop,
// simulateClosedLoop, simulateBatch) the integrator's state is y = x − x_ref(t), with
// ẏ = f(t, x_ref + y) − ẋ_ref(t): the same ODE, but rtol and atol then bound the local error
// against |x − x_ref| and atol, not against |x|. Near the reference the absolute accuracy of x is
// ~atol instead of rtol·|x|: on the hand the closed loop's error went from a floor of ~1e-5
// (rtol 1e-7 on x) to below 1e-7 (see the report of issue 11). With BDF and the difference-quotient
// Jacobian (exactJacobian = false) x itself is integrated: CVODES's increments, scaled to |y| and
// atol, would drown in the rounding of x_ref + y. A Policy (simulate) always integrates x.
//
// Restarts. The integration restarts (CVODES: order 1, a fresh step; Radau keeps its step size
// and Jacobian) only where the right-hand side jumps: at the sample times of sampled feedback, at options.breakpoints, and after a projection
// changed the state. u_ref(t) and K(t) are continuous, so the reference knots and the gain times
// are NOT restart points: there f is continuous with a kink in t, which the error control steps
// over like the kinks of saturation (switching of sat(·) is left to the error control too: on
// the hand the 23 tensions' active set changes at ~24 steps of a 3 s run and the switching costs
// ~400 of its ~2400 steps, about what a restart at order 1 per switch would cost, plus a root
// function per input; see the report of issue 11). Outputs are
// the integrator's dense output (the interpolating polynomial of the last step, of the accepted
// local error), except at restart points, where the integration stops exactly.
//
// Constraints (model.nc() > 0). The exact dynamics keep h(q) and A q̇ constant along the exact
// solution, so they drift only by integration error. The drift max(|h(q)|∞, |A q̇|∞) is measured
// at every output time and restart point. With ConstraintHandling::kProject the state is projected
// (core's projectState: feasibility in the mass-matrix metric, positions then velocities) where the
// drift exceeds the tolerance δ = driftTolerance (default 10·(atol + rtol)) — at t0 and at the
// output and restart times, not at every knot — and the integration restarts from the projected
// state. A drift still above δ after projection ends the run with kConstraintDrift (time, drift).
// kNone never changes the state (the drift is still reported).
//
// Step check (SimulationOptions::stepCheck). A condition the plant must keep along the whole run,
// such as unilateral contact inside a friction cone, is checked on the integrator's own steps,
// not only at the outputs: at t0, at the end of EVERY accepted internal step, and again at every
// restart point after a new sample or a projection (where u or x jumps). At each such point the
// simulator evaluates computeDynamics at (x, u) — u the input applied there (the held sample, or
// sat(π(t, x))) — and passes t, x, u and the constraint forces λ to the check: one dynamics
// evaluation per step beyond the integrator's own (none without a check; none with Radau, which
// evaluates every step end itself: its λ there is reused, the same function of the same (x, u)). A violation ends the run
// with kCheckFailed, the check's text, the time and the state; the outputs reached are kept.
// Between step ends the state is the integrator's interpolant and is not checked. Times may repeat
// or go back: a restart at a sample time checks te again with the new input, and a projection at
// an output time restarts there, behind the last step's end.
//
// Threads. simulate* read the Model, the reference and the gain schedule only (const methods);
// each call owns its Data, its CVODES memory and its buffers. Calls on distinct threads may share
// one Model, Trajectory and GainSchedule as long as nobody modifies them meanwhile; a Policy
// shared across threads must itself be safe to call concurrently. simulateBatch relies on this.
#pragma once

#include "trellis/core/gain_schedule.hpp"
#include "trellis/core/projection.hpp"
#include "trellis/core/status.hpp"
#include "trellis/core/trajectory.hpp"

#include <Eigen/Core>

#include <functional>
#include <string>
#include <vector>

namespace trellis {

class Model;

/// What the simulator does about numerical constraint drift (see the file comment).
enum class ConstraintHandling {
  kNone,     ///< integrate as is; drift is reported only
  kProject,  ///< project x0 and the state at every segment end onto h = 0, A q̇ = 0, then reinit
};

/// The integrator: CVODES's linear multistep families, or trellis's own implicit Runge–Kutta.
enum class IntegrationMethod {
  kAdams,  ///< Adams–Moulton with fixed-point iterations: no Jacobian, for non-stiff systems
  kBDF,    ///< BDF with Newton iterations and a dense Jacobian (exact where known, see the file
           ///< comment): stiff systems (stiff springs, very high gains, the hand)
  /// Three-stage Radau IIA (order 5, L-stable; RADAU5's step control, rtol met through its
  /// transformed tolerance 0.1·rtol^{2/3} on the embedded estimate) with the exact Jacobian: a
  /// one-step method, so a restart (every sample of a held input) keeps its step size and Jacobian
  /// where BDF drops to order 1 and a small step. For sampled feedback and stiff loops; needs the
  /// exact Jacobian (not a continuous Policy, not exactJacobian = false: refused).
  kRadau,
};

/// Names: adams, bdf, radau (toString).
inline EnumNameTable<IntegrationMethod> enumNames(IntegrationMethod) {
  static constexpr EnumName<IntegrationMethod> table[] = {{IntegrationMethod::kAdams, "adams"},
                                                          {IntegrationMethod::kBDF, "bdf"},
                                                          {IntegrationMethod::kRadau, "radau"}};
  return table;
}
/// parseEnum<IntegrationMethod>(text, "integration method"): throws std::invalid_argument
/// "integration method 'TEXT' is not one of adams, bdf, radau".
IntegrationMethod parseIntegrationMethod(const std::string& text);

/// The step check of SimulationOptions (file comment): t, x (2n), the applied u (m) and the
/// constraint forces λ (nc; empty without constraints) of computeDynamics at (x, u). Returns an
/// empty string where the condition holds, else what is violated and by how much (it ends the run
/// as kCheckFailed; a throw does too, with the exception's text). Called on the simulating thread;
/// a check shared by simulateBatch's threads must be safe to call concurrently.
using StepCheck = std::function<std::string(double t, const Eigen::VectorXd& x, const Eigen::VectorXd& u,
                                            const Eigen::VectorXd& lambda)>;

/// Options of simulate / simulateBatch: integrator tolerances and method, sampled or continuous
/// feedback, input limits, output times, constraint projection.
struct SimulationOptions {
  double rtol = 1e-8;      ///< CVODES relative tolerance (> 0)
  double atol = 1e-10;     ///< CVODES absolute tolerance on each state entry (> 0)
  long maxSteps = 500000;  ///< total internal steps over [t0, t1] (> 0); more is kIntegratorFailure
  /// 0: continuous feedback u(t) = π(t, x(t)); > 0: sampled at this rate (Hz), from t0, u held
  /// (zero-order hold) between samples.
  double sampleRate = 0.0;
  ///@{
  /// Input box: empty = unbounded; else size m each (±inf allowed, lower ≤ upper). u is clipped.
  Eigen::VectorXd inputLower, inputUpper;
  ///@}
  /// 0: output at the reference's knots inside [t0, t1] (plus t0 and t1; needs a reference);
  /// > 0: t0, t0 + h, t0 + 2h, …, and t1.
  double outputStep = 0.0;
  ConstraintHandling constraints = ConstraintHandling::kProject;  ///< project onto the constraints, or only report the drift
  IntegrationMethod method = IntegrationMethod::kAdams;  ///< Adams (non-stiff), BDF (stiff closed loops, e.g. high gains) or Radau (stiff and sampled)
  double maxStep = 0.0;  ///< largest internal step; 0 = unlimited (≥ 0)
  /// Radau only: Newton's stopping test κ, in units of the step's error tolerance (the iteration
  /// stops when its estimated remaining error is ≤ κ; RADAU5's fnewt). 0: RADAU5's default
  /// min(0.03, √rtol') with rtol' = 0.1 rtol^(2/3) (6.8e-3 at rtol 1e-5). Larger κ, fewer
  /// iterations: the iteration's error stays a fraction κ of what the step's error estimate
  /// allows. (0 or in (0, 1))
  double newtonTolerance = 0.0;
  /// Extra times where the policy jumps (integration restarts there). Times outside (t0, t1) are
  /// ignored. (Kinks need none: the reference knots and gain times are not restart points.)
  std::vector<double> breakpoints;
  int projectionIterations = 10;  ///< Newton iterations per position projection (≥ 1)
  /// Constraint drift tolerated before projecting (units of h and A q̇); 0: 10·(atol + rtol). A
  /// projection that cannot bring the drift below it is kConstraintDrift. (≥ 0)
  double driftTolerance = 0.0;
  /// BDF only: the exact closed-loop Jacobian A − B S K (true) or CVODES's difference quotient
  /// (false; the fallback, 2n extra right-hand sides per Jacobian). A generic Policy always uses
  /// the difference quotient unless sampled (then ∂f/∂x = A). Radau needs it true.
  bool exactJacobian = true;
  /// Empty: none; else checked at t0, after every accepted integrator step and at every restart
  /// (file comment, "Step check").
  StepCheck stepCheck;

  /// Throws std::invalid_argument naming the field and its value (sizes against the model are
  /// checked by simulate).
  void validate() const;
};

/// A failing right-hand side (dynamics, policy returning NaN) is first reported to CVODES as
/// recoverable, so a bad trial point only shortens the step; after 10 failures in one segment, or
/// on a policy exception, the simulation stops with the last failure's time, state and message.
enum class SimulationCode {
  kOk,
  kIntegratorFailure,  ///< CVODES failed (too much work / maxSteps, error test, convergence)
  kDynamicsFailure,    ///< computeDynamics returned a status that is not ok (singular M or
                       ///< constraints)
  kNonFinite,          ///< the state, the input or q̈ became NaN/Inf
  kPolicyFailure,      ///< the policy threw (e.g. a time outside the reference)
  kConstraintDrift,    ///< the drift stayed above driftTolerance after a projection
  kCheckFailed,        ///< SimulationOptions::stepCheck reported a violation (its text in the message)
};

/// Names: ok, integrator_failure, dynamics_failure, non_finite, policy_failure, constraint_drift,
/// check_failed.
inline EnumNameTable<SimulationCode> enumNames(SimulationCode) {
  static constexpr EnumName<SimulationCode> table[] = {
      {SimulationCode::kOk, "ok"},
      {SimulationCode::kIntegratorFailure, "integrator_failure"},
      {SimulationCode::kDynamicsFailure, "dynamics_failure"},
      {SimulationCode::kNonFinite, "non_finite"},
      {SimulationCode::kPolicyFailure, "policy_failure"},
      {SimulationCode::kConstraintDrift, "constraint_drift"},
      {SimulationCode::kCheckFailed, "check_failed"}};
  return table;
}

/// The closed loop x(t), u(t) at the output times, the tracking error and constraint drift there,
/// the integrator's work, and the status (with the time and state of a failure).
struct SimulationResult {
  /// code; message (empty when ok; names the time and the state of the failure); t: the time of
  /// the failure (NaN when ok); index unused.
  Status<SimulationCode> status;
  Eigen::VectorXd failureState;  ///< x = [q; q̇] at status.t (2n; not ok only)
  /// Closed-loop x and the applied (saturated) u at the output times (names from the model), up to
  /// the last output time reached before a failure. States are recorded after projection; the
  /// state derivatives [q̇; q̈(q, q̇, u)] at the recorded points are set (so the result can serve as
  /// a reference). For sampled feedback u is right-continuous (the new sample at a sample time; at
  /// t1 the value held over the last interval).
  Trajectory trajectory;
  /// ‖x(t_k) − x_ref(t_k)‖₂ per output time; empty without a reference.
  Eigen::VectorXd trackingError;
  /// Per output time: max(|h(q)|∞, |A(q) q̇|∞) before any projection at that time; zeros if the
  /// model has no constraints.
  Eigen::VectorXd constraintDrift;
  /// Max of the drift over every point where it was measured (the output times and, when
  /// projecting, every segment end), before projection.
  double maxConstraintDrift = 0.0;
  /// Control evaluations in which any input was clipped: continuous feedback counts the
  /// evaluations at the output times, sampled feedback counts the samples.
  int saturatedSamples = 0;
  int controlSamples = 0;          ///< the evaluations counted for saturatedSamples
  double saturatedFraction = 0.0;  ///< saturatedSamples / controlSamples (0 if none)
  long steps = 0;                  ///< CVODES internal steps, all segments
  long rhsEvaluations = 0;         ///< right-hand sides by the integrator itself
  long linearRhsEvaluations = 0;   ///< right-hand sides for difference-quotient Jacobians (0 exact)
  long jacobianEvaluations = 0;    ///< Newton-matrix Jacobians formed (exact or difference quotient)
  long restarts = 0;               ///< restarts after t0: samples, breakpoints, projections
  long projections = 0;            ///< projections that were applied
  long checks = 0;                 ///< points where SimulationOptions::stepCheck was evaluated
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// One line: the status, rows, final and max tracking error, drift, steps.
  std::string describe() const;
  /// One JSON object: status, ok, message, t, index, rows, t0, t1, tracking error (initial,
  /// final, max, time of max), constraint drift, saturation, integrator work.
  std::string json() const;
};

/// u = policy(t, x): x is 2n, u arrives sized m and must be overwritten. It may throw (reported as
/// kPolicyFailure); it must not keep references to its arguments.
using Policy = std::function<void(double t, const Eigen::VectorXd& x, Eigen::VectorXd& u)>;

/// Simulates ẋ = [q̇; q̈(q, q̇, sat(u))] from x(t0) = x0 (2n, finite) to t1 > t0 under `policy`.
/// `reference` (optional; must match the model and cover [t0, t1]) supplies the default output
/// times, extra restart points (its knots) and the tracking error; its state derivatives are
/// computed if missing. Throws std::invalid_argument for bad options, sizes or times, and
/// TrajectoryError for a reference that does not match the model. Numerical failure is a status.
SimulationResult simulate(const Model& model, const Eigen::VectorXd& x0, double t0, double t1,
                          const Policy& policy, const SimulationOptions& options,
                          const Trajectory* reference = nullptr);

/// u = u_ref(t) − K(t)(x − x_ref(t)) over the reference's time span from x0 (e.g. the reference
/// start + a perturbation). gains must be m×2n and cover the reference's span.
SimulationResult simulateClosedLoop(const Model& model, const Trajectory& reference,
                                    const GainSchedule& gains, const Eigen::VectorXd& x0,
                                    const SimulationOptions& options = {});

/// Open loop: u = u_ref(t) (piecewise linear as Trajectory::evaluate) over the reference's span.
SimulationResult simulateOpenLoop(const Model& model, const Trajectory& reference,
                                  const Eigen::VectorXd& x0, const SimulationOptions& options = {});

/// simulateClosedLoop from each of initialStates (2n each) on `threads` threads (0: one per
/// hardware thread), results in the order of initialStates. The model, the reference and the
/// gains are shared read-only (see "Threads" in the file comment); every run has its own Data and
/// integrator, so each result is bit-identical to the same run alone, for any thread count.
/// Bad arguments throw std::invalid_argument before any thread starts.
std::vector<SimulationResult> simulateBatch(const Model& model, const Trajectory& reference,
                                            const GainSchedule& gains,
                                            const std::vector<Eigen::VectorXd>& initialStates,
                                            const SimulationOptions& options = {},
                                            int threads = 0);

/// Outcome of projectOntoConstraints.
struct ConstraintProjection {
  double driftBefore = 0.0;  ///< max(|h(q)|∞, |A q̇|∞) before
  double driftAfter = 0.0;   ///< the same after
  int iterations = 0;        ///< Newton iterations on the positions
  /// core's projectState status (ProjectionCode: ok when |h| reached its tolerance, 1e-12;
  /// not_converged, non_finite otherwise, with its message); ok without constraints.
  Status<ProjectionCode> status;
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// One line: the status, then the drift before → after and the iterations.
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "drift_before", "drift_after", "iterations"}.
  std::string json() const;
};

/// Projects x = [q; q̇] (2n) in place onto h(q) = 0, A(q) q̇ = 0 exactly as kProject does (core's
/// projectState, feasibility only: the restoration's Newton steps in the mass-matrix metric). A model without constraints leaves x unchanged. Throws std::invalid_argument for
/// a wrong size; maxIterations ≥ 1.
ConstraintProjection projectOntoConstraints(const Model& model, Eigen::VectorXd& x,
                                            int maxIterations = 10);

}  // namespace trellis
