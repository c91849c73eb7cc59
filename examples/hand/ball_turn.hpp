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
// [0, u_max], digit joints in their ranges. Cost c ∫ uᵀ u + w_v ‖q̇‖² [+ w_a ‖q̈‖², implicit form] dt:
// effort, plus small weights on the velocities (and accelerations) that keep the motion smooth. Rest at the ends fixes only the independent
// coordinates' rates (and, with a fixed start, configuration): the knot rows A q̇ = 0 and h = 0
// then fix the rest, and no row is left with a zero Jacobian (makeBallTurnProblem).
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
  /// c: the cost is c ∫ uᵀu + w_v ‖q̇‖² dt (the same minimizer for any c > 0). Ipopt's filter
  /// weighs the objective against the constraint violation on their raw scales: at c = 1 the
  /// hand's cost (~7·10³ N² s) outweighs defects of ~1 and its first steps trade feasibility for
  /// cost (measured: inf_pr 4 → 10⁴ in 10 iterations); at 1e-3 the same start stays near feasible.
  double effortScale = 1e-3;
  /// The transcription's implicit dynamics form (q̈, λ variables, the equations of motion as rows
  /// in force units; problem.hpp DynamicsForm): measured to converge where the explicit form's
  /// velocity defects (~10² rad/s off equilibrium on the light phalanges) stall (README).
  bool implicitForm = false;
  /// w_a: with the implicit form, c w_a ∫ ‖q̈‖² dt joins the cost (OptimalControlProblem::
  /// accelerationWeights): the smoothness term that pins Hermite–Simpson's free q̈ direction
  /// (knots +a, midpoints −a/2) on the light phalanges. [N² s⁴/rad²]
  double accelerationWeight = 10.0;
  /// The start's configuration free except the yaw (at rest): the stored grasp is not an
  /// equilibrium under u ≥ 0, so the optimizer chooses the grasp it starts from.
  bool freeInitialConfiguration = true;
};

/// The optimal control problem of the file comment; q0 the grasp (nq, on the manifold).
OptimalControlProblem makeBallTurnProblem(std::shared_ptr<const Model> model, const Eigen::VectorXd& q0,
                                          const BallLimits& limits, const BallTurnOptions& options);

/// Ipopt's settings for the coarse implicit turn (the main job's and hand_ball_feedback
/// --optimize's): the quasi-static warm start is near feasible, so μ_init 1e-4 keeps it, but
/// bound push and fraction 1e-2 (Ipopt's defaults), not 1e-6: with variables 1e-6 inside their
/// bounds the first ~12 iterations crawled (step sizes 1e-5…1e-2, cut by the fraction-to-the-
/// boundary rule). Measured 2026-12-05, the same optimum (cost to 1e-11) in every case, iterations
/// 1e-6 → 1e-2: the 20° turn on 11 knots 64–70 → 41 (inertia corrections 23–32 → 6); 10° 56 → 51,
/// 25° 79 → 56, 9 knots 82 → 55, 15 knots 59 → 58, the pinch at 5° on 7 knots 43 → 40 and on 5
/// knots 69 → 48 (μ_init 1e-3 with it was faster on some but found a costlier optimum on 10° and
/// 15 knots: not taken); no refinement rounds (the coarse mesh's check is reported, the plant's reference is
/// the redistribution of ball_reference.hpp); at most 500 iterations; QAMD ordering of the KKT
/// matrix — measured on the 20° turn, 11 knots (3 runs each, 2026-12-04): the factorizations take
/// 7.7 s instead of 12.7 s with MUMPS's own choice (METIS), 70 iterations instead of 67, the same
/// cost to 1e-12 (MumpsOrdering); the Hessian's point blocks on `threads` threads (≥ 1).
OptimizerOptions ballTurnOptimizerOptions(int threads = 1);

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

/// A static hold of the free-ball scene at a fixed ball yaw ψ (the quasi-static turn's knots):
///   max s − w_u Σ (u_k/u_max,k)² − w_q ‖q − q_prev‖²/ℓ²   over x = [q; u; s]
///   subject to  h(q) = 0,  q̈_I(q, 0, u) = 0,  λ_n,d − s ≥ 0,  μ' λ_n,d − (cos θ_k λ_t1,d + sin θ_k λ_t2,d) ≥ 0,
///   q_yaw = ψ, joint ranges, 0 ≤ u ≤ u_max, s ≤ marginCap,
/// q̈ and λ the core's constrained dynamics at rest and their exact first derivatives
/// (computeLinearization). At rest A q̈ ≡ 0 for every q, so of the n rows q̈ = 0 only n − nc are
/// independent: q̈_I are the coordinates left when a column-pivoted QR of A(q_prev) picks nc
/// dependent ones (A_D invertible ⇒ q̈_D = −A_D⁻¹ A_I q̈_I = 0). μ' = μ cos(π/F)·frictionUse (the
/// pyramid inscribed in the cone, less a reserve for the motion), ℓ = 2 cm. Ipopt, exact first
/// derivatives, L-BFGS Hessian (solveNlp).
struct RestHoldOptions {
  int facets = 8;
  double frictionUse = 0.8;     ///< fraction of the facets' friction a hold may use
  double marginCap = 1.0;       ///< s ≤ this [N]
  double tensionWeight = 1e-3;  ///< w_u [N]
  double stayWeight = 1e-2;     ///< w_q [N]: keeps the hold near the previous one (continuation)
  /// Ipopt: rows to 1e-9 (h in m, the scaled q̈ rows in N or N m, λ in N); the KKT tolerance
  /// 1e-6; at most 1000 iterations (the hold's feasibility is what is used, and checked; L-BFGS
  /// needs ~10³ iterations for the last digits of optimality near a margin cap, and a path from
  /// such a point was measured to fail where the converged one passes).
  NlpOptions ipopt = [] {
    NlpOptions o;
    o.constraintTolerance = 1e-9;
    o.tolerance = 1e-6;
    o.maxIterations = 1000;
    return o;
  }();
};
struct RestHold {
  Eigen::VectorXd q, u, lambda;  ///< nq, nu, nc
  double margin = 0.0;           ///< min(s, the smallest λ_n at the result) [N]
  NlpResult nlp;
  /// A hold: Ipopt solved, or stopped at its iteration limit at a point where every row and bound
  /// holds to the tolerance (a feasible point, not certified optimal), and every λ_n ≥ normalMin.
  bool ok = false;
  bool certified = false;        ///< Ipopt's status was solved (the margin a local optimum)
  std::string message;
};
/// `velocity` (nq, or empty for rest): the rows are q̈_I(q, q̇, u) = 0 at that q̇ (a steady
/// motion's tensions, the dampers included).
RestHold solveRestHold(const Model& model, const BallLimits& limits, const Eigen::VectorXd& qPrev,
                       const Eigen::VectorXd& uPrev, double yaw, const RestHoldOptions& options = {},
                       const Eigen::VectorXd& velocity = {});

/// The quasi-static turn by holds: solveRestHold at each knot's yaw ψ_k = angle (3s² − 2s³) of
/// `knots` uniform knots over `horizon`, from the hold (q0, u0), each from the previous; between
/// knots a failed solve is retried from halfway (continuation, at most 6 halvings). The knots'
/// velocities are the chord rates of the hold path projected onto A q̇ = 0 (zero at both ends):
/// a warm start for the collocation, not a solution of the dynamics. `reached` is the largest yaw
/// held; the path stops there when a yaw cannot be held.
struct HoldPath {
  Trajectory guess;              ///< knots × [q; q̇], tensions of each hold (complete only)
  std::vector<RestHold> holds;   ///< one per knot reached
  double reached = 0.0;          ///< largest yaw held [rad]
  int solves = 0;                ///< solveRestHold calls (continuation included)
  bool complete = false;
  std::string message;
};
HoldPath quasiStaticHolds(const Model& model, const Eigen::VectorXd& q0, const Eigen::VectorXd& u0,
                          const BallLimits& limits, const BallTurnOptions& options,
                          const RestHoldOptions& holdOptions = {});

/// The kinematic reach of the turn: whether some configuration keeps every pad on its point of
/// the ball, the digits' joints in their ranges, with the ball's yaw at ψ — forces aside (no
/// hold can turn the ball further than this). Solves
///   min ‖q − q_prev‖²   subject to   h(q) = 0,  q_yaw = ψ,  joint ranges
/// (Ipopt, exact first derivatives) for ψ = step, 2 step, … from q0, halving the step where a
/// solve fails, until the step falls below `resolution`. `reached` is the largest ψ with a
/// configuration; `limit` the first ψ Ipopt declared locally infeasible (or where it stopped).
struct KinematicReach {
  double reached = 0.0, limit = 0.0;   ///< [rad]
  Eigen::VectorXd q;                   ///< the configuration at `reached`
  std::string stop;                    ///< Ipopt's status at `limit`
  std::vector<std::string> atRangeEnds;  ///< coordinates of q within 1e-4 of a range end
  int solves = 0;
};
KinematicReach kinematicReach(const Model& model, const BallLimits& limits, const Eigen::VectorXd& q0,
                              double maxYaw, double step, double resolution);

/// Contact quality of a λ (nc): the smallest normal force and the largest ‖λ_t‖ / (μ λ_n) (+inf
/// where λ_n ≤ 0) over the contacts, and the contact where each occurs.
struct ContactMargins {
  double minNormal = 0.0;
  double worstFrictionRatio = 0.0;
  int minNormalContact = -1, worstFrictionContact = -1;
};
ContactMargins contactMargins(const Eigen::VectorXd& lambda, const BallLimits& limits);

}  // namespace trellis::hand
