// test_riccati_factored_singular.cpp — the factored Riccati form when S(t) tends to a singular
// matrix (rank-deficient Q over a long horizon, the null direction not aligned with the axes):
// the factor's ODE turns stiff there, so the solve switches to the plain form past
// RiccatiOptions::factoredSwitchCondition; with the switch disabled it needs many more steps.
#include <trellis/control/riccati.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cmath>

using Eigen::MatrixXd;

namespace {

// A double integrator (observed through Q) ⊕ a stable mode ẋ3 = −x3 that Q does not see, in
// coordinates rotated by an orthogonal V: S(t) → V diag(S_di, 0) Vᵀ-like, singular along V e3.
struct SingularCase {
  MatrixXd A, B;
  trellis::LqrWeights w;
  SingularCase() {
    MatrixXd A0 = MatrixXd::Zero(3, 3), B0 = MatrixXd::Zero(3, 1);
    A0(0, 1) = 1.0;
    A0(2, 2) = -1.0;
    B0(1, 0) = 1.0;
    const MatrixXd V = Eigen::HouseholderQR<MatrixXd>(
                           (MatrixXd(3, 3) << 1, 2, 0.5, -1, 1, 2, 0.3, -2, 1).finished())
                           .householderQ();
    A = V * A0 * V.transpose();
    B = V * B0;
    MatrixXd Q0 = MatrixXd::Zero(3, 3);
    Q0(0, 0) = 1.0;  // rank 1: only the position of the double integrator
    w.Q = V * Q0 * V.transpose();
    w.R = MatrixXd::Identity(1, 1);
    w.Qf = MatrixXd::Identity(3, 3);
  }
  trellis::LinearizationCallback lin() const {
    return [A = A, B = B](double, MatrixXd& a, MatrixXd& b) {
      a = A;
      b = B;
      return trellis::ReferenceStatus{};
    };
  }
};

}  // namespace

TEST_CASE("riccati: factored form with S tending to a singular matrix switches to the plain form",
          "[riccati][factored]") {
  const SingularCase c;
  // Measured (rtol 1e-8): plain BDF 313 steps; factored with the switch 291; without 22468.
  // With the null direction along an axis (no rotation) the factor has no trouble (295 steps):
  // the stiffness comes from U⁻¹ amplifying the cancellation error in the rotated Ṡ.
  const double T = 200.0;  // e^{-2·200}: the null direction's part of S decays far below rtol·|S|
  trellis::RiccatiOptions plain;
  plain.rtol = 1e-8;
  plain.atol = 1e-10;
  const auto ref = trellis::solveRiccati(0.0, T, 3, 1, c.lin(), c.w, plain);
  REQUIRE(ref.ok());

  trellis::RiccatiOptions factored = plain;
  factored.method = trellis::RiccatiMethod::kFactored;
  const auto sol = trellis::solveRiccati(0.0, T, 3, 1, c.lin(), c.w, factored);
  INFO("plain " << ref.steps << " steps, factored " << sol.steps << " steps, switched at t = "
                << sol.switchedToPlainAt << "; " << sol.status.message);
  REQUIRE(sol.ok());
  CHECK(std::isfinite(sol.switchedToPlainAt));
  CHECK(sol.steps < 3 * ref.steps);
  for (double t : {0.0, 50.0, 150.0, 195.0, 199.9}) {
    const MatrixXd d = ref.S(t) - sol.S(t);
    CHECK(d.cwiseAbs().maxCoeff() < 1e-5 * ref.S(t).cwiseAbs().maxCoeff());
  }
  // The limit is singular: the smallest eigenvalue of S(0) is negligible against the largest.
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<MatrixXd>(ref.S(0.0)).eigenvalues();
  CHECK(std::abs(ev(0)) < 1e-8 * ev(2));

  // Without the switch the factored form needs far more steps (or fails with too much work).
  factored.factoredSwitchCondition = 0.0;
  factored.maxSteps = 30 * ref.steps;
  const auto noSwitch = trellis::solveRiccati(0.0, T, 3, 1, c.lin(), c.w, factored);
  INFO("without switch: " << noSwitch.steps << " steps, " << noSwitch.status.message);
  CHECK((!noSwitch.ok() || noSwitch.steps > 10 * ref.steps));
}
