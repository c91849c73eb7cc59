// test_riccati_psd.cpp — the S ⪰ 0 check of solveRiccati (RiccatiOptions::checkPositiveSemidefinite):
// a weight Q(t) that is indefinite between the three times where solveRiccati validates it makes
// S(t) indefinite, and the status says so with the time and the eigenvalue ratio; ordinary solves
// stay ok.
#include <trellis/control/riccati.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Dense>

using Eigen::MatrixXd;

namespace {

// A = 0, B = I, R = I on [0, 1]: two decoupled scalar equations dS_ii/dτ = Q_ii − S_ii².
trellis::LinearizationCallback zeroA() {
  return [](double, MatrixXd& A, MatrixXd& B) {
    A.setZero(2, 2);
    B.setIdentity(2, 2);
    return trellis::ReferenceStatus{};
  };
}

trellis::LqrWeights weights(bool indefiniteWindow) {
  trellis::LqrWeights w;
  w.R = MatrixXd::Identity(2, 2);
  w.Qf = MatrixXd::Identity(2, 2);
  w.Qfun = [indefiniteWindow](double t, MatrixXd& Q) {
    Q.setIdentity(2, 2);
    // Q = diag(1, −20) on (0.2, 0.4): not at t0 = 0, 0.5 or T = 1, where Q is validated.
    if (indefiniteWindow && t > 0.2 && t < 0.4) Q(1, 1) = -20.0;
  };
  return w;
}

}  // namespace

TEST_CASE("an indefinite Q(t) between the checked times makes S indefinite: status says where",
          "[riccati][psd]") {
  for (auto method : {trellis::RiccatiMethod::kBDF, trellis::RiccatiMethod::kAdams}) {
    trellis::RiccatiOptions o;
    o.method = method;
    o.rtol = 1e-8;
    o.atol = 1e-10;
    o.maxStep = 0.02;  // S = I is an equilibrium before the window: do not step over it
    const auto sol = trellis::solveRiccati(0.0, 1.0, 2, 2, zeroA(), weights(true), o);
    INFO(toString(method) << ": " << sol.status.message);
    REQUIRE(sol.status.code == trellis::RiccatiCode::kIndefinite);
    CHECK(!sol.ok());
    // S_22 = 1 until the window (τ = 1 − t < 0.6), falls to ≈ −3.6 across it (dS/dτ = −20 − S²),
    // then keeps falling (dS/dτ = 1 − S² < 0 below −1) to ≈ −11 at t = 0, while S_11 = 1: the
    // worst ratio is at t0, below the window.
    CHECK(sol.status.t < 0.4);
    CHECK(sol.indefiniteRatio < -o.psdSlack * 2 * o.rtol);
    CHECK_THAT(sol.status.message, Catch::Matchers::Contains("indefinite at t ="));
    // S itself is still available over the whole horizon.
    CHECK(sol.validFrom() == 0.0);
    const MatrixXd S = sol.S(sol.status.t);
    const Eigen::Vector2d lambda = Eigen::SelfAdjointEigenSolver<MatrixXd>(S).eigenvalues();
    CHECK(lambda(0) / lambda(1) == Approx(sol.indefiniteRatio).margin(1e-6));
  }
}

TEST_CASE("ordinary solves pass the S >= 0 check; switching it off keeps the old status",
          "[riccati][psd]") {
  trellis::RiccatiOptions o;
  o.rtol = 1e-8;
  o.atol = 1e-10;
  o.maxStep = 0.02;
  const auto good = trellis::solveRiccati(0.0, 1.0, 2, 2, zeroA(), weights(false), o);
  INFO(good.status.message);
  CHECK(good.ok());
  o.checkPositiveSemidefinite = false;
  const auto unchecked = trellis::solveRiccati(0.0, 1.0, 2, 2, zeroA(), weights(true), o);
  INFO(unchecked.status.message);
  CHECK(unchecked.ok());
}
