// trellis/analysis/consistency.hpp — is a trajectory file something the plant can follow?
//
// A-posteriori check of any trajectory (an optimizer's output, a hand-made CSV): for every
// interval [t_k, t_{k+1}] the exact dynamics ẋ = f(x, u(t)) (the core's computeDynamics) are
// integrated at a tight tolerance from the knot state x_k, under the input as every
// trellis tool reads a trajectory (trajectory.hpp: linear between knots, or the cubic Hermite
// spline through (u_k, u̇_k) when the trajectory carries input derivatives), and compared with
//  - the next knot:           e_end = x(t_{k+1}) − x_{k+1},
//  - the reference in between: e_mid = x(t_mid) − x_ref(t_mid) at the interval's midpoint, where
//    x_ref is the cubic Hermite spline that `gains` and `simulate` use as the reference.
// Each component i is divided by the state's scale s_i = max(range_i, rangeFloor · R_block,
// 1e-12), range_i = max_k x_ik − min_k x_ik and R_block the largest range among the
// configurations (for i < n) or among the velocities (i ≥ n): the defect is "a fraction of how
// far that state moves", and a state that barely moves is measured against its block's motion.
// The interval's defect is max_i over both points; the trajectory's is the worst interval.
//
// The integrator (ConsistencyOptions::method): Radau IIA with the exact Jacobian by default — a
// one-step method of order 5 that restarts at each knot without starting over, where the Adams
// method (the earlier default) restarts at order 1 and, on a stiff model, is held to steps below
// its stability limit. Measured on the hand turning the ball (201 knots, 26 coordinates, fast
// finger modes to −6 000 s⁻¹) at rtol 1e-10: Adams 18 500 steps and 30 100 right-hand sides,
// Radau 440 steps, 3 230 right-hand sides and 144 Jacobians (0.72 → 0.37 s for the stage that
// runs it), the worst defect 3.2353e-6 against 3.2395e-6 (the converged value, Adams and BDF at
// rtol 1e-12 and Radau at 1e-13: 3.2351e-6 — Radau's rtol bounds its third-order companion, so
// its error at the same rtol is larger, here 0.14 % of the defect and 4e-9 of the range).
#pragma once

#include "trellis/analysis/simulation.hpp"

#include "trellis/core/status.hpp"
#include "trellis/core/trajectory.hpp"

#include <Eigen/Core>

#include <string>

namespace trellis {

class Model;

/// Options of checkConsistency: the verdict's tolerance and the integrator's settings.
struct ConsistencyOptions {
  double tolerance = 1e-3;   ///< a trajectory is consistent when maxDefect ≤ tolerance
  double rtol = 1e-10;       ///< the integrator's relative tolerance
  double atolFraction = 1e-10;  ///< its absolute tolerance, per component: atolFraction · s_i
  double rangeFloor = 1e-2;  ///< see the file comment
  long maxStepsPerInterval = 100000;  ///< integrator steps per knot interval (> 0); more fails that interval
  /// kRadau (the exact Jacobian; file comment), kAdams (fixed-point iteration, no Jacobian) or
  /// kBDF (Newton with the exact Jacobian).
  IntegrationMethod method = IntegrationMethod::kRadau;

  /// Throws std::invalid_argument naming the bad field.
  void validate() const;
};

/// Outcome codes of checkConsistency (status.index: the interval or knot, status.t: the time).
enum class ConsistencyCode {
  kOk,                ///< consistent: every interval integrated and maxDefect ≤ tolerance
  kInconsistent,      ///< integrated, but maxDefect > tolerance (index, t: the worst interval, point)
  kDynamicsFailure,   ///< the dynamics fail at a knot (index: the knot): nothing was integrated
  kIntegratorFailure, ///< the integrator stopped inside an interval (index: the interval, t: where)
  kNotChecked,        ///< default-constructed: no check ran
};

/// Names: ok, inconsistent, dynamics_failure, integrator_failure, not_checked.
inline EnumNameTable<ConsistencyCode> enumNames(ConsistencyCode) {
  static constexpr EnumName<ConsistencyCode> table[] = {
      {ConsistencyCode::kOk, "ok"},
      {ConsistencyCode::kInconsistent, "inconsistent"},
      {ConsistencyCode::kDynamicsFailure, "dynamics_failure"},
      {ConsistencyCode::kIntegratorFailure, "integrator_failure"},
      {ConsistencyCode::kNotChecked, "not_checked"}};
  return table;
}

/// The verdict of checkConsistency: how far the exact dynamics, integrated from each knot over its
/// interval, land from the trajectory's own state (relative defects; the file comment defines them).
struct ConsistencyResult {
  /// ok: consistent; inconsistent: the worst interval and point; otherwise why it was not checked.
  /// The message is one line for a person: the verdict and where.
  Status<ConsistencyCode> status{ConsistencyCode::kNotChecked, "not checked"};
  double tolerance = 0.0;    ///< the tolerance used
  double maxDefect = 0.0;    ///< worst relative defect (see the file comment); set when checked()
  int worstInterval = -1;    ///< interval k of the worst defect
  double worstTime = 0.0;    ///< where it was measured: t_{k+1} or the interval's midpoint
  bool worstAtMidpoint = false;  ///< whether worstTime is the interval's midpoint (else its end)
  int worstState = -1;       ///< component i of x = [q; q̇]
  std::string worstStateName;  ///< its name ("theta", "dtheta")
  Eigen::VectorXd intervalDefects;  ///< N − 1: each interval's relative defect
  Eigen::VectorXd stateScale;       ///< 2n: s_i
  ///@{
  /// The integrator's totals over all intervals: steps, right-hand sides and Jacobians.
  long steps = 0, rhsEvaluations = 0, jacobianEvaluations = 0;
  ///@}

  bool ok() const { return status.ok(); }  ///< status.ok(): consistent
  /// Every interval was integrated, so maxDefect and intervalDefects are measured (ok or
  /// inconsistent).
  bool checked() const {
    return status.code == ConsistencyCode::kOk || status.code == ConsistencyCode::kInconsistent;
  }
  /// One line: Status::describe (the verdict, with the interval and time).
  std::string describe() const;
  /// One JSON object: status fields, tolerance, max_defect (null unless checked), the worst
  /// interval, time, state, and the integrator's totals.
  std::string json() const;
};

/// Checks `trajectory` against the exact dynamics of `model` (names and sizes must match:
/// throws TrajectoryError otherwise, std::invalid_argument for bad options). A failure of the
/// dynamics at a knot or of the integrator inside an interval is the result's status (the knot or the
/// interval, and the time), never thrown.
ConsistencyResult checkConsistency(const Model& model, const Trajectory& trajectory,
                                   const ConsistencyOptions& options = {});

}  // namespace trellis
