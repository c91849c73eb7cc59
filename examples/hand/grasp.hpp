// examples/hand/grasp.hpp — a grasp of the free ball that the pads hold by pushing (issue 26,
// step 1): the digits' posture, the ball's centre and tensions 0 ≤ u ≤ u_max in static
// equilibrium with every contact pressing and inside the friction pyramid.
//
// Posture. The search variables are the ball's centre c (palm axes) and each digit's driver (a
// finger's MCP flexion, the thumb's CMC flexion). The digit's other three coordinates solve
//   |p − c| = r,   x̂ᵀ(c − p) = 0,   ŷᵀ(c − p) = 0
// (p the pad point, x̂, ŷ the distal phalanx's long and lateral axes) by Newton's method: the pad
// lies on the sphere and its normal, the phalanx's palmar axis −ẑ, passes through the centre, as
// the scene's contact frame (inward normal n = (c − p)/r) assumes. The ball's contact points are
// the pads, the ball at zero orientation; a candidate's model is the scene with its ball moved
// there (ball_grasp_centre = c, ball_contact_<digit> = p − c, the rows' n, t1, t2 recomputed as
// make_hand_scene.py's contact_directions does).
//
// Equilibrium. At rest the equations of motion are B u + Aᵀλ + Q₀ = 0, Q₀ = M q̈(q, 0, 0) −
// Aᵀλ(q, 0, 0) the rest load (gravity, joint springs): linear in (u, λ) for a fixed posture. A
// contact force in the F-facet pyramid of friction μ' with normal force ≥ f_min is exactly
//   λ_d = f_min n + Σ_k α_k (n + μ' (cos θ_k t1 + sin θ_k t2)),  α ≥ 0,  θ_k = 2πk/F
// (λ is in contact frames, so n, t1, t2 are the rows 3d, 3d+1, 3d+2). A hold with these margins
// exists iff the non-negative least squares
//   min ‖W (B u + Aᵀ(λ_min + E α) + Q₀)‖   over u ≥ 0, α ≥ 0
// leaves residual 0 (W divides the rows of angular coordinates by a length ℓ = 2 cm so every row
// is a force). The posture search (Nelder–Mead) minimizes that residual relative to ‖W Q₀‖ plus
// penalties for joint ranges and tensions over u_max, for targets (f_min, μ') that decrease until a
// hold exists. The tensions of the hold are then the NNLS with a small weight on ‖u‖ (small
// tensions) and findEquilibrium polishes q at those tensions (q̈ = 0 to its tolerance); `ok` only
// when the polished point keeps every contact condition, the tensions and the joint ranges.
#pragma once

#include "ball_turn.hpp"

#include <trellis/core.hpp>

#include <Eigen/Core>

#include <string>
#include <vector>

namespace trellis::hand {

/// Options of findFreeBallGrasp.
struct GraspSearchOptions {
  double ballRadius = 0.035;       ///< r [m] (the scene's ball)
  int facets = 8;                  ///< F of the pyramid the hold is checked in
  /// Largest angle between a pad's normal and the direction to the centre [rad]: a finger's pad
  /// normal stays in its flexion plane (no axial rotation in the model), so the pads cannot all
  /// face the centre exactly; the fingertip's rounded pad allows some tilt (modelling choice).
  double maxTilt = 0.5;
  /// Targets (f_min [N], μ'/(μ cos π/F)) tried in turn, strongest first; the first reached wins.
  std::vector<std::pair<double, double>> targets = {{1.0, 0.5}, {0.5, 0.6}, {0.3, 0.8}, {0.1, 0.95}};
  int maxEvaluations = 3000;       ///< Nelder–Mead objective evaluations per target
  double tensionWeight = 1e-4;     ///< weight of ‖u‖² against the squared force residual [1]
};

/// A grasp found by findFreeBallGrasp.
struct FreeBallGrasp {
  Eigen::VectorXd q;               ///< nq: the polished equilibrium (ball coordinates near 0)
  Eigen::VectorXd u;               ///< nu: tensions, 0 ≤ u ≤ u_max
  Eigen::VectorXd lambda;          ///< nc: contact forces in contact frames
  Eigen::Vector3d centre;          ///< c: the ball's centre [m], palm axes
  std::vector<Eigen::Vector3d> contacts;  ///< per digit, the contact point relative to c [m]
  double targetNormal = 0.0;       ///< f_min of the target reached [N]
  double targetFriction = 0.0;     ///< μ' of the target reached
  double accelerationResidual = 0.0;  ///< ‖q̈(q, 0, u)‖∞ at the polished point
  double alignment = 0.0;          ///< max angle between a pad normal and the direction to c [rad]
  ContactMargins margins;
  int evaluations = 0;             ///< objective evaluations of the whole search
  bool ok = false;
  std::string message;             ///< what failed, when not ok
};

/// The scene text `sceneJson` (a free-ball scene of make_hand_scene.py --free-ball) with the ball
/// centred at c, the contact points `contacts` (relative to c, one per digit in row order) and the
/// rows' contact frames recomputed from them; state q, u stored when given (sizes nq, nu).
std::string placeBall(const std::string& sceneJson, const std::vector<std::string>& digits,
                      const Eigen::Vector3d& centre, const std::vector<Eigen::Vector3d>& contacts,
                      const Model& model, const Eigen::VectorXd& q = {}, const Eigen::VectorXd& u = {});

/// The hold of a fixed posture (file comment): the NNLS over u ≥ 0 and the pyramid's generators
/// with normal force ≥ fMin and friction μ' (`muPrime`), F = `facets`; with tensionWeight > 0 the
/// rows √w·‖W Q₀‖·u are appended (small tensions, at the price of a residual of that order).
struct PyramidHold {
  Eigen::VectorXd tension;          ///< nu, ≥ 0
  Eigen::VectorXd lambda;           ///< nc: the contact forces the hold assigns (inside the pyramid)
  Eigen::VectorXd residual;         ///< nq: W (B u + Aᵀλ + Q₀) / ‖W Q₀‖, per coordinate
  double relativeResidual = 0.0;    ///< its norm (0: a hold)
  bool ok = false;                  ///< false when the dynamics failed at q
};
PyramidHold pyramidHold(const Model& model, const Eigen::VectorXd& q, double fMin,
                        double muPrime, int facets, double tensionWeight = 0.0);

/// Searches the grasp of the file comment for the scene text `sceneJson` (its hand; its stored
/// grasp is the start). Throws std::runtime_error when the scene is not a free-ball scene.
FreeBallGrasp findFreeBallGrasp(const std::string& sceneJson, const BallLimits& limits,
                                const GraspSearchOptions& options = {});

}  // namespace trellis::hand
