// trellis/control/riccati.hpp — finite-horizon continuous time-varying LQR.
//
// Along ẋ ≈ A(t) δx + B(t) δu (δx: nx = 2n, δu: m) minimize
//   J = ∫_{t0}^{T} δxᵀ Q(t) δx + δuᵀ R(t) δu dt + δx(T)ᵀ Qf δx(T).
// The cost-to-go δxᵀ S(t) δx solves the Riccati differential equation
//   −Ṡ = AᵀS + SA − S B R⁻¹ Bᵀ S + Q,   S(T) = Qf,
// and the optimal feedback is δu = −K(t) δx, K = R⁻¹ Bᵀ S (m×nx).
//
// solveRiccati integrates it backward with SUNDIALS CVODES (through the control module's one
// driver, control/src/ode_driver.hpp) in reversed time τ = T − t, on the
// nx(nx+1)/2 entries of the upper triangle of S (column by column), so S is symmetric by
// construction. BDF uses Newton iterations with a dense linear solver and the exact Jacobian of
// the right-hand side (the Lyapunov operator E ↦ A_clᵀE + E A_cl, A_cl = A − BK); Adams uses
// fixed-point (functional) iterations and no Jacobian — suited to non-stiff problems only.
//
// Factored (square-root) form, RiccatiMethod::kFactored. The unknown is the upper-triangular
// Cholesky factor U of S = UᵀU (U = Lᵀ, L lower-triangular), again nx(nx+1)/2 entries, packed
// like S. With Ṡ = dS/dτ = AᵀS + SA − S B R⁻¹ Bᵀ S + Q evaluated at S = UᵀU,
//   dU/dτ = Υ(M) U,   M = U⁻ᵀ Ṡ U⁻¹,   Υ(M) = strict upper triangle of M + ½ diag(M),
// because U̇ᵀU + UᵀU̇ = Uᵀ(Υ(M)ᵀ + Υ(M))U = UᵀMU = Ṡ and Υ(M)·U stays upper triangular. S = UᵀU is
// symmetric positive semidefinite for every U — at every step, at every trial point of the
// Newton iterations and at every dense-output point (the polynomial interpolates U, not S) — so
// round-off and step-size error can never make S indefinite, however stiff the problem, long
// the horizon or small R. The diagonal obeys dU_ii/dτ = ½ M_ii U_ii, so it keeps its sign and
// U stays invertible along the exact flow as long as S(τ) ≻ 0, which holds for every finite τ
// when Qf ≻ 0 (the cost of any x ≠ 0 is positive: either u ≠ 0 or x(T) ≠ 0).
// Choice (against the information form P = S⁻¹, which breaks down for Qf singular and for S
// growing without bound, and against the Davison–Maki/Hamiltonian form S = Y X⁻¹, whose S is
// symmetric and PSD only up to the integration error): the Cholesky ODE keeps N unknowns, costs
// two triangular solves and one triangular product on top of the plain right-hand side
// (still O(nx³)), and guarantees the structure by construction.
// It needs Qf ≻ 0 (U(T) = chol(Qf)). When Qf is only PSD (e.g. Qf = 0), either solveRiccati
// throws std::invalid_argument naming Qf and its smallest eigenvalue (factoredQfShift = 0, the
// default), or it factors Qf + factoredQfShift·I (documented regularization: the terminal cost is
// raised by factoredQfShift·|δx(T)|²; its effect on S(t) is factoredQfShift·‖Φ_cl(T, t)‖², which
// decays where the closed loop is stable; a tiny shift makes dU/dτ ≈ Q/(2√shift) large near T —
// a steep start that CVODES resolves with small first steps).
// Integration: BDF (Newton) with the dense solver and a difference-quotient Jacobian, or
// matrix-free GMRES with difference-quotient Jacobian-vector products; the preconditioner (if
// enabled) maps the residual to S coordinates (δS = UᵀδU + δUᵀU), applies the exact Lyapunov
// solve below and maps back (δU = Υ(U⁻ᵀ δS U⁻¹) U) — exact up to the terms proportional to Ṡ.
//
// Krylov preconditioner (plain BDF): the Newton matrix I − γJ acts on symmetric E as
// E − γ(A_clᵀE + E A_cl), so solving with it is the Lyapunov equation FᵀX + XF = −R,
// F = γA_cl − ½I. With the complex Schur form A_cl = Z T Zᴴ (computed once per Jacobian update,
// O(nx³); γ changes only rescale T) it is a triangular Bartels–Stewart solve, O(nx³) per
// application: GMRES then converges in one iteration and a Newton iteration costs O(nx³) instead
// of the dense solver's O(N³) = O(nx⁶/8) factorization. When 2γ‖A_cl‖_∞ < ½ (a non-stiff step:
// the Newton matrix is within ½ of the identity) the Schur form and the solve are skipped and the
// preconditioner is the identity. On a non-stiff problem the preconditioner can cost more than
// the GMRES iterations it saves (see bench/riccati_bench.cpp); on a stiff one unpreconditioned
// GMRES stalls (tests/control/test_riccati_hard.cpp), so it is on by default.
//
// Dense output: after every internal step the solution keeps CVODES' Nordsieck data (the
// derivatives 0…q of the step's interpolating polynomial, from CVodeGetDky) so S(t) at any t is
// the same polynomial CVODES itself would use for output: its error is of the order of the local
// error the integrator accepted (≈ rtol·|S| + atol per entry), not an extra interpolation error.
#pragma once

#include "trellis/analysis/dense_output.hpp"
#include "trellis/core/reference.hpp"
#include "trellis/core/status.hpp"

#include <Eigen/Core>

#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace trellis {

class Model;
class Trajectory;

/// Writes A(t) (nx×nx) and B(t) (nx×m) for the requested time (the matrices arrive sized) and
/// returns the outcome: a status that is not ok (e.g. the dynamics failed at x(t)) stops the solve
/// with kCallbackFailure and its message. The library's own callbacks report failure only this
/// way; an exception from a user's callback is caught at the integrator's C boundary and
/// reported the same way (nothing throws through CVODES).
using LinearizationCallback =
    std::function<ReferenceStatus(double t, Eigen::MatrixXd& A, Eigen::MatrixXd& B)>;
/// Writes a weight matrix W(t) (arrives sized).
using WeightCallback = std::function<void(double t, Eigen::MatrixXd& W)>;

/// The quadratic cost. Q (nx×nx, symmetric PSD) and R (m×m, symmetric PD) are constants unless the
/// matching callback is set, in which case the callback wins. Qf (nx×nx, symmetric PSD) is required.
struct LqrWeights {
  ///@{
  /// Constant weights: Q (nx×nx, PSD) on the state error, R (m×m, PD) on the input, Qf (nx×nx,
  /// PSD) on the final state error.
  Eigen::MatrixXd Q, R, Qf;
  ///@}
  ///@{
  /// Time-varying Q(t), R(t) (the callback wins over the constant when set; same sizes and
  /// definiteness).
  WeightCallback Qfun, Rfun;
  ///@}
};

/// kBDF and kAdams integrate the entries of S; kFactored integrates the Cholesky factor U of
/// S = UᵀU with BDF (see the top of this header), so S is symmetric PSD by construction.
enum class RiccatiMethod { kBDF, kAdams, kFactored };

/// Names: bdf, adams, factored (the names the CLI, Python and the benchmarks use; toString).
inline EnumNameTable<RiccatiMethod> enumNames(RiccatiMethod) {
  static constexpr EnumName<RiccatiMethod> table[] = {{RiccatiMethod::kBDF, "bdf"},
                                                      {RiccatiMethod::kAdams, "adams"},
                                                      {RiccatiMethod::kFactored, "factored"}};
  return table;
}
/// parseEnum<RiccatiMethod>(text, "Riccati method"): throws std::invalid_argument
/// "Riccati method 'TEXT' is not one of bdf, adams, factored".
RiccatiMethod parseRiccatiMethod(const std::string& text);

/// Linear solver inside BDF's Newton iterations. kDense factors the exact N×N Jacobian
/// (N = nx(nx+1)/2; O(N³) per factorization, only sensible for small nx); kKrylov is matrix-free
/// GMRES with the exact Jacobian-vector product A_clᵀV + V A_cl (O(nx³) each), preconditioned by
/// the exact Lyapunov solve of the Newton matrix unless krylovPreconditioner is false.
/// kLyapunov (plain forms only) is a direct Newton solve without Krylov iterations: the same
/// exact Lyapunov (Bartels–Stewart) solve of I − γJ, applied once per Newton iteration with the
/// current γ on the real Schur form of A_cl taken at the last Jacobian update (CVODES decides when
/// to refresh it, as for a dense Jacobian): O(nx³) per iteration, no Gram–Schmidt on N unknowns.
/// kAuto: kDense for nx ≤ 10, kLyapunov above (plain forms); kFactored uses kDense / kKrylov
/// (difference-quotient Jacobians; its Newton matrix is not a Lyapunov operator, the solve is
/// only its preconditioner there).
enum class RiccatiLinearSolver { kAuto, kDense, kKrylov, kLyapunov };

/// Names: auto, dense, krylov, lyapunov.
inline EnumNameTable<RiccatiLinearSolver> enumNames(RiccatiLinearSolver) {
  static constexpr EnumName<RiccatiLinearSolver> table[] = {
      {RiccatiLinearSolver::kAuto, "auto"},
      {RiccatiLinearSolver::kDense, "dense"},
      {RiccatiLinearSolver::kKrylov, "krylov"},
      {RiccatiLinearSolver::kLyapunov, "lyapunov"}};
  return table;
}
/// parseEnum<RiccatiLinearSolver>(text, "Riccati linear solver").
RiccatiLinearSolver parseRiccatiLinearSolver(const std::string& text);

/// Options of solveRiccati: integrator, tolerances, limits, linear solver.
struct RiccatiOptions {
  double rtol = 1e-8;           ///< CVODES relative tolerance (> 0)
  double atol = 1e-10;          ///< CVODES absolute tolerance on each entry of S (> 0)
  RiccatiMethod method = RiccatiMethod::kBDF;  ///< plain entries of S by BDF or Adams, or the Cholesky factor
  long maxSteps = 100000;       ///< total internal steps over the horizon (> 0)
  double maxNorm = 1e15;        ///< max |S_ij| above which the solve stops with kBlowUp (> 0)
  /// Largest BDF order (1…5; Adams 1…12); 0: CVODES's default (5, 12). With the default, a BDF
  /// solve whose S passes maxNorm or turns non-finite is redone at order ≤ 2 before that is
  /// reported (RiccatiSolution::lowOrderRetry; when the redone solve fails too, the first report
  /// stands, its message saying so): variable-step BDF of order 3–5 is not zero-stable when the
  /// error test keeps cutting the step, and its solution can then grow without bound over steps
  /// that tend to zero — the integrator's instability, not S's (measured: the 20-link chain held,
  /// rtol 1e-4, atol 1e-6: max |S_ij| 1 → 1e15 within Δτ = 1e-11 at order 5, while order ≤ 3 finds
  /// S bounded, λmax = 26.8). BDF 2 is A-stable and zero-stable under the step changes CVODES makes.
  int maxOrder = 0;
  double initialStep = 0.0;     ///< first step size in τ; 0 lets CVODES choose (≥ 0)
  double maxStep = 0.0;         ///< largest step size; 0 = unlimited (≥ 0)
  RiccatiLinearSolver linearSolver = RiccatiLinearSolver::kAuto;  ///< BDF only
  bool exactJacobian = true;    ///< BDF + dense: analytic Jacobian (false: difference quotients)
  bool trackEigenvalues = true; ///< min/max eigenvalue of S over the stored steps (O(nx³) per step)
  /// BDF/kFactored + kKrylov: precondition GMRES with the exact Lyapunov (Bartels–Stewart) solve.
  bool krylovPreconditioner = true;
  /// kFactored only: U(T) = chol(Qf + factoredQfShift·I). 0 requires Qf ≻ 0 (otherwise
  /// std::invalid_argument); > 0 is the documented regularization for a PSD Qf (≥ 0).
  double factoredQfShift = 0.0;
  /// kFactored only: when S becomes this ill-conditioned along the solve (estimated by
  /// (max U_ii / min U_ii)², from the diagonal of its factor), the rest of the horizon is
  /// integrated in the plain form on S itself (reported in RiccatiSolution::switchedToPlainAt).
  /// Near a singular S the factor's ODE turns stiff — U⁻¹ amplifies the error of U's small
  /// diagonal — while S stays smooth: a rank-deficient Q over a long horizon otherwise costs
  /// ~100 times the steps of the plain form, or fails with too much work. 0 never switches (> 0 or 0).
  double factoredSwitchCondition = 1e8;
  /// Check that S stays positive semidefinite (plain forms; the factored form is PSD by
  /// construction): at every stored step, S is accepted when λmin(S) ≥ −ε·λmax(S) with
  /// ε = psdSlack·nx·rtol — the eigenvalue shift a per-entry error of rtol·max|S_ij| could cause
  /// (‖E‖₂ ≤ nx·max|E_ij|), times a safety factor. The test is a Cholesky factorization of
  /// S + ε·max_i S_ii·I (O(nx³/3) per step); only a step that fails it gets the eigenvalues.
  /// A violation makes the status kIndefinite (the solve still covers the whole horizon).
  bool checkPositiveSemidefinite = true;
  double psdSlack = 10.0;       ///< ε = psdSlack·nx·rtol (≥ 0)
  /// Throws std::invalid_argument naming the field and its value.
  void validate() const;
};

enum class RiccatiCode {
  kOk,
  kIntegratorFailure,  ///< CVODES returned an error (too much work, convergence, error test)
  kNonFinite,          ///< S became NaN/Inf
  kBlowUp,             ///< max |S_ij| exceeded options.maxNorm
  kCallbackFailure,    ///< A/B/Q/R callback threw, returned a wrong size or non-finite values,
                       ///< or R(t) was not positive definite
  kIndefinite,         ///< S lost positive semidefiniteness beyond the tolerance-scaled slack
                       ///< (RiccatiOptions::checkPositiveSemidefinite): status.t is the
                       ///< worst step, indefiniteRatio = λmin/λmax there; S covers the horizon
};

/// Names: ok, integrator_failure, non_finite, blow_up, callback_failure, indefinite.
inline EnumNameTable<RiccatiCode> enumNames(RiccatiCode) {
  static constexpr EnumName<RiccatiCode> table[] = {
      {RiccatiCode::kOk, "ok"},
      {RiccatiCode::kIntegratorFailure, "integrator_failure"},
      {RiccatiCode::kNonFinite, "non_finite"},
      {RiccatiCode::kBlowUp, "blow_up"},
      {RiccatiCode::kCallbackFailure, "callback_failure"},
      {RiccatiCode::kIndefinite, "indefinite"}};
  return table;
}

/// The solve's outcome and S(t) on [validFrom(), T] (the whole horizon when ok()).
class RiccatiSolution {
 public:
  /// code; message (empty when ok; otherwise what failed, at which t and ‖S‖); t: where the
  /// failure happened (kIndefinite: the worst step; NaN when ok); index unused.
  Status<RiccatiCode> status;
  double failureNorm = 0.0;         ///< max |S_ij| at the last accepted step before the failure
  long steps = 0;                   ///< CVODES internal steps
  long rhsEvaluations = 0;          ///< right-hand sides of the Riccati ODE evaluated by CVODES
  long jacobianEvaluations = 0;     ///< Jacobians of the right-hand side formed (BDF, dense)
  long linearIterations = 0;        ///< GMRES iterations (Krylov solver only; 0 for kLyapunov)
  long preconditionerSolves = 0;    ///< Lyapunov solves (Krylov preconditioner or kLyapunov)
  long newtonIterations = 0;        ///< nonlinear iterations of BDF (Newton) or Adams (fixed point)
  long linearSolverSetups = 0;      ///< Newton-matrix set-ups CVODES asked for (BDF)
  long schurFactorizations = 0;     ///< real Schur forms of A_cl (Lyapunov solve; one per fresh A_cl)
  long errorTestFailures = 0;       ///< steps rejected by the local error test
  long convergenceFailures = 0;     ///< steps retried because the nonlinear iteration failed
  double switchedToPlainAt = std::numeric_limits<double>::quiet_NaN();  ///< kFactored: the time t
                                    ///< where the solve switched to the plain form (NaN: never)
  double indefiniteRatio = 0.0;     ///< kIndefinite: λmin(S)/λmax(S) at status.t (< −ε)
  /// The first solve (default maximum order) stopped with kBlowUp or kNonFinite and this ok
  /// solution is the one redone at BDF order ≤ 2 (RiccatiOptions::maxOrder), with its counters.
  bool lowOrderRetry = false;
  std::string firstAttempt;         ///< lowOrderRetry: the first solve's status line
  long linearizations = 0;          ///< calls of the linearization callback (solve and gains)
  double minEigenvalue = 0.0;       ///< of S over the stored steps (if tracked)
  double maxEigenvalue = 0.0;       ///< of S over the stored steps (if tracked)

  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// One line: the status, then the steps, right-hand sides and S's eigenvalue range.
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "nx", "nu", "t0", "t1", "valid_from", "steps",
  /// "rhs_evaluations", "jacobian_evaluations", "linear_iterations", "newton_iterations",
  /// "linearizations", "failure_norm", "indefinite_ratio", "switched_to_plain_at",
  /// "min_eigenvalue_S", "max_eigenvalue_S", "low_order_retry"}.
  std::string json() const;
  int nx() const { return nx_; }            ///< states (S is nx×nx)
  int nu() const { return nu_; }            ///< inputs (K is m×nx)
  double startTime() const { return t0_; }  ///< t0 of the horizon [s]
  double endTime() const { return tf_; }    ///< T, the end of the horizon [s]
  /// Earliest time where S is available: t0 when ok(), else the last accepted step's time.
  double validFrom() const;
  /// Times (ascending) of the stored step points, T included.
  std::vector<double> stepTimes() const;
  /// Order (degree of the interpolating polynomial) of each stored step, aligned with
  /// stepTimes() (0 for the terminal point).
  std::vector<int> stepOrders() const;

  /// S(t) (nx×nx, symmetric). Throws std::out_of_range outside [validFrom(), T].
  Eigen::MatrixXd S(double t) const;
  /// S(t) into `out` (resized only when its size is wrong: no allocation in a loop).
  void S(double t, Eigen::MatrixXd& out) const;
  /// K(t) = G(t) S(t), G = R⁻¹Bᵀ (m×nx). The solution owns everything it needs (no reference to
  /// the model or the callbacks: it may outlive them): G is stored at every step end and step
  /// midpoint of the solve and interpolated by the cubic through the four nearest of these nodes
  /// (error O(h⁴·max‖G⁗‖) for steps of size h; exact at the nodes, e.g. at the step times).
  /// Throws std::out_of_range outside [validFrom(), T].
  Eigen::MatrixXd K(double t) const;
  /// Times (ascending) where G = R⁻¹Bᵀ is stored.
  std::vector<double> gainNodeTimes() const { return gainTimes_; }

 private:
  friend RiccatiSolution solveRiccati(double, double, int, int, const LinearizationCallback&,
                                      const LqrWeights&, const RiccatiOptions&);
  int nx_ = 0, nu_ = 0;
  double t0_ = 0.0, tf_ = 0.0;
  DenseOutput steps_;              // packed S (or U) in τ = T − t, ascending; first: τ = 0 (S = Qf)
  std::size_t factoredSteps_ = 0;  // steps [0, factoredSteps_) hold the packed factor U (S = UᵀU)
  std::vector<double> gainTimes_;           // ascending t
  std::vector<Eigen::MatrixXd> gainNodes_;  // G = R⁻¹Bᵀ at gainTimes_
};

/// Integrates the Riccati equation on [t0, T] (t0 < T). Throws std::invalid_argument for sizes,
/// an invalid option, R not positive definite or Q, Qf not positive semidefinite (checked for
/// constants; a callback is checked at t0, (t0+T)/2 and T), naming the matrix and the offending
/// eigenvalue. Numerical trouble is reported in the returned status, never thrown.
RiccatiSolution solveRiccati(double t0, double T, int nx, int nu,
                             const LinearizationCallback& linearization, const LqrWeights& weights,
                             const RiccatiOptions& options = {});

/// A(t), B(t) from computeLinearization at the trajectory's interpolated x(t), u(t). The callback
/// owns a copy of the trajectory and its own Data (not thread safe; one per solve). The trajectory
/// must have state derivatives and match the model; the model must outlive the callback.
/// Throws TrajectoryError / std::logic_error when it does not.
LinearizationCallback makeTrajectoryLinearization(const Model& model, const Trajectory& trajectory);

/// solveRiccati over the trajectory's time span with makeTrajectoryLinearization.
RiccatiSolution solveRiccati(const Model& model, const Trajectory& trajectory,
                             const LqrWeights& weights, const RiccatiOptions& options = {});

/// Throws std::invalid_argument unless W is rows×cols, finite, symmetric (to 1e-10 relative) and
/// its smallest eigenvalue is > 0 (definite) or ≥ −1e-12·max(1, ‖W‖) (semidefinite).
void checkWeightMatrix(const Eigen::MatrixXd& W, const char* name, Eigen::Index size, bool definite);

}  // namespace trellis
