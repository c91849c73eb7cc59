// Tests for OdeMethod::Radau (analysis/src/radau_stepper.hpp) and IntegrationMethod::kRadau:
// accuracy against closed forms (a stiff linear system through exp(At), a stiff oscillator in
// second-order form with and without the halved solves), the dense output, a stiff nonlinear
// problem against CVODES at a tight tolerance, restarts that keep the step, failures, and the
// simulator with sampled feedback against BDF.
#include "control_test_support.hpp"
#include "ode_test_systems.hpp"

#include "trellis/analysis/detail/ode_driver.hpp"
#include "trellis/analysis/detail/radau_tableau.hpp"
#include "trellis/analysis/detail/split_complex_lu.hpp"
#include "radau_stepper.hpp"

#include <trellis/analysis/simulation.hpp>
#include <trellis/control/lqr.hpp>
#include <trellis/core.hpp>
#include <trellis/core/gain_schedule.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Dense>
#include <unsupported/Eigen/MatrixFunctions>

#include <cmath>
#include <string>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::detail::ConstVectorMap;
using trellis::detail::MatrixMap;
using trellis::detail::OdeDriver;
using trellis::detail::OdeMethod;
using trellis::detail::OdeOptions;
using trellis::detail::OdeOutcome;
using trellis::detail::OdeSystem;
using trellis::detail::VectorMap;

namespace {

/// ẏ = A y + g sin(ω t) with the exact Jacobian A; `second` declares A = [[0, I], [A_q, A_v]].
class LinearForced : public OdeSystem {
 public:
  explicit LinearForced(MatrixXd a, bool second = false) : A(std::move(a)), second_(second) {
    g = VectorXd::Zero(A.rows());
  }
  int rhs(double t, ConstVectorMap y, VectorMap ydot) override {
    ++rhsCalls;
    if (t > failAfter) {
      failure = "the test's right-hand side refuses t > " + std::to_string(failAfter);
      return recoverable ? 1 : -1;
    }
    ydot.noalias() = A * y;
    ydot += std::sin(omega * t) * g;
    return 0;
  }
  bool hasJacobian() const override { return true; }
  int jacobian(double, ConstVectorMap, ConstVectorMap, MatrixMap J) override {
    ++jacobianCalls;
    J = A;
    return 0;
  }
  bool secondOrder() const override { return second_; }
  MatrixXd A;
  VectorXd g;
  double omega = 0.0;
  long rhsCalls = 0, jacobianCalls = 0;
  double failAfter = 1e300;
  bool recoverable = false;

 private:
  bool second_;
};

MatrixXd stiffLinear() { return trellis::test::stiffLinearMatrix(); }
VectorXd start5() { return trellis::test::stiffLinearStart(); }

/// q̈ = −K q − D q̇ for 3 coordinates: a stiff spring (ω = 300) beside slow ones, coupled.
MatrixXd oscillator() {
  MatrixXd K(3, 3), D(3, 3);
  K << 9e4, -10, 0,  //
      -10, 4, -1,    //
      0, -1, 1;
  D << 30, 0, 0,  //
      0, 0.1, 0,  //
      0, 0, 0.05;
  MatrixXd A = MatrixXd::Zero(6, 6);
  A.topRightCorner(3, 3).setIdentity();
  A.bottomLeftCorner(3, 3) = -K;
  A.bottomRightCorner(3, 3) = -D;
  return A;
}

OdeOptions radauOptions(double rtol, double atol) {
  OdeOptions o;
  o.method = OdeMethod::Radau;
  o.rtol = rtol;
  o.atol = atol;
  o.what = "radau test";
  return o;
}

/// Van der Pol in Hairer & Wanner's scaling (VDPOL), y0' = y1, y1' = ((1 − y0²) y1 − y0)/ε:
/// slow motion along a manifold with fast jumps, stiffness ~1/ε.
class VanDerPol : public OdeSystem {
 public:
  explicit VanDerPol(double eps) : k_(1.0 / eps) {}
  int rhs(double, ConstVectorMap y, VectorMap f) override {
    f(0) = y(1);
    f(1) = k_ * ((1.0 - y(0) * y(0)) * y(1) - y(0));
    return 0;
  }
  bool hasJacobian() const override { return true; }
  int jacobian(double, ConstVectorMap y, ConstVectorMap, MatrixMap J) override {
    J(0, 0) = 0.0;
    J(0, 1) = 1.0;
    J(1, 0) = k_ * (-2.0 * y(0) * y(1) - 1.0);
    J(1, 1) = k_ * (1.0 - y(0) * y(0));
    return 0;
  }
  bool secondOrder() const override { return true; }

 private:
  double k_;
};

}  // namespace

TEST_CASE("radau: the tableau's decomposition a = T diag(γ0, μ, μ̄) T⁻¹ and its order conditions", "[radau]") {
  const auto& tab = trellis::detail::RadauTableau::get();
  Eigen::Matrix3cd a;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) a(i, j) = tab.a[i][j];
  Eigen::Matrix3cd D = Eigen::Matrix3cd::Zero();
  D(0, 0) = tab.gamma0;
  D(1, 1) = tab.mu;
  D(2, 2) = std::conj(tab.mu);
  CHECK((tab.T * D * tab.Tinv - a).cwiseAbs().maxCoeff() < 1e-14);
  CHECK(tab.T.col(0).imag().cwiseAbs().maxCoeff() == 0.0);
  // Collocation: Σ_j a_ij c_j^{k−1} = c_i^k / k for k = 1, 2, 3.
  for (int i = 0; i < 3; ++i) {
    for (int k = 1; k <= 3; ++k) {
      double s = 0.0;
      for (int j = 0; j < 3; ++j) s += tab.a[i][j] * std::pow(tab.c[j], k - 1);
      CHECK(s == Approx(std::pow(tab.c[i], k) / k).epsilon(1e-14));
    }
  }
}

TEST_CASE("radau: the split-storage complex LU solves as Eigen's, pivoting where it must", "[radau]") {
  // A diagonally dominant matrix, one whose first pivot is zero (a row swap is required), and one
  // with rows scaled over 12 orders: each solve against Eigen's PartialPivLU<MatrixXcd> and as a
  // residual relative to |M||x| + |b|.
  const int n = 9;
  std::vector<Eigen::MatrixXcd> cases;
  cases.push_back(Eigen::MatrixXcd::Random(n, n) + 8.0 * Eigen::MatrixXcd::Identity(n, n));
  Eigen::MatrixXcd swap = Eigen::MatrixXcd::Random(n, n);
  swap(0, 0) = 0.0;
  cases.push_back(swap);
  Eigen::MatrixXcd scaled = Eigen::MatrixXcd::Random(n, n);
  for (int i = 0; i < n; ++i) scaled.row(i) *= std::pow(10.0, 12.0 * i / (n - 1) - 6.0);
  cases.push_back(scaled);
  for (std::size_t c = 0; c < cases.size(); ++c) {
    CAPTURE(c);
    const Eigen::MatrixXcd& M = cases[c];
    trellis::detail::SplitComplexLu lu;
    lu.resize(n);
    lu.re() = M.real();
    lu.im() = M.imag();
    lu.factor();
    const Eigen::VectorXcd b = Eigen::VectorXcd::Random(n);
    Eigen::VectorXcd x = b;
    lu.solve(x);
    const Eigen::VectorXcd ref = Eigen::PartialPivLU<Eigen::MatrixXcd>(M).solve(b);
    const double residual = ((M * x - b).cwiseAbs().array() /
                             (M.cwiseAbs() * x.cwiseAbs() + b.cwiseAbs()).array()).maxCoeff();
    CHECK(residual < 1e-14);
    CHECK((x - ref).cwiseAbs().maxCoeff() <= 1e-12 * ref.cwiseAbs().maxCoeff());
    // Several columns in split storage (the sampled discretization's twin: row operations across
    // all of them, AVX2 where the CPU has it), views into larger matrices: each column as the
    // vector solve gives it up to rounding (the multi-column kernel fuses its multiply-adds), as
    // a residual, and nothing outside touched; 4 columns (one chunk), 18 (a masked last chunk) and
    // 1 (the vector solve itself, exactly).
    for (const int m : {1, 4, 18}) {
      CAPTURE(m);
      const Eigen::MatrixXcd B = Eigen::MatrixXcd::Random(n, m);
      Eigen::MatrixXd Xr = Eigen::MatrixXd::Constant(n + 2, m, 7.0), Xi = Eigen::MatrixXd::Constant(n + 2, m, 7.0);
      Xr.middleRows(1, n) = B.real();
      Xi.middleRows(1, n) = B.imag();
      lu.solve(Xr.middleRows(1, n), Xi.middleRows(1, n));
      for (int j = 0; j < m; ++j) {
        Eigen::VectorXcd xj = B.col(j);
        lu.solve(xj);
        const Eigen::VectorXcd got = Xr.col(j).segment(1, n) + std::complex<double>(0.0, 1.0) * Xi.col(j).segment(1, n);
        if (m == 1) {
          CHECK(got == xj);
        } else {
          CHECK((got - xj).cwiseAbs().maxCoeff() <= 1e-13 * xj.cwiseAbs().maxCoeff());
        }
        const double res = ((M * got - B.col(j)).cwiseAbs().array() /
                            (M.cwiseAbs() * got.cwiseAbs() + B.col(j).cwiseAbs()).array()).maxCoeff();
        CHECK(res < 1e-14);
      }
      CHECK((Xr.row(0).array() == 7.0).all());
      CHECK((Xi.row(n + 1).array() == 7.0).all());
    }
  }
}

TEST_CASE("radau: a stiff linear system reaches exp(At) y0 at the asked accuracy", "[radau]") {
  for (const double rtol : {1e-6, 1e-9, 1e-11}) {
    CAPTURE(rtol);
    LinearForced sys(stiffLinear());
    OdeDriver d(sys, 5, radauOptions(rtol, 1e-3 * rtol));
    d.start(0.0, start5());
    for (const double t : {0.1, 0.5, 1.0, 2.0}) {
      const auto st = d.advanceTo(t);
      REQUIRE(st.ok());
      CHECK(d.time() == t);
      const VectorXd exact = (sys.A * t).exp() * start5();
      // The local tolerance accumulated over the run: a few times rtol relative to max |y0|.
      CHECK((d.state() - exact).cwiseAbs().maxCoeff() < 20.0 * rtol * 2.0);
    }
    const auto s = d.stats();
    CHECK(s.steps > 0);
    CHECK(s.rhsEvaluations == sys.rhsCalls);
    CHECK(s.jacobianEvaluations == sys.jacobianCalls);
    CHECK(s.linearRhsEvaluations == 0);
  }
}

TEST_CASE("radau: second-order systems — the halved solves equal the full ones", "[radau]") {
  // The oscillator with a forcing: the same steps either way (the two solves agree to rounding),
  // and the result against the forced solution of the exact linear system.
  const VectorXd x0 = (VectorXd(6) << 0.01, 1.0, -0.5, 0.0, 0.3, 0.0).finished();
  LinearForced full(oscillator(), false), halved(oscillator(), true);
  for (LinearForced* s : {&full, &halved}) {
    s->g = (VectorXd(6) << 0, 0, 0, 100.0, 0.0, 1.0).finished();
    s->omega = 7.0;
  }
  OdeDriver df(full, 6, radauOptions(1e-10, 1e-12)), dh(halved, 6, radauOptions(1e-10, 1e-12));
  df.start(0.0, x0);
  dh.start(0.0, x0);
  REQUIRE(df.advanceTo(3.0).ok());
  REQUIRE(dh.advanceTo(3.0).ok());
  // The same method: the step sequences differ only where rounding tips a decision.
  CHECK(std::abs(df.stats().steps - dh.stats().steps) <= df.stats().steps / 100);
  CHECK((df.state() - dh.state()).cwiseAbs().maxCoeff() < 1e-8 * x0.cwiseAbs().maxCoeff());
  // Reference: the augmented linear system [y; sin ωt; cos ωt] by its exponential.
  MatrixXd M = MatrixXd::Zero(8, 8);
  M.topLeftCorner(6, 6) = full.A;
  M.block(0, 6, 6, 1) = full.g;
  M(6, 7) = 7.0;   // d/dt sin = ω cos
  M(7, 6) = -7.0;  // d/dt cos = −ω sin
  VectorXd z0(8);
  z0 << x0, 0.0, 1.0;
  const VectorXd exact = ((M * 3.0).exp() * z0).head(6);
  CHECK((dh.state() - exact).cwiseAbs().maxCoeff() < 1e-8 * exact.cwiseAbs().maxCoeff());
  CHECK((df.state() - exact).cwiseAbs().maxCoeff() < 1e-8 * exact.cwiseAbs().maxCoeff());
}

TEST_CASE("radau: dense output is the step's collocation polynomial, accurate inside the step", "[radau]") {
  LinearForced sys(stiffLinear());
  OdeDriver d(sys, 5, radauOptions(1e-10, 1e-13));
  d.start(0.0, start5());
  VectorXd y(5), dy(5);
  CHECK(d.interpolate(0.0, 0, y));  // before a step: the start itself
  CHECK((y - start5()).cwiseAbs().maxCoeff() == 0.0);
  CHECK_FALSE(d.interpolate(0.1, 0, y));
  double worst = 0.0, worstRate = 0.0;
  double t0 = 0.0;
  for (int k = 0; k < 30; ++k) {
    REQUIRE(d.step(5.0).ok());
    const double t1 = d.time();
    for (const double f : {0.25, 0.5, 0.9}) {
      const double t = t0 + f * (t1 - t0);
      REQUIRE(d.interpolate(t, 0, y));
      REQUIRE(d.interpolate(t, 1, dy));
      const VectorXd exact = (sys.A * t).exp() * start5();
      worst = std::max(worst, (y - exact).cwiseAbs().maxCoeff());
      worstRate = std::max(worstRate, (dy - sys.A * exact).cwiseAbs().maxCoeff() /
                                          std::max(1.0, (sys.A * exact).cwiseAbs().maxCoeff()));
    }
    CHECK(d.interpolate(t1, 0, y));
    CHECK((y - d.state()).cwiseAbs().maxCoeff() < 1e-14);  // the polynomial ends on the step's result
    CHECK_FALSE(d.interpolate(t1 + 0.5 * (t1 - t0) + 1e-9, 0, y));
    t0 = t1;
  }
  CHECK(worst < 1e-7);      // the degree-3 interpolant: below the steps' size, above their error
  CHECK(worstRate < 1e-3);  // its derivative, relative to |ẏ|
}

TEST_CASE("radau: stiff Van der Pol (ε = 1e-5) against CVODES BDF at rtol 1e-12", "[radau]") {
  const VectorXd y0 = (VectorXd(2) << 2.0, -0.66).finished();
  VanDerPol ref(1e-5), sys(1e-5);
  OdeOptions bo;
  bo.rtol = 1e-12;
  bo.atol = 1e-12;
  OdeDriver bdf(ref, 2, bo);
  bdf.start(0.0, y0);
  const auto bst = bdf.advanceTo(2.0);  // through the first jump (t ≈ 0.81)
  INFO(bst.message);
  REQUIRE(bst.ok());
  for (const double rtol : {1e-6, 1e-9}) {
    CAPTURE(rtol);
    OdeDriver d(sys, 2, radauOptions(rtol, rtol));
    d.start(0.0, y0);
    REQUIRE(d.advanceTo(2.0).ok());
    const double err = (d.state() - bdf.state()).cwiseAbs().maxCoeff() / bdf.state().cwiseAbs().maxCoeff();
    CHECK(err < 10.0 * rtol);  // through a jump whose timing amplifies the local errors
    CHECK(d.stats().steps < 2000);  // stiff: the steps are not limited by |λ| ~ 3000
  }
}

TEST_CASE("radau: a restart keeps the step size, the Jacobian and its factorizations", "[radau]") {
  // 100 restarts on a smooth problem: Radau's steps stay about those of one run; BDF's grow with
  // the restarts (order 1 and a small step each time).
  auto run = [](OdeMethod method, int restarts) {
    LinearForced sys(oscillator(), true);
    sys.A.bottomLeftCorner(3, 3)(0, 0) = -40.0;  // no stiff spring: steps set by accuracy
    OdeOptions o = radauOptions(1e-8, 1e-10);
    o.method = method;
    OdeDriver d(sys, 6, o);
    VectorXd x = (VectorXd(6) << 0.1, 1.0, -0.5, 0.0, 0.3, 0.0).finished();
    const double T = 2.0;
    for (int k = 0; k < restarts; ++k) {
      const double a = T * k / restarts, b = T * (k + 1) / restarts;
      d.start(a, x);
      REQUIRE(d.advanceTo(b).ok());
      x = d.state();
    }
    return std::make_pair(d.stats(), x);
  };
  const auto [once, xOnce] = run(OdeMethod::Radau, 1);
  const auto [many, xMany] = run(OdeMethod::Radau, 100);
  const auto [bdfMany, xBdf] = run(OdeMethod::Bdf, 100);
  CHECK(many.restarts == 99);
  CHECK((xMany - xOnce).cwiseAbs().maxCoeff() < 1e-6);
  CHECK((xBdf - xOnce).cwiseAbs().maxCoeff() < 1e-5);  // BDF's restarts cost it accuracy too
  // Each interval needs at least one step; beyond that the restarts add little.
  CHECK(many.steps < 100 + 2 * once.steps);
  CHECK(many.jacobianEvaluations < many.steps);
  CHECK(many.steps * 3 < bdfMany.steps);
}

TEST_CASE("radau: failures carry CVODES's flags, the time and the reason; bad set-ups are refused", "[radau]") {
  SECTION("an unrecoverable right-hand side") {
    LinearForced sys(stiffLinear());
    sys.failAfter = 0.4;
    OdeDriver d(sys, 5, radauOptions(1e-8, 1e-10));
    d.start(0.0, start5());
    const auto st = d.advanceTo(1.0);
    REQUIRE(st.outcome == OdeOutcome::Failed);
    CHECK(st.callbackFailed());
    CHECK(st.t <= 0.4);
    CHECK_THAT(st.message, Catch::Contains("radau test") && Catch::Contains("CV_RHSFUNC_FAIL") &&
                               Catch::Contains("refuses t > 0.4"));
  }
  SECTION("a recoverable one that never recovers") {
    LinearForced sys(stiffLinear());
    sys.failAfter = 0.4;
    sys.recoverable = true;
    OdeDriver d(sys, 5, radauOptions(1e-8, 1e-10));
    d.start(0.0, start5());
    const auto st = d.advanceTo(1.0);
    REQUIRE(st.outcome == OdeOutcome::Failed);
    CHECK(st.callbackFailed());
    CHECK(st.t <= 0.4);
    CHECK(st.t > 0.3);  // it crept up to the wall
  }
  SECTION("a target behind the current time") {
    LinearForced sys(stiffLinear());
    OdeDriver d(sys, 5, radauOptions(1e-8, 1e-10));
    d.start(1.0, start5());
    const auto st = d.advanceTo(0.5);
    REQUIRE(st.outcome == OdeOutcome::Failed);
    CHECK_THAT(st.message, Catch::Contains("behind the current time"));
  }
  SECTION("the step budget") {
    LinearForced sys(stiffLinear());
    OdeOptions o = radauOptions(1e-10, 1e-12);
    o.maxSteps = 3;
    OdeDriver d(sys, 5, o);
    d.start(0.0, start5());
    const auto st = d.advanceTo(10.0);
    REQUIRE(st.outcome == OdeOutcome::Failed);
    CHECK(st.tooMuchWork());
    CHECK_THAT(st.message, Catch::Contains("CV_TOO_MUCH_WORK"));
  }
  SECTION("no Jacobian, quadratures, root functions") {
    class NoJacobian : public OdeSystem {
      int rhs(double, ConstVectorMap y, VectorMap f) override {
        f = -y;
        return 0;
      }
    } nj;
    CHECK_THROWS_WITH(OdeDriver(nj, 2, radauOptions(1e-6, 1e-8)), Catch::Contains("exact Jacobian"));
    LinearForced sys(stiffLinear());
    OdeOptions o = radauOptions(1e-6, 1e-8);
    o.quadratureSize = 1;
    CHECK_THROWS_WITH(OdeDriver(sys, 5, o), Catch::Contains("no quadratures"));
    o.quadratureSize = 0;
    o.rootCount = 1;
    CHECK_THROWS_AS(OdeDriver(sys, 5, o), std::invalid_argument);
    o.rootCount = 0;
    o.atol = 0.0;
    CHECK_THROWS_WITH(OdeDriver(sys, 5, o), Catch::Contains("needs atol > 0"));
  }
}

TEST_CASE("radau: a looser Newton stopping test keeps the asked accuracy with fewer iterations", "[radau]") {
  // OdeOptions::newtonTolerance κ (SimulationOptions::newtonTolerance): Newton stops when its
  // remaining error is ≤ κ step tolerances. On stiff Van der Pol at rtol 1e-6 (RADAU5's default κ
  // there: min(0.03, √(0.1·rtol^(2/3))) = 0.01), κ = 0.1 and 0.5 still meet the same bound
  // against CVODES BDF at rtol 1e-12, with fewer Newton iterations than the default.
  const VectorXd y0 = (VectorXd(2) << 2.0, -0.66).finished();
  VanDerPol ref(1e-5);
  OdeOptions bo;
  bo.rtol = 1e-12;
  bo.atol = 1e-12;
  OdeDriver bdf(ref, 2, bo);
  bdf.start(0.0, y0);
  REQUIRE(bdf.advanceTo(2.0).ok());
  const double rtol = 1e-6;
  long defaultIterations = 0;
  for (const double kappa : {0.0, 0.1, 0.5}) {
    CAPTURE(kappa);
    VanDerPol sys(1e-5);
    OdeOptions o = radauOptions(rtol, rtol);
    o.newtonTolerance = kappa;
    OdeDriver d(sys, 2, o);
    d.start(0.0, y0);
    REQUIRE(d.advanceTo(2.0).ok());
    const double err = (d.state() - bdf.state()).cwiseAbs().maxCoeff() / bdf.state().cwiseAbs().maxCoeff();
    CHECK(err < 10.0 * rtol);
    if (kappa == 0.0) defaultIterations = d.stats().nonlinearIterations;
    else CHECK(d.stats().nonlinearIterations < defaultIterations);
  }
  // Outside [0, 1): refused by name, value and rule.
  trellis::SimulationOptions so;
  so.newtonTolerance = 1.0;
  CHECK_THROWS_WITH(so.validate(), Catch::Contains("SimulationOptions.newtonTolerance") && Catch::Contains("(0, 1)"));
  so.newtonTolerance = -0.1;
  CHECK_THROWS_WITH(so.validate(), Catch::Contains("newtonTolerance") && Catch::Contains("-0.1"));
}

TEST_CASE("radau: the simulator's sampled closed loop agrees with BDF at a fraction of the steps",
          "[radau][simulation]") {
  // The cart-pole held upright by its CARE gain, sampled at 200 Hz for 4 s from a tilt.
  const trellis::Model model = trellis::ctest::makeCartPole();
  const double T = 4.0;
  trellis::Data data(model);
  const VectorXd q = VectorXd::Zero(2), u = VectorXd::Zero(1);
  REQUIRE(trellis::computeLinearization(model, data, q, q, u).ok());
  const MatrixXd Q = VectorXd((VectorXd(4) << 10.0, 10.0, 1.0, 1.0).finished()).asDiagonal();
  const auto care = trellis::solveCare(data.A, data.B, Q, MatrixXd::Identity(1, 1));
  REQUIRE(care.ok());
  MatrixXd X = MatrixXd::Zero(4, 2), U = MatrixXd::Zero(1, 2);
  trellis::Trajectory ref(model.configNames(), model.inputNames(), (VectorXd(2) << 0.0, T).finished(), X, U);
  ref.computeStateDerivatives(model, data);
  const trellis::GainSchedule gains((VectorXd(2) << 0.0, T).finished(), {care.K, care.K});
  const VectorXd x0 = (VectorXd(4) << 0.2, 0.25, 0.0, 0.0).finished();

  trellis::SimulationOptions o;
  o.sampleRate = 200.0;
  o.outputStep = 0.01;
  o.rtol = 1e-9;
  o.atol = 1e-11;
  o.method = trellis::IntegrationMethod::kBDF;
  const trellis::SimulationResult bdf = trellis::simulateClosedLoop(model, ref, gains, x0, o);
  o.method = trellis::IntegrationMethod::kRadau;
  const trellis::SimulationResult radau = trellis::simulateClosedLoop(model, ref, gains, x0, o);
  REQUIRE(bdf.ok());
  REQUIRE(radau.ok());
  // The reference: BDF at rtol 1e-12 (~27 000 steps). Radau at rtol 1e-9 is within 4e-10 of it
  // (measured), BDF at 1e-9 within 1.3e-7 (its order-1 restart at every sample adds up).
  trellis::SimulationOptions tight = o;
  tight.method = trellis::IntegrationMethod::kBDF;
  tight.rtol = 1e-12;
  tight.atol = 1e-14;
  const trellis::SimulationResult exact = trellis::simulateClosedLoop(model, ref, gains, x0, tight);
  REQUIRE(exact.ok());
  REQUIRE(radau.trajectory.size() == exact.trajectory.size());
  const double scale = x0.cwiseAbs().maxCoeff();
  CHECK((radau.trajectory.states() - exact.trajectory.states()).cwiseAbs().maxCoeff() < 1e-8 * scale);
  CHECK((radau.trajectory.inputs() - exact.trajectory.inputs()).cwiseAbs().maxCoeff() <
        1e-8 * exact.trajectory.inputs().cwiseAbs().maxCoeff());
  CHECK((bdf.trajectory.states() - exact.trajectory.states()).cwiseAbs().maxCoeff() < 1e-6 * scale);
  CHECK(radau.controlSamples == bdf.controlSamples);
  CHECK(radau.restarts == bdf.restarts);
  CHECK(radau.steps * 3 < bdf.steps);  // every sample restarts BDF at order 1

  SECTION("a continuous Policy has no known Jacobian: Radau is refused by name") {
    const trellis::Policy pi = [&](double, const VectorXd& x, VectorXd& v) { v = -care.K * x; };
    trellis::SimulationOptions c;
    c.method = trellis::IntegrationMethod::kRadau;
    c.outputStep = 0.1;
    CHECK_THROWS_WITH(trellis::simulate(model, x0, 0.0, 1.0, pi, c),
                      Catch::Contains("method = radau needs the exact Jacobian"));
    c.sampleRate = 100.0;  // sampled: ∂f/∂x = A, accepted
    CHECK(trellis::simulate(model, x0, 0.0, 1.0, pi, c).ok());
  }
}
