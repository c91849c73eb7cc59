// constraint_drift.hpp (private) — the simulator's constraint drift d(x) = max(|h(q)|∞, |A(q) q̇|∞)
// and its projection back onto h = 0, A q̇ = 0 (core's projectState, feasibility only).
#pragma once

#include "trellis/analysis/simulation.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/projection.hpp"

#include <Eigen/Core>

namespace trellis::detail {

class ConstraintDrift {
 public:
  /// maxIterations: Newton steps per position restoration (SimulationOptions::projectionIterations).
  ConstraintDrift(const Model& model, int maxIterations);

  /// d(x) (0 without constraints; +inf if not finite).
  double drift(const Eigen::VectorXd& x);

  /// Projects x in place. driftBefore/After from projectState's residuals; converged is its status
  /// kOk. A non-finite projection leaves x at the last finite iterate and driftAfter = +inf.
  ConstraintProjection project(Eigen::VectorXd& x);

 private:
  const Model& model_;
  Data data_;
  ProjectionOptions options_;
  int n_;
  Eigen::VectorXd q_, dq_, r_;
};

}  // namespace trellis::detail
