// tests/support/linearization_checks.hpp — the checks several test files apply to a model at a
// state: analytic linearization against central differences, its block structure, and the dense
// KKT solve that is the independent reference for q̈ and λ.
#pragma once

#include <trellis/core.hpp>

#include "support/finite_difference.hpp"
#include "support/random_state.hpp"

#include <string>

namespace trellis::test {

/// Tolerance for analytic derivatives against central differences, relative to
/// max(1, ‖FD column‖∞). The central differences are accurate to ~eps^(2/3) ≈ 1e-10 relative to the
/// scale of q̈'s first and third derivatives (finite_difference.hpp); 1e-6 leaves four orders of
/// margin and still catches any wrong term (those show up at 1e-3 … 1).
inline constexpr double kFdTolerance = 1e-6;

/// Runs computeLinearization at s and checks, with Catch2 CHECKs:
///  - status ok (REQUIRE), A is 2n×2n and B 2n×m, A = [[0, I], [dqdd_dq, dqdd_ddq]], B = [[0],
///  [dqdd_du]];
///  - data.qdd equals computeDynamics' q̈ (same function, 1e-13 relative: only rounding may differ);
///  - dqdd_dq, dqdd_ddq, dqdd_du and dlambda_dx against central differences of computeDynamics
///    (kFdTolerance, column-relative, unless `tolerance` overrides it; `stepScale` and `stencil`
///    as in centralDifferenceJacobian).
void checkLinearizationAgainstFd(const Model& model, const State& s,
                                 double tolerance = kFdTolerance, double stepScale = 1.0,
                                 Stencil stencil = Stencil::kSecondOrder);

/// The dense KKT system of data's last dynamics evaluation, [[M, Aᵀ], [A, 0]] [q̈; ν] = [−b; −drift]
/// (data.M, constraintJacobian, bias, constraintDrift), solved by full-pivoting LU: solution =
/// [q̈; ν] with ν = −λ (M q̈ + b = Aᵀλ), and the system's 2-norm condition number (SVD), whose
/// κ·eps bounds how far two correct solvers may differ.
struct DenseKkt {
  Eigen::VectorXd solution;  ///< [q̈; ν], n + nc
  double condition = 0.0;    ///< κ₂ of the KKT matrix
};
DenseKkt denseKktSolve(const Data& data);

}  // namespace trellis::test
