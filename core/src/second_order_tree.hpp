// Internal: the second-order contraction of a joint tree by forward mode over the closed-form
// gradient of the linearization (second_order.cpp chooses it per model). Not installed.
//
// For φ̃(z, y) = μᵀ r(z, y) (r = ID(q, q̇, q̈) − Q(q, q̇, u), the residual of linearization.hpp)
// the linearization's tangent pass gives each column of −∂r/∂z_k in closed form, O(1) per joint
// pair with composite subtree sums. Contracted with μ those columns collapse to O(1) per k:
//   g_k = −∂φ̃/∂z_k = Σ_j μ_j (−∂r_j/∂z_k) = coef_k · Σ_{j∈sub(k)} μ_j [β_j; γ_j] − ψ_{λ(k)} · δF_k,
// ψ_i = Σ_{j⪯i} μ_j S_j (the twist of body i at joint rates μ), β, γ, coef and δF_k as in
// linearization.cpp (tangentPass, compositePass), and ∂φ̃/∂q̈ = M μ with
// (M μ)_k = S_k · (Ic_k ψ_{λ(k)} + Σ_{j∈sub(k)} μ_j Ic_j S_j). So the whole gradient of φ̃ costs
// O(n). Running that O(n) pass in forward mode — numbers carrying L tangents at once, seeded with
// (e_a, Y e_a) for L directions a of q or q̇ — gives the rows of the contraction's Hessian
//   ∇²φ e_a = −ġ_z + Yᵀ (d/dε M μ),  φ(z') = φ̃(z', y + Y (z' − z)),
// exactly (no step), in O(n) per block of directions: O(n²) for all 2n, like one linearization.
//
// The blocks never mix components (the subtrees hanging from the world): M is block diagonal by
// component and the forces covered here act on one coordinate each, so a direction of one
// component moves nothing in another (its Y entries there are zero), and a block runs over the
// joints of its own component only (a hand of five fingers: five blocks of 4 lanes over 4 joints
// each, not 16 lanes over all 20 joints).
// The q and the q̇ directions run in blocks of their own (16 lanes, the last 4, 8, 12 or 16). The
// kinematics, inertias, ψ and M μ do not depend on q̇, and −∂r/∂q̇ holds no q̈, so a q̇ block carries
// tangents only on twists and momenta and gives the (q̇, q̇) rows; the (q, q̇) rows are the
// transpose of the q blocks' (q̇, q) rows (∇²φ is symmetric), the (u, q̇) rows are zero. In a q
// block, a joint none of whose ancestors (nor itself) is one of the block's directions keeps the
// plain values of its pose, twist and inertia (one plain pass per call computes them), and where
// no joint of a subtree moves, only its inertial forces carry tangents (through q̈) inwards.
//
// It covers the models whose residual holds nothing but the tree's inertia, gravity and the
// forces on coordinates (configuration springs, damping, configuration forces: affine in z, so
// without second derivatives): no linear spring, tendon, body wrench or constraint row. Every
// other model runs the recorded tape (second_order.cpp).
#pragma once

#include "trellis/core/second_order.hpp"

#include <Eigen/Core>

#include <memory>

namespace trellis::detail {

/// Whether the tree pass covers this model (see the file comment).
bool treeSecondOrderApplies(const Model& model);

/// Tests: build later workspaces with the tape even where the tree pass applies (true), or back to
/// the automatic choice (false).
void secondOrderForceTape(bool force);
/// The current setting of secondOrderForceTape.
bool secondOrderTapeForced();
/// Whether this workspace's contraction runs the tree pass (else the recorded tape).
bool secondOrderUsesTreePath(const SecondOrderWorkspace& ws);

struct TreeSecondOrderImpl;

/// The buffers of the tree pass for one model (sized once; allocation-free afterwards).
class TreeSecondOrder {
 public:
  explicit TreeSecondOrder(const Model& model);
  ~TreeSecondOrder();
  TreeSecondOrder(TreeSecondOrder&&) noexcept;
  TreeSecondOrder& operator=(TreeSecondOrder&&) noexcept;

  /// rows (N×2n, N = 2n + m) ← ∇²φ e_a for the q and q̇ directions a = 0 … 2n − 1, φ as in the file
  /// comment, at (q, q̇, q̈) with the adjoint mu (n) and Y = ∂q̈/∂z (n×N); the (q, q̇) rows exactly
  /// the transpose of the (q̇, q) rows.
  void computeRows(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd,
                   const Eigen::VectorXd& mu, const Eigen::MatrixXd& Y, Eigen::MatrixXd& rows);

 private:
  std::unique_ptr<TreeSecondOrderImpl> impl_;
};

}  // namespace trellis::detail
