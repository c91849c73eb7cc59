// trellis/control/sampled_lqr.hpp — sampled-data (zero-order-hold) LQR along a time-varying
// linearization: the exact discretization of each sample interval and the discrete Riccati
// recursion with the cross term.
//
// A controller running at rate f holds δu_k on [t_k, t_{k+1}) (t_k = t0 + k h, h = 1/f; the last
// interval ends at T and may be shorter). Over one interval the linearization δẋ = A(t)δx + B(t)δu
// gives exactly
//   δx(t_{k+1}) = Φ_k δx_k + Γ_k δu_k,  Φ_k = Φ(t_{k+1}, t_k),  Γ_k = ∫_{t_k}^{t_{k+1}} Φ(t_{k+1}, s) B(s) ds,
// and, for s in the interval, δx(s) = Φ(s, t_k) δx_k + Γ(s) δu_k, so the continuous cost of the
// interval is the quadratic form
//   ∫ δxᵀQδx + δuᵀRδu ds = [δx_k; δu_k]ᵀ [[Q_k, N_k], [N_kᵀ, R_k]] [δx_k; δu_k],
//   [[Q_k, N_k], [N_kᵀ, R_k]] = ∫ [Φ(s,t_k) Γ(s)]ᵀ Q(s) [Φ(s,t_k) Γ(s)] ds + [[0, 0], [0, ∫R ds]].
// discretizeSampledData integrates the intervals that are not constant, by default
// (SampledIntegrator::kRadau), with the three-stage Radau IIA collocation of the variational
// equation Ẏ = A(s)Y + [0 B(s)], Y = [Φ(s, t_k) Γ(s)], and the method's own quadrature of the
// cost on its stages: one linear solve per step (the problem is linear; halved for a mechanical
// A = [[0, I], [Aq, Av]], B = [0; Bv]: the position stages substituted), L-stable (a stiff A does
// not limit the step), A, B, Q, R at the three nodes only (the start's are the previous step's
// end), the error by Hairer's embedded estimate (RADAU5: the difference to a third-order
// companion, filtered by (I − γ0δA)⁻¹ so the damped stiff part does not count; one more nx×nx
// solve), steps carried from one interval to the next (a one-step method restarts for free) and
// ending on the reference's knots. The restart transient (each interval starts from [I 0], which
// brings a stiff A's fast modes back in full) is split off exactly: the twin system frozen at the
// interval's start (A, B, Q, R at t_k) has exact blocks by the block exponential below, and the
// same Radau steps integrate it alongside; the result is the twin's exact blocks plus the
// difference of the two Radau solutions, and the step control measures the error of that
// difference (the pair's embedded estimate), which has no transient to resolve where A(t) moves
// little over the fast modes' decay. The twin's stage system, with its constant A, decouples on
// the eigenvectors of the method's matrix into one real and one complex nx×nx solve. Where the
// caller says A(t), B(t) are analytic between the breakpoints (SampledStructure::
// smoothBetweenBreakpoints: solveTvlqr along an unconstrained reference, polynomial between its
// knots), the nodes' A, B come from a Chebyshev interpolant of exact linearizations per piece
// between breakpoints (9 or 17 Chebyshev–Lobatto nodes), accepted only when its coefficients'
// tail and one exact point off the nodes agree to 1e-12 of the entries' scale in the coordinates
// that balance A (so the verdict does not depend on the states' or inputs' units), else halved,
// else evaluated exactly: on the 6-link swing 1 080 linearizations instead of 5 254 at 100 Hz,
// the gains the same to 1e-10 (SampledDiscretizationOptions::interpolateLinearization). The estimate
// bounds the companion's error, far above the fifth-order result's: the default rtol is
// kRadauRtol = 1e-6, which leaves the gains ~5e-10 of the exact recursion on the stiff 6-link
// swing (docs/performance.md; its 2026-12-03 note: where the time goes). SampledIntegrator::
// kMagnus integrates the Van Loan system Ẋ = V(s)X, V = [[−Mᵀ, Q̃], [0, M]] (M = [[A, B], [0, 0]],
// Q̃ = blkdiag(Q, R)), whose solution holds [[Φ_k, Γ_k], [0, I]] and the cost blocks, by a
// sixth-order Magnus step over the whole interval (between knots): A, B, Q, R at three Gauss
// points, one block exponential of the Magnus generator (the block scaling and squaring below,
// exact for any stiffness when A is constant), no restart transient to resolve. A check makes it
// exact: each step against its two half steps, bisecting where they differ by more than rtol.
// Where the stiff part of A(t) itself changes, the series needs |λ|δ ≲ 1 and the check bisects
// that far (the 6-link chain's swing: ~30 pieces per 10 ms interval at rtol 1e-10, slower than
// Radau); on a non-stiff A(t) one step per interval usually passes. SampledIntegrator::kBdf integrates
// Y = [Φ(s, t_k) Γ(s)] from Y(t_k) = [I 0] by the variational equation Ẏ = A(s) Y + [0 B(s)] with
// CVODES (BDF; GMRES with the exact Jacobian product A·V and the exact block preconditioner
// (I − γA)⁻¹ per column; restarted per interval), on the exact A(s), B(s) at every point the
// integrator asks for, and the cost matrix as a CVODES quadrature (error-controlled, outside the
// Newton iteration). Against the usual shortcut — ZOH of a frozen A(t_mid), B(t_mid) — this
// removes the O(h³) local error per interval from Ȧ, Ḃ (O(h²) after N ~ 1/h intervals), which for
// a fast-changing reference is the whole difference between the gains (tests/control/
// test_sampled_lqr.cpp measures it).
//
// The finite-horizon discrete recursion with cross term (S_N = Qf):
//   G_k = R_k + Γ_kᵀ S_{k+1} Γ_k,  H_k = Γ_kᵀ S_{k+1} Φ_k + N_kᵀ,  K_k = G_k⁻¹ H_k,
//   S_k = Q_k + Φ_kᵀ S_{k+1} Φ_k − H_kᵀ K_k   (symmetrized),
// minimizes Σ_k [δx_k; δu_k]ᵀ[[Q_k, N_k], [N_kᵀ, R_k]][δx_k; δu_k] + δx_Nᵀ Qf δx_N with δu_k = −K_k δx_k
// — i.e. exactly the continuous cost of the sampled-data closed loop of the linearization.
// As h → 0, K_k → K(t_k) of the continuous Riccati equation, with an O(h) difference.
//
// Intervals on which A, B, Q, R are exactly constant (a held pose; a reference whose knots repeat
// at rest — the caller says so through a ConstantSpanCallback, nothing is guessed from samples)
// are not integrated: with M = [[A, B], [0, 0]] and Q̃ = blkdiag(Q, R) their blocks are
//   e^{Mh} = [[Φ_k, Γ_k], [0, I]],  [[Q_k, N_k], [N_kᵀ, R_k]] = ∫₀ʰ e^{Mᵀs} Q̃ e^{Ms} ds,
// computed by a block scaling and squaring (sampled_lqr.cpp: Van Loan's exponential on h/2^s with
// ‖M‖h/2^s ≤ ½, then the doubling formulas), exact to rounding also for a stiff A (|λ|h ≫ 1), and
// computed once for all intervals of the same length in one constant stretch.
#pragma once

#include "trellis/control/riccati.hpp"
#include "trellis/core/status.hpp"

#include <Eigen/Core>

#include <functional>
#include <string>
#include <vector>

namespace trellis {

/// One sample interval [t0, t1] of the exact discretization (see the file comment).
struct SampledInterval {
  ///@{
  /// The interval's start and end [s].
  double t0 = 0.0, t1 = 0.0;
  ///@}
  Eigen::MatrixXd Phi;    ///< nx×nx, Φ(t1, t0)
  Eigen::MatrixXd Gamma;  ///< nx×m
  Eigen::MatrixXd Q;      ///< nx×nx, symmetric PSD
  Eigen::MatrixXd N;      ///< nx×m cross term
  Eigen::MatrixXd R;      ///< m×m, symmetric PD
};

/// Outcome codes of the sampled-data discretization and recursion (status.index: the interval or
/// step k, status.t: the time).
enum class SampledCode {
  kOk,
  kCallbackFailure,      ///< the linearization or a weight callback failed (or returned a bad size)
  kIntegratorFailure,    ///< CVODES stopped inside an interval
  kNonFinite,            ///< Φ, Γ, the cost, S or K became NaN/Inf
  kNotPositiveDefinite,  ///< R_k + Γ_kᵀ S_{k+1} Γ_k is not positive definite
};

/// Names: ok, callback_failure, integrator_failure, non_finite, not_positive_definite.
inline EnumNameTable<SampledCode> enumNames(SampledCode) {
  static constexpr EnumName<SampledCode> table[] = {
      {SampledCode::kOk, "ok"},
      {SampledCode::kCallbackFailure, "callback_failure"},
      {SampledCode::kIntegratorFailure, "integrator_failure"},
      {SampledCode::kNonFinite, "non_finite"},
      {SampledCode::kNotPositiveDefinite, "not_positive_definite"}};
  return table;
}

/// How the intervals that are not constant are integrated (file comment).
enum class SampledIntegrator {
  /// Sixth-order Magnus on the Van Loan system, one exponential over each whole interval
  /// (between knots), checked against its two half steps and bisected where they differ by more
  /// than rtol. Best where A(t)'s stiff part changes little over an interval (its series needs
  /// |λ|δ ≲ 1 there: on the 6-link chain's swing ~30 pieces per 10 ms, slower than Radau).
  kMagnus,
  /// Three-stage Radau IIA (order 5, L-stable) on the variational equation and its quadrature
  /// of the cost, as the difference to the system frozen at each interval's start (whose blocks
  /// are exact), Hairer's embedded error estimate, steps carried across intervals (the default).
  kRadau,
  kBdf,     ///< CVODES BDF on the variational equation and a cost quadrature, per interval
};

/// Names: magnus, radau, bdf.
inline EnumNameTable<SampledIntegrator> enumNames(SampledIntegrator) {
  static constexpr EnumName<SampledIntegrator> table[] = {{SampledIntegrator::kMagnus, "magnus"},
                                                          {SampledIntegrator::kRadau, "radau"},
                                                          {SampledIntegrator::kBdf, "bdf"}};
  return table;
}

/// Options of discretizeSampledData (the integration of Φ, Γ and the cost over each interval).
struct SampledDiscretizationOptions {
  SampledIntegrator integrator = SampledIntegrator::kRadau;  ///< for the intervals not constant
  /// Relative tolerance on Φ, Γ and the cost (≥ 0; 0: relativeTolerance()'s default for the
  /// integrator): CVODES's, the Magnus check's, or the bound on Radau's embedded estimate of each
  /// step's local error relative to each block's size.
  double rtol = 0.0;
  double atol = 1e-12;     ///< kBdf: absolute tolerance on the entries of Φ, Γ (> 0); the cost's is
                           ///< atol·h·max(1, max|Q|, max|R|)
  long maxSteps = 100000;  ///< internal steps per interval (> 0); also bounds each plant run of
                           ///< solveTvlqr's held feed-forward
  /// Intervals the ConstantSpanCallback declares constant get the exact block exponential (file
  /// comment); false integrates every interval (the reference path of the tests).
  bool exactConstantIntervals = true;
  /// kRadau, where SampledStructure::smoothBetweenBreakpoints says A(t), B(t) are analytic between
  /// the breakpoints: A, B at the steps' nodes from a Chebyshev interpolant of exact linearizations
  /// per piece between breakpoints, checked (its coefficients' tail and one exact point, relative
  /// to A's balanced scale: unit-invariant) to 1e-12 of the entries' scale, else halved, else
  /// evaluated exactly (sampled_lqr.cpp, ChebyshevLinearization); false: exact at every node.
  bool interpolateLinearization = true;
  void validate() const;   ///< throws std::invalid_argument naming the field
  /// The tolerance used: rtol when set (> 0), else kRadauRtol for kRadau and kRtol otherwise.
  double relativeTolerance() const;
  /// kMagnus and kBdf's default rtol (and that of solveTvlqr's held plant runs).
  static constexpr double kRtol = 1e-10;
  /// kRadau's default rtol: its embedded estimate bounds a third-order companion's error, not the
  /// fifth-order result's, which is ~1e-4 of it here (the gains ~1e-10 of the exact recursion on
  /// the stiff 6-link swing: docs/performance.md).
  static constexpr double kRadauRtol = 1e-6;
};

/// For a sample interval [a, b]: a time c at which A, B, Q and R take the values they keep on all
/// of [a, b] when they are exactly constant there by construction (a held pose, knots repeating at
/// rest), or NaN when they are not (or it is not known). Return the same c (e.g. the start of the
/// constant stretch) for every interval of one stretch: intervals with the same c, the same
/// length and the same A, B, Q, R share one exponential.
using ConstantSpanCallback = std::function<double(double a, double b)>;

/// What the caller knows of A(t), B(t), Q(t), R(t) beyond the callbacks (both optional).
struct SampledStructure {
  ConstantSpanCallback constantOn;  ///< the exactly constant intervals (ConstantSpanCallback)
  /// Ascending times where they may have a kink (e.g. the reference's knots: the linear input
  /// rule makes A(t) only continuous there). The Magnus steps end on them.
  std::vector<double> breakpoints;
  /// A(t), B(t) are analytic between consecutive breakpoints (a reference interpolated by
  /// polynomials between its knots and linearized exactly, no constraint basis transported along
  /// it): kRadau may then interpolate them (SampledDiscretizationOptions::interpolateLinearization).
  bool smoothBetweenBreakpoints = false;
};

/// The exact discretization over the sample intervals, and how it went.
struct SampledDiscretization {
  std::vector<SampledInterval> intervals;  ///< those completed (all of them when ok)
  /// code; message (empty when ok; the time and the cause); t: where it failed; index: the interval.
  Status<SampledCode> status;
  long steps = 0;            ///< integrator steps over all intervals (CVODES's or Magnus's)
  long rhsEvaluations = 0;   ///< right-hand sides evaluated by CVODES
  long linearizations = 0;   ///< calls of the linearization callback
  long constantIntervals = 0;  ///< intervals discretized by the exact exponential (no integration)
  /// Block exponentials computed: for the constant intervals (shared where equal) and, with
  /// kRadau, one per integrated interval (its frozen twin).
  long exponentials = 0;
  /// kMagnus: pieces whose check (one step against two half steps) failed, each then split in two.
  long bisections = 0;
  ///@{
  /// kRadau with interpolateLinearization: the pieces between breakpoints where A, B were
  /// interpolated, and those whose check failed even when split (evaluated exactly instead).
  long interpolationPieces = 0, interpolationFallbacks = 0;
  ///@}
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  std::string describe() const;  ///< one line: the status, intervals, steps
  /// {"status", "ok", "message", "t", "index", "intervals", "steps", "rhs_evaluations",
  /// "linearizations", "constant_intervals", "exponentials", "bisections", "interpolation_pieces",
  /// "interpolation_fallbacks"}.
  std::string json() const;
};

/// The exact discretization of δẋ = A(t)δx + B(t)δu on the intervals [times_k, times_{k+1}]
/// (times strictly increasing, ≥ 2 entries) and the sampled-data cost of Q (constant or
/// weights.Qfun) and R (constant or weights.Rfun); weights.Qf is not used. Throws
/// std::invalid_argument for bad sizes/options; a failing callback or CVODES error is reported in
/// the result (with the time), never thrown. structure (optional): which intervals are exactly
/// constant (not integrated unless options say so) and where A(t) may have kinks.
SampledDiscretization discretizeSampledData(const Eigen::VectorXd& times, int nx, int nu,
                                            const LinearizationCallback& linearization,
                                            const LqrWeights& weights,
                                            const SampledDiscretizationOptions& options = {},
                                            const SampledStructure& structure = {});

/// The exact blocks of one interval of length h on which A (nx×nx), B (nx×m), Q (nx×nx, PSD) and
/// R (m×m, PD) are constant (file comment): Φ, Γ, Q_k, N_k, R_k into `out` (t0, t1 untouched).
/// Throws std::invalid_argument for bad sizes, non-finite entries or h ≤ 0.
void discretizeConstantInterval(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B,
                                const Eigen::MatrixXd& Q, const Eigen::MatrixXd& R, double h,
                                SampledInterval& out);

/// Backward recursion with cross term (file comment) over the intervals, S_N = Qf. S has N+1
/// entries, K N. Not ok (message naming the step and its time) when G_k is not positive
/// definite or S_k is not finite.
struct SampledRiccatiRecursion {
  ///@{
  /// S_0 … S_N (nx×nx, symmetric) and K_0 … K_{N−1} (m×nx): u_k = −K_k x_k held over interval k.
  std::vector<Eigen::MatrixXd> S, K;
  ///@}
  /// code (kNotPositiveDefinite, kNonFinite); message; t and index: the step k and its time.
  Status<SampledCode> status;
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  std::string describe() const;  ///< one line: the status and the number of steps
  std::string json() const;      ///< {"status", "ok", "message", "t", "index", "steps"}
};
SampledRiccatiRecursion solveSampledRiccatiRecursion(const std::vector<SampledInterval>& intervals,
                                                     const Eigen::MatrixXd& Qf);

/// Sample times t0 + k/rate (k = 0, 1, …) below T, then T: the grid the sampled solvers use. The
/// last interval is shorter when (T − t0)·rate is not an integer (a sample within 1e-9 of a period
/// of T is dropped, so no interval is shorter than that). Throws std::invalid_argument for
/// rate ≤ 0 or t0 ≥ T.
Eigen::VectorXd sampleTimes(double t0, double T, double rate);

}  // namespace trellis
