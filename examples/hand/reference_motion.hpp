// examples/hand/reference_motion.hpp — a reference motion of the hand (examples/scenes/hand.json)
// on its constraint manifold, with tendon tensions from an inverse-dynamics tension distribution.
//
// Motion design. p "driver" coordinates q_d follow smooth prescribed paths; the others q_o solve
// h(q) = 0 by Newton's method at every knot (A_o = ∂h/∂q_o square and invertible), and
//   q̇_o = −A_o⁻¹ A_d q̇_d,     q̈_o = −A_o⁻¹ (A_d q̈_d + Ȧ q̇)
// so that h = 0, A q̇ = 0 and A q̈ + Ȧ q̇ = 0 hold at every knot (to Newton/rounding accuracy).
//
// Tension distribution. At each knot find u > 0 and λ with
//   B(q) u + Aᵀ λ = M q̈ + b(q, q̇)           (b: bias with u = 0 — gravity, springs, damping,
//                                             Coriolis; B = ∂Q/∂u, the tendons' input matrix).
// With N an orthonormal basis of null(A) (n × (n − rank A)) this splits into the tangential part
// Nᵀ B u = Nᵀ r (r = M q̈ + b), which u alone must meet, and λ = least squares of Aᵀ λ = r − B u,
// which meets the normal part exactly when A has full row rank. u is the interior-point (log
// barrier) solution of
//   min ½‖u − u_rest‖² − μ Σᵢ ln uᵢ   subject to   Nᵀ B u = Nᵀ r   (exactly),
// i.e. near the resting tension u_rest (muscle tone) with every tendon strictly positive: a
// tendon that the closest point to u_rest would push below zero keeps ≈ μ / (its shortfall).
// Why a barrier and not u ≥ 0 with an active set: the solution of the barrier problem is an
// analytic function of (q, q̇, q̈) — the KKT system is smooth and nonsingular — so along the
// motion u(t) is smooth and the cubic Hermite input rule below reproduces it to O(h⁴). With an
// active set (non-negative least squares, the rule before) a tendon reaching u = 0 between two
// knots puts a kink into u(t) that no cubic can follow: the reference was inconsistent with the
// dynamics there and the closed-loop error floor rose from ~5e-8 to ~2e-6 at those instants. And
// the equality is met to rounding, where the regularized least squares left an O(ε²) residual
// (~1e-7 rad/s² in q̈ after the hand's M⁻¹ ~ 1e6).
// Solved by Newton's method on the KKT system, globalized by a homotopy in the right-hand side
// from u_rest (reference_motion.cpp); when it fails, non-negative least squares on the tangential
// equations tells whether any u ≥ 0 meets them, for the message.
// Input derivatives (the tensions' rates u̇_k, so that the trajectory's cubic Hermite input rule
// reproduces the motion between knots; trajectory.hpp). The distribution u*(t) is a smooth
// function of t (above); it is an
// interior-point solve, whose exact derivative would need the derivatives of N(q), B(q), M(q) and b along
// the motion. It is differentiated in two parts:
//  1. a central difference quotient of the whole design in t (drivers, Newton projection,
//     distribution at t_k ± δ): u̇_fd = (u*(t_k + δ) − u*(t_k − δ)) / 2δ, error δ² |d³u*/dt³| / 6
//     plus the design's rounding over δ;
//  2. an exact correction of the part the dynamics see. Along the design, d/dt q̈(x(t), u(t))
//     must equal the designed q⃛; with the core's exact linearization at the knot,
//       ∂q̈/∂x · ẋ_k + ∂q̈/∂u · u̇ = q⃛_k,
//     and since every forward-dynamics q̈ satisfies A q̈ + Ȧ q̇ = 0, the driver rows suffice (the
//     others follow, as the drivers parameterize the manifold; q⃛ of a driver is analytic). u̇ is
//     u̇_fd plus the least-norm change over the tendons that meets these p equations, so the
//     dynamically relevant part of u̇ is exact and the rest (which tendon pulls how much more) is
//     the difference quotient's. Both the correction (the quotient's error where it matters) and
//     |u̇_δ − u̇_2δ| (its error estimate) are reported per knot.
#pragma once

#include <trellis/core/trajectory.hpp>
#include <trellis/core/data.hpp>
#include <trellis/core/model.hpp>

#include <Eigen/Core>

#include <string>
#include <vector>

namespace trellis::hand {

/// Result of min ‖C x − d‖ subject to x ≥ 0.
struct NnlsResult {
  Eigen::VectorXd x;          ///< k, every entry ≥ 0
  double residualNorm = 0.0;  ///< ‖C x − d‖
  int iterations = 0;         ///< outer iterations (one variable freed per iteration)
  bool converged = false;     ///< KKT conditions met (all multipliers w = Cᵀ(d − Cx) ≤ tol on the bound)
};

/// Lawson–Hanson active-set non-negative least squares. C: r×k, d: r. maxIterations ≤ 0 means 3k.
/// tolerance: a bound variable is freed when its multiplier w_j = [Cᵀ(d − Cx)]_j exceeds it;
/// ≤ 0 means 10·eps·k·‖C‖·max(1, ‖d‖) (the rounding level of w). Throws std::invalid_argument on
/// a size mismatch or a non-finite entry.
NnlsResult solveNonNegativeLeastSquares(const Eigen::MatrixXd& C, const Eigen::VectorXd& d,
                                        int maxIterations = 0, double tolerance = 0.0);

struct TensionDistributionOptions {
  /// μ (N²), the barrier weight (file comment). A tendon whose resting-point shortfall is s keeps
  /// ≈ μ/s: 1e-2 N² leaves the hand's "unneeded" tendons at 1.6–12 mN, far below u_rest, yet above
  /// what the feedback takes away once the perturbation has decayed (1e-3: tensions down to 0.2 mN
  /// and the closed loop clipped at 0 in 10 % of its evaluations instead of 0.2 %).
  double barrier = 1e-2;
  double restingTension = 0.5;  ///< u_rest (N), every tendon
  int maxIterations = 200;      ///< Newton iterations of the interior-point solve (all phases)
};

struct TensionDistribution {
  Eigen::VectorXd tension;        ///< m, every entry > 0 when converged
  Eigen::VectorXd lambda;         ///< nc
  /// ‖B u + Aᵀ λ − r‖∞ / max(‖r‖∞, ‖B‖∞·‖u‖∞): the relative inverse-dynamics residual.
  double relativeResidual = 0.0;
  double residual = 0.0;          ///< ‖B u + Aᵀ λ − r‖∞ (N m / N)
  int iterations = 0;             ///< Newton iterations of the interior-point solve
  /// Converged: the KKT residual at rounding level, every tension > 0, and the dynamics
  /// evaluation was ok.
  bool converged = false;
  std::string message;            ///< empty when converged; else what failed and the residuals
};

/// The tension distribution at (q, q̇) for the acceleration q̈ (n-vectors). Uses data as workspace.
/// Throws std::invalid_argument on size mismatches.
TensionDistribution distributeTensions(const Model& model, Data& data, const Eigen::VectorXd& q,
                                       const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd,
                                       const TensionDistributionOptions& options = {});

struct ReferenceMotionOptions {
  double duration = 3.0;  ///< s
  int knots = 301;        ///< N ≥ 2, uniform in [0, duration]
  /// Drivers: each digit's main flexion coordinate (fingers' MCP flexion, thumb's CMC flexion),
  /// moving by amplitude_i · (1 − cos(2π t / T)) / 2 (out and back; zero velocity at both ends).
  std::vector<std::string> drivers = {"index_mcp_flex", "middle_mcp_flex", "ring_mcp_flex",
                                      "little_mcp_flex", "thumb_cmc_flex"};
  /// rad, one per driver. Positive = more MCP (CMC) flexion, which with the pads pinned extends
  /// PIP and DIP; the grasp reaches the PIP-straight posture near +0.25 and the DIP-straight
  /// singularity near −0.06, so the motion flexes by about half the available range.
  std::vector<double> amplitudes = {0.12, 0.10, 0.12, 0.10, 0.12};
  TensionDistributionOptions tensions;
  /// Give the trajectory input derivatives (the cubic Hermite input rule; file comment). False:
  /// no rates, the linear rule (the rates are still computed and reported).
  bool inputRates = true;
  /// δ (s) of the central difference quotient of the design: truncation δ² |d³u/dt³| / 6 against
  /// the design's rounding (~1e-12 N) over δ.
  double rateStep = 1e-4;
};

struct ReferenceMotion {
  Trajectory trajectory;                 ///< states [q; q̇] (2n×N), inputs = tensions (m×N);
                                         ///< state derivatives [q̇; q̈] of the design are set
  Eigen::MatrixXd accelerations;         ///< n×N designed q̈
  Eigen::MatrixXd lambda;                ///< nc×N constraint forces of the distribution
  Eigen::VectorXd constraintResidual;    ///< N: ‖h(q_k)‖∞ (m)
  Eigen::VectorXd velocityResidual;      ///< N: ‖A q̇_k‖∞
  Eigen::VectorXd accelerationResidual;  ///< N: ‖A q̈_k + Ȧ q̇_k‖∞
  Eigen::VectorXd dynamicsResidual;      ///< N: relative inverse-dynamics residual (see above)
  /// N: ‖q̈_fd − q̈_k‖∞ with q̈_fd = forward dynamics (computeDynamics) under the tensions u_k.
  Eigen::VectorXd forwardDynamicsError;
  /// m×N: the tensions' rates u̇_k (given to the trajectory when options.inputRates).
  Eigen::MatrixXd inputRates;
  /// N: ‖u̇ − u̇_fd‖∞, the exact correction of the difference quotient (its error in the directions
  /// the dynamics see; N/s).
  Eigen::VectorXd rateCorrection;
  /// N: ‖u̇_fd(δ) − u̇_fd(2δ)‖∞ ≈ 3 × the quotient's truncation error (N/s).
  Eigen::VectorXd rateDifferenceEstimate;
  /// N: ‖∂q̈_d/∂x ẋ + ∂q̈_d/∂u u̇ − q⃛_d‖∞ / max(‖q⃛_d − ∂q̈_d/∂x ẋ‖∞, 1e-300) of the final u̇ on
  /// the driver rows (rounding level when the correction succeeded).
  Eigen::VectorXd rateResidual;
  bool ok = false;
  std::string message;                   ///< first failure (knot, time, what), empty when ok
};

/// Designs the motion from the configuration q0 (projected onto h = 0 first; q0 need not be exact)
/// and distributes the tensions. Throws std::invalid_argument on unknown driver names, a
/// driver/amplitude count mismatch or knots < 2; numerical failure is reported in the result.
ReferenceMotion makeReferenceMotion(const Model& model, const Eigen::VectorXd& q0,
                                    const ReferenceMotionOptions& options = {});

}  // namespace trellis::hand
