// radau_stepper.hpp (private) — OdeMethod::Radau: the three-stage Radau IIA collocation (order 5,
// L-stable, stiffly accurate) of a nonlinear ẏ = f(t, y) with its exact Jacobian, as RADAU5
// (Hairer & Wanner, Solving ODEs II, §IV.8) lays it out; OdeDriver's second engine.
//
// Why a one-step method beside CVODES's BDF: a held input jumps at every sample, and BDF restarts
// there at order 1 with a small step (on the hand's 200 Hz loops ~22 of its steps per 5 ms sample,
// even at rtol 1e-3). A one-step method needs no history: start() keeps the step size, the
// Jacobian and its factorizations, so a restart costs nothing beyond the new right-hand side.
//
// One step from (t, y) of size h solves for the stage increments Z_i ≈ y(t + c_i h) − y
//   Z = h (a ⊗ I) F(Z),  F_i = f(t + c_i h, y + Z_i),
// by simplified Newton with J = ∂f/∂y at (t, y) (possibly an earlier point's, see below). With
// a = T diag(γ0, μ, μ̄) T⁻¹ (radau_tableau.hpp) and W = (T⁻¹ ⊗ I) Z each iteration is
//   (σ_k I − J) ΔW_k = Σ_i T⁻¹_ki F_i − σ_k W_k,  σ_0 = 1/(γ0 h) real, σ_1 = 1/(μ h) complex,
// (W_2 = conj W_1): one real and one complex linear system of J's size, factored once per (J, h).
// When the system declares J = [[0, I], [A_q, A_v]] (OdeSystem::secondOrder: y = [q; q̇], n/2
// coordinates) each solve σ(I − J/σ) z = r halves to n/2 unknowns (shifted_solve.hpp: 8× fewer
// flops per factorization). The iteration stops when the contraction
// estimate θ predicts the remaining error below κ of the tolerance (OdeOptions::newtonTolerance;
// 0: RADAU5's min(0.03, √rtol′)), and fails
// (h shrinks, J is refreshed) when θ ≥ 0.99 or the prediction over the remaining iterations (at
// most 7) misses. The result y + Z_3 (c_3 = 1).
//
// Error: the embedded estimate of radau_tableau.hpp in the RMS norm with weights
// atol′ + rtol′ max(|y_n|, |y_{n+1}|), where rtol′ = 0.1 rtol^{2/3} and atol′ = atol rtol′/rtol
// (RADAU5's transformation: the estimate is of order 3, the result of order 5, so the user's rtol
// is met with a looser bound on the estimate); refined once through f(t, y + err) when it fails on
// a first step after start() or after a rejection (a stiff transient inflates the unfiltered
// part). New step h/max(1/8, min(5, err^{1/4}/s)) with a safety s that drops as Newton needed more
// iterations; on accepted steps after the first, Gustafsson's predictive controller instead
// (alone, not the smaller of the two as in RADAU5: it follows a falling error after a restart);
// no growth right after a rejection. The Jacobian is re-evaluated after an accepted step unless
// Newton's last contraction θ was below 1e-3 (RADAU5's default: J still describes the step), and
// after any Newton failure; h is kept (and with it the factorizations) when the new step would be
// 1–1.2× the old. Measured on the hand's closed loop (4 860 steps, 37 400 right-hand sides, 4
// Jacobians per loop with θ < 0.1 and the smaller of the two steps): θ < 1e-3 refreshes J every
// ~24 steps (each ~7 right-hand sides' cost) and Newton needs 1.8 iterations instead of 2.2
// (30 200 right-hand sides); Gustafsson's step alone then takes 9 steps per 5 ms sample instead
// of 12 with no rejection (3 770 steps, 26 200 right-hand sides; 0.62 → 0.48 s per loop).
//
// Stops: step(tstop) never passes tstop and lands on it exactly when it is within 5 % of the
// step; a step shortened to land keeps the step size proposed before it. Dense output on the last
// step: the collocation polynomial through y_n + (0, Z_1, Z_2, Z_3) at (0, c_1, c_2, 1) (degree
// 3), which also extrapolates the next step's Newton start (not after start(): the right-hand side
// jumped there).
//
// Failures carry CVODES's flags (so OdeStatus reads the same): a right-hand side > 0 is
// recoverable (the step is halved; after kMaxRhsRetries in a row it is CV_REPTD_RHSFUNC_ERR), < 0
// ends the run (CV_RHSFUNC_FAIL); a failed Jacobian CV_LSETUP_FAIL; a step below the resolution of
// t after error-test failures CV_ERR_FAILURE, after Newton failures CV_CONV_FAILURE; the budget
// CV_TOO_MUCH_WORK. No quadratures, no root functions (the constructor refuses them).
//
// Allocation: the constructor allocates every buffer; start(), step(), interpolate() do not (Eigen's
// LU factorizations write into storage sized there).
#pragma once

#include "trellis/analysis/detail/ode_driver.hpp"
#include "trellis/analysis/detail/shifted_solve.hpp"

#include <Eigen/Core>
#include <Eigen/LU>

#include <complex>
#include <string>

namespace trellis::detail {

class RadauStepper {
 public:
  /// Throws std::invalid_argument when the system has no exact Jacobian, options ask for
  /// quadratures or root functions, or an absolute tolerance is not positive.
  RadauStepper(OdeSystem& system, Eigen::Index n, const OdeOptions& options);

  /// (Re)starts at (t0, y0): keeps the step size, the Jacobian and its factorizations (the next
  /// step refreshes J only when Newton converges poorly); resets the step budget.
  void start(double t0, const Eigen::Ref<const Eigen::VectorXd>& y0);
  /// One accepted step, never past tstop. Failure: flag (CVODES's numbering) and reason set.
  bool step(double tstop);
  double time() const { return t_; }
  const Eigen::VectorXd& state() const { return y_; }
  /// The k-th derivative (k ≤ 3) of the last step's collocation polynomial at t in that step;
  /// at the start point before any step, y itself (k = 0).
  bool interpolate(double t, int k, Eigen::Ref<Eigen::VectorXd> out) const;
  void setMaxStep(double h) { maxStep_ = h; }
  /// Adds the counters to into (steps, right-hand sides, Jacobians, Newton iterations,
  /// factorizations, failures) and sets lastOrder (5) and lastStep.
  void addStats(OdeStats& into) const;
  long stepsSinceStart() const { return stepsSinceStart_; }

  int flag = 0;        ///< CVODES's flag of the last failure
  std::string reason;  ///< what failed (without the system's own failure text)

 private:
  enum class Attempt { kAccepted, kRejected, kNewtonFailed, kFailed };
  Attempt attempt(double h, bool landing, double tstop);
  bool evaluate(double t, const Eigen::VectorXd& y, Eigen::Ref<Eigen::VectorXd> f, bool& recoverable);
  bool refreshJacobian();
  void factor(double h);
  void solveReal(const Eigen::VectorXd& r, Eigen::VectorXd& z);      // (σ0 I − J) z = r
  void solveComplex(const Eigen::VectorXcd& r, Eigen::VectorXcd& z);  // (σ1 I − J) z = r
  double initialStep(double tstop);
  double rms(const Eigen::Ref<const Eigen::MatrixXd>& v, const Eigen::VectorXd& scale) const;

  OdeSystem& system_;
  Eigen::Index n_;
  bool secondOrder_;
  double rtol_;           // RADAU5's transformed tolerances (file comment)
  Eigen::VectorXd atol_;  // per component
  double newtonTolerance_;
  long maxSteps_;
  double maxStep_;
  double initialStep_;

  double t_ = 0.0, h_ = 0.0;
  double firstStep_ = 0.0;  // the step the last start's first step asked for (start())
  Eigen::VectorXd y_, f0_, y1_, scale_, errScale_, tmpN_, err_, rhsErr_;
  Eigen::MatrixXd Z_, F_, dZ_, poly_;  // n×3: stage increments, F, Newton update, dense output
  Eigen::VectorXd W0_, G0_, dW0_;
  Eigen::VectorXcd W1_, G1_, dW1_;
  Eigen::MatrixXd J_;
  double sigma0_ = 0.0;
  std::complex<double> sigma1_;
  // Factorizations at (J, factoredH_): full n×n or, for second-order systems, n/2×n/2.
  ShiftedSolve realSolve_;
  ComplexShiftedSolve complexSolve_;
  Eigen::VectorXd zr_, zi_;  // the complex solve's right-hand side and solution, split
  double factoredH_ = 0.0;
  bool haveJacobian_ = false, jacobianCurrent_ = false, haveFactors_ = false, f0Valid_ = false;
  bool haveStep_ = false, extrapolate_ = false, afterStart_ = true, lastRejected_ = false, needJacobian_ = false;
  bool rhsFailed_ = false, lastWasNewton_ = false;
  double newtonFactor_ = 0.5;  // h's factor after a Newton failure
  double tOld_ = 0.0, hOld_ = 0.0;  // the last accepted step (dense output)
  Eigen::VectorXd yOld_;
  double theta_ = 1.0, faccon_ = 1.0, hAccepted_ = 0.0, errAccepted_ = 1e-2;
  bool predictive_ = false;
  int newtonIterations_ = 0;
  int rhsRetries_ = 0;
  static constexpr int kMaxNewton = 7;
  static constexpr int kMaxRhsRetries = 10;

  long stepsSinceStart_ = 0;
  long steps_ = 0, rhs_ = 0, jacobians_ = 0, newtonIts_ = 0, factorizations_ = 0, errorFailures_ = 0,
       newtonFailures_ = 0;
};

}  // namespace trellis::detail
