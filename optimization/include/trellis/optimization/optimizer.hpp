// trellis/optimization/optimizer.hpp — solves an optimal control problem with Ipopt.
//
// The transcription (transcription.hpp) is handed to Ipopt 3.11 through its TNLP interface (kept
// in src/, Ipopt appears in no public header): exact sparse constraint Jacobian, analytic cost
// gradient, and the Hessian of the Lagrangian approximated by Ipopt's limited-memory
// quasi-Newton (L-BFGS) update. Linear solver: MUMPS (Debian's build).
#pragma once

#include "trellis/control/trajectory.hpp"
#include "trellis/optimization/problem.hpp"
#include "trellis/optimization/transcription.hpp"

#include <Eigen/Core>

#include <functional>
#include <string>

namespace trellis {

/// One Ipopt iteration, as its intermediate callback reports it.
struct IterationInfo {
  int iteration = 0;
  double cost = 0.0;
  double constraintViolation = 0.0;  ///< inf_pr: max |g(z)| (scaled by Ipopt's NLP scaling)
  double dualInfeasibility = 0.0;    ///< inf_du
  double stepSize = 0.0;             ///< alpha_pr
  bool restoration = false;          ///< in the feasibility restoration phase
};

struct OptimizerOptions {
  int printLevel = 0;              ///< Ipopt's print_level (0 silent … 12); 5 is its usual log
  int maxIterations = 1000;        ///< max_iter
  double tolerance = 1e-8;         ///< tol (relative KKT error)
  double constraintTolerance = 1e-8;  ///< constr_viol_tol (absolute, on g and the bounds)
  double maxCpuTime = 1e6;         ///< max_cpu_time, seconds
  int limitedMemorySize = 6;       ///< limited_memory_max_history
  DerivativeMode derivatives = DerivativeMode::kExact;
  /// Called after every iteration (on the solver's thread); return false to stop the solve
  /// (status "User_Requested_Stop").
  std::function<bool(const IterationInfo&)> onIteration;

  /// Throws std::invalid_argument naming the bad field.
  void validate() const;
};

enum class OptimizationStatus {
  kSolved,              ///< Ipopt converged to tol (Solve_Succeeded)
  kSolvedAcceptable,    ///< converged to its acceptable tolerances (Solved_To_Acceptable_Level)
  kInfeasible,          ///< converged to a point of local infeasibility (Infeasible_Problem_Detected)
  kIterationLimit,      ///< Maximum_Iterations_Exceeded or Maximum_CpuTime_Exceeded
  kStopped,             ///< onIteration returned false
  kFailed,              ///< any other Ipopt failure (restoration failed, step too small, …)
};

/// "solved", "solved_acceptable", "infeasible", "iteration_limit", "stopped", "failed".
const char* toString(OptimizationStatus status);

struct OptimizationResult {
  OptimizationStatus status = OptimizationStatus::kFailed;
  std::string ipoptStatus;     ///< Ipopt's ApplicationReturnStatus name, e.g. "Solve_Succeeded"
  std::string message;         ///< one line for a person: the status and, on failure, why
  int iterations = 0;
  double cost = 0.0;           ///< J at the returned iterate
  double constraintViolation = 0.0;  ///< max |g(z)| of the returned iterate (unscaled)
  double boundViolation = 0.0;       ///< max violation of the variable bounds (unscaled)
  double maxSlack = 0.0;       ///< closed chains: max |γ|, |μ| (transcription.hpp)
  double solveTime = 0.0;      ///< wall-clock seconds of the Ipopt solve
  double solveCpuTime = 0.0;   ///< CPU seconds of the process during the solve (std::clock)
  double horizon = 0.0;        ///< T of the returned iterate
  long dynamicsEvaluations = 0, linearizationEvaluations = 0;
  /// The returned iterate at the knots — the solution, or the last iterate when the solve failed
  /// (empty only if that iterate is not finite; the message then says so).
  Trajectory trajectory;
  Eigen::MatrixXd midpointStates, midpointInputs;  ///< Hermite–Simpson only (2n×(N−1), m×(N−1))
  Eigen::VectorXd variables;   ///< z (transcription layout)

  bool success() const {
    return status == OptimizationStatus::kSolved || status == OptimizationStatus::kSolvedAcceptable;
  }
};

/// Transcribes and solves. Throws ProblemError / std::invalid_argument for a bad problem or bad
/// options; a numerical failure is the result's status, never an exception.
OptimizationResult optimizeTrajectory(const OptimalControlProblem& problem,
                                      const OptimizerOptions& options = {});

}  // namespace trellis
