// Tests for trellis/control/riccati.hpp: closed forms, the CARE limit, a manufactured
// time-varying solution, method agreement, bad weights and the hard cases.
#include "control_test_support.hpp"

#include <trellis/control.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Eigenvalues>

#include <cmath>

using Eigen::MatrixXd;
using trellis::LqrWeights;
using trellis::RiccatiMethod;
using trellis::RiccatiOptions;
using trellis::RiccatiCode;

namespace {

trellis::LinearizationCallback constantSystem(const MatrixXd& A, const MatrixXd& B) {
  return [A, B](double, MatrixXd& a, MatrixXd& b) {
    a = A;
    b = B;
    return trellis::ReferenceStatus{};
  };
}

RiccatiOptions tight(RiccatiMethod method = RiccatiMethod::kBDF) {
  RiccatiOptions o;
  o.rtol = 1e-12;
  o.atol = 1e-12;
  o.method = method;
  return o;
}

const char* methodName(RiccatiMethod m) {
  switch (m) {
    case RiccatiMethod::kBDF: return "BDF";
    case RiccatiMethod::kAdams: return "Adams";
    case RiccatiMethod::kFactored: return "factored";
  }
  return "?";
}

double minEig(const MatrixXd& S) {
  return Eigen::SelfAdjointEigenSolver<MatrixXd>(S, Eigen::EigenvaluesOnly).eigenvalues()(0);
}

// Manufactured problem: S*(t) SPD and smooth; A(t) strongly stable so that
// Q(t) = −Ṡ − AᵀS − SA + S B R⁻¹ Bᵀ S is positive definite.
MatrixXd manufacturedS(double t) {
  MatrixXd S(3, 3);
  S << 2 + std::sin(t), 0.5 * std::cos(t), 0.1,                      //
      0.5 * std::cos(t), 3 + 0.5 * std::sin(2 * t), 0.2 * std::sin(t),  //
      0.1, 0.2 * std::sin(t), 2.5 + 0.3 * std::cos(t);
  return S;
}
MatrixXd manufacturedSdot(double t) {
  MatrixXd D(3, 3);
  D << std::cos(t), -0.5 * std::sin(t), 0.0,                       //
      -0.5 * std::sin(t), std::cos(2 * t), 0.2 * std::cos(t),          //
      0.0, 0.2 * std::cos(t), -0.3 * std::sin(t);
  return D;
}
MatrixXd manufacturedA(double t) {
  MatrixXd A(3, 3);
  A << -2.0, 1.0, 0.3 * std::sin(t),  //
      -0.5 - 0.5 * std::sin(t), -2.2, 0.3 * std::cos(t), //
      0.1, 0.0, -2.5;
  return A;
}
MatrixXd manufacturedB(double t) {
  MatrixXd B(3, 2);
  B << 0.0, 0.3,  //
      1.0 + 0.2 * std::cos(t), 0.0, //
      0.5, 0.4 * std::sin(t);
  return B;
}
MatrixXd manufacturedR() { return (MatrixXd(2, 2) << 1.0, 0.1, 0.1, 2.0).finished(); }
MatrixXd manufacturedQ(double t) {
  const MatrixXd S = manufacturedS(t), A = manufacturedA(t), B = manufacturedB(t);
  const MatrixXd Q = -manufacturedSdot(t) - A.transpose() * S - S * A +
                     S * B * manufacturedR().llt().solve(B.transpose() * S);
  return 0.5 * (Q + Q.transpose());
}

LqrWeights manufacturedWeights(double T) {
  LqrWeights w;
  w.R = manufacturedR();
  w.Qf = manufacturedS(T);
  w.Qfun = [](double t, MatrixXd& Q) { Q = manufacturedQ(t); };
  return w;
}

trellis::LinearizationCallback manufacturedSystem() {
  return [](double t, MatrixXd& A, MatrixXd& B) {
    A = manufacturedA(t);
    B = manufacturedB(t);
    return trellis::ReferenceStatus{};
  };
}

}  // namespace

TEST_CASE("scalar Riccati equation matches its closed form", "[riccati]") {
  // τ = T − t: ds/dτ = q + 2as − (b²/r)s² = −c(s − s₊)(s − s₋), c = b²/r, d = √(a² + cq),
  // s± = (a ± d)/c; w = (s − s₊)/(s − s₋) obeys dw/dτ = −2d w.
  const double a = 0.5, b = 1.0, q = 2.0, r = 0.5, sf = 0.3, T = 3.0;
  const double c = b * b / r, d = std::sqrt(a * a + c * q);
  const double sp = (a + d) / c, sm = (a - d) / c;
  auto exact = [&](double t) {
    const double w = (sf - sp) / (sf - sm) * std::exp(-2 * d * (T - t));
    return (sp - w * sm) / (1 - w);
  };
  LqrWeights w;
  w.Q = MatrixXd::Constant(1, 1, q);
  w.R = MatrixXd::Constant(1, 1, r);
  w.Qf = MatrixXd::Constant(1, 1, sf);
  const auto lin = constantSystem(MatrixXd::Constant(1, 1, a), MatrixXd::Constant(1, 1, b));
  for (auto method : {RiccatiMethod::kBDF, RiccatiMethod::kAdams, RiccatiMethod::kFactored}) {
    SECTION(methodName(method)) {
      const auto sol = trellis::solveRiccati(0.0, T, 1, 1, lin, w, tight(method));
      REQUIRE(sol.ok());
      double worst = 0.0;
      // Step points and points between them (dense output).
      for (int i = 0; i <= 300; ++i) {
        const double t = T * i / 300.0;
        worst = std::max(worst, std::abs(sol.S(t)(0, 0) - exact(t)) / std::abs(exact(t)));
      }
      for (double t : sol.stepTimes()) {
        worst = std::max(worst, std::abs(sol.S(t)(0, 0) - exact(t)) / std::abs(exact(t)));
      }
      INFO("worst relative error " << worst << " over " << sol.steps << " steps");
      CHECK(worst < 1e-8);
      CHECK(sol.K(1.0)(0, 0) == Approx(b * sol.S(1.0)(0, 0) / r).epsilon(1e-14));
    }
  }
}

TEST_CASE("long horizon on a time-invariant system converges to the CARE solution", "[riccati]") {
  // Double integrator, Q = I, R = 1: S = [[√3, 1], [1, √3]], K = [1, √3].
  MatrixXd A(2, 2), B(2, 1);
  A << 0, 1, 0, 0;
  B << 0, 1;
  LqrWeights w;
  w.Q = MatrixXd::Identity(2, 2);
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = MatrixXd::Zero(2, 2);
  MatrixXd Sexact(2, 2);
  Sexact << std::sqrt(3.0), 1, 1, std::sqrt(3.0);
  const auto sol = trellis::solveRiccati(0.0, 40.0, 2, 1, constantSystem(A, B), w, tight());
  REQUIRE(sol.ok());
  CONTROL_CHECK_CLOSE(Sexact, sol.S(0.0), 1e-8, 1.0);
  CONTROL_CHECK_CLOSE((MatrixXd(1, 2) << 1, std::sqrt(3.0)).finished(), sol.K(0.0), 1e-8, 1.0);
  // S stays symmetric positive semidefinite; it starts from Qf = 0.
  CHECK(sol.minEigenvalue >= -1e-12);
  CHECK(sol.maxEigenvalue == Approx(std::sqrt(3.0) + 1).epsilon(1e-8));
  for (double t : {0.0, 10.0, 39.0, 39.9}) {
    const MatrixXd S = sol.S(t);
    CHECK((S - S.transpose()).norm() == 0.0);
    CHECK(minEig(S) >= -1e-12);
  }
  const auto care = trellis::solveCare(A, B, w.Q, w.R);
  REQUIRE(care.ok());
  CONTROL_CHECK_CLOSE(Sexact, care.S, 1e-12, 1.0);

  // Factored form: Qf = 0 is rejected unless regularized; with Qf = 1e-10·I the extra terminal
  // cost is carried back through the stable closed loop (|eig| ≥ 0.5 → factor e^{-40} at t = 0),
  // so the CARE limit is reached to the same 1e-8.
  RiccatiOptions f = tight(RiccatiMethod::kFactored);
  CHECK_THROWS_WITH(trellis::solveRiccati(0.0, 40.0, 2, 1, constantSystem(A, B), w, f),
                    Catch::Matchers::Contains("factoredQfShift"));
  f.factoredQfShift = 1e-10;
  const auto fs = trellis::solveRiccati(0.0, 40.0, 2, 1, constantSystem(A, B), w, f);
  REQUIRE(fs.ok());
  CONTROL_CHECK_CLOSE(Sexact, fs.S(0.0), 1e-8, 1.0);
  CHECK(fs.minEigenvalue >= 0.0);  // S = UᵀU: PSD by construction, Qf + shift ≻ 0
}

TEST_CASE("manufactured time-varying solution is reproduced", "[riccati]") {
  const double t0 = 0.0, T = 4.0;
  for (int i = 0; i <= 40; ++i) {
    const double t = t0 + (T - t0) * i / 40.0;
    INFO("t = " << t);
    REQUIRE(minEig(manufacturedQ(t)) > 0.1);  // Q(t) is a valid (positive definite) weight
  }
  for (auto method : {RiccatiMethod::kBDF, RiccatiMethod::kAdams, RiccatiMethod::kFactored}) {
    SECTION(methodName(method)) {
      const auto sol = trellis::solveRiccati(t0, T, 3, 2, manufacturedSystem(),
                                             manufacturedWeights(T), tight(method));
      REQUIRE(sol.ok());
      double worst = 0.0;
      for (int i = 0; i <= 200; ++i) {
        const double t = t0 + (T - t0) * i / 200.0;
        worst = std::max(worst, trellis::ctest::compareRelative(manufacturedS(t), sol.S(t)).worst);
      }
      INFO("worst error " << worst << ", steps " << sol.steps);
      CHECK(worst < 1e-8);
      // K(t) = R⁻¹BᵀS.
      const double t = 1.3;
      const MatrixXd Kexact =
          manufacturedR().llt().solve(manufacturedB(t).transpose() * manufacturedS(t));
      CONTROL_CHECK_CLOSE(Kexact, sol.K(t), 1e-8, 1.0);
    }
  }
}

TEST_CASE("BDF and Adams agree", "[riccati]") {
  const double T = 4.0;
  RiccatiOptions bdf, adams;
  bdf.rtol = adams.rtol = 1e-10;
  bdf.atol = adams.atol = 1e-12;
  adams.method = RiccatiMethod::kAdams;
  const auto a = trellis::solveRiccati(0, T, 3, 2, manufacturedSystem(), manufacturedWeights(T), bdf);
  const auto b = trellis::solveRiccati(0, T, 3, 2, manufacturedSystem(), manufacturedWeights(T), adams);
  REQUIRE(a.ok());
  REQUIRE(b.ok());
  for (double t : {0.0, 0.77, 2.0, 3.99}) CONTROL_CHECK_CLOSE(a.S(t), b.S(t), 1e-7, 1.0);
  // Difference-quotient Jacobian gives the same answer as the exact one.
  RiccatiOptions dq = bdf;
  dq.exactJacobian = false;
  const auto c = trellis::solveRiccati(0, T, 3, 2, manufacturedSystem(), manufacturedWeights(T), dq);
  REQUIRE(c.ok());
  CONTROL_CHECK_CLOSE(a.S(0.0), c.S(0.0), 1e-7, 1.0);
  CHECK(a.jacobianEvaluations > 0);
  // Matrix-free GMRES with the exact Jacobian-vector product.
  RiccatiOptions kr = bdf;
  kr.linearSolver = trellis::RiccatiLinearSolver::kKrylov;
  const auto k = trellis::solveRiccati(0, T, 3, 2, manufacturedSystem(), manufacturedWeights(T), kr);
  REQUIRE(k.ok());
  for (double t : {0.0, 0.77, 2.0}) CONTROL_CHECK_CLOSE(a.S(t), k.S(t), 1e-7, 1.0);
}

TEST_CASE("bad weights and options are rejected with a clear message", "[riccati]") {
  MatrixXd A(2, 2), B(2, 1);
  A << 0, 1, 0, 0;
  B << 0, 1;
  const auto lin = constantSystem(A, B);
  LqrWeights w;
  w.Q = MatrixXd::Identity(2, 2);
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = MatrixXd::Zero(2, 2);
  using Catch::Matchers::Contains;
  SECTION("R not positive definite") {
    w.R(0, 0) = -1.0;
    CHECK_THROWS_WITH(trellis::solveRiccati(0, 1, 2, 1, lin, w),
                      Contains("R is not positive definite") && Contains("-1"));
  }
  SECTION("R zero") {
    w.R(0, 0) = 0.0;
    CHECK_THROWS_WITH(trellis::solveRiccati(0, 1, 2, 1, lin, w), Contains("R is not positive definite"));
  }
  SECTION("Q indefinite") {
    w.Q(1, 1) = -2.0;
    CHECK_THROWS_WITH(trellis::solveRiccati(0, 1, 2, 1, lin, w),
                      Contains("Q is not positive semidefinite") && Contains("-2"));
  }
  SECTION("Qf not symmetric") {
    w.Qf(0, 1) = 1.0;
    CHECK_THROWS_WITH(trellis::solveRiccati(0, 1, 2, 1, lin, w), Contains("Qf is not symmetric"));
  }
  SECTION("Q(t) callback indefinite at the horizon's end") {
    w.Qfun = [](double t, MatrixXd& Q) { Q = MatrixXd::Identity(2, 2) * (t > 0.9 ? -1.0 : 1.0); };
    CHECK_THROWS_WITH(trellis::solveRiccati(0, 1, 2, 1, lin, w), Contains("Q(t) is not positive semidefinite"));
  }
  SECTION("wrong size") {
    w.R = MatrixXd::Identity(2, 2);
    CHECK_THROWS_WITH(trellis::solveRiccati(0, 1, 2, 1, lin, w), Contains("R must be 1x1, got 2x2"));
  }
  SECTION("options") {
    RiccatiOptions o;
    o.rtol = -1;
    CHECK_THROWS_WITH(trellis::solveRiccati(0, 1, 2, 1, lin, w, o), Contains("rtol = -1"));
    CHECK_THROWS_WITH(trellis::solveRiccati(1, 1, 2, 1, lin, w), Contains("t0 < T"));
  }
}

TEST_CASE("numerical trouble is a status, never an exception or a NaN", "[riccati][hard]") {
  LqrWeights w;
  w.Q = MatrixXd::Identity(2, 2);
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = MatrixXd::Zero(2, 2);
  MatrixXd A(2, 2), B(2, 1);
  A << 0, 1, 0, 0;
  B << 0, 1;
  SECTION("callback throws") {
    auto lin = [&](double t, MatrixXd& a, MatrixXd& b) {
      if (t < 0.5) throw std::runtime_error("no linearization here");
      a = A;
      b = B;
      return trellis::ReferenceStatus{};
    };
    const auto sol = trellis::solveRiccati(0, 1, 2, 1, lin, w);
    CHECK(sol.status.code == RiccatiCode::kCallbackFailure);
    CHECK_THAT(sol.status.message, Catch::Matchers::Contains("no linearization here"));
    CHECK(sol.status.t <= 0.5 + 1e-12);
    CHECK(sol.validFrom() >= 0.5 - 1e-12);
    CHECK(sol.S(sol.validFrom()).allFinite());
    CHECK_THROWS_AS(sol.S(0.0), std::out_of_range);
  }
  SECTION("callback produces NaN") {
    auto lin = [&](double t, MatrixXd& a, MatrixXd& b) {
      a = A;
      b = B;
      if (t < 0.25) a(0, 0) = std::nan("");
      return trellis::ReferenceStatus{};
    };
    const auto sol = trellis::solveRiccati(0, 1, 2, 1, lin, w);
    CHECK(sol.status.code == RiccatiCode::kCallbackFailure);
    CHECK_THAT(sol.status.message, Catch::Matchers::Contains("non-finite"));
  }
  SECTION("callback returns a failed status: kCallbackFailure with its message, nothing thrown") {
    auto lin = [&](double t, MatrixXd& a, MatrixXd& b) {
      trellis::ReferenceStatus st;
      if (t < 0.5) {
        st.set(trellis::ReferenceCode::kLinearizationFailed, "the dynamics failed here", t);
        return st;
      }
      a = A;
      b = B;
      return st;
    };
    const auto sol = trellis::solveRiccati(0, 1, 2, 1, lin, w);
    CHECK(sol.status.code == RiccatiCode::kCallbackFailure);
    CHECK(std::string(sol.status.name()) == "callback_failure");
    CHECK_THAT(sol.status.message, Catch::Matchers::Contains("the dynamics failed here"));
    CHECK(sol.status.t <= 0.5 + 1e-12);
    CHECK_THAT(sol.describe(), Catch::Matchers::StartsWith("callback_failure at t = "));
    CHECK_THAT(sol.json(), Catch::Matchers::Contains("\"status\":\"callback_failure\""));
  }
  SECTION("uncontrollable unstable direction blows up with the time and the norm") {
    MatrixXd Au(2, 2), Bu(2, 1);
    Au << 1, 0, 0, -1;  // x₁ unstable and not reachable from u
    Bu << 0, 1;
    const auto sol = trellis::solveRiccati(0, 100, 2, 1, constantSystem(Au, Bu), w);
    REQUIRE(sol.status.code == RiccatiCode::kBlowUp);
    INFO(sol.status.message);
    // S₁₁ = (e^{2(T−t)} − 1)/2 crosses 1e15 at T − t ≈ 17.6.
    CHECK(sol.status.t == Approx(100 - 0.5 * std::log(2e15 + 1)).margin(0.5));
    CHECK(sol.failureNorm > 1e15);
    CHECK_THAT(sol.status.message, Catch::Matchers::Contains("blew up at t ="));
    CHECK(sol.S(sol.validFrom()).allFinite());
  }
  SECTION("too few steps") {
    RiccatiOptions o;
    o.maxSteps = 5;
    const auto sol = trellis::solveRiccati(0, 40, 2, 1, constantSystem(A, B), w, o);
    CHECK(sol.status.code == RiccatiCode::kIntegratorFailure);
    CHECK_THAT(sol.status.message, Catch::Matchers::Contains("maxSteps = 5"));
    CHECK(std::isfinite(sol.status.t));
    CHECK(std::isfinite(sol.failureNorm));
  }
}

TEST_CASE("hard cases are accurate", "[riccati][hard]") {
  SECTION("stiff: a damped spring at 1e4 rad/s (BDF)") {
    const double wn = 1e4;
    MatrixXd A(2, 2), B(2, 1);
    A << 0, 1, -wn * wn, -2 * wn;
    B << 0, 1;
    LqrWeights w;
    w.Q = MatrixXd::Identity(2, 2);
    w.R = MatrixXd::Identity(1, 1);
    w.Qf = MatrixXd::Zero(2, 2);
    RiccatiOptions o;
    o.rtol = 1e-10;
    o.atol = 1e-16;  // S entries are ~1e-13 … 1e-5
    const auto sol = trellis::solveRiccati(0, 1.0, 2, 1, constantSystem(A, B), w, o);
    REQUIRE(sol.ok());
    const auto care = trellis::solveCare(A, B, w.Q, w.R);
    REQUIRE(care.ok());
    CONTROL_CHECK_CLOSE(care.S, sol.S(0.0), 1e-7, 0.0);
    INFO("BDF steps " << sol.steps);
    CHECK(sol.steps < 2000);
    RiccatiOptions kr = o;
    kr.linearSolver = trellis::RiccatiLinearSolver::kKrylov;
    const auto sk = trellis::solveRiccati(0, 1.0, 2, 1, constantSystem(A, B), w, kr);
    if (sk.ok()) {
      CONTROL_CHECK_CLOSE(care.S, sk.S(0.0), 1e-6, 0.0);
    } else {
      CHECK(!sk.status.message.empty());
    }
    // Adams with functional iteration is not meant for this: accurate or a clear status.
    RiccatiOptions ad = o;
    ad.method = RiccatiMethod::kAdams;
    ad.maxSteps = 20000;
    const auto sa = trellis::solveRiccati(0, 1.0, 2, 1, constantSystem(A, B), w, ad);
    if (sa.ok()) {
      CONTROL_CHECK_CLOSE(care.S, sa.S(0.0), 1e-6, 0.0);
    } else {
      CHECK(sa.status.code == RiccatiCode::kIntegratorFailure);
      CHECK(!sa.status.message.empty());
      CHECK(sa.S(sa.validFrom()).allFinite());
    }
  }
  SECTION("100 s horizon on an open-loop unstable system, Qf = 0") {
    MatrixXd A(2, 2), B(2, 1);
    A << 0, 1, 10, 0;  // eigenvalues ±√10
    B << 0, 1;
    LqrWeights w;
    w.Q = MatrixXd::Identity(2, 2);
    w.R = MatrixXd::Identity(1, 1);
    w.Qf = MatrixXd::Zero(2, 2);
    const auto sol = trellis::solveRiccati(0, 100, 2, 1, constantSystem(A, B), w, tight());
    REQUIRE(sol.ok());
    const auto care = trellis::solveCare(A, B, w.Q, w.R);
    REQUIRE(care.ok());
    for (double t : {0.0, 50.0, 90.0}) CONTROL_CHECK_CLOSE(care.S, sol.S(t), 1e-8, 1.0);
  }
  SECTION("cheap control: R = 1e-6") {
    // Double integrator, Q = I, R = r: s12 = √r, s22 = √(r(1 + 2√r)), s11 = s12 s22 / r.
    const double r = 1e-6;
    MatrixXd A(2, 2), B(2, 1);
    A << 0, 1, 0, 0;
    B << 0, 1;
    LqrWeights w;
    w.Q = MatrixXd::Identity(2, 2);
    w.R = MatrixXd::Constant(1, 1, r);
    w.Qf = MatrixXd::Zero(2, 2);
    const double s12 = std::sqrt(r), s22 = std::sqrt(r * (1 + 2 * std::sqrt(r)));
    MatrixXd Sexact(2, 2);
    Sexact << s12 * s22 / r, s12, s12, s22;
    RiccatiOptions o = tight();
    o.atol = 1e-16;
    const auto sol = trellis::solveRiccati(0, 20, 2, 1, constantSystem(A, B), w, o);
    REQUIRE(sol.ok());
    CONTROL_CHECK_CLOSE(Sexact, sol.S(0.0), 1e-8, 0.0);
    const auto care = trellis::solveCare(A, B, w.Q, w.R);
    REQUIRE(care.ok());
    CONTROL_CHECK_CLOSE(Sexact, care.S, 1e-10, 0.0);
  }
}

TEST_CASE("cart-pole: TV-LQR along the upright equilibrium matches the CARE gain", "[riccati][model]") {
  const trellis::Model model = trellis::ctest::makeCartPole();
  trellis::Data data(model);
  Eigen::VectorXd times(3);
  times << 0.0, 15.0, 30.0;
  trellis::Trajectory traj(model.configNames(), model.inputNames(), times,
                           MatrixXd::Zero(4, 3), MatrixXd::Zero(1, 3));
  traj.computeStateDerivatives(model, data);
  CHECK(traj.stateDerivatives().norm() == 0.0);  // an equilibrium

  LqrWeights w;
  w.Q = MatrixXd::Identity(4, 4);
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = MatrixXd::Zero(4, 4);
  RiccatiOptions o;
  o.rtol = 1e-11;
  o.atol = 1e-11;
  const auto sol = trellis::solveRiccati(model, traj, w, o);
  REQUIRE(sol.ok());

  const Eigen::VectorXd z = Eigen::VectorXd::Zero(2), u = Eigen::VectorXd::Zero(1);
  REQUIRE(trellis::computeLinearization(model, data, z, z, u).ok());
  const auto care = trellis::solveCare(data.A, data.B, w.Q, w.R);
  REQUIRE(care.ok());
  CHECK(care.closedLoopEigenvalues.real().maxCoeff() < 0.0);
  CHECK(Eigen::EigenSolver<MatrixXd>(data.A).eigenvalues().real().maxCoeff() > 0.0);  // unstable
  CONTROL_CHECK_CLOSE(care.S, sol.S(0.0), 1e-7, 1.0);
  CONTROL_CHECK_CLOSE(care.K, sol.K(0.0), 1e-7, 1.0);
}
