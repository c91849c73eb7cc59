// Tests for trellis/control/lqr.hpp: CARE, DARE, Lyapunov, zero-order hold, discrete recursion.
#include "control_test_support.hpp"

#include <trellis/control.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <random>

using Eigen::MatrixXd;
using trellis::LqrCode;

namespace {

MatrixXd randomMatrix(std::mt19937& rng, int r, int c) {
  std::normal_distribution<double> nd(0.0, 1.0);
  MatrixXd M(r, c);
  for (int j = 0; j < c; ++j)
    for (int i = 0; i < r; ++i) M(i, j) = nd(rng);
  return M;
}

}  // namespace

TEST_CASE("CARE: closed forms and residuals", "[lqr][care]") {
  SECTION("double integrator, R = r") {
    for (double r : {1.0, 0.01, 1e-6, 100.0}) {
      MatrixXd A(2, 2), B(2, 1);
      A << 0, 1, 0, 0;
      B << 0, 1;
      const double s12 = std::sqrt(r), s22 = std::sqrt(r * (1 + 2 * std::sqrt(r)));
      MatrixXd S(2, 2);
      S << s12 * s22 / r, s12, s12, s22;
      const auto res = trellis::solveCare(A, B, MatrixXd::Identity(2, 2), MatrixXd::Constant(1, 1, r));
      INFO("r = " << r << ": " << res.status.message);
      REQUIRE(res.ok());
      CONTROL_CHECK_CLOSE(S, res.S, 1e-12, 0.0);
      CHECK(res.residual < 1e-14);
    }
  }
  SECTION("scalar: s = r(a + √(a² + b²q/r))/b²") {
    const double a = 2.0, b = 0.5, q = 3.0, r = 0.2;
    const auto res = trellis::solveCare(MatrixXd::Constant(1, 1, a), MatrixXd::Constant(1, 1, b),
                                        MatrixXd::Constant(1, 1, q), MatrixXd::Constant(1, 1, r));
    REQUIRE(res.ok());
    CHECK(res.S(0, 0) == Approx(r * (a + std::sqrt(a * a + b * b * q / r)) / (b * b)).epsilon(1e-14));
  }
  SECTION("random 12-state systems (seeded)") {
    std::mt19937 rng(20240603);
    for (int trial = 0; trial < 5; ++trial) {
      const MatrixXd A = randomMatrix(rng, 12, 12), B = randomMatrix(rng, 12, 3);
      const MatrixXd L = randomMatrix(rng, 12, 12);
      const MatrixXd Q = L * L.transpose() / 12.0;
      const auto res = trellis::solveCare(A, B, Q, MatrixXd::Identity(3, 3));
      INFO(res.status.message);
      REQUIRE(res.ok());
      CHECK(res.residual < 1e-12);
      CHECK(res.closedLoopEigenvalues.real().maxCoeff() < 0.0);
      CHECK((res.S - res.S.transpose()).norm() == 0.0);
      CHECK(Eigen::SelfAdjointEigenSolver<MatrixXd>(res.S).eigenvalues()(0) > -1e-10);
    }
  }
}

TEST_CASE("CARE: failures are reported", "[lqr][care]") {
  SECTION("not stabilizable") {
    MatrixXd A(2, 2), B(2, 1);
    A << 1, 0, 0, -1;
    B << 0, 1;
    const auto res = trellis::solveCare(A, B, MatrixXd::Identity(2, 2), MatrixXd::Identity(1, 1));
    CHECK(res.status.code == LqrCode::kNotStabilizable);
    CHECK_THAT(res.status.message, Catch::Matchers::Contains("not stabilizable") &&
                                Catch::Matchers::Contains("eigenvalue 1"));
  }
  SECTION("stable but uncontrollable is fine") {
    MatrixXd A(2, 2), B(2, 1);
    A << -1, 0, 0, 1;
    B << 0, 1;
    const auto res = trellis::solveCare(A, B, MatrixXd::Identity(2, 2), MatrixXd::Identity(1, 1));
    REQUIRE(res.ok());
    CHECK(res.S(0, 0) == Approx(0.5).epsilon(1e-12));  // 2·(−1)s + 1 = 0
  }
  SECTION("undetectable imaginary-axis mode: no stabilizing solution") {
    MatrixXd A(2, 2), B(2, 1);
    A << 0, 1, -1, 0;
    B << 0, 1;
    const auto res = trellis::solveCare(A, B, MatrixXd::Zero(2, 2), MatrixXd::Identity(1, 1));
    CHECK(res.status.code == LqrCode::kNoStabilizingSolution);
    CHECK(!res.status.message.empty());
  }
  SECTION("bad weights throw") {
    MatrixXd A = MatrixXd::Zero(2, 2), B = MatrixXd::Ones(2, 1);
    CHECK_THROWS_WITH(trellis::solveCare(A, B, MatrixXd::Identity(2, 2), MatrixXd::Constant(1, 1, -3.0)),
                      Catch::Matchers::Contains("R is not positive definite: smallest eigenvalue -3"));
    CHECK_THROWS_WITH(trellis::solveCare(A, B, (MatrixXd(2, 2) << 1, 2, 0, 1).finished(),
                                         MatrixXd::Identity(1, 1)),
                      Catch::Matchers::Contains("Q is not symmetric"));
    CHECK_THROWS_WITH(trellis::solveCare(A, B, MatrixXd::Identity(2, 2), MatrixXd::Identity(1, 1),
                                         MatrixXd::Ones(2, 2)),
                      Catch::Matchers::Contains("N must be 2x1, got 2x2"));
    CHECK_THROWS_WITH(trellis::solveCare(A, MatrixXd::Ones(3, 1), MatrixXd::Identity(2, 2), MatrixXd::Identity(1, 1)),
                      Catch::Matchers::Contains("B must be 2xm"));
  }
}

TEST_CASE("Lyapunov solver", "[lqr]") {
  std::mt19937 rng(7);
  const MatrixXd F = randomMatrix(rng, 8, 8) - 4.0 * MatrixXd::Identity(8, 8);
  const MatrixXd L = randomMatrix(rng, 8, 8);
  const MatrixXd C = L * L.transpose();
  const trellis::MatrixEquationSolution sol = trellis::solveLyapunov(F, C);
  REQUIRE(sol.ok());
  const MatrixXd& X = sol.X;
  const MatrixXd res = F.transpose() * X + X * F + C;
  CHECK(res.norm() / C.norm() < 1e-13);
  // A singular equation (F = 0: every λ_i + λ̄_j = 0) is a returned status, not an exception;
  // only bad sizes throw.
  const trellis::MatrixEquationSolution singular =
      trellis::solveLyapunov(MatrixXd::Zero(2, 2), MatrixXd::Identity(2, 2));
  CHECK(singular.status.code == trellis::MatrixEquationCode::kSingular);
  CHECK(singular.status.index == 0);
  CHECK(singular.X.size() == 0);
  CHECK_THROWS_AS(trellis::solveLyapunov(MatrixXd::Zero(2, 3), MatrixXd::Identity(2, 2)),
                  std::invalid_argument);
}

TEST_CASE("Stein solver", "[lqr][discrete]") {
  std::mt19937 rng(11);
  const MatrixXd F = 0.1 * randomMatrix(rng, 6, 6);
  const MatrixXd L = randomMatrix(rng, 6, 6);
  const MatrixXd C = L * L.transpose();
  const trellis::MatrixEquationSolution sol = trellis::solveStein(F, C);
  REQUIRE(sol.ok());
  const MatrixXd res = F.transpose() * sol.X * F - sol.X + C;
  CHECK(res.norm() / C.norm() < 1e-13);
  // F = I: every λ_i λ̄_j = 1, singular.
  const trellis::MatrixEquationSolution singular =
      trellis::solveStein(MatrixXd::Identity(3, 3), MatrixXd::Identity(3, 3));
  CHECK(singular.status.code == trellis::MatrixEquationCode::kSingular);
  CHECK_THAT(singular.json(), Catch::Matchers::Contains("\"status\":\"singular\""));
}

TEST_CASE("zero-order hold is exact", "[lqr][discrete]") {
  MatrixXd A(2, 2), B(2, 1);
  A << 0, 1, 0, 0;
  B << 0, 1;
  const double h = 0.1;
  const auto d = trellis::discretizeZeroOrderHold(A, B, h);
  CONTROL_CHECK_CLOSE((MatrixXd(2, 2) << 1, h, 0, 1).finished(), d.Ad, 1e-15, 1.0);
  CONTROL_CHECK_CLOSE((MatrixXd(2, 1) << h * h / 2, h).finished(), d.Bd, 1e-15, 1.0);
  // Scalar: Ad = e^{ah}, Bd = (e^{ah} − 1) b / a.
  const auto s = trellis::discretizeZeroOrderHold(MatrixXd::Constant(1, 1, -3.0),
                                                  MatrixXd::Constant(1, 1, 2.0), 0.25);
  CHECK(s.Ad(0, 0) == Approx(std::exp(-0.75)).epsilon(1e-14));
  CHECK(s.Bd(0, 0) == Approx((std::exp(-0.75) - 1) * 2 / -3.0).epsilon(1e-14));
  CHECK_THROWS_WITH(trellis::discretizeZeroOrderHold(A, B, 0.0), Catch::Matchers::Contains("h = 0"));
}

TEST_CASE("discrete recursion converges to the DARE", "[lqr][discrete]") {
  MatrixXd A(2, 2), B(2, 1);
  A << 0, 1, 10, 0;  // open-loop unstable
  B << 0, 1;
  const auto d = trellis::discretizeZeroOrderHold(A, B, 0.01);
  const MatrixXd Q = MatrixXd::Identity(2, 2), R = MatrixXd::Identity(1, 1);
  const auto dare = trellis::solveDare(d.Ad, d.Bd, Q, R);
  INFO(dare.status.message);
  REQUIRE(dare.ok());
  CHECK(dare.residual < 1e-12);
  CHECK(dare.closedLoopEigenvalues.cwiseAbs().maxCoeff() < 1.0);
  const auto rec = trellis::solveDiscreteRiccatiRecursion(d.Ad, d.Bd, Q, R, MatrixXd::Zero(2, 2), 5000);
  REQUIRE(rec.S.size() == 5001);
  REQUIRE(rec.K.size() == 5000);
  CHECK(rec.S.back().norm() == 0.0);
  CONTROL_CHECK_CLOSE(dare.S, rec.S.front(), 1e-10, 1.0);
  CONTROL_CHECK_CLOSE(dare.K, rec.K.front(), 1e-10, 1.0);
  // With weights Q h, R h the discrete solution approaches the continuous one as h → 0.
  const double h = 1e-3;
  const auto dh = trellis::discretizeZeroOrderHold(A, B, h);
  const auto dareh = trellis::solveDare(dh.Ad, dh.Bd, Q * h, R * h);
  const auto care = trellis::solveCare(A, B, Q, R);
  REQUIRE(dareh.ok());
  REQUIRE(care.ok());
  CONTROL_CHECK_CLOSE(care.S, dareh.S, 2e-2, 1.0);

  SECTION("not stabilizable") {
    MatrixXd Au(2, 2), Bu(2, 1);
    Au << 1.5, 0, 0, 0.5;
    Bu << 0, 1;
    const auto res = trellis::solveDare(Au, Bu, Q, R);
    CHECK(res.status.code == LqrCode::kNotStabilizable);
    CHECK_THAT(res.status.message, Catch::Matchers::Contains("(|lambda| = 1.5 >= 1)"));
  }
}
