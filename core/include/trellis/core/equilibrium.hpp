// trellis/core/equilibrium.hpp — static equilibria: configurations where the system rests.
//
// Given fixed inputs u, findEquilibrium searches q with q̇ = 0 and q̈(q, 0, u) = 0 on the
// holonomic constraints, i.e. the zero of
//   F(q) = [q̈(q, 0, u); h(q)]   (n + nh equations, n unknowns; consistent at an equilibrium),
// by Gauss–Newton with the exact Jacobian ∂F/∂q = [∂q̈/∂q; A_h] from computeLinearization
// (q̈ is tangent to the constraints, so its n rows alone are rank deficient by nh; the h rows
// complete them). Steps are least squares of minimum norm (complete orthogonal decomposition),
// with a backtracking line search on ½‖F‖². Converged when every row of F is within what a
// configuration change of `tolerance` would produce, |F_i| ≤ tol · Σ_j |∂F_i/∂q_j| s_j, with s_j = 1
// for a revolute coordinate and the model's length scale for a prismatic one (modelLengthScale):
// relative to the model's own terms, so the verdict does not change with units.
// A continuum of equilibria (a free coordinate, no gravity) gives a rank-deficient ∂F/∂q: the
// step of minimum norm still converges, to the nearest one, and `isolated` is false.
//
// The converse question — which inputs hold a given pose still — is inverse dynamics at q̇ = 0,
// q̈ = 0: computeHoldingInputs.
#pragma once

#include "trellis/core/inverse_dynamics.hpp"

#include <string>

namespace trellis {

/// Options of findEquilibrium (Gauss–Newton on F(q) = [q̈(q, 0, u); h(q)] with a line search).
struct EquilibriumOptions {
  /// Relative, in (0, 1e-3]: the configuration change (radians, or model lengths) the residual
  /// F = [q̈; h] amounts to at the answer (file comment).
  double tolerance = 1e-10;
  int maxIterations = 50;    ///< Newton iterations (≥ 1)
};

enum class EquilibriumCode {
  kOk,               ///< relativeResidual ≤ tolerance at q
  kNotConverged,     ///< iteration limit, or the line search found no decrease of ‖F‖ (a local
                     ///< minimum of ‖F‖ that is not an equilibrium): q is the best iterate
  kDynamicsFailure,  ///< the forward dynamics failed at an iterate (singular M or constraints)
};

/// Names: ok, not_converged, dynamics_failure.
inline EnumNameTable<EquilibriumCode> enumNames(EquilibriumCode) {
  static constexpr EnumName<EquilibriumCode> table[] = {
      {EquilibriumCode::kOk, "ok"},
      {EquilibriumCode::kNotConverged, "not_converged"},
      {EquilibriumCode::kDynamicsFailure, "dynamics_failure"}};
  return table;
}

/// What findEquilibrium found: the equilibrium or the best iterate, the status saying which, and
/// the residuals, rank and stability at q.
struct EquilibriumResult {
  /// code, message (empty when ok; names what failed and the values); t and index unused.
  Status<EquilibriumCode> status;
  Eigen::VectorXd q;                   ///< n: the equilibrium (the best iterate if not ok)
  Eigen::VectorXd u;                   ///< m: the inputs used
  Eigen::VectorXd lambda;              ///< nc: constraint forces holding it
  int iterations = 0;                  ///< Newton iterations taken
  double accelerationResidual = 0.0;   ///< ‖q̈(q, 0, u)‖∞
  double constraintResidual = 0.0;     ///< ‖h(q)‖∞ (holonomic rows)
  /// max_i |F_i| / Σ_j |∂F_i/∂q_j| s_j: the residual as a configuration change (file comment).
  double relativeResidual = 0.0;
  int jacobianRank = 0;                ///< rank of ∂F/∂q at q
  bool isolated = true;                ///< rank = n: no continuum of equilibria through q
  /// Largest real part of the eigenvalues of the linearization on the constraint tangent space
  /// (data.reducedA) at (q, 0, u): < 0 asymptotically stable, > 0 unstable, ≈ 0 marginal (e.g. an
  /// undamped stable equilibrium, whose eigenvalues are ± i ω).
  double maxRealEigenvalue = 0.0;
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// One line: "<status>[: message] (iterations, residuals, rank, stability)".
  std::string describe() const;
  /// {"status", "ok", "message", "t": null, "index": null, "iterations", "qdd_residual",
  /// "h_residual", "relative_residual", "jacobian_rank", "isolated", "max_real_eigenvalue", "q", "u", "lambda"}.
  std::string json() const;
};

/// Searches an equilibrium from the guess q0 (n) under the inputs u (m). Uses `data` as workspace.
/// Throws std::invalid_argument on size mismatches or invalid options; failure is a status.
EquilibriumResult findEquilibrium(const Model& model, Data& data, const Eigen::VectorXd& q0,
                                  const Eigen::VectorXd& u, const EquilibriumOptions& options = {});

/// The inputs (and constraint forces) that hold the pose q still: computeInverseDynamics(q, 0, 0).
/// Status kUnreachable when no inputs can (under-actuated), with the least-squares residual.
InverseDynamicsResult computeHoldingInputs(const Model& model, Data& data, const Eigen::VectorXd& q,
                                           const InverseDynamicsOptions& options = {});

}  // namespace trellis
