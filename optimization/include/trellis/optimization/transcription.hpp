// trellis/optimization/transcription.hpp — direct collocation: the optimal control problem of
// problem.hpp as a sparse nonlinear program
//
//   minimize J(z)   subject to   g(z) = 0,   z_lower ≤ z ≤ z_upper,
//
// with exact first derivatives: ∂g/∂z is assembled from the core's A = ∂f/∂x and B = ∂f/∂u
// (computeLinearization) and ∂J/∂z is analytic; and with exact second derivatives: the
// Lagrangian Hessian from the core's computeSecondOrderContraction (evalHessian, formulas in
// transcription.cpp and optimization/README.md). The NLP is independent of the solver; the Ipopt
// adapter (optimizer.hpp) and the tests' finite-difference checker both call it.
//
// Knots t_k = T τ_k on the mesh τ (problem.mesh; uniform τ_k = k/(N − 1) by default), interval
// k has length h_k = T (τ_{k+1} − τ_k). Points p are where f is evaluated:
//  - Hermite–Simpson (separated form, Betts' "HS separated"): the knots and the interval
//    midpoints t_{k+½}, in time order (knot k is point 2k, midpoint k is point 2k + 1; P = 2N − 1).
//    The midpoint state x_m and the midpoint input u_m are variables; per interval [a, b]:
//      Simpson defect   x_b − x_a − h/6 (f_a + 4 f_m + f_b)       = 0   (2n rows)
//      Hermite defect   x_m − (x_a + x_b)/2 − h/8 (f_a − f_b)     = 0   (2n rows)
//      linear input     u_m − (u_a + u_b)/2                       = 0   (m rows)
//    The state is the cubic Hermite spline of the knots and the input is LINEAR between knots —
//    the rule by which every trellis tool reads a trajectory CSV (trajectory.hpp), so the knots
//    written are exactly what was optimized (a free u_m, the textbook choice, would make the
//    optimized input a quadratic the CSV cannot carry). Local error O(h⁵), global O(h⁴) for
//    the dynamics under that input. The separated form keeps each row's Jacobian a few dense
//    blocks (best for a sparse LDLᵀ).
//  - trapezoidal: the knots only (P = N); per interval x_b − x_a − h/2 (f_a + f_b) = 0; the input
//    is piecewise linear; global error O(h²).
// The running cost uses the same quadrature (Simpson weights h/6, 4h/6, h/6, or h/2, h/2).
//
// Closed chains (nc rows, Jacobian A_c; the nH holonomic ones have h(q), A_c = ∂h/∂q; a knife
// edge is a nonholonomic row A_c(q) q̇ = 0 without h): every knot adds the rows
//   h(q_k) = 0 (nH holonomic rows),  A_c(q_k) q̇_k = 0 (nc),
// with ∂(A_c q̇)/∂q from the core (data.constraintVelocityJacobian). The discrete dynamics keep
// these only to the collocation error, so imposing them at every knot over-determines the NLP; as
// Posa, Kuindersma & Tedrake (2016) do, each interval gets slack γ_k (nH), μ_k (nc) that enter
// the end knot's defect along the constraint normals:  Simpson (or trapezoidal) defect −
// [A_H(q_b)ᵀ γ_k; A_c(q_b)ᵀ μ_k]. At a solution γ, μ are of the order of the collocation error
// (the optimizer refuses "solved" when their contribution exceeds its consistency tolerance).
// ∂(A_rᵀ γ_r)/∂q = γ_r S_r with S_r(i, j) = ∂A_{r,i}/∂q_j: for holonomic rows S_r = ∇²h_r,
// exact from the core's drift Ȧ q̇ = q̇ᵀ ∇²h q̇ at unit and paired unit velocities
// (polarization); with a knife edge, row i of every S_r is the core's ∂(A q̇)/∂q at q̇ = e_i.
//
// Variable layout: z = [x_0, u_0, x_1, u_1, …, x_{P−1}, u_{P−1}, γ_0, μ_0, …, γ_{N−2}, μ_{N−2}, T]
// (slack only with constraints, T only when free). Constraint layout: per interval the Simpson
// (or trapezoidal) defect, then for Hermite–Simpson the Hermite defect and the m input rows;
// then the knot constraints knot by knot (h rows, then A q̇ rows); then, with bounds on constraint
// forces (problem.forceLower/Upper), point by point the rows λ_r(x_p, u_p) of the bounded
// constraints r, with Jacobian ∂λ/∂[x; u] (the core's dlambda_dx): inequalities, whose bounds
// constraintBounds() gives (every other row is an equality g = 0).
//
// Implicit dynamics form (problem.dynamics = kImplicit): each point's block is [x_p; u_p; q̈_p; λ_p]
// (stride 3n + m + nc), f_p = [q̇_p; q̈_p] is read from z (the defects are linear in the point
// variables), the force rows are C λ_p (linear), and after the force rows come, point by point,
// the rows [r; c] = [M q̈ + b − Aᵀλ; A q̈ + Ȧ q̇] (n + nc, equalities; computeImplicitDynamics).
// The guess's q̈ is the slope of its velocities between neighbouring points, λ the least-squares
// balance Aᵀλ ≈ M q̈ + b. Hessian: per point ∇²(νᵀr + ηᵀc) by computeImplicitSecondOrder.
//
// Evaluations are cached: f (and A, B for derivatives) are computed once per distinct z, whatever
// the order of the calls: z is compared with the cached copy (a memcmp), which covers Ipopt's
// new_x flag and also callers that do not pass one (the tests' checker).
#pragma once

#include "trellis/core/trajectory.hpp"
#include "trellis/optimization/problem.hpp"

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

namespace trellis {

/// How ∂f/∂x, ∂f/∂u are obtained for the constraint Jacobian.
enum class DerivativeMode {
  kExact,             ///< the core's computeLinearization (the product)
  kFiniteDifference,  ///< central differences of computeDynamics at every point, step
                      ///< ε^(1/3)·max(1, |v|) (a baseline for the benchmark; same NLP, same pattern)
};

/// The problem as a nonlinear program (file comment): the variable layout z, the cost J(z), the
/// defects and path constraints g(z) with their Jacobian's fixed sparsity, and reading a solution
/// back. Owns its workspace (one per solve, not thread safe); evaluations never throw.
class Transcription {
 public:
  /// Validates the problem (throws ProblemError) and sizes every buffer.
  explicit Transcription(OptimalControlProblem problem,
                         DerivativeMode derivatives = DerivativeMode::kExact);
  ~Transcription();
  ///@{
  /// Movable (the workspace moves with it), not copyable.
  Transcription(Transcription&&) noexcept;
  Transcription& operator=(Transcription&&) noexcept;
  ///@}

  const OptimalControlProblem& problem() const;  ///< the validated problem it transcribes
  /// Threads for the Hessian's per-point blocks, the knots' third-derivative terms and constraint
  /// Hessians (1..kMaxThreads; independent pieces gathered in order: the same values on any
  /// count). Throws std::invalid_argument.
  void setThreads(int threads);
  static constexpr int kMaxThreads = 256;  ///< the largest thread count setThreads accepts

  // ---- Sizes and layout ----------------------------------------------------------------------
  int numVariables() const;    ///< entries of z
  int numConstraints() const;  ///< entries of g(z)
  int numPoints() const;       ///< P: knots (and midpoints for Hermite–Simpson)
  int numKnots() const;        ///< N
  int stateIndex(int point) const;   ///< index in z of x at point p (2n entries follow)
  int inputIndex(int point) const;   ///< index in z of u at point p (m entries follow)
  int slackIndex(int interval) const;  ///< index of γ_k (then μ_k); −1 without constraints
  int horizonIndex() const;    ///< index of T in z, −1 when the horizon is fixed
  int knotPoint(int knot) const;     ///< point index of knot k
  /// Number of the first constraint row of knot k's constraint rows (2 nc rows), −1 without.
  int knotConstraintRow(int knot) const;

  /// The declared sparsity pattern of ∂g/∂z (row, column pairs; fixed for the problem).
  ///@{
  /// The declared sparsity pattern of ∂g/∂z: row and column of each nonzero (fixed for the problem).
  const std::vector<int>& jacobianRows() const;
  const std::vector<int>& jacobianCols() const;
  ///@}

  /// Bounds on z (fixed boundary entries have equal bounds; no bound is ±infinity).
  void variableBounds(Eigen::VectorXd& lower, Eigen::VectorXd& upper) const;
  /// Bounds on g: 0 = 0 for every equality row; [λ_lower_r, λ_upper_r] for the constraint-force
  /// rows (±infinity for no bound on one side).
  void constraintBounds(Eigen::VectorXd& lower, Eigen::VectorXd& upper) const;
  /// Constraint-force rows per point (the constraint rows with a finite bound; 0 without) and the
  /// first of point p's (−1 without).
  ///@{
  int forceRowsPerPoint() const;
  int forceRow(int point) const;
  ///@}
  /// The initial guess z₀ (problem.initialGuess, else linear interpolation), inside the bounds.
  Eigen::VectorXd initialGuess() const;

  // ---- Evaluation: z has numVariables() entries. Each returns false when the dynamics cannot
  // be evaluated at some point (lastError() names the point and the time); never throws. ------
  bool evalCost(const double* z, double& cost);                ///< J(z) (file comment's quadrature)
  bool evalCostGradient(const double* z, double* gradient);    ///< numVariables()
  bool evalConstraints(const double* z, double* g);            ///< numConstraints()
  bool evalJacobian(const double* z, double* values);          ///< in jacobianRows/Cols order
  const std::string& lastError() const;  ///< what the last failing evaluation could not compute, where

  // ---- Lagrangian Hessian: σ ∇²J + Σ_c μ_c ∇²g_c, exact (the core's second derivatives of the
  // dynamics, computeSecondOrderContraction, one per point per evaluation). Lower triangle
  // (row ≥ column) in a pattern fixed at construction; values allocation-free.
  /// Whether evalHessian can give the exact Hessian (else hessianUnavailableReason() says why and
  /// evalHessian returns false). True for every problem the constructor accepts: knife-edge rows
  /// included, whose third-derivative terms ∇²_q(ρᵀA(q)v) come from the recorded implicit residual.
  bool hessianAvailable() const;
  const std::string& hessianUnavailableReason() const;  ///< empty when hessianAvailable()
  ///@{
  /// The Hessian's pattern: row and column of each stored entry (lower triangle, row ≥ column).
  const std::vector<int>& hessianRows() const;
  const std::vector<int>& hessianCols() const;
  ///@}
  /// objectiveFactor σ, multipliers μ (numConstraints()); values in hessianRows/Cols order.
  bool evalHessian(const double* z, double objectiveFactor, const double* multipliers, double* values);

  /// Number of core evaluations so far (computeDynamics and computeLinearization calls, per
  /// point), a measure of the caching.
  long dynamicsEvaluations() const;
  /// Number of computeLinearization calls so far (see dynamicsEvaluations).
  long linearizationEvaluations() const;
  long secondOrderEvaluations() const;  ///< computeSecondOrderContraction calls

  // ---- Reading a solution --------------------------------------------------------------------
  double horizon(const double* z) const;  ///< T at z (the fixed horizon, or z's horizon entry)
  /// The knots as a Trajectory (times, states 2n×N, inputs m×N, the model's names).
  Trajectory trajectory(const double* z) const;
  /// Hermite–Simpson midpoints: states 2n×(N−1) and inputs m×(N−1); empty for trapezoidal.
  Eigen::MatrixXd midpointStates(const double* z) const;
  /// The Hermite–Simpson midpoint inputs, m×(N−1); empty for trapezoidal (see midpointStates).
  Eigen::MatrixXd midpointInputs(const double* z) const;
  /// max |γ|, |μ| over the intervals (0 without constraints).
  double maxSlack(const double* z) const;
  /// What the slack adds to each interval's defect, [A_H(q_b)ᵀ γ_k; A_c(q_b)ᵀ μ_k] (2n×(N−1),
  /// zero without constraints): the amount by which the knots depart from the discrete dynamics.
  Eigen::MatrixXd slackContributions(const double* z) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace trellis
