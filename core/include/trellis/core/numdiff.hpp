// trellis/core/numdiff.hpp — finite differences of the dynamics: the one numerical baseline the
// exact linearization is checked and measured against (the optimizer's finite-difference mode,
// the tests, the benchmarks and the hand's main job all call this).
//
// J = ∂q̈/∂z, z = [q; q̇; u] (n × (2n + m)) is the nontrivial part of the linearization:
// A = [[0, I], [J_q, J_q̇]], B = [[0], [J_u]].
//
// Step rule: column j uses h_j = relativeStep · max(1, |z_j|) and divides by the step actually
// taken ((z_j + h) − (z_j − h), which differs from 2h by rounding). Default relative steps balance
// truncation against rounding (eps = 2.2e-16):
//  - forward  (f(z + h) − f(z)) / h:               truncation h/2·|f''|, rounding eps|f|/h;
//    h = eps^(1/2) ≈ 1.5e-8, error ~eps^(1/2) ≈ 1e-8 relative; 2n + m + 1 evaluations;
//  - central  (f(z + h) − f(z − h)) / 2h:          truncation h²/6·|f'''|, rounding eps|f|/h;
//    h = eps^(1/3) ≈ 6.1e-6, error ~eps^(2/3) ≈ 4e-11 relative; 2(2n + m) evaluations;
//  - fourth-order central (−f(z+2h) + 8f(z+h) − 8f(z−h) + f(z−2h)) / 12h: truncation h⁴/30·|f⁽⁵⁾|;
//    h = eps^(1/5) ≈ 7.4e-4, error ~eps^(4/5) ≈ 3e-13 relative; 4(2n + m) evaluations. For an
//    ill-conditioned f (rounding κ·eps) the error is ~(κ eps)^(4/5) instead of ~(κ eps)^(2/3).
#pragma once

#include "trellis/core/data.hpp"
#include "trellis/core/status.hpp"

#include <Eigen/Core>

#include <functional>
#include <string>

namespace trellis {

class Model;

enum class DifferenceScheme { kForward, kCentral, kCentralFourthOrder };

/// Names: forward, central, central4.
inline EnumNameTable<DifferenceScheme> enumNames(DifferenceScheme) {
  static constexpr EnumName<DifferenceScheme> table[] = {{DifferenceScheme::kForward, "forward"},
                                                         {DifferenceScheme::kCentral, "central"},
                                                         {DifferenceScheme::kCentralFourthOrder, "central4"}};
  return table;
}

/// Which difference scheme, and its step h = relativeStep · max(1, |z|) per variable z.
struct NumDiffOptions {
  DifferenceScheme scheme = DifferenceScheme::kCentral;  ///< forward, central or fourth-order central
  double relativeStep = 0.0;  ///< 0: the scheme's default (defaultRelativeStep)
  double step(double z) const;  ///< h = relativeStep · max(1, |z|)
};

/// eps^(1/2), eps^(1/3), eps^(1/5) (file comment).
double defaultRelativeStep(DifferenceScheme scheme);

/// Buffers for differenceDynamics (sized once; no allocation in the call).
struct NumDiffWorkspace {
  /// Sized for `model` (n, m): allocates; differenceDynamics then does not.
  explicit NumDiffWorkspace(const Model& model);
  ///@{
  /// The perturbed point (q: n, q̇: n, u: m).
  Eigen::VectorXd q, dq, u;
  ///@}
  ///@{
  /// q̈ (n) at z (forward differences) and at z ± h e_j.
  Eigen::VectorXd qddBase, qddPlus, qddMinus;
  ///@}
};

/// J = ∂q̈/∂[q; q̇; u] (n × (2n + m); resized only if its size is wrong) by `options` from
/// computeDynamics(model, data, ·). Returns ok, or the status of the first evaluation that
/// failed (its message prefixed with the perturbed column). `data` holds the last evaluation.
DynamicsStatus differenceDynamics(const Model& model, Data& data, const Eigen::VectorXd& q,
                                  const Eigen::VectorXd& dq, const Eigen::VectorXd& u,
                                  const NumDiffOptions& options, NumDiffWorkspace& workspace,
                                  Eigen::MatrixXd& J);

/// The Jacobian (p × k) of any f: R^k → R^p with the same schemes and step rule (allocates; for
/// tests and tools). f writes its value into its second argument.
using DifferenceFunction = std::function<void(const Eigen::VectorXd&, Eigen::VectorXd&)>;
Eigen::MatrixXd differenceJacobian(const DifferenceFunction& f, const Eigen::VectorXd& x,
                                   const NumDiffOptions& options = {});

/// Outcome codes of checkLinearization (status.message says which path failed and why).
enum class LinearizationCheckCode {
  kOk,                ///< both paths evaluated; maxError and the worst entry are set
  kExactFailed,       ///< computeLinearization returned a status that is not ok
  kDifferenceFailed,  ///< the dynamics failed at a perturbed state of the differences
};

/// Names: ok, exact_failed, difference_failed.
inline EnumNameTable<LinearizationCheckCode> enumNames(LinearizationCheckCode) {
  static constexpr EnumName<LinearizationCheckCode> table[] = {
      {LinearizationCheckCode::kOk, "ok"},
      {LinearizationCheckCode::kExactFailed, "exact_failed"},
      {LinearizationCheckCode::kDifferenceFailed, "difference_failed"}};
  return table;
}

/// Exact A, B (computeLinearization) against differenceDynamics at one state. The error of
/// column j is max_i |J_ij − D_ij| / max(1, max_i |D_ij|) (relative to the column's scale, so a
/// light body's columns are not hidden by a heavy one's); the worst entry is named. A measurement,
/// not a verdict: the caller compares maxError with its own tolerance.
struct LinearizationCheck {
  Status<LinearizationCheckCode> status;  ///< ok: both paths evaluated (else which one failed)
  double maxError = 0.0;   ///< worst column-relative error
  ///@{
  /// The worst entry in J (row i: q̈_i; column j of [q; q̇; u]); −1 when not evaluated.
  int row = -1, column = -1;
  ///@}
  ///@{
  /// Names of the worst entry's row and column, e.g. "ddtheta" and "dx" / an input name.
  std::string rowName, columnName;
  ///@}
  ///@{
  /// The exact and the difference value at the worst entry.
  double exact = 0.0, difference = 0.0;
  ///@}
  ///@{
  /// Both Jacobians, n × (2n + m).
  Eigen::MatrixXd exactJ, differenceJ;
  ///@}

  bool ok() const { return status.ok(); }  ///< status.ok(): both paths evaluated
  /// One line: the worst entry, both values and the error ("ok: worst entry d(ddx)/d(theta): …"),
  /// or the failure.
  std::string describe() const;
  /// One JSON object: status fields, max_error, the worst entry (row, column, names, both values).
  std::string json() const;
};
LinearizationCheck checkLinearization(const Model& model, const Eigen::VectorXd& q,
                                      const Eigen::VectorXd& dq, const Eigen::VectorXd& u,
                                      const NumDiffOptions& options = {});

}  // namespace trellis
