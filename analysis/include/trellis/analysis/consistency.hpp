// trellis/analysis/consistency.hpp — is a trajectory file something the plant can follow?
//
// A-posteriori check of any trajectory (an optimizer's output, a hand-made CSV): for every
// interval [t_k, t_{k+1}] the exact dynamics ẋ = f(x, u(t)) (the core's computeDynamics) are
// integrated with CVODES at a tight tolerance from the knot state x_k, under the input as every
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
#pragma once

#include "trellis/core/trajectory.hpp"

#include <Eigen/Core>

#include <string>

namespace trellis {

class Model;

/// Options of checkConsistency: the verdict's tolerance and the integrator's settings.
struct ConsistencyOptions {
  double tolerance = 1e-3;   ///< a trajectory is consistent when maxDefect ≤ tolerance
  double rtol = 1e-10;       ///< CVODES relative tolerance (Adams, fixed-point iteration)
  double atolFraction = 1e-10;  ///< CVODES absolute tolerance, per component: atolFraction · s_i
  double rangeFloor = 1e-2;  ///< see the file comment
  long maxStepsPerInterval = 100000;  ///< CVODES steps per knot interval (> 0); more fails that interval

  /// Throws std::invalid_argument naming the bad field.
  void validate() const;
};

/// The verdict of checkConsistency: how far the exact dynamics, integrated from each knot over its
/// interval, land from the trajectory's own state (relative defects; the file comment defines them).
struct ConsistencyResult {
  bool integrated = false;   ///< every interval was integrated (else `message` says where it failed)
  bool consistent = false;   ///< integrated and maxDefect ≤ options.tolerance
  double tolerance = 0.0;    ///< the tolerance used
  double maxDefect = 0.0;    ///< worst relative defect (see the file comment)
  int worstInterval = -1;    ///< interval k of the worst defect
  double worstTime = 0.0;    ///< where it was measured: t_{k+1} or the interval's midpoint
  bool worstAtMidpoint = false;  ///< whether worstTime is the interval's midpoint (else its end)
  int worstState = -1;       ///< component i of x = [q; q̇]
  std::string worstStateName;  ///< its name ("theta", "dtheta")
  Eigen::VectorXd intervalDefects;  ///< N − 1: each interval's relative defect
  Eigen::VectorXd stateScale;       ///< 2n: s_i
  ///@{
  /// CVODES totals over all intervals: internal steps and right-hand-side evaluations.
  long steps = 0, rhsEvaluations = 0;
  ///@}
  std::string message;       ///< one line for a person: the verdict and where
};

/// Checks `trajectory` against the exact dynamics of `model` (names and sizes must match:
/// throws TrajectoryError otherwise, std::invalid_argument for bad options). A failure of the
/// dynamics or of CVODES inside an interval is reported in the result (integrated = false, the
/// interval and time in the message), never thrown.
ConsistencyResult checkConsistency(const Model& model, const Trajectory& trajectory,
                                   const ConsistencyOptions& options = {});

}  // namespace trellis
