// trellis/optimization/optimizer.hpp — solves an optimal control problem with Ipopt.
//
// The transcription (transcription.hpp) is handed to Ipopt 3.11 through its TNLP interface (kept
// in src/, Ipopt appears in no public header): exact sparse constraint Jacobian, analytic cost
// gradient, and the Hessian of the Lagrangian approximated by Ipopt's limited-memory
// quasi-Newton (L-BFGS) update. Linear solver: MUMPS (Debian's build).
//
// "solved" means the plant can follow the result: after Ipopt converges, the knots are checked a
// posteriori (checkConsistency, trellis/analysis/consistency.hpp: the exact dynamics integrated by
// CVODES over every interval from every knot under the linear input every reader applies), and
// with a closed chain the slack's share of the defect is measured on the same scale. When either
// exceeds `consistencyTolerance`, the mesh is refined and the problem solved again (below); when
// the refinement limit is reached first, the status is `inconsistent` and the message says where.
//
// Mesh refinement (the explicit-simulation error estimate of Haman & Rao 2024; the subdivision
// rule of Betts' SOS and GPOPS-II's h-method): interval k with relative defect ε_k > tol is cut
// into M_k = clamp(⌈(ε_k / (tol/2))^(1/(p+1))⌉, 2, maxSplit) equal parts, where p + 1 is the
// local order of the defect (5 for Hermite–Simpson, 3 for trapezoidal): with ε ∝ h^(p+1), that
// brings the interval to half the tolerance. The new problem is warm-started from the previous
// solution (states from its Hermite spline, inputs exactly, since the input is piecewise linear
// and the new knots subdivide the old intervals). Rounds stop at the tolerance, at
// maxRefinements, or when the knots would exceed maxKnots.
#pragma once

#include "trellis/analysis/consistency.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/optimization/problem.hpp"
#include "trellis/optimization/transcription.hpp"

#include <Eigen/Core>

#include <functional>
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

/// Options of optimizeTrajectory: Ipopt's settings, the derivative mode, and the a-posteriori
/// consistency check with its mesh refinement.
struct OptimizerOptions {
  int printLevel = 0;              ///< Ipopt's print_level (0 silent … 12); 5 is its usual log
  int maxIterations = 1000;        ///< max_iter
  double tolerance = 1e-8;         ///< tol (relative KKT error)
  double constraintTolerance = 1e-8;  ///< constr_viol_tol (absolute, on g and the bounds)
  double maxCpuTime = 1e6;         ///< max_cpu_time, seconds
  int limitedMemorySize = 6;       ///< limited_memory_max_history
  DerivativeMode derivatives = DerivativeMode::kExact;  ///< exact linearizations (or differences, for comparison)
  /// The a-posteriori check (file comment): "solved" requires the worst relative defect, and
  /// the slack's relative share, ≤ consistencyTolerance.
  double consistencyTolerance = 1e-3;
  int maxRefinements = 6;   ///< rounds of mesh refinement after the first solve (0: check only)
  int maxKnots = 2001;      ///< refinement stops before exceeding this
  int maxSplit = 4;         ///< at most this many parts per interval and round
  /// Called after every iteration (on the solver's thread); return false to stop the solve
  /// (status "User_Requested_Stop").
  std::function<bool(const IterationInfo&)> onIteration;

  /// Throws std::invalid_argument naming the bad field.
  void validate() const;
};

enum class OptimizationStatus {
  kSolved,              ///< Ipopt converged to tol (Solve_Succeeded)
  kSolvedAcceptable,    ///< converged to its acceptable tolerances (Solved_To_Acceptable_Level)
                        ///< and consistent
  kInconsistent,        ///< Ipopt converged but the solution fails the consistency check (or the
                        ///< slack is above it) after the allowed refinements
  kInfeasible,          ///< converged to a point of local infeasibility (Infeasible_Problem_Detected)
  kIterationLimit,      ///< Maximum_Iterations_Exceeded or Maximum_CpuTime_Exceeded
  kStopped,             ///< onIteration returned false
  kFailed,              ///< any other Ipopt failure (restoration failed, step too small, …)
};

/// One solve of the refinement sequence.
struct RefinementRound {
  int knots = 0;                ///< N, the mesh's knots in this round
  int iterations = 0;           ///< Ipopt iterations of this round
  std::string ipoptStatus;      ///< Ipopt's return status name of this round
  double maxDefect = 0.0;       ///< checkConsistency's worst relative defect (NaN when not checked)
  double maxSlackDefect = 0.0;  ///< the slack's worst relative share of a defect
  double solveTime = 0.0;       ///< wall-clock seconds (Ipopt and the check)
};

/// "solved", "solved_acceptable", "inconsistent", "infeasible", "iteration_limit", "stopped",
/// "failed".
const char* toString(OptimizationStatus status);

/// The optimized trajectory (or the last iterate), the status — solved only when Ipopt converged
/// and the a-posteriori check against the exact dynamics passed —, and the solve's diagnostics.
struct OptimizationResult {
  OptimizationStatus status = OptimizationStatus::kFailed;  ///< see OptimizationStatus
  std::string ipoptStatus;     ///< Ipopt's ApplicationReturnStatus name, e.g. "Solve_Succeeded"
  std::string message;         ///< one line for a person: the status and, on failure, why
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
  double horizon = 0.0;        ///< T of the returned iterate
  ///@{
  /// Forward dynamics and exact linearizations evaluated, all rounds.
  long dynamicsEvaluations = 0, linearizationEvaluations = 0;
  ///@}
  /// The returned iterate at the knots — the solution, or the last iterate when the solve failed
  /// (empty only if that iterate is not finite; the message then says so).
  Trajectory trajectory;
  ///@{
  /// Hermite–Simpson only: the states (2n×(N−1)) and inputs (m×(N−1)) at the interval midpoints.
  Eigen::MatrixXd midpointStates, midpointInputs;
  ///@}
  Eigen::VectorXd variables;   ///< z (transcription layout)

  /// Solved or solved to the acceptable level, and consistent with the exact dynamics.
  bool success() const {
    return status == OptimizationStatus::kSolved || status == OptimizationStatus::kSolvedAcceptable;
  }
};

/// Transcribes, solves, checks and refines (file comment). Throws ProblemError / std::invalid_argument for a bad problem or bad
/// options; a numerical failure is the result's status, never an exception.
OptimizationResult optimizeTrajectory(const OptimalControlProblem& problem,
                                      const OptimizerOptions& options = {});

}  // namespace trellis
