// trellis/analysis/detail/ode_driver.hpp (internal: for trellis's own libraries, not an API) — the
// one ODE driver of trellis: CVODES (BDF, Adams) and, behind the same calls, its own Radau IIA
// stepper (OdeMethod::Radau, analysis/src/radau_stepper.hpp).
//
// Every integration in analysis/ and control/ (Riccati equation, tangent-basis transport, manifold
// Riccati, Gramian, closed-loop simulation, sampled-data discretization, consistency check) goes
// through OdeDriver: one place for the SUNDIALS objects (owned, freed in reverse order), the
// choice of method and linear solver, stop times, dense output, root finding, step budget,
// statistics and failure messages that name the time and the state.
//
// The problem is an OdeSystem: ẏ = f(t, y) with, optionally, its exact Jacobian ∂f/∂y (dense) or
// Jacobian-vector products and a preconditioner (Krylov), quadratures q̇ = g(t, y) and root
// functions. A system without an exact Jacobian gets CVODES's difference quotient (n extra
// right-hand sides per Jacobian; stats().linearRhsEvaluations counts them) — the documented
// fallback, never the default where the Jacobian is known.
//
// Callbacks return 0 on success, > 0 for a recoverable failure (CVODES retries with a smaller
// step), < 0 for an unrecoverable one; set OdeSystem::failure to say what went wrong — it is
// carried into OdeStatus::message.
//
// Allocation: the constructor allocates everything; start(), advanceTo(), step(), interpolate()
// and the callbacks' Eigen::Map arguments do not allocate (CVODES itself allocates nothing per
// step). Failure messages (std::string) are built only on failure.
#pragma once

#include <Eigen/Core>

#include <memory>
#include <string>

namespace trellis::detail {

using ConstVectorMap = Eigen::Map<const Eigen::VectorXd>;
using VectorMap = Eigen::Map<Eigen::VectorXd>;
using MatrixMap = Eigen::Map<Eigen::MatrixXd>;

/// ẏ = f(t, y) and what CVODES may use of its derivatives. Override what you can provide.
class OdeSystem {
 public:
  virtual ~OdeSystem() = default;

  /// ẏ = f(t, y).
  virtual int rhs(double t, ConstVectorMap y, VectorMap ydot) = 0;

  /// Dense J = ∂f/∂y (n×n, column-major, every entry to be written). Used with
  /// OdeLinearSolver::Dense when hasJacobian().
  virtual bool hasJacobian() const { return false; }
  virtual int jacobian(double /*t*/, ConstVectorMap /*y*/, ConstVectorMap /*fy*/, MatrixMap /*J*/) {
    return -1;
  }

  /// J = [[0, I], [A_q, A_v]] in halves of y (y = [q; q̇]): OdeMethod::Radau then solves its
  /// stage systems on half the unknowns (radau_stepper.hpp).
  virtual bool secondOrder() const { return false; }

  /// Krylov (OdeLinearSolver::Gmres): Jv = J(t, y) v. jacTimesSetup is called once per Newton
  /// matrix update, before the products at that (t, y) (evaluate what every product reuses).
  virtual bool hasJacTimes() const { return false; }
  virtual int jacTimesSetup(double /*t*/, ConstVectorMap /*y*/, ConstVectorMap /*fy*/) { return 0; }
  virtual int jacTimes(double /*t*/, ConstVectorMap /*y*/, ConstVectorMap /*fy*/,
                       ConstVectorMap /*v*/, VectorMap /*Jv*/) {
    return -1;
  }
  /// Left preconditioner P ≈ I − γJ for Gmres (and the linear solver of SystemSolve, where P
  /// must be I − γJ at the set-up's J with the solve's γ): setup (jacOk: the system may reuse its Jacobian
  /// data; set *jacUpdated when it recomputed it) and solve P z = r.
  virtual bool hasPreconditioner() const { return false; }
  virtual int preconditionerSetup(double /*t*/, ConstVectorMap /*y*/, ConstVectorMap /*fy*/,
                                  bool /*jacOk*/, bool* /*jacUpdated*/, double /*gamma*/) {
    return -1;
  }
  virtual int preconditionerSolve(double /*t*/, ConstVectorMap /*y*/, ConstVectorMap /*fy*/,
                                  ConstVectorMap /*r*/, VectorMap /*z*/, double /*gamma*/) {
    return -1;
  }

  /// Quadratures q̇ = g(t, y) (OdeOptions::quadratureSize components).
  virtual int quadrature(double /*t*/, ConstVectorMap /*y*/, VectorMap /*qdot*/) { return -1; }

  /// Root functions g_i(t, y) (OdeOptions::rootCount of them); CVODES locates sign changes.
  virtual int roots(double /*t*/, ConstVectorMap /*y*/, double* /*g*/) { return -1; }

  /// What went wrong in the last failing callback (read by the driver for its message).
  std::string failure;
};

/// Bdf, Adams: CVODES. Radau: trellis's own three-stage Radau IIA (radau_stepper.hpp) — a
/// one-step method whose start() keeps its step size and Jacobian, for right-hand sides that jump
/// often (held inputs); needs the exact Jacobian, has no quadratures or root functions, and
/// ignores linearSolver and maxOrder.
enum class OdeMethod { Bdf, Adams, Radau };

enum class OdeLinearSolver {
  Dense,       ///< Newton with a dense direct solver: the exact Jacobian when the system has one
               ///< (and OdeOptions::exactJacobian), else CVODES's difference quotient
  Gmres,       ///< Newton with matrix-free SPGMR: jacTimes when provided, else difference quotients;
               ///< the system's left preconditioner when it has one
  FixedPoint,  ///< no linear solver: fixed-point iteration (non-stiff problems, usually Adams)
  SystemSolve, ///< Newton with the system's own exact solve of (I − γJ) x = b: its
               ///< preconditionerSetup/preconditionerSolve used as the linear solver, no Krylov
               ///< iterations (stats().linearIterations stays 0; preconditionerSolves counts the
               ///< solves). CVODES keeps deciding when J is refreshed (jacOk false: after a
               ///< convergence failure, every 20 steps, or a γ change > 30 %); the solve gets the
               ///< current γ, so a stale J is the only approximation (modified Newton).
};

struct OdeOptions {
  OdeMethod method = OdeMethod::Bdf;
  OdeLinearSolver linearSolver = OdeLinearSolver::Dense;
  bool exactJacobian = true;   ///< false: use the difference quotient even if the system has J
  double rtol = 1e-8;
  double atol = 1e-10;
  Eigen::VectorXd atolVector;  ///< per-component absolute tolerances; empty: atol for all
  long maxSteps = 500000;      ///< internal steps allowed between start() and the next start()
  double maxStep = 0.0;        ///< 0: no limit
  double initialStep = 0.0;    ///< 0: CVODES's estimate
  int maxOrder = 0;            ///< 0: CVODES's default (5 for BDF, 12 for Adams)
  double newtonTolerance = 0.0;  ///< Radau: Newton's stopping test κ; 0: RADAU5's min(0.03, √rtol')
  int quadratureSize = 0;
  bool quadratureErrorControl = false;
  double quadratureRtol = 1e-8;
  double quadratureAtol = 1e-10;
  int rootCount = 0;
  std::string what = "integration";  ///< named first in every message ("Riccati equation", ...)
};

/// OdeOptions with the fields every solver sets (the rest at their defaults), so that each solver's
/// options map onto the driver in one statement: what names the integration in messages.
OdeOptions makeOdeOptions(const char* what, OdeMethod method, OdeLinearSolver linearSolver,
                          double rtol, double atol, long maxSteps, double maxStep = 0.0);

/// A linear ODE ẏ = J(t) y + g(t) (the variational equations of trellis: tangent transport,
/// Gramian, sampled-data discretization). The system provides J(t) as a product and g(t); the
/// right-hand side and CVODES's Jacobian-vector products follow from them, so the Krylov solver
/// never takes a difference quotient:
///   f(t, y) = J(t) y + g(t),   J(t) v = applyJacobian(v).
class LinearOdeSystem : public OdeSystem {
 public:
  /// Evaluates what J(t) and g(t) need at t (cache it: called for every product at the same t).
  /// Returns false, with OdeSystem::failure set, when that fails.
  virtual bool prepareAt(double t) = 0;
  /// out = J(t) v at the prepared t.
  virtual void applyJacobian(ConstVectorMap v, VectorMap out) = 0;
  /// out += g(t) at the prepared t (none by default: ẏ = J(t) y).
  virtual void addForcing(VectorMap /*out*/) {}

  int rhs(double t, ConstVectorMap y, VectorMap ydot) final {
    if (!prepareAt(t)) return -1;
    applyJacobian(y, ydot);
    addForcing(ydot);
    return 0;
  }
  bool hasJacTimes() const final { return true; }
  int jacTimesSetup(double t, ConstVectorMap, ConstVectorMap) final { return prepareAt(t) ? 0 : -1; }
  int jacTimes(double t, ConstVectorMap, ConstVectorMap, ConstVectorMap v, VectorMap Jv) final {
    if (!prepareAt(t)) return -1;
    applyJacobian(v, Jv);
    return 0;
  }
};

/// Counters summed over every start() of one driver.
struct OdeStats {
  long steps = 0;
  long rhsEvaluations = 0;          ///< by the integrator (not counting linearRhsEvaluations)
  long linearRhsEvaluations = 0;    ///< by difference-quotient Jacobians / products
  long jacobianEvaluations = 0;     ///< dense Jacobians formed (exact or difference quotient)
  long linearIterations = 0;        ///< Krylov iterations
  long nonlinearIterations = 0;     ///< Newton (or fixed-point) iterations
  long linearSolverSetups = 0;      ///< calls of the linear solver's set-up (Newton matrix updates)
  long preconditionerSetups = 0;
  long preconditionerSolves = 0;
  long errorTestFailures = 0;
  long nonlinearFailures = 0;       ///< nonlinear solver convergence failures
  long restarts = 0;                ///< start() calls after the first (each drops to order 1)
  int lastOrder = 0;
  double lastStep = 0.0;
};

enum class OdeOutcome { Reached, Root, Failed };

struct OdeStatus {
  OdeOutcome outcome = OdeOutcome::Reached;
  double t = 0.0;       ///< where the call stopped: the target, the root, or the failure time
  int flag = 0;         ///< CVODES return flag (0 on success)
  std::string message;  ///< on failure: what, the CVODES flag, t, |y|∞ and the callback's failure
  bool ok() const { return outcome != OdeOutcome::Failed; }
  /// The failure came from a callback (right-hand side, Jacobian, linear or nonlinear solve):
  /// the system's own record says why.
  bool callbackFailed() const;
  /// The step budget (OdeOptions::maxSteps) ran out.
  bool tooMuchWork() const;
};

class RadauStepper;

class OdeDriver {
 public:
  /// Creates the SUNDIALS context, vectors, solvers and CVODES memory for n states. The system
  /// must outlive the driver. Throws std::invalid_argument for bad options, std::runtime_error if
  /// SUNDIALS cannot create an object.
  OdeDriver(OdeSystem& system, Eigen::Index n, OdeOptions options);
  ~OdeDriver();
  OdeDriver(const OdeDriver&) = delete;
  OdeDriver& operator=(const OdeDriver&) = delete;

  /// (Re)starts at (t0, y0) (and quadratures at q0, zero when empty): the first call initializes,
  /// later calls re-initialize — the integration restarts at order 1 with a small step, so call
  /// it only where the right-hand side really jumps. Resets the step budget.
  void start(double t0, const Eigen::Ref<const Eigen::VectorXd>& y0,
             const Eigen::Ref<const Eigen::VectorXd>& q0 = Eigen::VectorXd());

  /// Integrates to exactly tout (a stop time: f is never evaluated beyond it). The state at the
  /// stop is state(); outcome Root when a root function changed sign first (then t is the root).
  OdeStatus advanceTo(double tout);
  /// One internal step, never past tstop.
  OdeStatus step(double tstop);

  double time() const { return t_; }
  ConstVectorMap state() const;
  Eigen::Index size() const { return n_; }

  /// k-th derivative of the interpolating polynomial at t within the last step (CVodeGetDky);
  /// k ≤ lastOrder. Returns false if t is outside the last step or k is too large.
  bool interpolate(double t, int k, Eigen::Ref<Eigen::VectorXd> out);
  /// The quadratures at time().
  void quadrature(Eigen::Ref<Eigen::VectorXd> out);
  /// After outcome Root: which root functions crossed (±1 for the direction, 0 for none).
  void rootDirections(int* directions);

  void setMaxStep(double h);
  /// Changes the quadratures' error-control tolerances (OdeOptions::quadratureErrorControl must
  /// be on), e.g. per interval when the quadrature's scale depends on the interval's length.
  void setQuadratureTolerances(double rtol, double atol);
  /// Order of the last internal step (the interpolating polynomial's degree; 0 before a step).
  int lastOrder() const;

  OdeStats stats() const;
  const OdeOptions& options() const { return options_; }

 private:
  struct Impl;
  OdeStatus failed(int flag, const char* call);
  void collectCounters(OdeStats& into) const;

  OdeSystem& system_;
  Eigen::Index n_;
  OdeOptions options_;
  std::unique_ptr<Impl> impl_;
  std::unique_ptr<RadauStepper> radau_;  ///< OdeMethod::Radau (then impl_ holds no CVODES memory)
  OdeStatus radauFailed();
  double t_ = 0.0;
  bool started_ = false;
  long stepsAtStart_ = 0;
  OdeStats finished_;  ///< counters of the runs before the last start()
};

}  // namespace trellis::detail
