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
// The blocks never mix components (the subtrees hanging from the world, joined where a point
// constraint row links two of them): M and A are block diagonal by component and the forces
// covered here act on one coordinate each, so a direction of one
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
// Point constraint rows (kPoint) enter φ̃ as μ_cᵀ c + μᵀ(−Aᵀλ): per row r on the points a, b,
// μ_c,r e·(p̈_a − p̈_b) − λ_r e·(ψ(a) − ψ(b)), e the row's world axis, p̈ a point's acceleration and
// ψ(P) = ψ_l + ψ_ω × p_P its velocity at joint rates μ. Each point P on body j is a site of the
// terms T = F·ψ(P) + G·p̈_P (F = ∓Σ λ_r e_r, G = ±Σ μ_c,r e_r over the rows of its pair), and
// moving q_k (k ⪯ j) turns body j's chain part about S_k: δp = S_k,l + S_k,ω × p, δV_j =
// S_k × (V_j − v_λ(k)), δΨ_j likewise, δA_j = S_k × (A_j − a_λ(k)) − w × (V_j − v_λ(k)), w =
// S_k × v_λ(k); δV_j/δq̇_k = S_k, δA_j/δq̇_k = S_k × V_j − 2 w, δA_j/δq̈_k = S_k. With the site's
// adjoints T_Ψ = [F; p × F], T_A = [G; p × G], T_V = [G × ω; ṗ × G + p × (G × ω)], T_p = F × Ψ_ω
// + G × A_ω + (G × ω) × ω and (S × X)·Y = S·(X ×* Y) the gradient collapses onto subtree sums
// over the sites below k (Ω = Σ [T_p; p × T_p] + V ×* T_V + Ψ ×* T_Ψ + A ×* T_A, Θ = Σ T_V + V ×* T_A,
// ΣT_Ψ, ΣT_A):
//   ∂/∂q_k = S_k·Ω − w·Θ − (S_k × ψ_λ(k))·ΣT_Ψ − (S_k × a_λ(k))·ΣT_A + (w × v_λ(k))·ΣT_A,
//   ∂/∂q̇_k = S_k·Θ − 2 w·ΣT_A,   ∂/∂q̈_k = S_k·ΣT_A,   ∂/∂λ_r = −(±) e_r·ψ(P),
// O(1) per site and joint, and the same forward mode gives their tangents (λ seeded with the
// rows of Y = ∂[q̈; λ]/∂z). Subtrees joined by a constraint row or a tendon segment form one
// component (their q̈ and λ move together); rows to the world do not join anything.
// A tendon segment between points A, B on different bodies (tension τ = u_t, d = p_B − p_A,
// n = d/|d|) adds −τ n·E, E = ψ(A) − ψ(B): two sites with F = ∓τ n and no G, whose T_p gains
// ±τ ∂(n·E)/∂d = ±τ (E − n (n·E))/|d|; it holds no q̇, q̈ or λ, and its u gradient −n·E gives the
// (u, q) rows (the u directions themselves follow by symmetry, as before).
//
// It covers the models whose residual holds nothing but the tree's inertia, gravity, the forces
// on coordinates (configuration springs, damping, configuration forces: affine in z, so without
// second derivatives), tendons and point constraint rows: no linear spring, body wrench or other
// constraint kind. Every other model runs the recorded tape (second_order.cpp).
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
  /// comment, at (q, q̇, q̈, u, λ) with the adjoints mu (n) and muC (nc) and Y = ∂[q̈; λ]/∂z ((n + nc)×N);
  /// the (q, q̇) rows exactly the transpose of the (q̇, q) rows.
  void computeRows(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd,
                   const Eigen::VectorXd& u, const Eigen::VectorXd& lambda, const Eigen::VectorXd& mu, const Eigen::VectorXd& muC,
                   const Eigen::MatrixXd& Y, Eigen::MatrixXd& rows);

 private:
  std::unique_ptr<TreeSecondOrderImpl> impl_;
};

}  // namespace trellis::detail
