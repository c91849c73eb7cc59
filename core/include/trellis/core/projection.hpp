// trellis/core/projection.hpp — projection of a state x = [q; q̇] onto the constraint manifold
// {h(q) = 0, A(q) q̇ = 0} in the metric of the mass matrix (the one projection of the project;
// the simulator's drift correction and the hand's reference motion use it).
//
// Positions: q* is the point of {h = 0} closest to the given q0 in the kinetic-energy metric
// W = M(q0),  min ½ (q − q0)ᵀ W (q − q0)  s.t.  h(q) = 0  (holonomic rows only). First restoration,
// minimum-W-norm Newton steps q ← q − W⁻¹Aᵀ (A W⁻¹ Aᵀ)⁺ h(q) (quadratic convergence near the
// manifold); then descent along the manifold: d = −(I − W⁻¹Aᵀ (A W⁻¹ Aᵀ)⁺ A)(q − q0), the
// W-orthogonal tangent component of the displacement, each trial point restored onto h = 0 and
// accepted when the distance decreases (halved otherwise). d = 0 exactly where W (q − q0) = Aᵀ ν,
// the first-order conditions of the closest point. (The plain Gauss–Newton iteration on the KKT
// conditions, which ignores the curvature of h, oscillates when q0 is far from the manifold.)
// Velocities: q̇* = q̇ − W*⁻¹ Aᵀ (A W*⁻¹ Aᵀ)⁺ A q̇ over all rows (holonomic and nonholonomic) with
// W* = M(q*): the velocity change of a constraint impulse, the correction of least kinetic energy.
// Pseudo-inverses go through a complete orthogonal decomposition of A L⁻ᵀ (W = L Lᵀ), so redundant
// rows are handled. Weighting by M makes the result independent of the units of the coordinates;
// where M is not positive definite (a coordinate that moves no mass) the Euclidean metric is used
// and the result says so. Coordinates listed in `fixed` keep their value and velocity; the others
// move (the metric restricted to them).
#pragma once

#include "trellis/core/data.hpp"

#include <limits>
#include <string>
#include <vector>

namespace trellis {

/// Options of projectToConstraints: tolerances, iteration limit, held coordinates.
struct ProjectionOptions {
  /// Positions count as on the manifold when |h(q)|∞ ≤ tolerance (units of h; a distance
  /// constraint's h is a squared length). > 0.
  double tolerance = 1e-12;
  /// The closest-point condition: converged when the descent direction has
  /// ‖d‖∞ ≤ stepTolerance · (1 + ‖q‖∞). +infinity: feasibility only (the restoration's point).
  double stepTolerance = 1e-10;
  int maxIterations = 50;  ///< restoration steps per restoration, and descent steps (≥ 1)
  std::vector<int> fixed;  ///< indices of coordinates held at their given q and q̇
  bool velocities = true;  ///< also project q̇ onto A(q*) q̇ = 0
  /// Throws std::invalid_argument naming the field and value.
  void validate(const Model& model) const;
};

enum class ProjectionCode {
  kOk,            ///< |h(q*)|∞ ≤ tolerance, the step test passed, and (velocities) each row
                  ///< |(A q̇*)_r| ≤ 1e-9 Σ_j |A_rj| (|q̇*_j| + |q̇0_j|) (checked: kNotConverged if not)
  kNotConverged,  ///< maxIterations reached (or the constraints cannot be met, e.g. out of reach):
                  ///< q, dq are the last iterate, the residuals say how far off
  kNonFinite,     ///< h, A or M became NaN/Inf; q, dq are the last finite iterate
};

/// Names: ok, not_converged, non_finite.
inline EnumNameTable<ProjectionCode> enumNames(ProjectionCode) {
  static constexpr EnumName<ProjectionCode> table[] = {
      {ProjectionCode::kOk, "ok"},
      {ProjectionCode::kNotConverged, "not_converged"},
      {ProjectionCode::kNonFinite, "non_finite"}};
  return table;
}

/// The projected state (q*, q̇*): the mass-weighted closest point on h = 0 and A q̇ = 0, with the
/// status and the residuals before and after.
struct ProjectionResult {
  /// code, message (empty when ok; names what failed and the values); t and index unused.
  Status<ProjectionCode> status;
  ///@{
  /// The projected state (n each; the last iterate when not ok).
  Eigen::VectorXd q, dq;
  ///@}
  int iterations = 0;                ///< restoration (Newton) steps taken in all
  double positionResidualBefore = 0; ///< |h(q0)|∞ over the holonomic rows
  double positionResidual = 0;       ///< |h(q*)|∞
  double velocityResidualBefore = 0; ///< |A(q0) q̇0|∞ over all rows
  double velocityResidual = 0;       ///< |A(q*) q̇*|∞
  double lastStep = 0;               ///< ‖Δq‖∞ of the last accepted descent step
  bool massWeighted = true;          ///< false: M was not positive definite, Euclidean metric used
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// One line: "<status>[: message] (iterations, residuals before and after)".
  std::string describe() const;
  /// {"status", "ok", "message", "t": null, "index": null, "iterations", "h_before", "h_after",
  /// "velocity_before", "velocity_after", "last_step", "mass_weighted", "q", "dq"}.
  std::string json() const;
};

/// Projects (q, dq) (n each) onto the constraints (see the file comment). Without constraints the
/// state is returned unchanged with status kOk. Uses `data` as workspace. Throws
/// std::invalid_argument on size mismatches or invalid options; numerical failure is a status.
ProjectionResult projectState(const Model& model, Data& data, const Eigen::VectorXd& q,
                              const Eigen::VectorXd& dq, const ProjectionOptions& options = {});

}  // namespace trellis
