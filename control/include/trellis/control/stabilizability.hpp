// trellis/control/stabilizability.hpp — is every unstable mode of (A, B) controllable? (PBH test, O(n³)).
#pragma once

#include <Eigen/Core>

#include <complex>
#include <string>

namespace trellis {

/// Stabilizability of (A, B) in O(n³): one complex Schur form A = U T Uᴴ; for every eigenvalue
/// outside the stability region (continuous: Re λ ≥ −1e-8|λ|; discrete: |λ| ≥ 1 − 1e-8) a left
/// eigenvector w from the triangular T, and the margin ‖wᴴB‖ / (‖w‖‖B‖) (the sine of the angle
/// between w and range B; invariant under input scaling). Margin ≤ tolerance: not stabilizable.
/// Repeated unstable eigenvalues (where one left eigenvector does not span the eigenspace) are also
/// checked by the PBH singular value σ_min[A − λI, B] / ‖[A, B]‖. The solvers apply it to the
/// balanced problem; callers with badly scaled data should balance first.
struct StabilizabilityCheck {
  bool stabilizable = true;                   ///< every unstable mode's margin above the tolerance
  std::complex<double> eigenvalue{0.0, 0.0};  ///< the least controllable unstable eigenvalue
  double margin = 1.0;                        ///< its controllability margin (1 if none unstable)
  std::string message;                        ///< empty when stabilizable
};
StabilizabilityCheck checkStabilizability(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B,
                                          bool discrete, double tolerance = 1e-10);

}  // namespace trellis
