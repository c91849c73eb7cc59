// examples/hand/grasp.hpp — a grasp of the free ball that the pads hold by pushing (issue 26,
// step 1): the digits' posture, the ball's centre and tensions 0 ≤ u ≤ u_max in static
// equilibrium with every contact pressing and inside the friction pyramid.
//
// Posture. The search variables are the ball's centre c (palm axes), each digit's driver (a
// finger's MCP flexion, the thumb's CMC flexion), each pad's tilt φ_d and the thumb base's turn ω
// and shift δ (GraspSearchOptions). The digit's other three coordinates solve
//   |p − c| = r  exactly,   ẑ' + (c − p)/|c − p| = 0  in least squares
// (p the pad point, ẑ' the distal phalanx's dorsal axis turned by φ_d about its lateral axis) by
// Gauss–Newton: the pad lies on the sphere and its normal −ẑ' points to the centre as closely as
// the digit allows (the scene's contact frame has the inward normal n = (c − p)/r). The ball's contact points are
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

#include <memory>
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
  /// Targets (f_min [N], μ'/(μ cos π/F)) tried in turn, weakest first: the first must be reached
  /// (else there is no grasp), each further one is tried from the last posture that holds, and the
  /// strongest reached is kept.
  std::vector<std::pair<double, double>> targets = {{0.05, 1.0}, {0.1, 0.9}, {0.3, 0.8}, {0.5, 0.7}, {1.0, 0.6}};
  int maxEvaluations = 3000;       ///< Nelder–Mead objective evaluations for the first target (0: only
                                   ///< evaluate the start, e.g. to build the start of solveGraspNlp)
  int strengthenEvaluations = 600; ///< ... and for each further target
  int restarts = 4;                ///< Nelder–Mead restarts from its best point within a budget
  /// A target counts as reached when the hold's relative residual (+ penalties) is below this: the
  /// NNLS residual of a near-hold posture; the polish (findEquilibrium) then makes q̈ = 0 and
  /// checkGrasp decides ok with the exact conditions.
  double holdTolerance = 1e-6;
  /// The search's start p = [c − c0; drivers; pad tilts φ; thumb ω; δ] (FreeBallGrasp::parameters
  /// of an earlier search); empty: the scene's stored grasp, no tilt, the scene's thumb base.
  Eigen::VectorXd start;
  /// Largest turn of the thumb base (thumb_cmc_site) from the scene's, |ω| [rad]; 0 keeps it. The
  /// base was designed for the fixed ball (make_hand_scene.py); the real trapeziometacarpal joint
  /// moves the metacarpal through ~±40° in both of its planes, so a turn of the base within 0.6 rad
  /// stays within what a thumb does (modelling choice).
  double thumbBaseRotation = 0.6;
  double thumbBaseShift = 0.01;    ///< largest shift of the CMC site per palm axis [m] (with the turn)
  double tensionWeight = 1e-4;     ///< weight of ‖u‖² against the squared force residual [1]
};

/// A grasp found by findFreeBallGrasp.
struct FreeBallGrasp {
  Eigen::VectorXd q;               ///< nq: the polished equilibrium (ball coordinates near 0)
  Eigen::VectorXd u;               ///< nu: tensions, 0 ≤ u ≤ u_max
  Eigen::VectorXd lambda;          ///< nc: contact forces in contact frames
  Eigen::Vector3d centre;          ///< c: the ball's centre [m], palm axes
  Eigen::Isometry3d thumbBase = Eigen::Isometry3d::Identity();  ///< thumb_cmc_site in palm axes
  Eigen::Vector3d thumbTurn = Eigen::Vector3d::Zero();   ///< ω: the base turned by exp([ω]×) in its axes [rad]
  Eigen::Vector3d thumbShift = Eigen::Vector3d::Zero();  ///< δ: the CMC site moved by δ [m], palm axes
  std::vector<Eigen::Vector3d> contacts;  ///< per digit, the contact point relative to c [m]
  double targetNormal = 0.0;       ///< f_min of the target reached [N]
  double targetFriction = 0.0;     ///< μ' of the target reached
  double accelerationResidual = 0.0;  ///< ‖q̈(q, 0, u)‖∞ at the polished point
  double relativeAcceleration = 0.0;  ///< ‖W M q̈‖ / ‖W Q₀‖ there (checkGrasp)
  double alignment = 0.0;          ///< max angle between a pad normal and the direction to c [rad]
  ContactMargins margins;
  int evaluations = 0;             ///< objective evaluations of the whole search
  Eigen::VectorXd parameters;      ///< p of the result (or of the best posture when not ok)
  std::string scene;               ///< the scene text of that posture (thumb base and ball placed)
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

/// The ball pose of q folded into the placement: the ball's centre c (palm axes) and the contact
/// points (each digit's pad relative to c) where q puts them, the ball coordinates of q set to 0,
/// and the scene text placed there (placeBall). The ball is a uniform sphere, so its orientation
/// changes nothing; the placed scene has h(q) = 0 at ball coordinates 0 where q had h = 0.
std::string foldBallPose(const std::string& sceneJson, const Model& model, const std::vector<std::string>& digits,
                         Eigen::VectorXd& q, Eigen::Vector3d& centre, std::vector<Eigen::Vector3d>& contacts);

/// The scene text with the thumb base (frame thumb_cmc_site, relative to the palm) set to `base`.
std::string placeThumbBase(const std::string& sceneJson, const Eigen::Isometry3d& base);

/// Whether (q, q̇ = 0, u) is a static hold of the ball by pushing pads: the one check behind the
/// search's `ok` and the stored scene's tests. With the core's forward dynamics at (q, 0, u):
///   ‖h(q)‖∞ ≤ 1e-10 m (on the manifold), ‖W M q̈‖ ≤ accelerationTolerance · ‖W Q₀‖ (W as pyramidHold:
///   the residual force relative to the rest load Q₀ = gravity + springs), every λ_n ≥ normalMin,
///   every contact inside the F-facet pyramid inscribed in the cone (|cos θ_k λ_t1 + sin θ_k λ_t2| ≤
///   μ cos(π/F) λ_n), 0 ≤ u ≤ u_max, the digits' joints in range. `message` names the first
///   condition that fails (empty when ok).
struct GraspCheck {
  ContactMargins margins;
  double relativeAcceleration = 0.0;   ///< ‖W M q̈‖ / ‖W Q₀‖
  double accelerationResidual = 0.0;   ///< ‖q̈‖∞ [rad/s², m/s²]
  double constraintResidual = 0.0;     ///< ‖h(q)‖∞
  double facetRatio = 0.0;             ///< max over contacts and facets of the facet's use (≤ 1 inside)
  double rangeExcess = 0.0;            ///< largest excursion outside a joint range [rad] (≤ 0 inside)
  double tensionExcess = 0.0;          ///< max(u − u_max, −u) [N] (≤ 0 inside)
  bool ok = false;
  std::string message;
};
GraspCheck checkGrasp(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& u,
                      const BallLimits& limits, int facets = 8, double accelerationTolerance = 1e-8);

/// Where a posture's hold falls short (hand_ball_grasp --diagnose): the NNLS of pyramidHold on
/// all rows, on the ball's 6 rows alone (can forces inside the pyramids balance the ball?) and on
/// each digit's 4 rows alone (can its tendons press its pad with such a force, against its springs
/// and weight?). Relative residuals (÷ ‖W Q₀‖); 0 means that part can be balanced on its own.
struct HoldDiagnosis {
  PyramidHold whole;
  double ballResidual = 0.0;
  std::string ballWorst;                 ///< its least balanced coordinate and residual
  std::vector<double> digitResidual;     ///< per digit (order of `digits`)
  std::vector<std::string> digitWorst;   ///< per digit, its least balanced coordinate and residual
};
HoldDiagnosis diagnoseHold(const Model& model, const Eigen::VectorXd& q, const std::vector<std::string>& digits,
                           double fMin, double muPrime, int facets);

/// Searches the grasp of the file comment for the scene text `sceneJson` (its hand; its stored
/// grasp is the start). Throws std::runtime_error when the scene is not a free-ball scene.
FreeBallGrasp findFreeBallGrasp(const std::string& sceneJson, const BallLimits& limits,
                                const GraspSearchOptions& options = {});

/// Options of solveGraspNlp.
struct GraspNlpOptions {
  double ballRadius = 0.035;   ///< r [m] (the scene's ball)
  int facets = 8;              ///< F: the cone of friction μ cos(π/F) is inscribed in the F-facet pyramid
  double maxTilt = 0.5;        ///< largest angle between a pad's normal and the contact normal [rad]
  double marginCap = 1.0;      ///< s ≤ this [N]: above it only the effort term is minimized
  double tensionWeight = 1e-3; ///< w of w Σ (u_k / u_max,k)² beside −s [N]
  /// Every tension in [reserve, u_max − reserve] [N]. Tendons only pull and are clipped to
  /// [0, u_max] in the closed loops: a hold with tensions at 0 N (the effort term's pull) leaves
  /// the feedback no authority one way on those tendons. Measured on the hold after the tendon
  /// geometry change: with 5 tendons at 0 N the 200 Hz closed loops diverged (error 1e-3 → 5 in
  /// 0.9 s); with the reserve, examples/hand/README.md.
  double tensionReserve = 1.0;
  /// Ipopt's settings of the first solve, with Ipopt's default bound relaxation 1e-8 (from the
  /// search's point its iterates reach a better local maximum of s than without; measured, README).
  /// The equalities are then met to ~1e-8 only; a second solve from its result without relaxation
  /// meets them to constr_viol_tol.
  NlpOptions ipopt = [] {
    NlpOptions o;
    o.boundRelaxFactor = 1e-8;
    return o;
  }();
};

/// The hold as a smooth program (issue 26, step 1), solved by Ipopt with exact first derivatives
/// and a quasi-Newton Hessian. The contact sites are free: the program works on the hand alone
/// (the scene without its 15 contact rows) with a force f_d on each pad as an input (a body
/// wrench at the tip frame, f_d in tip axes), and the ball as a sphere of centre c. Variables
/// x = [q_h (the hand's coordinates); c; u; f; s]:
///   max s − w Σ (u_k/u_max,k)²   subject to
///   S q̈_h(q_h, 0, [u; f]) = 0,  S = W M_hh(q₀) / ‖W Q₀‖    (the hand at rest under u and the pad forces),
///   Σ_d F_d + m_b g = 0,  Σ_d (p_d − c) × F_d / ℓ = 0      (the ball at rest; F_d = −R_d f_d, the
///                                                          pad's force on the ball, palm axes),
///   (|p_d − c|² − r²) / 2r = 0                             (each pad on the sphere),
///   λ_n,d − s ≥ 0,  λ_n,d = n_d · F_d,  n_d = (c − p_d)/|c − p_d|   (every pad presses by s),
///   μ'² (λ_n,d − s)² − (|F_d|² − λ_n,d²) ≥ 0                (inside the cone μ' = μ cos(π/F), apex
///                                                          at λ_n = s: inside the F-facet pyramid for
///                                                          any turn of t1 about n),
///   v_d · n_d ≥ cos(maxTilt),  v_d = −R_d ẑ                 (the pad faces the centre: pad tilt),
///   hand joints in their ranges, 0 ≤ u ≤ u_max, s ≤ marginCap.
/// q̈_h and ∂q̈_h/∂q, ∂q̈_h/∂[u; f] from the core's computeLinearization; p_d, R_d and their
/// derivatives from the frames' body velocities at q̇ = e_i (exact). The thumb base is that of
/// `sceneJson` (fixed here; the grasp search varies it). A hold with the margin exists at
/// the result iff s ≥ normalMin; `check` is checkGrasp on the free-ball scene placed there (ball
/// at c, contact points the pads, ball coordinates 0), where the core's λ are the f's.
struct GraspNlpResult {
  Eigen::VectorXd q, u, lambda;   ///< the result on the placed free-ball scene (nq, nu, nc)
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  ///< c [m], palm axes
  std::vector<Eigen::Vector3d> contacts;  ///< per digit, p_d − c [m]
  std::string scene;              ///< the free-ball scene text placed there
  double margin = 0.0;            ///< s: the smallest normal force the program reached [N]
  double alignment = 0.0;         ///< max angle between a pad's normal and its contact normal [rad]
  NlpResult nlp;                  ///< Ipopt's status, iterations, multipliers, time
  double relaxedViolation = 0.0;  ///< the first (relaxed) solve's constraint violation
  int firstIterations = 0;        ///< the first solve's iterations (nlp.iterations: both)
  bool keptRelaxed = false;       ///< the exact solve ended farther from feasible: the relaxed point was kept
  bool polished = false;          ///< findEquilibrium made q̈ = 0 at the result's tensions
  GraspCheck check;               ///< checkGrasp at (q, u) on `scene`
  /// The constraint groups still violated at the last iterate and by how much, and the bounds
  /// with the largest multipliers (∂(−s + effort)/∂bound: which range limits s most), named.
  std::string report;
  /// check.ok: (q, u) is a static hold by the project's one check. Ipopt's status (nlp) says
  /// whether s is also certified as a local maximum; a hold can be found without that.
  bool ok = false;
};
/// The program of solveGraspNlp and its layout (x = [q_h; c; u; f; s], rows [hand rest; ball
/// force; ball moment; sphere; per digit normal, cone, facing]); its callbacks own their workspace.
struct GraspProgram {
  NlpProblem problem;
  std::vector<int> hand;   ///< x[0..nh): these coordinates of the scene's q (the others, the ball's, are 0)
  int centre = 0, tensions = 0, forces = 0, margin = 0;                  ///< offsets of c, u, f, s in x
  int rest = 0, ballForce = 0, ballMoment = 0, sphere = 0, digitRows = 0;  ///< first row of each group
  std::shared_ptr<const void> state;  ///< the hand model and workspace the callbacks use
};
GraspProgram makeGraspProgram(const std::string& sceneJson, const Eigen::VectorXd& q0, const Eigen::VectorXd& u0,
                              const BallLimits& limits, const GraspNlpOptions& options = {});

/// From the posture q0 (nq, on the manifold of `sceneJson`, a free-ball scene) and tensions u0.
/// Throws std::invalid_argument on sizes that do not match, std::runtime_error when the scene is
/// not a free-ball scene or the dynamics fail at the start.
GraspNlpResult solveGraspNlp(const std::string& sceneJson, const Eigen::VectorXd& q0, const Eigen::VectorXd& u0,
                             const BallLimits& limits, const GraspNlpOptions& options = {});

}  // namespace trellis::hand
