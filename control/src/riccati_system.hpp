// riccati_system.hpp (private) — the Riccati equation as an OdeSystem for OdeDriver.
//
// In reversed time τ = T − t, on the packed upper triangle of S (plain form) or of its Cholesky
// factor U, S = UᵀU (factored form; see riccati.hpp):
//   plain:     dS/dτ = AᵀS + SA − P K + Q,   P = S B, K = G S, G = R⁻¹Bᵀ;
//   factored:  dU/dτ = Υ(U⁻ᵀ Ṡ U⁻¹) U.
// Derivatives (plain form): the dense N×N Jacobian of E ↦ A_clᵀE + E A_cl (A_cl = A − BK), its
// matrix-free product, and the exact Lyapunov (Bartels–Stewart) preconditioner of the Newton
// matrix; the factored form uses difference quotients and the preconditioner mapped to U.
//
// Cost per right-hand side: the coefficients A, B, Q, R and G = R⁻¹Bᵀ depend on t only and are
// cached on t (BDF's Newton iterations and the Jacobian set-up evaluate the same t several
// times: one linearization per distinct t); then one nx³ product (S A, whose symmetric part is
// that of AᵀS), one nx²m product (K = GS) and the upper half of another (P K, with P = KᵀR). A
// mechanical A = [0 I; Aq Av], B = [0; Bv] (detected exactly per t) halves the first two: only
// the velocity rows and columns of S enter. The products run through matmul (dense_kernels.hpp:
// AVX2+FMA when the CPU has it). Nothing allocates after construction.
#pragma once

#include "trellis/analysis/detail/ode_driver.hpp"
#include "riccati_lyapunov.hpp"
#include "trellis/control/riccati.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <limits>
#include <string>

namespace trellis::detail {

class RiccatiSystem final : public OdeSystem {
 public:
  RiccatiSystem(int nx, int nu, double T, const LinearizationCallback& linearization,
                const LqrWeights& weights);

  bool factored = false;         ///< integrate U (S = UᵀU) instead of S
  bool preconditioned = false;   ///< offer the Lyapunov solve (Krylov preconditioner or solver)
  bool exactSolve = false;       ///< the Lyapunov solve is the linear solver (no identity shortcut)

  int rhs(double tau, ConstVectorMap y, VectorMap ydot) override;
  bool hasJacobian() const override { return !factored; }
  int jacobian(double tau, ConstVectorMap y, ConstVectorMap fy, MatrixMap J) override;
  bool hasJacTimes() const override { return !factored; }
  int jacTimesSetup(double tau, ConstVectorMap y, ConstVectorMap fy) override;
  int jacTimes(double tau, ConstVectorMap y, ConstVectorMap fy, ConstVectorMap v,
               VectorMap Jv) override;
  bool hasPreconditioner() const override { return preconditioned; }
  int preconditionerSetup(double tau, ConstVectorMap y, ConstVectorMap fy, bool jacOk,
                          bool* jacUpdated, double gamma) override;
  int preconditionerSolve(double tau, ConstVectorMap y, ConstVectorMap fy, ConstVectorMap r,
                          VectorMap z, double gamma) override;

  /// A, B, Q, R and G = R⁻¹Bᵀ at t (cached: a repeated t calls no callback). False on failure
  /// (recorded: failed, failTime, failStatus, failMessage).
  bool coefficientsAt(double t);
  const Eigen::MatrixXd& gain() const { return G_; }  ///< G = R⁻¹Bᵀ of the last coefficientsAt
  long linearizations() const { return linearizations_; }
  long schurFactorizations() const { return schurFactorizations_; }

  bool failed = false;
  double failTime = 0.0;
  RiccatiCode failStatus = RiccatiCode::kCallbackFailure;
  std::string failMessage;

 private:
  bool evaluate(double tau, const double* y);  // coefficients, S (from y) and K = G S
  void closedLoop();                           // A_cl = A − B K
  void fail(RiccatiCode status, double t, const std::string& message);
  template <class M>
  bool checkSize(const M& X, Eigen::Index r, Eigen::Index c, const char* name, double t);

  int nx_, nu_;
  double T_;
  const LinearizationCallback& lin_;
  const LqrWeights& w_;
  Eigen::MatrixXd A_, B_, Q_, R_, Rinv_, G_, S_, P_, Pt_, K_, F_, Acl_, PK_;
  Eigen::LLT<Eigen::MatrixXd> Rllt_;
  double cachedT_ = std::numeric_limits<double>::quiet_NaN();
  bool cacheValid_ = false;
  bool mechanical_ = false;  // A = [0 I; Aq Av], B = [0; Bv] at the cached t (see coefficientsAt)
  long linearizations_ = 0;
  long schurFactorizations_ = 0;
  // Factored form: U (upper triangular, zero below), Ṡ, M = U⁻ᵀṠU⁻¹, dU/dτ, U at the last
  // preconditioner set-up.
  Eigen::MatrixXd U_, Sdot_, M_, Udot_, Upre_;
  // Preconditioner: A_cl at the last set-up, its ∞-norm, and its Schur form (computed lazily,
  // only when a stiff step needs it).
  SchurLyapunov lyap_;
  Eigen::MatrixXd Xr_;
  bool aclOk_ = false, schurOk_ = false;
  double aclNorm_ = 0.0;
};

}  // namespace trellis::detail
