// trellis/optimization/problem.hpp — an optimal control problem on a trellis model.
//
//   minimize    ∫₀ᵀ uᵀ R u + (x − x_goal)ᵀ Q (x − x_goal) dt + (x(T) − x_goal)ᵀ Q_f (x(T) − x_goal)
//               + w_T · T
//   subject to  ẋ = f(x, u) = [q̇; q̈(q, q̇, u)]            (the core's constrained forward dynamics)
//               h(q) = 0, A(q) q̇ = 0                      (closed chains: at every knot;
//                                                          knife edges: A(q) q̇ = 0 only)
//               x_lower ≤ x(t) ≤ x_upper, u_lower ≤ u(t) ≤ u_upper
//               λ_lower ≤ λ(x, u) ≤ λ_upper                (constraint forces, at the points)
//               x(0)_i = x_initial_i for the fixed entries, x(T)_i = x_final_i likewise
//               T fixed, or T_min ≤ T ≤ T_max
//
// x = [q; q̇] (2n) in the model's configuration order, u (m) in its input order. The problem is
// transcribed by direct collocation (transcription.hpp) and solved with Ipopt (optimizer.hpp).
// A problem can also be read from a JSON problem file (optimization/README.md describes it).
#pragma once

#include "trellis/core/enum_names.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/core/model.hpp"

#include <Eigen/Core>

#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace trellis {

/// Bad problem description (C++ struct or problem file). The message names the field (for a
/// file, the file and the JSON path, e.g. "cost.Q.dtheta") and the offending value.
class ProblemError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The collocation rule that turns ẋ = f(x, u) into algebraic defects (transcription.hpp).
enum class CollocationMethod {
  kHermiteSimpson,  ///< separated Hermite–Simpson, midpoint states and inputs are variables (O(h⁴))
  kTrapezoidal,     ///< trapezoidal rule (O(h²)), the cheap option
  /// Radau IIA with 3 stages (c = (4 ∓ √6)/10, 1; O(h⁵)): stage states and inputs are variables,
  /// the inputs linear between knots. L-stable — its stability function tends to 0 as λh → −∞,
  /// where Hermite–Simpson's and the trapezoid's tend to ±1 — so stiff modes (light, damped
  /// bodies: time constants far below h) decay within an interval as they do in the plant,
  /// instead of being carried from knot to knot.
  kRadau,
};

/// How the transcription imposes the dynamics at each collocation point (transcription.hpp).
enum class DynamicsForm {
  /// f(x, u) = [q̇; q̈(q, q̇, u)] from the core's constrained forward dynamics (λ eliminated).
  kExplicit,
  /// q̈ and λ are variables at every point and the equations of motion are rows,
  /// M(q) q̈ + b(q, q̇, u) − A(q)ᵀλ = 0 and A(q) q̈ + Ȧ q̇ = 0 (computeImplicitDynamics): rows in
  /// force units, linear in (q̈, u, λ), where the explicit form divides by light inertias
  /// (|∂q̈/∂q| ~ 10⁵ on the hand) and eliminates λ; force bounds are then linear in the variables.
  /// Exact first and second derivatives (computeImplicitDynamics, computeImplicitSecondOrder).
  kImplicit,
};

/// Names: explicit, implicit.
inline EnumNameTable<DynamicsForm> enumNames(DynamicsForm) {
  static constexpr EnumName<DynamicsForm> table[] = {{DynamicsForm::kExplicit, "explicit"},
                                                     {DynamicsForm::kImplicit, "implicit"}};
  return table;
}

/// The Hessian of the Lagrangian Ipopt works with (problem file "hessian", OptimizerOptions,
/// CLI --hessian).
enum class HessianMode {
  kExact,          ///< the transcription's exact second derivatives (Transcription::evalHessian)
  kLimitedMemory,  ///< Ipopt's limited-memory quasi-Newton (L-BFGS) approximation
};

/// Names: exact, lbfgs.
inline EnumNameTable<HessianMode> enumNames(HessianMode) {
  static constexpr EnumName<HessianMode> table[] = {{HessianMode::kExact, "exact"},
                                                    {HessianMode::kLimitedMemory, "lbfgs"}};
  return table;
}

/// A trajectory optimization problem: minimize J = ∫ uᵀRu + (x − x_g)ᵀQ(x − x_g) [+ q̈ᵀW_a q̈] dt +
/// (x(T) − x_g)ᵀQf(x(T) − x_g) + w_T·T subject to the model's dynamics, boundary states, state and
/// input bounds, over a fixed or free horizon T, transcribed by collocation on a mesh of N knots.
struct OptimalControlProblem {
  /// The model; shared so that the problem, its transcription and results can outlive the scene.
  std::shared_ptr<const Model> model;

  CollocationMethod method = CollocationMethod::kHermiteSimpson;  ///< the collocation rule
  DynamicsForm dynamics = DynamicsForm::kExplicit;  ///< dynamics as f(x, u) or as implicit rows
  int knots = 41;  ///< N ≥ 2 knots t_k = T·τ_k
  /// The mesh τ_0 = 0 < τ_1 < … < τ_{N−1} = 1 (N entries, knot k at t_k = T·τ_k); empty for the
  /// uniform mesh τ_k = k/(N − 1). Mesh refinement (optimizer.hpp) produces non-uniform ones.
  Eigen::VectorXd mesh;
  /// τ_k: `mesh` or the uniform mesh.
  Eigen::VectorXd meshFractions() const;

  /// Horizon T: fixed when minHorizon == maxHorizon (== horizon), otherwise free in
  /// [minHorizon, maxHorizon] with `horizon` as its initial guess.
  double horizon = 1.0;
  ///@{
  /// The horizon's bounds [s] (equal: a fixed horizon).
  double minHorizon = 1.0;
  double maxHorizon = 1.0;
  ///@}
  bool freeHorizon() const { return minHorizon < maxHorizon; }  ///< minHorizon < maxHorizon
  /// Sets a fixed horizon T.
  void setFixedHorizon(double T) { horizon = minHorizon = maxHorizon = T; }

  ///@{
  /// Boundary states x(0), x(T) (2n each; entries not fixed are initial values only).
  Eigen::VectorXd initialState, finalState;
  ///@}
  ///@{
  /// Which entries of the boundary states are fixed (2n flags each, default all fixed).
  std::vector<bool> initialFixed, finalFixed;
  ///@}

  ///@{
  /// Bounds on every knot's state (2n) and input (m); ±infinity for none (the constructor's
  /// defaults).
  Eigen::VectorXd stateLower, stateUpper, inputLower, inputUpper;
  ///@}
  /// Bounds on the constraint forces λ_r (nc, the model's constraint rows; M q̈ = … + Aᵀλ),
  /// imposed at every collocation point (knots and Hermite–Simpson midpoints); ±infinity for none
  /// (problem file "constraint_force_bounds": {"<constraint row>": [lower, upper]}).
  ///@{
  Eigen::VectorXd forceLower, forceUpper;
  ///@}
  /// Bounds on linear combinations of the constraint forces, lower ≤ cᵀλ(x, u) ≤ upper, imposed at
  /// every collocation point like forceLower/Upper (e.g. the facets of a friction pyramid on a
  /// contact's (λ_n, λ_t1, λ_t2) rows: cos θ_k λ_t1 + sin θ_k λ_t2 − μ' λ_n ≤ 0). Not in the
  /// problem file; C++ only.
  struct ForceCombination {
    std::string name;              ///< for messages and reports, e.g. "thumb friction facet 3"
    Eigen::VectorXd coefficients;  ///< c (nc)
    double lower = -std::numeric_limits<double>::infinity();  ///< may be −infinity
    double upper = std::numeric_limits<double>::infinity();   ///< may be +infinity (not both)
  };
  std::vector<ForceCombination> forceCombinations;  ///< empty: none

  /// Cost weights: R (m×m), Q, Qf (2n×2n), all symmetric positive semidefinite; goal state
  /// (2n); w_T ≥ 0 weighs the horizon (minimum time when the other terms are small).
  ///@{
  /// The cost's weight matrices: R (m×m), Q and Qf (2n×2n), symmetric PSD.
  Eigen::MatrixXd R, Q, Qf;
  ///@}
  Eigen::VectorXd goalState;   ///< x_g (2n), the state Q and Qf pull toward
  double timeWeight = 0.0;     ///< w_T ≥ 0 [cost per second of horizon]
  /// W_a: adds ∫ q̈ᵀ diag(W_a) q̈ dt, quadrature-weighted at every collocation point (n entries ≥ 0;
  /// empty: none). Implicit dynamics form only (q̈ is a variable there; validate() refuses it
  /// with the explicit form). Why: separated Hermite–Simpson leaves one direction free of the
  /// defects — q̈ alternating +a at the knots and −a/2 at the midpoints integrates to zero —,
  /// which the equations of motion pin only through the inertia; on light bodies (the hand's
  /// phalanges, M ~ 1e-6 kg m²) Ipopt's steps run along it (measured: |Δq̈| 30–60 rad/s² in the
  /// first two steps of the free-ball turn, ‖d‖ 144). A small weight gives it curvature (‖d‖ 7).
  /// C++ only (not in the problem file).
  Eigen::VectorXd accelerationWeights;
  ///@{
  /// q̈_i = 0 at the first / last knot for the flagged coordinates (n flags; empty: none) —
  /// with q̇ = 0 there, an end that is an equilibrium: the start does not accelerate away, the end
  /// holds. Implicit dynamics form only (the knot's q̈ variables get the bounds 0, 0; validate()
  /// refuses them with the explicit form). On a constrained model flag the independent
  /// coordinates only: the point's rows A q̈ + Ȧ q̇ = 0 fix the others, and flagging all leaves
  /// those rows without a free variable (a rank-deficient program). Why: Radau's rows do not
  /// involve the first knot's dynamics, and Hermite–Simpson's only through the quadrature, so a
  /// rest-to-rest problem may otherwise start where the plant accelerates at once.
  std::vector<bool> initialAccelerationFixed, finalAccelerationFixed;
  ///@}

  /// The Hessian the solver uses unless OptimizerOptions::hessian overrides it (problem file
  /// "hessian": "exact" | "lbfgs"; default exact).
  HessianMode hessian = HessianMode::kExact;

  /// Initial guess. Without one, the states are interpolated linearly from initialState to
  /// finalState and the inputs are 0 (clamped into their bounds).
  std::optional<Trajectory> initialGuess;

  OptimalControlProblem() = default;
  /// Sizes every vector for `model` with defaults: zero states, all boundary entries fixed, no
  /// bounds, R = I, Q = Qf = 0, goal = 0.
  explicit OptimalControlProblem(std::shared_ptr<const Model> model);

  int nq() const;  ///< n
  int nx() const { return 2 * nq(); }  ///< 2n
  int nu() const;  ///< m

  /// Names of the state entries: the configuration names, then "d" + each name (the trajectory
  /// CSV layout).
  std::vector<std::string> stateNames() const;

  /// Throws ProblemError naming the first bad field (size, non-finite value, lower > upper,
  /// a fixed boundary value outside the state bounds, a non-symmetric or indefinite weight, a
  /// bad mesh). With constraints it also checks the fixed boundary states before any solve:
  /// when every configuration entry of a boundary state is fixed, each holonomic row must have
  /// |h_r(q)| ≤ kBoundaryTolerance, and when every entry is fixed, each row |A_r(q) q̇| ≤ it too;
  /// the message names the boundary, the constraint, its row and the residual.
  void validate() const;
  static constexpr double kBoundaryTolerance = 1e-8;  ///< on fixed boundary states' constraint residuals (units of h)
};

/// Parses a problem file (JSON text). `source` is the file name used in messages and `baseDir`
/// the directory against which the "scene" path (and an "initial_guess" CSV path) is resolved.
/// Throws ProblemError naming the field, or trellis::ModelError for a bad scene file.
OptimalControlProblem parseProblem(const std::string& jsonText, const std::string& source,
                                   const std::string& baseDir);

/// Reads and parses a problem file; paths inside are relative to the file's directory.
OptimalControlProblem loadProblem(const std::string& path);

}  // namespace trellis
