// examples/hand/ball_reference.hpp — a reference the plant follows, made from an optimized turn:
// the optimizer's motion kept, its tensions and contact forces redistributed by inverse dynamics
// on a dense grid (issue 26).
//
// Why. The collocation solves the turn on a coarse mesh (21–41 knots in 2 s); the hand's light
// phalanges have damper modes of 0.1–3 ms and unstable modes of +18…+37 s⁻¹, so between knots
// the plant under the optimizer's interpolated tensions leaves the optimizer's states (relative
// defects 0.02–0.6 of the states' ranges, checkConsistency). A reference for feedback must be a
// solution of the dynamics between its knots. Here the *motion* is the optimizer's and the
// *tensions* are whatever makes the plant do exactly that motion, with the contacts kept
// unilateral and inside the friction pyramid.
//
// Motion. p = n − nc driver coordinates (the complement of a column-pivoted QR's pivots of
// A(q_0): A_D square and well conditioned) follow the quintic Hermite spline through the knots'
// (q, q̇, q̈), q̈_k = the forward dynamics at (q_k, q̇_k, u_k) — C² in t, so q̈(t) has no jumps
// at the knots. The other coordinates solve h(q) = 0 by Newton with the drivers fixed, and
//   q̇_D = −A_D⁻¹ A_I q̇_I,   q̈_D = −A_D⁻¹ (A_I q̈_I + c₀),   c₀ = A q̈ + Ȧ q̇ at q̈ = 0,
// so h = 0, A q̇ = 0, A q̈ + Ȧ q̇ = 0 hold at every dense knot.
//
// Inverse dynamics. The implicit equations r(q, q̇, q̈, u, λ) = M q̈ + b(q, q̇, u) − Aᵀλ = 0 are
// affine in (u, λ). Each contact's force is λ_d = f₀ n + Σ_k α_dk e_k, α ≥ 0, with e_k =
// (1, μ' cos φ_k, μ' sin φ_k), φ_k = (2k + 1)π/F, the edges of the F-facet pyramid inscribed in
// the cone of μ' = frictionUse · μ: every α ≥ 0 gives λ_n ≥ f₀ and a force inside the pyramid,
// hence inside the cone ‖λ_t‖ ≤ μ' λ_n. Unknowns z = [u; α] (m + F·contacts), rows r = 0 (n),
//   min ½‖u − u_rest‖² + ½ ε‖α‖² − β Σ [ln u_i + ln(u_max,i − u_i)] − β Σ ln α_j   s.t.  r = 0,
// by Newton's method on its KKT system from the previous knot's solution (infeasible start,
// fraction to the boundary 0.99, backtracking on the KKT residual). The barrier keeps every
// bound strict and makes the solution an analytic function of the motion, so u(t) is smooth
// (an active set would put kinks into it wherever a tendon reached 0 between knots). u_rest, a
// muscle tone as in reference_motion.hpp, keeps the tensions away from 0 so that the feedback can
// lower them as well as raise them: without it the unneeded tendons sit at ~β/u_max and every
// correction that lowers one is clipped at 0 (measured on the turn: the 20 closed loops' errors
// grew, ×1.6–27 over 2 s, where the stored hold's decay to 1e-8).
//
// Tension rates. u̇_k = (u*(t_k + δ) − u*(t_k − δ)) / 2δ, the whole design (spline, projection,
// distribution) at t_k ± δ, so that the trajectory's cubic Hermite input rule reproduces u*(t)
// between knots to O(h⁴) (trajectory.hpp). It is the interpolation rule's slope, not a derivative
// an algorithm uses; how well the rule follows the design is what checkConsistency measures.
#pragma once

#include "ball_turn.hpp"

#include <trellis/core/model.hpp>
#include <trellis/core/trajectory.hpp>

#include <Eigen/Core>

#include <string>
#include <vector>

namespace trellis::hand {

struct InverseReferenceOptions {
  int knots = 201;             ///< uniform dense knots on the motion's time span (≥ 2)
  int facets = 8;              ///< F ≥ 3, the pyramid's edges
  double frictionUse = 0.9;    ///< μ' = frictionUse · μ (a reserve for the feedback), in (0, 1]
  double normalMargin = 0.05;  ///< f₀ = limits.normalMin + normalMargin [N] (≥ 0)
  double barrier = 1e-2;       ///< β [N²]
  double restingTension = 0.5; ///< u_rest [N], every tendon (muscle tone)
  /// u_floor [N]: the barrier's lower bound on every tension, u > u_floor (and < u_max), a reserve
  /// the feedback can take away before a tension is clipped at 0.
  double tensionFloor = 0.3;
  double edgeWeight = 1e-2;    ///< ε: the contact forces' share of the objective
  double rateStep = 1e-4;      ///< δ [s] of the tension rates (0: no rates, linear tensions)
  int maxIterations = 200;     ///< Newton iterations per distribution

  /// Throws std::invalid_argument naming the field and the value.
  void validate() const;
};

struct InverseReference {
  Trajectory trajectory;          ///< [q; q̇] and tensions on the dense knots (with rates when δ > 0)
  Eigen::MatrixXd lambda;         ///< nc × N, the distribution's contact forces (contact frames)
  std::vector<std::string> drivers;  ///< the coordinates taken from the spline
  double maxConstraintResidual = 0.0;  ///< max ‖h(q_k)‖∞ [m]
  /// max over knots of ‖r‖∞ / max(‖M q̈‖∞, ‖b(u = 0)‖∞, ‖B u‖∞, ‖Aᵀλ‖∞): the equations' residual
  /// relative to their largest term (the same verdict in any units).
  double maxRelativeResidual = 0.0;
  double minNormal = 0.0;          ///< min λ_n over the knots [N]
  double worstFrictionRatio = 0.0; ///< max ‖λ_t‖ / (μ λ_n) over the knots (μ the scene's)
  double minTensionMargin = 0.0;   ///< min over knots and tendons of min(u, u_max − u) [N]
  double minTension = 0.0;         ///< min over knots and tendons of u [N]
  int iterations = 0;              ///< Newton iterations, all distributions
  bool ok = false;                 ///< every knot distributed, residuals at rounding, limits kept
  std::string message;             ///< the first failure (knot, time, what); empty when ok
};

/// The reference of the file comment from `motion` (a trajectory of `model`, e.g. the optimized
/// turn; ≥ 2 knots on the manifold). Throws std::invalid_argument on bad options or a motion that
/// does not match the model; numerical failure is reported in the result.
InverseReference inverseDynamicsReference(const Model& model, const BallLimits& limits, const Trajectory& motion,
                                          const InverseReferenceOptions& options = {});

}  // namespace trellis::hand
