// trellis/core/inverse_dynamics.hpp — the inputs (and constraint forces) that produce a given
// acceleration: solve the equations of motion for u and λ instead of q̈.
//
// The generalized forces are affine in the inputs, Q(q, q̇, u) = Q(q, q̇, 0) + B_u(q) u with
// B_u = ∂Q/∂u (data.inputMatrix), so the equations of motion at a given (q, q̇, q̈) read
//   B_u u + Aᵀ λ = r,   r = M(q) q̈ + b(q, q̇),   b = ID(q, q̇, 0) − Q(q, q̇, 0)   (n equations),
// linear in z = [u; λ] (m + nc unknowns). z is the least-squares solution of minimum norm
// (complete orthogonal decomposition of G = [B_u  Aᵀ]): exact when q̈ is reachable (fully actuated,
// or an under-actuated system along a feasible motion), otherwise the residual G z − r reports by
// how much the equations miss (it is orthogonal to every column of G). The acceleration must
// also satisfy the constraints, A q̈ + Ȧ q̇ = 0; its residual is reported and checked.
// The inputs that hold a pose still are computeInverseDynamics(q, 0, 0) (see equilibrium.hpp).
#pragma once

#include "trellis/core/data.hpp"

#include <string>

namespace trellis {

/// Options of computeInverseDynamics: the exactness test's tolerance and optional input bounds.
struct InverseDynamicsOptions {
  /// Exact when every row i of the residual, r = M q̈ + b with b = ID(q, q̇, 0) − Q_cfg, satisfies
  /// |(G z − r)_i| ≤ tolerance · (Σ_j |M_ij q̈_j| + |ID_i| + |Q_cfg,i| + Σ_j |G_ij z_j|), and each
  /// constraint row |(A q̈ + Ȧ q̇)_k| ≤ tolerance · (Σ_j |A_kj q̈_j| + |(Ȧ q̇)_k|): relative to the
  /// terms compared, with no absolute floor, so scaling the model's units keeps the verdict.
  /// In (0, 0.1]; larger would accept answers off by more than a tenth of the terms.
  double tolerance = 1e-9;
  /// Optional input bounds: empty (unbounded) or m entries each (±infinity allowed, lower ≤ upper).
  /// With bounds, u is the bounded least-squares solution (an active set on the bounds: inputs
  /// that would leave their interval are held at the bound and the others re-solved, until the
  /// held ones satisfy the optimality sign conditions); λ stays free.
  ///@{
  /// The bounds [N, N m or the inputs' units]: empty, or m entries each (see above).
  Eigen::VectorXd lowerBound, upperBound;
  ///@}
};

enum class InverseDynamicsCode {
  kOk,                      ///< u, λ reproduce q̈ exactly (to tolerance)
  kUnreachable,             ///< no u, λ give this q̈ (under-actuated): least squares, see residual
  kInadmissibleAcceleration,///< q̈ violates A q̈ + Ȧ q̇ = 0; u, λ are still the least squares
  kInputBounds,             ///< q̈ needs inputs outside their bounds: u is the bounded least squares,
                            ///< the message names the input, its bound and by how much the unbounded
                            ///< answer exceeds it (see boundExcess)
  kNonFinite,               ///< an input or a result is NaN/Inf
};

/// Names: ok, unreachable, inadmissible_acceleration, input_bounds, non_finite.
inline EnumNameTable<InverseDynamicsCode> enumNames(InverseDynamicsCode) {
  static constexpr EnumName<InverseDynamicsCode> table[] = {
      {InverseDynamicsCode::kOk, "ok"},
      {InverseDynamicsCode::kUnreachable, "unreachable"},
      {InverseDynamicsCode::kInadmissibleAcceleration, "inadmissible_acceleration"},
      {InverseDynamicsCode::kInputBounds, "input_bounds"},
      {InverseDynamicsCode::kNonFinite, "non_finite"}};
  return table;
}

/// The inputs u and constraint forces λ that give the accelerations asked for, M q̈ = Q(q, q̇, u) + Aᵀλ
/// (least squares over [B_u Aᵀ] when that is not possible exactly), and how well they do.
struct InverseDynamicsResult {
  /// code, message (empty when ok; names what failed and the values); t and index unused.
  Status<InverseDynamicsCode> status;
  Eigen::VectorXd u;                ///< m inputs
  Eigen::VectorXd lambda;           ///< nc constraint forces (M q̈ = … + Aᵀ λ)
  Eigen::VectorXd residual;         ///< n: G z − r (generalized forces; 0 when reachable)
  double residualNorm = 0.0;        ///< ‖residual‖∞
  double constraintResidual = 0.0;  ///< ‖A q̈ + Ȧ q̇‖∞
  int rank = 0;                     ///< numerical rank of G = [B_u  Aᵀ]
  bool unique = true;               ///< rank = m + nc: u and λ are determined (else minimum norm)
  /// With bounds: by how much the unbounded answer exceeds each input's interval (m; 0 inside).
  Eigen::VectorXd boundExcess;
  int boundIterations = 0;          ///< active-set iterations (0: the unbounded answer was feasible)
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// One line: "<status>[: message] (residuals, rank)".
  std::string describe() const;
  /// {"status", "ok", "message", "t": null, "index": null, "residual", "constraint_residual",
  /// "rank", "unique", "bound_iterations", "u", "lambda", "bound_excess"}.
  std::string json() const;
};

/// u and λ for the acceleration qdd at (q, dq) (n-vectors each). Uses `data` as workspace (its
/// M, bias, inputMatrix and constraint members are left at (q, dq)). Throws std::invalid_argument
/// on a size mismatch; numerical outcomes are a status.
InverseDynamicsResult computeInverseDynamics(const Model& model, Data& data, const Eigen::VectorXd& q,
                                             const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd,
                                             const InverseDynamicsOptions& options = {});

}  // namespace trellis
