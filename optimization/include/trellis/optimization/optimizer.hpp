// trellis/optimization/optimizer.hpp — solves an optimal control problem with Ipopt.
//
// The transcription (transcription.hpp) is handed to Ipopt 3.11 through its TNLP interface (kept
// in src/, Ipopt appears in no public header): exact sparse constraint Jacobian, analytic cost
// gradient, and the exact Hessian of the Lagrangian (Transcription::evalHessian, every constraint
// kind; or, by choice, Ipopt's limited-memory quasi-Newton (L-BFGS) update). Linear
// solver: MUMPS (Debian's build).
//
// "solved" means the plant can follow the result: after Ipopt converges, the knots are checked a
// posteriori (checkConsistency, trellis/analysis/consistency.hpp: the exact dynamics integrated by
// CVODES over every interval from every knot under the linear input every reader applies), and
// with a closed chain the slack's share of the defect is measured on the same scale. When either
// exceeds `consistencyTolerance`, the mesh is refined and the problem solved again (below); when
// the refinement limit is reached first, the status is `inconsistent` and the message says where.
//
// Mesh refinement (the explicit-simulation error estimate of Haman & Rao 2024; the subdivision
// rule of Betts' SOS and GPOPS-II's h-method; refinementSplits): interval k with relative defect
// ε_k > tol is cut into M_k = clamp(⌈(ε_k / (tol/2))^(1/(p+1))⌉, 2, maxSplit) equal parts, where
// p + 1 is the local order of the defect (5 for Hermite–Simpson, 3 for trapezoidal): with
// ε ∝ h^(p+1), that brings the interval to half the tolerance. Two rules make that converge on
// swing-ups whose minimum-effort motion is a fast "whip" (issue 30): the `refinementBand`
// intervals on each side of a cut interval are halved too, since the re-optimized motion moves
// its fast phase into the neighbours of the intervals that were cut (without the band it moved
// one step further every round, and the worst defect was not monotone); and when the worst
// defect exceeds `unresolvedDefect` (a share of the state's range, 5 %) the motion is resolved
// nowhere and every interval is halved. With `refinementGrading` ρ > 0 (opt-in) neighbouring new
// widths then differ by at most ρ. Intervals are never merged. The new problem is
// warm-started from the previous solution (states from its Hermite spline, inputs exactly, since
// the input is piecewise linear and the new knots subdivide the old intervals) and, with
// `warmStart`, from its multipliers carried onto the new mesh (Ipopt's warm_start_init_point;
// optimizer.cpp: carryOver). Rounds stop at the tolerance, at maxRefinements, or when the knots
// would exceed maxKnots.
#pragma once

#include "trellis/analysis/consistency.hpp"
#include "trellis/core/status.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/optimization/problem.hpp"
#include "trellis/optimization/transcription.hpp"

#include <Eigen/Core>

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace trellis {

/// One Ipopt iteration, as its intermediate callback reports it.
struct IterationInfo {
  int iteration = 0;                 ///< Ipopt's iteration count (0: the starting point)
  double cost = 0.0;                 ///< J at the iterate
  double constraintViolation = 0.0;  ///< inf_pr: max |g(z)| (scaled by Ipopt's NLP scaling)
  double dualInfeasibility = 0.0;    ///< inf_du
  double stepSize = 0.0;             ///< alpha_pr
  bool restoration = false;          ///< in the feasibility restoration phase
};

/// The fill-reducing ordering MUMPS computes for Ipopt's KKT matrix (its ICNTL(7), Ipopt's
/// mumps_pivot_order). The ordering sets the factor's fill, so the factorizations' cost; the
/// iterates agree to the solver's rounding. kAuto lets MUMPS choose (METIS here). Measured on
/// the hand turning the ball (6 100 × 6 100 KKT, 67–70 iterations, 2026-12-04): auto 12.7 s of
/// factorizations, PORD 10.3 s, SCOTCH 12.8 s, AMD 7.8 s, QAMD 7.7 s.
enum class MumpsOrdering { kAuto, kAmd, kAmf, kScotch, kPord, kMetis, kQamd };

/// Options of optimizeTrajectory: Ipopt's settings, the derivative mode, and the a-posteriori
/// consistency check with its mesh refinement.
struct OptimizerOptions {
  int printLevel = 0;              ///< Ipopt's print_level (0 silent … 12); 5 is its usual log
  int maxIterations = 1000;        ///< max_iter
  double tolerance = 1e-8;         ///< tol (relative KKT error)
  double constraintTolerance = 1e-8;  ///< constr_viol_tol (absolute, on g and the bounds)
  double maxCpuTime = 1e6;         ///< max_cpu_time, seconds
  int limitedMemorySize = 6;       ///< limited_memory_max_history
  MumpsOrdering ordering = MumpsOrdering::kAuto;  ///< mumps_pivot_order (MumpsOrdering)
  /// Threads for the Hessian's blocks and the knots' second derivatives (Transcription::setThreads;
  /// 1..256): the same iterates on any count. Ipopt and MUMPS (sequential) stay on the calling
  /// thread.
  int threads = 1;
  DerivativeMode derivatives = DerivativeMode::kExact;  ///< exact linearizations (or differences, for comparison)
  /// The Lagrangian Hessian; unset: the problem's (OptimalControlProblem::hessian, default exact).
  /// Should the transcription not give the exact one, L-BFGS is used (the result's `hessian` and
  /// message say so; no model the transcription accepts does that today).
  std::optional<HessianMode> hessian;
  /// Refinement rounds start from the previous round's primal and multipliers (carried onto the
  /// refined mesh) with Ipopt's warm_start_init_point and μ_init = warmStartBarrier.
  bool warmStart = true;
  double warmStartBarrier = 1e-6;  ///< Ipopt's mu_init in warm-started rounds
  /// The first round's start: Ipopt's mu_init and its bound_push = bound_frac (how far the guess
  /// is moved off its bounds; Ipopt's defaults 0.1 and 0.01). A guess that is nearly a solution
  /// wants both small: on a stiff model a push of 0.01 in an input at its bound can cost more
  /// defect than the whole guess has (a hand's tendon at 0 N moves a phalanx by ~10² rad/s²).
  double initialBarrier = 0.1;     ///< mu_init of the first round
  double initialBoundPush = 1e-2;  ///< bound_push and bound_frac of the first round
  /// The a-posteriori check (file comment): "solved" requires the worst relative defect, and
  /// the slack's relative share, ≤ consistencyTolerance.
  double consistencyTolerance = 1e-3;
  int maxRefinements = 6;   ///< rounds of mesh refinement after the first solve (0: check only)
  int maxKnots = 2001;      ///< refinement stops before exceeding this
  int maxSplit = 4;         ///< at most this many parts per interval and round
  /// Intervals on each side of an interval that is cut which are halved too (the safety band;
  /// file comment). 0: only the intervals above the tolerance are cut.
  int refinementBand = 3;
  /// A worst relative defect above this (a share of the state's range) halves every interval.
  double unresolvedDefect = 0.05;
  /// Opt-in grading (0: off): neighbouring new widths differ by at most this factor (> 1), so a
  /// moving fast phase finds no coarse interval next to a fine one. Measured with 1.5 (issue 30,
  /// docs/performance.md): solves the 4-link chain from 51 and 61 knots where the band alone does
  /// not, but from the file's 41 knots ends at the iteration limit — hence not the default.
  double refinementGrading = 0.0;
  /// Called after every iteration (on the solver's thread); return false to stop the solve
  /// (status "User_Requested_Stop").
  std::function<bool(const IterationInfo&)> onIteration;

  /// Throws std::invalid_argument naming the bad field.
  void validate() const;
};

/// The outcome of optimizeTrajectory (Status<OptimizationCode>: success is solved or
/// solved_acceptable).
enum class OptimizationCode {
  kSolved,              ///< Ipopt converged to tol (Solve_Succeeded) and the result is consistent
  kSolvedAcceptable,    ///< converged to its acceptable tolerances (Solved_To_Acceptable_Level)
                        ///< and consistent
  kInconsistent,        ///< Ipopt converged but the solution fails the consistency check (or the
                        ///< slack is above it) after the allowed refinements
  kInfeasible,          ///< converged to a point of local infeasibility (Infeasible_Problem_Detected)
  kIterationLimit,      ///< Maximum_Iterations_Exceeded or Maximum_CpuTime_Exceeded
  kStopped,             ///< onIteration returned false
  kFailed,              ///< any other Ipopt failure (restoration failed, step too small, …)
};

/// Names: solved, solved_acceptable, inconsistent, infeasible, iteration_limit, stopped, failed.
inline EnumNameTable<OptimizationCode> enumNames(OptimizationCode) {
  static constexpr EnumName<OptimizationCode> table[] = {
      {OptimizationCode::kSolved, "solved"},
      {OptimizationCode::kSolvedAcceptable, "solved_acceptable"},
      {OptimizationCode::kInconsistent, "inconsistent"},
      {OptimizationCode::kInfeasible, "infeasible"},
      {OptimizationCode::kIterationLimit, "iteration_limit"},
      {OptimizationCode::kStopped, "stopped"},
      {OptimizationCode::kFailed, "failed"}};
  return table;
}

constexpr bool isSuccess(OptimizationCode code) {
  return code == OptimizationCode::kSolved || code == OptimizationCode::kSolvedAcceptable;
}

/// One solve of the refinement sequence.
struct RefinementRound {
  int knots = 0;                ///< N, the mesh's knots in this round
  int iterations = 0;           ///< Ipopt iterations of this round
  HessianMode hessian = HessianMode::kExact;  ///< the Hessian Ipopt used
  std::string ipoptStatus;      ///< Ipopt's return status name of this round
  double maxDefect = 0.0;       ///< checkConsistency's worst relative defect (NaN when not checked)
  double maxSlackDefect = 0.0;  ///< the slack's worst relative share of a defect
  double solveTime = 0.0;       ///< wall-clock seconds (Ipopt and the check)
};

/// The optimized trajectory (or the last iterate), the status — solved only when Ipopt converged
/// and the a-posteriori check against the exact dynamics passed —, and the solve's diagnostics.
struct OptimizationResult {
  /// code; message (empty on success; else why, with Ipopt's status and the last evaluation
  /// failure, or for inconsistent the state, interval and time of the worst defect); for
  /// inconsistent, t and index are the worst interval's start time and index (else NaN, −1).
  Status<OptimizationCode> status{OptimizationCode::kFailed, {}};
  std::string ipoptStatus;     ///< Ipopt's ApplicationReturnStatus name, e.g. "Solve_Succeeded"
  /// Non-empty when the exact Hessian was asked for but not available
  /// (Transcription::hessianAvailable): why, and that L-BFGS was used.
  std::string hessianNote;
  int iterations = 0;          ///< Ipopt iterations, summed over the rounds
  double cost = 0.0;           ///< J at the returned iterate
  double constraintViolation = 0.0;  ///< max |g(z)| of the returned iterate (unscaled)
  double boundViolation = 0.0;       ///< max violation of the variable bounds (unscaled)
  double maxSlack = 0.0;       ///< closed chains: max |γ|, |μ| (transcription.hpp)
  /// The slack's share of the defects relative to the state's scale (consistency.hpp), its worst
  /// interval (−1 without constraints).
  double maxSlackDefect = 0.0;
  int worstSlackInterval = -1;  ///< the interval of maxSlackDefect (−1 without constraints)
  ConsistencyResult consistency;  ///< the check of the returned trajectory (empty if not run)
  std::vector<RefinementRound> rounds;  ///< every solve, first to last
  Eigen::VectorXd mesh;         ///< the returned solution's mesh τ (N entries)
  double solveTime = 0.0;      ///< wall-clock seconds of all rounds (Ipopt and checks)
  double solveCpuTime = 0.0;   ///< CPU seconds of the process during them (std::clock)
  ///@{
  /// Where solveTime went (wall seconds, all rounds): inside Ipopt's calls of the cost, the
  /// constraints, their Jacobian and the Hessian (the transcription with the core's dynamics and
  /// derivatives) — of which the Hessian's —, and in the a-posteriori checks. The rest of solveTime
  /// is Ipopt itself with its linear solver (MUMPS) and the set-up.
  double evaluationTime = 0.0, hessianTime = 0.0, checkTime = 0.0;
  ///@}
  double horizon = 0.0;        ///< T of the returned iterate
  ///@{
  /// Forward dynamics, exact linearizations and second-order contractions evaluated, all rounds.
  long dynamicsEvaluations = 0, linearizationEvaluations = 0, secondOrderEvaluations = 0;
  ///@}
  HessianMode hessian = HessianMode::kExact;  ///< the Hessian Ipopt used (last round)
  ///@{
  /// Ipopt's final multipliers (transcription layout): of g(z) = 0, and of the lower and upper
  /// variable bounds.
  Eigen::VectorXd constraintMultipliers, lowerBoundMultipliers, upperBoundMultipliers;
  ///@}
  /// The returned iterate at the knots — the solution, or the last iterate when the solve failed
  /// (empty only if that iterate is not finite; the message then says so).
  Trajectory trajectory;
  ///@{
  /// Hermite–Simpson only: the states (2n×(N−1)) and inputs (m×(N−1)) at the interval midpoints.
  Eigen::MatrixXd midpointStates, midpointInputs;
  ///@}
  Eigen::VectorXd variables;   ///< z (transcription layout)

  /// Solved (or solved_acceptable) and consistent: the trajectory is right and complete.
  bool ok() const { return status.ok(); }
  /// One line: the status, then Ipopt's status, iterations, rounds, knots, cost, constraint
  /// violation, consistency defect (and the slack's share with constraints), Hessian, time.
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "ipopt_status", "iterations", "cost",
  /// "constraint_violation", "bound_violation", "max_slack", "horizon", "knots", "hessian",
  /// "consistency_defect" (null when not checked), "consistency_checked", "consistency_where"
  /// (when checked: state, interval, time), "slack_defect" (with constraints), "refinement_rounds",
  /// "rounds" ([{knots, iterations, defect, hessian}]), "solve_time_ms", "solve_cpu_time_ms",
  /// "evaluation_time_ms", "hessian_time_ms", "check_time_ms"}.
  std::string json() const;
};

/// The refinement rule (file comment): the number of equal parts (1: kept) each interval of
/// `mesh` (N increasing points, e.g. the fractions of T) is cut into, given its relative defect
/// (N − 1: the consistency check's intervalDefects, or the slack's share where larger). Throws
/// std::invalid_argument for bad options, a mesh that does not match or is not increasing, or a
/// negative or NaN defect.
std::vector<int> refinementSplits(const Eigen::VectorXd& mesh, const Eigen::VectorXd& intervalDefects,
                                  CollocationMethod method, const OptimizerOptions& options = {});

/// Transcribes, solves, checks and refines (file comment). Throws ProblemError / std::invalid_argument for a bad problem or bad
/// options; a numerical failure is the result's status, never an exception.
OptimizationResult optimizeTrajectory(const OptimalControlProblem& problem,
                                      const OptimizerOptions& options = {});

}  // namespace trellis
