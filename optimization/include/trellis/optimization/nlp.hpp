// trellis/optimization/nlp.hpp — a small dense nonlinear program solved with Ipopt: for problems
// that are not trajectories (a static equilibrium with inequality constraints, a design point).
//
//   min f(x)   subject to   g_L ≤ g(x) ≤ g_U,   x_L ≤ x ≤ x_U        (x: n, g: m)
//
// The caller gives f with its exact gradient and g with its exact dense Jacobian (one callback
// each; both are asked at the same x in turn, so a caller may share the work). The Hessian of the
// Lagrangian is Ipopt's limited-memory quasi-Newton (L-BFGS) update; linear solver MUMPS. Ipopt
// stays in src/ (nlp.cpp). Numerical failure is the result's status (the same OptimizationCode as
// optimizeTrajectory); a bad problem (sizes, bounds) throws std::invalid_argument naming the field.
#pragma once

#include "trellis/optimization/optimizer.hpp"

#include <Eigen/Core>

#include <functional>
#include <string>

namespace trellis {

/// The program: sizes, bounds (±infinity allowed), the start and the two callbacks. A callback
/// returns false when it cannot evaluate at x (Ipopt then shortens its step); it must not throw
/// (solveNlp catches and stops the solve with the exception's text as the message).
struct NlpProblem {
  Eigen::VectorXd lower;            ///< n: x_L (−infinity: none)
  Eigen::VectorXd upper;            ///< n: x_U (+infinity: none)
  Eigen::VectorXd constraintLower;  ///< m: g_L (equal to g_U for an equality)
  Eigen::VectorXd constraintUpper;  ///< m: g_U
  Eigen::VectorXd start;                           ///< n: x₀ (Ipopt moves it inside the bounds)
  /// f(x) and ∇f(x) (n).
  std::function<bool(const Eigen::VectorXd& x, double& f, Eigen::VectorXd& gradient)> objective;
  /// g(x) (m) and ∂g/∂x (m×n, dense).
  std::function<bool(const Eigen::VectorXd& x, Eigen::VectorXd& g, Eigen::MatrixXd& jacobian)> constraints;
};

/// Ipopt's settings for solveNlp.
struct NlpOptions {
  int printLevel = 0;               ///< print_level (0 silent … 12)
  int maxIterations = 3000;         ///< max_iter
  double tolerance = 1e-8;          ///< tol (relative KKT error)
  double constraintTolerance = 1e-10;  ///< constr_viol_tol (absolute, on g and the bounds)
  double maxCpuTime = 600.0;        ///< max_cpu_time [s]
  int limitedMemorySize = 20;       ///< limited_memory_max_history
  /// bound_relax_factor: Ipopt relaxes every bound, and g_L = g_U of an equality, by this
  /// (relative); its default 1e-8 leaves equalities met only to ~1e-8, so 0 here: the bounds and
  /// equalities as given, met to constraintTolerance.
  double boundRelaxFactor = 0.0;
};

/// The outcome: Ipopt's last iterate (the solution when ok), its multipliers and the figures.
struct NlpResult {
  Status<OptimizationCode> status{OptimizationCode::kFailed, {}};  ///< message: why, when not ok
  std::string ipoptStatus;          ///< Ipopt's ApplicationReturnStatus name
  int iterations = 0;               ///< Ipopt's iterations
  Eigen::VectorXd x;                ///< n: the last iterate
  Eigen::VectorXd g;                ///< m: g(x) there (NaN when it could not be evaluated)
  double objective = 0.0;           ///< f(x)
  double constraintViolation = 0.0;  ///< max over rows of the violation of g_L ≤ g ≤ g_U at x (unscaled)
  double boundViolation = 0.0;       ///< max violation of x_L ≤ x ≤ x_U (unscaled)
  Eigen::VectorXd constraintMultipliers;  ///< m: Ipopt's multipliers of the rows
  Eigen::VectorXd lowerBoundMultipliers;  ///< n: z_L
  Eigen::VectorXd upperBoundMultipliers;  ///< n: z_U
  long evaluations = 0;             ///< calls of the constraint callback
  double solveTime = 0.0;           ///< wall-clock seconds
  bool ok() const { return status.ok(); }  ///< solved, and checked again at x (solveNlp)
};

/// Solves the program with Ipopt (file comment). Throws std::invalid_argument for sizes that do
/// not match, a lower bound above its upper bound, or a missing callback.
NlpResult solveNlp(const NlpProblem& problem, const NlpOptions& options = {});

}  // namespace trellis
