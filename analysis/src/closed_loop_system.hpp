// closed_loop_system.hpp (private) — the simulator's right-hand side and its exact Jacobian.
//
// ẋ = f(t, x) = [q̇; q̈(q, q̇, u)] with u = sat(π(t, x)) (continuous) or the held sample (ZOH).
// The input law π is one of: a user Policy (∂π/∂x unknown), the open loop u_ref(t) (∂π/∂x = 0),
// or the closed loop u_ref(t) − K(t)(x − x_ref(t)) (∂π/∂x = −K(t)). The Jacobian, when known, is
//   ∂f/∂x = A(x, u) − B(x, u) S ∂π/∂x,   S = diag(1 where u_i is inside the box, 0 where clipped).
// Failures inside callbacks are recorded (status, time, state, message), never thrown.
//
// Deviation coordinates. With a reference (open and closed loop) the integrator's state is the
// deviation y = x − x_ref(t), ẏ = f(t, x_ref(t) + y) − ẋ_ref(t) (the same ODE, shifted by a known
// function; ∂ẏ/∂y = ∂f/∂x). The error control then weighs the local error against |y| and atol
// instead of |x|: once the tracking error is small the steps are limited by how well y is
// resolved, not by the reference motion itself, and the absolute accuracy of x near the reference
// is ~atol, not rtol·|x| (measured on the hand, see the report of issue 11). Not used with BDF's
// difference-quotient Jacobian (its increments, scaled to |y| and atol, drown in the rounding of
// x_ref + y), so the fallback integrates x itself.
#pragma once

#include "trellis/analysis/detail/ode_driver.hpp"
#include "trellis/analysis/simulation.hpp"
#include "trellis/core/data.hpp"

#include <Eigen/Core>
#include <Eigen/LU>

#include <string>

namespace trellis::detail {

/// What π is. The pointers are borrowed for the simulation's duration (read-only, see the
/// threading contract in simulation.hpp).
struct InputLaw {
  enum class Kind { kPolicy, kOpenLoop, kFeedback };
  Kind kind = Kind::kPolicy;
  const Policy* policy = nullptr;         ///< kPolicy
  const Trajectory* reference = nullptr;  ///< kOpenLoop, kFeedback (with state derivatives)
  const GainSchedule* gains = nullptr;    ///< kFeedback
};

class ClosedLoopSystem final : public OdeSystem {
 public:
  ClosedLoopSystem(const Model& model, const InputLaw& law, const SimulationOptions& options);

  int rhs(double t, ConstVectorMap y, VectorMap ydot) override;
  bool hasJacobian() const override { return jacobianKnown_; }
  int jacobian(double t, ConstVectorMap y, ConstVectorMap fy, MatrixMap J) override;
  /// J = [[0, I], [A_q, A_v]] (the same in deviation coordinates): Radau's halved solves.
  bool secondOrder() const override { return true; }

  /// The Newton solve (I − γJ) z = r of BDF by its structure (OdeLinearSolver::SystemSolve).
  /// J = [[0, I], [A_q, A_v]] (x = [q; q̇], the same in deviation coordinates), so with
  /// z = [a; b], r = [r₁; r₂]:  a = r₁ + γb,  (I − γA_v − γ²A_q) b = r₂ + γA_q r₁ —
  /// one n×n LU instead of a 2n×2n one (8× fewer flops) and no copy or shift of a 2n×2n matrix.
  /// Set-up recomputes J only when CVODES says it is stale (jacOk false); a solve with another
  /// γ than the factored one refactors the n×n matrix, so every solve is exact for its γ.
  bool hasPreconditioner() const override { return jacobianKnown_; }
  int preconditionerSetup(double t, ConstVectorMap y, ConstVectorMap fy, bool jacOk, bool* jacUpdated,
                          double gamma) override;
  int preconditionerSolve(double t, ConstVectorMap y, ConstVectorMap fy, ConstVectorMap r, VectorMap z,
                          double gamma) override;
  /// The constraint forces of the last right-hand side when it was evaluated at exactly (t, x)
  /// with the input u, else nullptr. Radau evaluates f at every accepted step's end, where the
  /// step check then needs λ: the same computeDynamics at the same point, so it is reused.
  const Eigen::VectorXd* lambdaAt(double t, const Eigen::VectorXd& x, const Eigen::VectorXd& u) const {
    return lastValid_ && t == lastT_ && x == x_ && u == u_ ? &data_.lambda : nullptr;
  }
  /// Jacobians formed for the structured solve (CVODES counts only those of its dense solver).
  long structuredJacobians() const { return structuredJacobians_; }

  /// out = sat(π(t, x)); clipped says whether any entry was clipped. On failure records it and
  /// returns false.
  bool control(double t, const Eigen::VectorXd& x, Eigen::VectorXd& out, bool& clipped);
  /// Samples the held input at (t, x) (sampled feedback).
  bool sample(double t, const Eigen::VectorXd& x, bool& clipped) {
    return control(t, x, held_, clipped);
  }
  const Eigen::VectorXd& heldInput() const { return held_; }
  /// True when the integrator's state is y = x − x_ref(t) (file comment).
  bool deviation() const { return deviation_; }
  /// x from the integrator's state y at t (x = y without deviation coordinates); and back.
  void toState(double t, const Eigen::Ref<const Eigen::VectorXd>& y, Eigen::VectorXd& x);
  void toIntegrator(double t, const Eigen::VectorXd& x, Eigen::VectorXd& y);
  bool sampled() const { return sampled_; }

  /// Clears the per-advance failure state (call before each integrator call).
  void resetCallState();

  // The last failure recorded (valid when failed).
  bool failed = false;
  SimulationCode failStatus = SimulationCode::kOk;
  double failTime = 0.0;
  Eigen::VectorXd failState;
  std::string failMessage;

 private:
  void fail(SimulationCode s, double t, const Eigen::VectorXd& state, std::string message);
  int failureReturn();
  /// u = sat(π(t, x)) and active_(i) = 1 where u_i is not clipped. referenceFresh: xr_, ur_ hold
  /// the reference at t already.
  bool input(double t, const Eigen::VectorXd& x, Eigen::VectorXd& u, bool referenceFresh = false);
  /// x_ from the integrator's y at t (with xr_, ur_, xrdot_ at t in deviation coordinates).
  bool stateFrom(double t, ConstVectorMap y);

  const Model& model_;
  InputLaw law_;
  int n_, m_;
  bool sampled_, bounded_, jacobianKnown_, deviation_;
  Data data_;
  Eigen::VectorXd x_, q_, dq_, u_, held_, lower_, upper_, xr_, ur_, xrdot_, dx_, xc_, uc_, active_;
  Eigen::MatrixXd K_, SK_;
  // The structured solve: J (2n×2n) at the last set-up, I − γA_v − γ²A_q factored at gammaLu_.
  Eigen::MatrixXd jac_, newton_;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu_;
  Eigen::VectorXd rhsB_, solB_;
  double gammaLu_ = 0.0;
  // The last successful right-hand side's time (lambdaAt); invalid once data_ serves another call.
  double lastT_ = 0.0;
  bool lastValid_ = false;
  bool haveJac_ = false;
  long structuredJacobians_ = 0;
  void factorNewton(double gamma);
  // Right-hand-side failures are first reported as recoverable (CVODES retries with a smaller
  // step, which helps when only a trial point was bad). After kMaxRecoverableFailures in one
  // integrator call, or after a policy exception, every further call fails unrecoverably until
  // the call returns (SUNDIALS's fixed-point solver, used with Adams, treats even a negative
  // return as a convergence failure; the sticky failure ends a crawl through maxSteps).
  static constexpr int kMaxRecoverableFailures = 10;
  int failuresThisCall_ = 0;
  bool aborted_ = false;
};

std::string formatVector(const Eigen::VectorXd& v);
std::string formatTime(double t);

}  // namespace trellis::detail
