// trellis/core/second_order.hpp — exact second derivatives of the constrained dynamics (issue 30).
//
// q̈ = f(q, q̇, u) and λ(q, q̇, u) are defined by F(z, y) = 0, z = [q; q̇; u] (N = 2n + m entries),
// y = [q̈; λ], with the residuals of linearization.hpp:
//   r(z, y) = ID(q, q̇, q̈) − Q(q, q̇, u) − A(q)ᵀ λ,    c(z, y) = A(q) q̈ + Ȧ(q, q̇) q̇,
// and K = ∂F/∂y = [M −Aᵀ; A 0]. Differentiating F(z, y(z)) = 0 twice along directions a, b:
//   K y_zz[a, b] = −G[a, b],   G[a, b] = ∂²/∂s∂t F(z + s a + t b, y + s Y a + t Y b) at s = t = 0,
// with Y = y_z the exact first derivatives (computeLinearization). G holds F_zz[a, b] and the two
// cross terms F_zy[a, Y b] + F_zy[b, Y a] (F is linear in y, so F_yy = 0).
//
// Both forms evaluate the residual's recursive Newton-Euler pass over the joint tree (kinematics
// from the world outwards, the wrenches of every force element and of the constraint forces at
// fixed λ, subtree sums inwards, forces on coordinates, constraint accelerations) in a
// differentiating arithmetic; no step, no symbolic expression, exact to rounding.
//  - Tensors: one pass in hyper-dual numbers (x + x_s ε1 + x_t ε2 + x_st ε1ε2) per pair (a, b)
//    gives G[a, b] as the ε1ε2 part, then one KKT solve per pair: O(N² n) with N = 2n + m.
//  - Contraction with weights w (on q̈) and ρ (on λ): one transposed KKT solve μ = K⁻ᵀ [w; ρ]
//    turns it into the Hessian of one scalar, Σᵢ wᵢ ∇²q̈ᵢ + Σ_r ρ_r ∇²λ_r = −∇²φ,
//    φ(z') = μᵀ F(z', y + Y (z' − z)), computed forward-over-reverse: the pass is recorded as
//    elementary operations (one node per operation, with its partials; constants folded), one
//    reverse sweep gives φ's adjoints, and per q or q̇ direction a, a tangent sweep and a second
//    reverse sweep give the row ∇²φ e_a = x̄̇_z + Yᵀ x̄̇_y. No tensor is formed. The 2n directions
//    run in blocks of up to 16 through the same two sweeps (node-major lane arrays: a node's
//    partials are read once per block, the lanes are SIMD vectors; the AVX2+FMA build of the
//    sweeps is chosen at run time when the CPU has it, the baseline build otherwise), and the
//    second-order sweep adds, per node, only the second partial its kind has (none for sums and
//    scalings, ∂²/∂x_i∂x_j for a product, g'' for sin, cos, sqrt, 1/x).
//    Cost: O(n · pass) like the 2n separate sweeps it replaces: the recording, one reverse sweep
//    and 2 sweeps per block of 16 directions, each over every node of the recording (some 330
//    per joint of a 3D chain), plus the linearization it needs for Y.
//  - Contraction on a joint tree (chosen per model when the workspace is built, where the residual
//    holds only the tree's inertia, gravity, forces on coordinates — configuration springs,
//    damping, configuration forces — tendons and point constraint rows: no linear spring, body
//    wrench or other constraint kind):
//    the same rows, by forward mode over the closed-form gradient of φ instead of the recording.
//    The linearization's tangents (O(1) per joint pair with composite subtree sums) contracted
//    with μ give ∂φ/∂z in O(n), and ∂φ/∂q̈ = M μ also; that O(n) pass run on numbers that carry
//    16 tangents (seeded with e_a and Y e_a) gives 16 rows ∇²φ e_a = ∂_a(∇_z φ) + Yᵀ ∂_a(M μ).
//    O(n) per block of 16 directions over spatial quantities (6-vectors, 3×3 inertias), not
//    scalar nodes (core/src/second_order_tree.hpp); a block holds directions of one subtree
//    hanging from the world and runs over that subtree's joints only; q̇ directions carry tangents
//    only on twists and momenta, and what a block of q directions does not move keeps its plain
//    values; point rows and tendon segments enter as sites on their bodies, summed inwards.
//    Callgrind, instructions per call against one exact linearization (docs/performance.md,
//    2026-12-03): tree pass: planar 10-chain 3.54×, 3D 40-chain 3.84×, hand-like tree (n = 20)
//    2.53×, the same with a fingertip pinned (3 point rows) 2.31×, hand scene (23 tendons, 15
//    point rows) 1.79× (the recording on the same models: 5.8×, 14×, 15×, 12.9×, 10.0×). Models
//    with linear springs, body wrenches or other constraint kinds run the recording.
// Every input enters F linearly (configuration forces, body wrench entries, tendon tensions) and K
// does not depend on u, so G[e_uj, e_uk] = 0 and ∂²q̈/∂u∂u = 0 exactly: those pairs (and, in the
// contraction, the u directions, which follow by symmetry) are not evaluated.
//
// Allocation-free after the workspace is built (tests/core/no_malloc covers it).
#pragma once

#include "trellis/core/data.hpp"

#include <Eigen/Core>

#include <memory>
#include <vector>

namespace trellis {

namespace detail {
struct SecondOrderImpl;  // hyper-dual buffers and the KKT factors (core/src/second_order.cpp)
}  // namespace detail

/// Buffers and results of the second-order functions for one model (sized here, once; one per
/// thread, beside a Data of the same model).
class SecondOrderWorkspace {
 public:
  /// Sizes every buffer; `withTensors` also allocates the full tensors (n + nc matrices N×N);
  /// `recording` builds the recorded residual pass even where the tree pass applies
  /// (computeImplicitSecondOrder needs it).
  explicit SecondOrderWorkspace(const Model& model, bool withTensors = true, bool recording = false);
  ~SecondOrderWorkspace();
  ///@{
  /// Movable (the buffers move with it), not copyable.
  SecondOrderWorkspace(SecondOrderWorkspace&&) noexcept;
  SecondOrderWorkspace& operator=(SecondOrderWorkspace&&) noexcept;
  ///@}

  // ---- Results of computeSecondOrderTensors --------------------------------------------------
  /// n matrices N×N (N = 2n + m, z = [q; q̇; u]): qddHessian[i](a, b) = ∂²q̈ᵢ/∂z_a∂z_b (symmetric).
  std::vector<Eigen::MatrixXd> qddHessian;
  /// nc matrices N×N: ∂²λ_r/∂z_a∂z_b (with redundant constraints: of the minimum-norm λ).
  std::vector<Eigen::MatrixXd> lambdaHessian;

  /// The six blocks of the issue, output index first, each as a vector of n matrices:
  /// d2qdd_dqdq[i](j, k) = ∂²q̈ᵢ/∂q_j∂q_k (n×n), d2qdd_dqddq (∂q_j ∂q̇_k, n×n), d2qdd_ddqddq
  /// (∂q̇_j ∂q̇_k, n×n), d2qdd_dudq (∂u_j ∂q_k, m×n), d2qdd_duddq (∂u_j ∂q̇_k, m×n), d2qdd_dudu
  /// (∂u_j ∂u_k, m×m). Copies of blocks of qddHessian (allocates; for output, not hot paths).
  enum class Block { kQQ, kQDq, kDqDq, kUQ, kUDq, kUU };
  /// The n matrices of one block (above), copied out of qddHessian (none when the workspace was
  /// made without tensors).
  std::vector<Eigen::MatrixXd> qddBlock(Block block) const;

  int n() const { return n_; }    ///< configuration variables of the model
  int m() const { return m_; }    ///< inputs
  int nc() const { return nc_; }  ///< constraint rows
  bool hasTensors() const { return withTensors_; }  ///< made with withTensors (the full Hessians allocated)

 private:
  friend struct detail::SecondOrderImpl;
  friend DynamicsStatus computeSecondOrderTensors(const Model&, Data&, SecondOrderWorkspace&,
                                                  const Eigen::VectorXd&, const Eigen::VectorXd&,
                                                  const Eigen::VectorXd&);
  friend DynamicsStatus computeImplicitSecondOrder(const Model&, Data&, SecondOrderWorkspace&, const Eigen::VectorXd&,
                                                   const Eigen::VectorXd&, const Eigen::VectorXd&,
                                                   const Eigen::VectorXd&, const Eigen::VectorXd&,
                                                   const Eigen::VectorXd&, const Eigen::VectorXd&,
                                                   Eigen::Ref<Eigen::MatrixXd>, Eigen::Ref<Eigen::MatrixXd>);
  friend DynamicsStatus computeSecondOrderContraction(const Model&, Data&, SecondOrderWorkspace&,
                                                      const Eigen::VectorXd&, const Eigen::VectorXd&,
                                                      const Eigen::VectorXd&, const Eigen::VectorXd&,
                                                      const Eigen::VectorXd&, Eigen::Ref<Eigen::MatrixXd>);
  int n_ = 0, m_ = 0, nc_ = 0;
  bool withTensors_ = true;
  std::unique_ptr<detail::SecondOrderImpl> impl_;
};

/// The full second-derivative tensors of q̈ and λ at (q, q̇, u) (n, n, m entries) into
/// ws.qddHessian and ws.lambdaHessian; computes the exact linearization on the way (data holds
/// it afterwards). Returns the status of the KKT solve (also data.status): the results are valid
/// when it is ok or kRedundantConstraints (q̈'s derivatives exact, λ's of the minimum-norm choice);
/// for kSingularMassMatrix / kNonFinite nothing is computed. Throws std::invalid_argument on a
/// size mismatch or a workspace built for another model size or without tensors.
DynamicsStatus computeSecondOrderTensors(const Model& model, Data& data, SecondOrderWorkspace& ws,
                                         const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                         const Eigen::VectorXd& u);

/// The implicit form's second derivatives (linearization.hpp's computeImplicitDynamics, for a
/// transcription whose variables include q̈ and λ): for φ(z, y) = νᵀ r(z, y) + ηᵀ c(z, y) at the
/// GIVEN y = [q̈; λ] (not the forward solution), z = [q; q̇; u],
///   Hzz = ∇²_z φ (N×N, symmetric; the (u, u) block 0),
///   Hyz = ∂²φ/∂y∂[q; q̇] ((n + nc)×2n; its q̇ columns are 0: ∂φ/∂q̈ = M ν + Aᵀη and ∂φ/∂λ = −A ν
///         depend on q only), and ∂²φ/∂y∂u = ∂²φ/∂y² = 0 (r, c are affine in y and in u).
/// Hzz by forward-over-reverse on the recorded residual pass (the workspace must be built with
/// recording = true), Hyz from two first-order evaluations (computeImplicitDynamics at q̇ = 0 with
/// q̈ = ν, λ = −η and with q̈ = λ = 0: r, c are affine in them, so the difference is exact).
/// `data` is scratch. Allocation-free. Throws std::invalid_argument on sizes or a tree-pass workspace.
DynamicsStatus computeImplicitSecondOrder(const Model& model, Data& data, SecondOrderWorkspace& ws,
                                          const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                          const Eigen::VectorXd& qdd, const Eigen::VectorXd& u,
                                          const Eigen::VectorXd& lambda, const Eigen::VectorXd& nu,
                                          const Eigen::VectorXd& eta, Eigen::Ref<Eigen::MatrixXd> Hzz,
                                          Eigen::Ref<Eigen::MatrixXd> Hyz);

/// H = Σᵢ wᵢ ∇²_z q̈ᵢ + Σ_r ρ_r ∇²_z λ_r (N×N, symmetric; z = [q; q̇; u]) without forming the
/// tensors: one transposed KKT solve, then forward mode over the closed-form gradient on a joint
/// tree, else the second-order adjoint of one recorded residual pass (file comment). w: n entries;
/// rho: nc entries, or empty for none. Computes the linearization on the way (in data). Status
/// and throws as computeSecondOrderTensors (H must be N×N).
DynamicsStatus computeSecondOrderContraction(const Model& model, Data& data, SecondOrderWorkspace& ws,
                                             const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                             const Eigen::VectorXd& u, const Eigen::VectorXd& w,
                                             const Eigen::VectorXd& rho, Eigen::Ref<Eigen::MatrixXd> H);

}  // namespace trellis
