// examples/hand/ball_turn.hpp — the hand turns a free ball (issue 26): the limits of the scene
// (examples/scenes/hand_ball*.json and examples/hand/*_limits.json, written by make_hand_scene.py
// --free-ball) and the trajectory optimization problem that turns the ball about the palm's normal.
//
// Contacts. Rows 3d, 3d+1, 3d+2 of the scene's constraints are digit d's force on the ball along
// its contact frame (n inward, t1, t2; make_hand_scene.py), so λ is already in contact frames.
// At every collocation point the problem imposes
//   λ_n ≥ normalMin                                              (unilateral, with a margin),
//   cos θ_k λ_t1 + sin θ_k λ_t2 ≤ μ cos(π/F) λ_n,  θ_k = 2πk/F   (F-facet pyramid inscribed in
//                                                                 the cone ‖λ_t‖ ≤ μ λ_n),
// the second as the transcription's force combinations (linear in λ, so their exact first and
// second derivatives are the core's dλ/d[x; u] and its second-order contraction). The inscribed
// pyramid is conservative: a point inside it is inside the smooth cone, and its facets leave at
// worst cos(π/F) of the cone (92 % for F = 8).
//
// Motion. Rest to rest in T: x(0) = the stored grasp at rest; at T the ball's yaw (the first of
// its Z-Y-X angles, a turn about the palm normal z) is `angle`, every velocity is zero, the other
// coordinates are free (the knot constraints h = 0 keep the pads on the ball). Tensions in
// [0, u_max], digit joints in their ranges. Cost ∫ uᵀ u + w_v ‖q̇‖² dt: effort, plus a small weight
// on the velocities that keeps the motion smooth.
#pragma once

#include <trellis/optimization.hpp>

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

namespace trellis::hand {

/// The limits of a free-ball hand scene (its *_limits.json).
struct BallLimits {
  double friction = 0.0;      ///< μ, Coulomb friction coefficient of skin on the ball
  double normalMin = 0.0;     ///< margin on the normal force [N]
  std::vector<std::string> digits;  ///< contact order: digit d owns constraint rows 3d..3d+2
  Eigen::VectorXd qLower, qUpper;   ///< nq: joint ranges (ball coordinates: ±infinity) [rad, m]
  Eigen::VectorXd uMax;             ///< nu: maximal tendon tensions [N]
};

/// Reads `path` (a *_limits.json) for `model`; throws std::runtime_error naming the file, the
/// field and the value when something is missing or does not match the model.
BallLimits loadBallLimits(const std::string& path, const Model& model);

/// Options of the ball turn.
struct BallTurnOptions {
  double angle = 0.349066;    ///< yaw at T [rad] (20°)
  double horizon = 2.0;       ///< T [s]
  int knots = 11;             ///< Hermite–Simpson knots
  int facets = 8;             ///< F ≥ 3, facets of the friction pyramid
  double velocityWeight = 1e-2;  ///< w_v [N² s²/rad²]
  /// The start's configuration free except the yaw (at rest): the stored grasp is not an
  /// equilibrium under u ≥ 0, so the optimizer chooses the grasp it starts from.
  bool freeInitialConfiguration = true;
};

/// The optimal control problem of the file comment; q0 the grasp (nq, on the manifold).
OptimalControlProblem makeBallTurnProblem(std::shared_ptr<const Model> model, const Eigen::VectorXd& q0,
                                          const BallLimits& limits, const BallTurnOptions& options);

/// The warm start: a quasi-static turn. At each of `knots` uniform knots the yaw follows the
/// smooth rest-to-rest profile ψ(t) = angle (3s² − 2s³), s = t/T; the other coordinates solve
/// h(q) = 0 by Gauss–Newton with minimum-norm steps from the previous knot (the pads follow the
/// ball), the velocities are the exact tangent q̇ = ψ̇ (e_ψ − A_o⁺ A_ψ), A_o the Jacobian without
/// the yaw column, and the tensions hold each pose at rest with the contacts inside the pyramid
/// where they can (pyramidHold of grasp.hpp: normal force ≥ 2·normalMin, 90 % of the facets'
/// friction, small tensions). Throws std::runtime_error naming the knot when the projection or the
/// dynamics fail.
Trajectory quasiStaticTurn(const Model& model, const Eigen::VectorXd& q0, const BallLimits& limits,
                           const BallTurnOptions& options);

/// Contact quality of a λ (nc): the smallest normal force and the largest ‖λ_t‖ / (μ λ_n) (+inf
/// where λ_n ≤ 0) over the contacts, and the contact where each occurs.
struct ContactMargins {
  double minNormal = 0.0;
  double worstFrictionRatio = 0.0;
  int minNormalContact = -1, worstFrictionContact = -1;
};
ContactMargins contactMargins(const Eigen::VectorXd& lambda, const BallLimits& limits);

}  // namespace trellis::hand
