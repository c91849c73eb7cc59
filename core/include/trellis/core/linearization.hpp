// trellis/core/linearization.hpp — exact linearization of ẋ = [q̇; q̈(q, q̇, u)] (paper Sec. III).
//
// With q̈ and λ from computeDynamics, the residuals
//   r(q, q̇, u) = ID(q, q̇, q̈) − Q(q, q̇, u) − A(q)ᵀ λ     (equations of motion)
//   c(q, q̇)    = A(q) q̈ + Ȧ(q, q̇) q̇                     (constraint acceleration)
// are differentiated analytically with q̈ and λ held fixed (one tangent Newton-Euler pass per
// state direction, touching only the joints a coordinate moves), and
//   [M Aᵀ; A 0] [∂q̈; −∂λ] = −[∂r; ∂c]
// is solved with the factorization already used for the dynamics (docs/paper_errata.md: this is the paper's
// ∂q̈/∂q, ∂q̈/∂q̇, ∂q̈/∂u, ∂λ/∂· written without expanding the inverse).
#pragma once

#include "trellis/core/data.hpp"

namespace trellis {

/// data.A = [[0, I], [∂q̈/∂q, ∂q̈/∂q̇]] (2n×2n), data.B = [[0], [∂q̈/∂u]] (2n×m), plus the blocks
/// dqdd_dq, dqdd_ddq, dqdd_du, dlambda_dx, and everything computeDynamics computes.
/// Returns the status of the KKT solve (also in data.status); A, B are valid when status.ok().
DynamicsStatus computeLinearization(const Model& model, Data& data, const Eigen::VectorXd& q,
                                    const Eigen::VectorXd& dq, const Eigen::VectorXd& u);

/// The equations of motion as residuals at a GIVEN acceleration and constraint force (the implicit
/// form a direct transcription imposes when q̈ and λ are its own variables):
///   r(q, q̇, q̈, u, λ) = M(q) q̈ + b(q, q̇, u) − A(q)ᵀ λ   (n; b = ID(q, q̇, 0) − Q(q, q̇, u) = data.bias)
///   c(q, q̇, q̈)       = A(q) q̈ + Ȧ(q, q̇) q̇            (nc; Ȧ q̇ = data.constraintDrift)
/// and their exact first derivatives by the same tangent passes as computeLinearization, here at
/// (q̈, λ) as given instead of the forward solution (no KKT solve). The other blocks are data
/// members: ∂r/∂q̈ = data.M, ∂r/∂u = −data.inputMatrix, ∂r/∂λ = −Aᵀ, ∂c/∂q̈ = A
/// (data.constraintJacobian); ∂c/∂u = ∂c/∂λ = 0. r and c are linear in (q̈, u, λ).
struct ImplicitDynamics {
  Eigen::VectorXd r;      ///< n: the equations' residual [N, N m]
  Eigen::VectorXd c;      ///< nc: the constraint acceleration's residual
  Eigen::MatrixXd dr_dx;  ///< n×2n: ∂r/∂[q; q̇] at fixed q̈, u, λ
  Eigen::MatrixXd dc_dx;  ///< nc×2n: ∂c/∂[q; q̇] at fixed q̈
  ImplicitDynamics() = default;
  explicit ImplicitDynamics(const Model& model);  ///< sized for `model`
};

/// Fills `out` (sized for the model) and data.M, bias, inputMatrix, constraintJacobian,
/// constraintDrift, constraintValue, constraintVelocityJacobian at (q, q̇, u); data.qdd and
/// data.lambda are set to the given qdd and lambda (not a forward solution). Allocation-free.
/// Throws std::invalid_argument on sizes; a non-finite input or result is the status kNonFinite
/// naming it.
DynamicsStatus computeImplicitDynamics(const Model& model, Data& data, const Eigen::VectorXd& q,
                                       const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd,
                                       const Eigen::VectorXd& u, const Eigen::VectorXd& lambda,
                                       ImplicitDynamics& out);

/// Orthonormal basis T (data.tangentBasis, 2n×d) of the tangent space at x = [q; q̇] of the
/// constraint manifold {h(q) = 0, A(q) q̇ = 0} — the null space of ∂Φ/∂x, Φ = [h; A q̇] (holonomic
/// rows in both, nonholonomic rows only in A q̇) — and the linearization on it,
/// data.reducedA = Tᵀ A T, data.reducedB = Tᵀ B. Requires computeLinearization at the same state.
/// Returns d = 2n − rank(∂Φ/∂x). Without constraints T = I.
int computeConstraintTangentBasis(const Model& model, Data& data);

}  // namespace trellis
