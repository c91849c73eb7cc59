// tests/support/finite_difference.hpp — central differences, the reference leg of every derivative
// test (STYLE.md "Derivatives on three legs", leg 1), on the core's finite differences
// (trellis/core/numdiff.hpp: the same schemes and step rule the optimizer and benchmarks use).
//
// Step and error model. For a component x_i the step is
//     h_i = eps^(1/3) · max(1, |x_i|),    eps = 2.2e-16  ⇒  eps^(1/3) ≈ 6.06e-6.
// The central difference (f(x + h e_i) − f(x − h e_i)) / 2h has
//   - truncation error  h²/6 · |∂³f/∂x_i³|                  ≈ 6e-12 · (third-derivative scale),
//   - rounding error    eps · |f| / h                        ≈ 4e-11 · (scale of f),
// and h = eps^(1/3) balances the two, so the total is ~eps^(2/3) ≈ 4e-11 relative to the scale of
// f and of its third derivatives along x_i (≈ 1e-10 with the constant factors). For q̈ of the
// systems in this suite (trigonometric in angles, rational in lengths) the first and third
// derivatives have comparable magnitude, so a column of the Jacobian is accurate to ~1e-10 relative
// to max(1, ‖column‖∞). The tests compare with 1e-6 relative to that scale: four orders of margin
// above the expected FD error, while any wrong term of an analytic derivative (a missing Coriolis
// term, a sign, a transposed block) shows up at the 1e-2 … 1 level.
#pragma once

#include <trellis/core.hpp>
#include <trellis/core/numdiff.hpp>

#include <Eigen/Core>

#include <functional>
#include <string>

namespace trellis::test {

/// eps^(1/3) for double.
double fdRelativeStep();

/// The step h = eps^(1/3) · max(1, |x|).
double fdStep(double x);

using VectorFunction = std::function<Eigen::VectorXd(const Eigen::VectorXd&)>;

/// Central-difference stencils.
///  - kSecondOrder: (f(x+h) − f(x−h)) / 2h, h = eps^(1/3)·max(1,|x|) (error model above).
///  - kFourthOrder: (−f(x+2h) + 8 f(x+h) − 8 f(x−h) + f(x−2h)) / 12h, truncation h⁴/30·|f⁽⁵⁾|,
///    rounding ~(3/2)·δf/h; with h = eps^(1/5)·max(1,|x|) ≈ 7.4e-4·max(1,|x|) the total is
///    ~eps^(4/5) ≈ 3e-13 relative for a well-conditioned f. For an f whose evaluation carries a
///    rounding error δf ≈ κ·eps·|f| (κ: condition number of the solve inside it, e.g. cond(M)),
///    the error becomes ~(κ eps)^(4/5) instead of the second-order stencil's ~(κ eps)^(2/3) — the
///    stencil for ill-conditioned systems (long chains, extreme mass ratios).
enum class Stencil { kSecondOrder, kFourthOrder };

/// The base relative step of a stencil: eps^(1/3) or eps^(1/5).
double fdBaseStep(Stencil stencil);

/// Jacobian (p×k) of f: R^k → R^p by central differences, column j with step
/// stepScale · fdBaseStep(stencil) · max(1, |x_j|). stepScale ≠ 1 adapts the step to a function
/// that varies on a length scale other than 1, or whose evaluation is noisier than eps·|f|: the
/// optimal step grows like (noise)^(1/3) (second order) or (noise)^(1/5) (fourth order).
Eigen::MatrixXd centralDifferenceJacobian(const VectorFunction& f, const Eigen::VectorXd& x,
                                          double stepScale = 1.0,
                                          Stencil stencil = Stencil::kSecondOrder);

/// Directional derivative d/dε f(x + ε v) at ε = 0 by one central difference. The step along the
/// unit direction v/‖v‖∞ is eps^(1/3) · max(1, ‖x‖∞); the result is scaled back by ‖v‖∞.
Eigen::VectorXd centralDifferenceDirectional(const VectorFunction& f, const Eigen::VectorXd& x,
                                             const Eigen::VectorXd& v);

/// Central differences of computeDynamics with respect to z = [q; q̇; u] (2n + m columns).
struct DynamicsFiniteDifference {
  Eigen::MatrixXd dqdd;     ///< n × (2n + m): ∂q̈/∂[q; q̇; u]
  Eigen::MatrixXd dlambda;  ///< nc × (2n + m): ∂λ/∂[q; q̇; u]
  bool ok = true;           ///< false if computeDynamics failed at a perturbed point
  std::string failure;      ///< which perturbation failed and the status message
  Eigen::MatrixXd dq() const { return dqdd.leftCols(dqdd.rows()); }
  Eigen::MatrixXd ddq() const { return dqdd.middleCols(dqdd.rows(), dqdd.rows()); }
  Eigen::MatrixXd du() const { return dqdd.rightCols(dqdd.cols() - 2 * dqdd.rows()); }
};

DynamicsFiniteDifference finiteDifferenceDynamics(const Model& model, const Eigen::VectorXd& q,
                                                  const Eigen::VectorXd& dq,
                                                  const Eigen::VectorXd& u, double stepScale = 1.0,
                                                  Stencil stencil = Stencil::kSecondOrder);

/// d/dt of the world pose of frame k along q̇ (central difference of framePose along q̇), turned
/// into the body velocity [Rᵀ ṗ; vee(Rᵀ Ṙ)] that Data::frameVelocity documents.
Vector6d finiteDifferenceBodyVelocity(const Model& model, const Eigen::VectorXd& q,
                                      const Eigen::VectorXd& dq, int frame);

}  // namespace trellis::test
