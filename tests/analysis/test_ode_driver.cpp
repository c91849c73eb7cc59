// Tests for trellis/analysis/detail/ode_driver.hpp (internal): the ODE driver on CVODES (its Radau
// engine: test_radau.cpp).
#include "ode_test_systems.hpp"
#include "trellis/analysis/detail/ode_driver.hpp"

#include <catch2/catch.hpp>

#include <Eigen/Dense>
#include <unsupported/Eigen/MatrixFunctions>

#include <cmath>

using trellis::detail::ConstVectorMap;
using trellis::detail::MatrixMap;
using trellis::detail::OdeDriver;
using trellis::detail::OdeLinearSolver;
using trellis::detail::OdeMethod;
using trellis::detail::OdeOptions;
using trellis::detail::OdeOutcome;
using trellis::detail::OdeSystem;
using trellis::detail::VectorMap;

namespace {

// ẏ = A y, a stiff linear system (eigenvalues −1, −10, −1000, −2 ± 3i) with exact Jacobian A,
// the quadrature ∫ yᵀy dt and the root function y_0.
class Linear : public OdeSystem {
 public:
  Linear() : A(trellis::test::stiffLinearMatrix()) {}
  int rhs(double t, ConstVectorMap y, VectorMap ydot) override {
    ++rhsCalls;
    if (t > failAfter) {
      failure = "the test's right-hand side refuses t > " + std::to_string(failAfter);
      return -1;
    }
    ydot.noalias() = A * y;
    return 0;
  }
  bool hasJacobian() const override { return true; }
  int jacobian(double, ConstVectorMap, ConstVectorMap, MatrixMap J) override {
    ++jacobianCalls;
    J = A;
    return 0;
  }
  int quadrature(double, ConstVectorMap y, VectorMap qdot) override {
    qdot(0) = y.squaredNorm();
    return 0;
  }
  int roots(double, ConstVectorMap y, double* g) override {
    g[0] = y(3);
    return 0;
  }
  Eigen::MatrixXd A;
  long rhsCalls = 0, jacobianCalls = 0;
  double failAfter = 1e300;
};

Eigen::VectorXd y0() { return trellis::test::stiffLinearStart(); }

}  // namespace

TEST_CASE("ode driver: BDF with the exact Jacobian reaches exp(At) y0 and uses no difference quotient") {
  Linear sys;
  OdeOptions o;
  o.rtol = 1e-10;
  o.atol = 1e-12;
  o.what = "test integration";
  OdeDriver d(sys, 5, o);
  d.start(0.0, y0());
  for (double t : {0.1, 0.5, 1.0, 2.0}) {
    const auto st = d.advanceTo(t);
    REQUIRE(st.ok());
    CHECK(st.t == t);  // a stop time: exactly the target
    const Eigen::VectorXd exact = (sys.A * t).exp() * y0();
    CHECK((d.state() - exact).cwiseAbs().maxCoeff() < 1e-8);
  }
  const auto s = d.stats();
  CHECK(s.jacobianEvaluations > 0);
  CHECK(sys.jacobianCalls == s.jacobianEvaluations);
  CHECK(s.linearRhsEvaluations == 0);  // the exact Jacobian, not a difference quotient
  CHECK(s.rhsEvaluations == sys.rhsCalls);
  CHECK(s.restarts == 0);
}

TEST_CASE("ode driver: the difference-quotient fallback agrees and is counted") {
  Linear exact, dq;
  OdeOptions o;
  o.rtol = 1e-9;
  o.atol = 1e-12;
  OdeDriver de(exact, 5, o);
  o.exactJacobian = false;
  OdeDriver dd(dq, 5, o);
  de.start(0.0, y0());
  dd.start(0.0, y0());
  REQUIRE(de.advanceTo(1.5).ok());
  REQUIRE(dd.advanceTo(1.5).ok());
  CHECK((de.state() - dd.state()).cwiseAbs().maxCoeff() < 1e-7);
  CHECK(dq.jacobianCalls == 0);
  CHECK(dd.stats().linearRhsEvaluations >= 5 * dd.stats().jacobianEvaluations);
  CHECK(dd.stats().jacobianEvaluations > 0);
}

TEST_CASE("ode driver: Adams with fixed point, GMRES, quadrature, dense output, roots, restarts") {
  Linear sys;
  sys.A(2, 2) = -3.0;  // not stiff, for the fixed-point iteration
  const double T = 0.7;
  const Eigen::VectorXd exact = (sys.A * T).exp() * y0();
  for (auto [method, linear] : {std::pair{OdeMethod::Adams, OdeLinearSolver::FixedPoint},
                                std::pair{OdeMethod::Bdf, OdeLinearSolver::Gmres}}) {
    OdeOptions o;
    o.method = method;
    o.linearSolver = linear;
    o.rtol = 1e-10;
    o.atol = 1e-12;
    o.quadratureSize = 1;
    o.quadratureErrorControl = true;
    o.quadratureRtol = 1e-10;
    o.quadratureAtol = 1e-12;
    OdeDriver d(sys, 5, o);
    d.start(0.0, y0());
    REQUIRE(d.advanceTo(T).ok());
    CHECK((d.state() - exact).cwiseAbs().maxCoeff() < 1e-8);
    // ∫_0^T yᵀy dt by a fine composite Simpson rule on the exact solution
    const int N = 2000;
    double integral = 0.0;
    for (int i = 0; i <= N; ++i) {
      const double w = (i == 0 || i == N) ? 1.0 : (i % 2 ? 4.0 : 2.0);
      integral += w * ((sys.A * (T * i / N)).exp() * y0()).squaredNorm();
    }
    integral *= T / N / 3.0;
    Eigen::VectorXd q(1);
    d.quadrature(q);
    CHECK(std::abs(q(0) - integral) < 1e-8 * integral);
    // dense output inside the last step: the first derivative is f(y)
    Eigen::VectorXd yd(5), ydd(5);
    const double tin = T - 0.25 * std::abs(d.stats().lastStep);
    REQUIRE(d.interpolate(tin, 0, yd));
    REQUIRE(d.interpolate(tin, 1, ydd));
    CHECK((ydd - sys.A * yd).cwiseAbs().maxCoeff() < 1e-5);
    CHECK_FALSE(d.interpolate(T + 1.0, 0, yd));
    // a restart is counted and the counters keep the earlier run
    const long stepsBefore = d.stats().steps;
    d.start(T, exact);
    REQUIRE(d.advanceTo(2 * T).ok());
    CHECK(d.stats().restarts == 1);
    CHECK(d.stats().steps > stepsBefore);
  }
}

TEST_CASE("ode driver: a root stops the integration at the sign change") {
  Linear sys;
  OdeOptions o;
  o.rtol = 1e-10;
  o.atol = 1e-12;
  o.rootCount = 1;
  OdeDriver d(sys, 5, o);
  d.start(0.0, y0());
  const auto st = d.advanceTo(3.0);
  REQUIRE(st.outcome == OdeOutcome::Root);
  // y_3(t) = e^{−2t}(cos 3t + 0.5 sin 3t) vanishes first at 3t = π − atan(2)
  const double root = (M_PI - std::atan(2.0)) / 3.0;
  CHECK(std::abs(st.t - root) < 1e-8);
  int dir = 0;
  d.rootDirections(&dir);
  CHECK(dir == -1);
  CHECK(d.advanceTo(3.0).ok());  // continues past the root
}

TEST_CASE("ode driver: failures carry the time, the state size and the callback's reason") {
  Linear sys;
  sys.failAfter = 0.4;
  OdeOptions o;
  o.what = "test integration";
  OdeDriver d(sys, 5, o);
  d.start(0.0, y0());
  const auto st = d.advanceTo(1.0);
  REQUIRE(st.outcome == OdeOutcome::Failed);
  CHECK(st.t <= 0.4 + 1e-12);
  CHECK(st.t > 0.0);
  CHECK_THAT(st.message, Catch::Contains("test integration") && Catch::Contains("t = ") &&
                             Catch::Contains("refuses t > 0.4"));

  Linear ok;
  o.maxSteps = 3;
  OdeDriver small(ok, 5, o);
  small.start(0.0, y0());
  const auto budget = small.advanceTo(10.0);
  REQUIRE(budget.outcome == OdeOutcome::Failed);
  CHECK_THAT(budget.message, Catch::Contains("CV_TOO_MUCH_WORK"));

  CHECK_THROWS_AS(OdeDriver(ok, 0, OdeOptions{}), std::invalid_argument);
  OdeOptions bad;
  bad.rtol = -1;
  CHECK_THROWS_AS(OdeDriver(ok, 5, bad), std::invalid_argument);
  OdeDriver d2(ok, 5, OdeOptions{});
  CHECK_THROWS_AS(d2.advanceTo(1.0), std::logic_error);
  Eigen::VectorXd nan = y0();
  nan(1) = std::nan("");
  CHECK_THROWS_AS(d2.start(0.0, nan), std::invalid_argument);
}

namespace {

// The linear system with the exact solve of its Newton matrix (I − γA) z = r (LU of the 5×5
// matrix at each call: γ changes) for OdeLinearSolver::SystemSolve.
class LinearWithSolve : public Linear {
 public:
  bool hasPreconditioner() const override { return true; }
  int preconditionerSetup(double, ConstVectorMap, ConstVectorMap, bool jacOk, bool* jacUpdated,
                          double) override {
    ++setups;
    if (!jacOk) ++refreshes;
    *jacUpdated = !jacOk;
    return failSetup ? -1 : 0;
  }
  int preconditionerSolve(double, ConstVectorMap, ConstVectorMap, ConstVectorMap r, VectorMap z,
                          double gamma) override {
    ++solves;
    if (failSolve) {
      failure = "the test's solve refuses";
      return 1;
    }
    const Eigen::MatrixXd M = Eigen::MatrixXd::Identity(5, 5) - gamma * A;
    z = M.partialPivLu().solve(r);
    return 0;
  }
  long setups = 0, refreshes = 0, solves = 0;
  bool failSetup = false, failSolve = false;
};

}  // namespace

TEST_CASE("ode driver: SystemSolve uses the system's exact solve, no Krylov iteration") {
  LinearWithSolve sys;
  OdeOptions o;
  o.linearSolver = OdeLinearSolver::SystemSolve;
  o.rtol = 1e-10;
  o.atol = 1e-12;
  OdeDriver d(sys, 5, o);
  d.start(0.0, y0());
  for (double t : {0.1, 1.0, 2.0}) {
    REQUIRE(d.advanceTo(t).ok());
    const Eigen::VectorXd exact = (sys.A * t).exp() * y0();
    CHECK((d.state() - exact).cwiseAbs().maxCoeff() < 1e-8);
  }
  const auto s = d.stats();
  CHECK(s.linearIterations == 0);
  CHECK(s.preconditionerSolves == sys.solves);
  CHECK(sys.solves > 0);
  CHECK(s.preconditionerSetups == sys.refreshes);  // CVODES counts the set-ups that refreshed J
  CHECK(sys.refreshes > 0);
  CHECK(sys.setups >= sys.refreshes);
  CHECK(sys.jacobianCalls == 0);
  CHECK(s.linearRhsEvaluations == 0);
  // The stiff eigenvalue −1000: as few steps as Newton with the dense exact Jacobian (an explicit
  // method would need h < 2e-3 from the start).
  Linear denseSys;
  OdeOptions od = o;
  od.linearSolver = OdeLinearSolver::Dense;
  OdeDriver dd(denseSys, 5, od);
  dd.start(0.0, y0());
  REQUIRE(dd.advanceTo(2.0).ok());
  CHECK(s.steps <= dd.stats().steps * 11 / 10);

  // A system without a solve is rejected; failing solves and set-ups are failures naming t.
  Linear plain;
  CHECK_THROWS_WITH(OdeDriver(plain, 5, o), Catch::Contains("SystemSolve"));
  LinearWithSolve badSolve;
  badSolve.failSolve = true;
  o.what = "test integration";
  OdeDriver ds(badSolve, 5, o);
  ds.start(0.0, y0());
  const auto st = ds.advanceTo(1.0);
  REQUIRE(st.outcome == OdeOutcome::Failed);
  // (A recoverable solve failure makes CVODES shrink the step; it ends in too much work or a
  // convergence failure, either way with the system's reason in the message.)
  CHECK_THAT(st.message, Catch::Contains("test integration") && Catch::Contains("t = ") &&
                             Catch::Contains("the test's solve refuses"));
  LinearWithSolve badSetup;
  badSetup.failSetup = true;
  OdeDriver du(badSetup, 5, o);
  du.start(0.0, y0());
  const auto su = du.advanceTo(1.0);
  REQUIRE(su.outcome == OdeOutcome::Failed);
  CHECK(su.callbackFailed());
  CHECK_THAT(su.message, Catch::Contains("t = "));
}
