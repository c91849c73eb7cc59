// Tests for trellis/core/trajectory.hpp: validation, CSV round trip, interpolation.
#include "support/cart_pole_model.hpp"

#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <sstream>

using Catch::Matchers::Contains;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::Trajectory;
using trellis::TrajectoryError;

namespace {

Trajectory cubicTrajectory() {
  // q(t) = t³ − 2t + 1, q̇ = 3t² − 2, q̈ = 6t; u(t) = 2t + 1.
  VectorXd t(4);
  t << 0.0, 0.4, 1.1, 2.0;
  MatrixXd x(2, 4), u(1, 4), xd(2, 4);
  for (int k = 0; k < 4; ++k) {
    const double s = t(k);
    x.col(k) << s * s * s - 2 * s + 1, 3 * s * s - 2;
    xd.col(k) << 3 * s * s - 2, 6 * s;
    u(0, k) = 2 * s + 1;
  }
  Trajectory traj({"q"}, {"f"}, t, x, u);
  traj.setStateDerivatives(xd);
  return traj;
}

}  // namespace

TEST_CASE("trajectory CSV round trip", "[trajectory]") {
  const Trajectory a = cubicTrajectory();
  std::stringstream ss;
  a.writeCsv(ss);
  CHECK(ss.str().rfind("t,q,dq,f\n", 0) == 0);
  const Trajectory b = Trajectory::readCsv(ss, "mem");
  CHECK(b.configNames() == a.configNames());
  CHECK(b.inputNames() == a.inputNames());
  CHECK(b.times() == a.times());
  CHECK(b.states() == a.states());
  CHECK(b.inputs() == a.inputs());

  std::istringstream two("t, x, theta, dx, dtheta, push\n0,1,2,3,4,5\n\n1,1,2,3,4,6\n");
  const Trajectory c = Trajectory::readCsv(two);
  CHECK(c.nq() == 2);
  CHECK(c.nu() == 1);
  CHECK(c.size() == 2);
  CHECK(c.states()(3, 1) == 4.0);
  std::istringstream noInputs("t,a,da\n0,1,2\n");
  CHECK(Trajectory::readCsv(noInputs).nu() == 0);
}

TEST_CASE("trajectory CSV errors name the row and column", "[trajectory]") {
  auto read = [](const std::string& s) {
    std::istringstream in(s);
    return Trajectory::readCsv(in, "traj.csv");
  };
  CHECK_THROWS_WITH(read("t,x,dx,u\n0,1,2,3\n0.5,1,2,3\n0.5,1,2,3\n"),
                    Contains("row 3 (line 4), column 1 ('t')") && Contains("not greater"));
  CHECK_THROWS_WITH(read("t,x,dx,u\n0,1,2,3\n1,1,nan,3\n"),
                    Contains("row 2 (line 3), column 3 ('dx')") && Contains("not finite"));
  CHECK_THROWS_WITH(read("t,x,dx,u\n0,1,2,3\n1,1,abc,3\n"),
                    Contains("column 3 ('dx')") && Contains("not a number"));
  CHECK_THROWS_WITH(read("t,x,dx,u\n0,1,2\n"), Contains("row 1 (line 2): expected 4 columns, got 3"));
  CHECK_THROWS_WITH(read("time,x,dx\n0,1,2\n"), Contains("header must start with 't'"));
  CHECK_THROWS_WITH(read("t,x,vx\n0,1,2\n"), Contains("velocity columns"));
  CHECK_THROWS_WITH(read("t,x,dx\n"), Contains("no data rows"));
  CHECK_THROWS_WITH(read(""), Contains("empty"));
  CHECK_THROWS_AS(Trajectory::readCsvFile("/nonexistent/traj.csv"), TrajectoryError);
}

TEST_CASE("trajectory CSV: the missing velocity column is named; endless input is cut off", "[trajectory]") {
  auto read = [](const std::string& s) {
    std::istringstream in(s);
    return Trajectory::readCsv(in, "traj.csv");
  };
  CHECK_THROWS_WITH(read("t,x,theta,dx,push\n0,0,0,0,0\n"), Contains("missing the velocity column 'dtheta'"));
  CHECK_THROWS_WITH(read("t,a,b,db,u\n0,0,0,0,0\n"), Contains("missing the velocity column 'da'"));
  // A line without end (as from /dev/zero) and a stream of blank lines stop at the limits.
  CHECK_THROWS_WITH(read("t,x,dx\n" + std::string(2 << 20, '0')),
                    Contains("traj.csv: line 2 is longer than 1048576 characters"));
  CHECK_THROWS_WITH(read("t,x,dx\n" + std::string(10'000'001, '\n')), Contains("more than 10000000 lines"));
  CHECK_THROWS_WITH(Trajectory::readCsvFile("/"), Contains("/: is a directory, not a trajectory CSV file"));
}

TEST_CASE("trajectory array validation", "[trajectory]") {
  VectorXd t(3);
  t << 0, 1, 1;
  CHECK_THROWS_WITH(Trajectory({"q"}, {}, t, MatrixXd::Zero(2, 3), MatrixXd()),
                    Contains("row 3, column 1 ('t')"));
  t << 0, 1, 2;
  MatrixXd x = MatrixXd::Zero(2, 3);
  x(1, 2) = std::nan("");
  CHECK_THROWS_WITH(Trajectory({"q"}, {}, t, x, MatrixXd()), Contains("row 3, column 3 ('dq')"));
  CHECK_THROWS_WITH(Trajectory({"q"}, {"u"}, t, MatrixXd::Zero(2, 3), MatrixXd::Zero(2, 3)),
                    Contains("inputs must be 1x3"));
  CHECK_THROWS_WITH(Trajectory({"q"}, {}, t, MatrixXd::Zero(3, 3), MatrixXd()),
                    Contains("states must be 2x3"));
}

TEST_CASE("trajectory interpolation: Hermite state, linear input", "[trajectory]") {
  const Trajectory traj = cubicTrajectory();
  for (double s : {0.0, 0.1, 0.4, 0.77, 1.5, 2.0}) {
    const VectorXd x = traj.state(s);
    // A cubic is reproduced exactly by cubic Hermite with exact derivatives.
    CHECK(x(0) == Approx(s * s * s - 2 * s + 1).margin(1e-13));
    CHECK(traj.input(s)(0) == Approx(2 * s + 1).margin(1e-13));
  }
  CHECK_THROWS_AS(traj.state(2.5), std::out_of_range);
  CHECK_THROWS_AS(traj.state(-0.1), std::out_of_range);
  Trajectory noDeriv({"q"}, {}, traj.times(), traj.states(), MatrixXd());
  CHECK_THROWS_AS(noDeriv.state(0.5), std::logic_error);
}

TEST_CASE("trajectory state derivatives from the model", "[trajectory][model]") {
  const trellis::Model model = trellis::test::cartPole();
  trellis::Data data(model);
  VectorXd t(2);
  t << 0.0, 1.0;
  MatrixXd x = MatrixXd::Zero(4, 2);
  x(1, 0) = 0.1;  // pole tilted: it falls
  Trajectory traj(model.configNames(), model.inputNames(), t, x, MatrixXd::Zero(1, 2));
  traj.computeStateDerivatives(model, data);
  const VectorXd q = x.col(0).head(2), dq = x.col(0).tail(2), u = VectorXd::Zero(1);
  trellis::computeDynamics(model, data, q, dq, u);
  CHECK(traj.stateDerivatives().col(0).tail(2) == data.qdd);
  CHECK(traj.stateDerivatives()(3, 0) > 0.0);  // θ̈ > 0: tilting further

  Trajectory wrong({"x", "phi"}, {"push"}, t, x, MatrixXd::Zero(1, 2));
  CHECK_THROWS_WITH(wrong.computeStateDerivatives(model, data),
                    Contains("configuration names do not match") && Contains("phi"));
}

namespace {

// u(t) = t³ − t² + 0.5 t − 2 with its exact derivative at the knots of cubicTrajectory().
Trajectory cubicInputTrajectory() {
  Trajectory traj = cubicTrajectory();
  MatrixXd u(1, traj.size()), du(1, traj.size());
  for (int k = 0; k < traj.size(); ++k) {
    const double s = traj.times()(k);
    u(0, k) = s * s * s - s * s + 0.5 * s - 2;
    du(0, k) = 3 * s * s - 2 * s + 0.5;
  }
  Trajectory out({"q"}, {"f"}, traj.times(), traj.states(), u);
  out.setStateDerivatives(traj.stateDerivatives());
  out.setInputDerivatives(du);
  return out;
}

}  // namespace

TEST_CASE("trajectory input rule: cubic Hermite with input derivatives", "[trajectory]") {
  SECTION("exact on cubics and on lines") {
    const Trajectory traj = cubicInputTrajectory();
    REQUIRE(traj.hasInputDerivatives());
    for (double s : {0.0, 0.13, 0.4, 0.77, 1.1, 1.5, 1.99, 2.0}) {
      CHECK(traj.input(s)(0) == Approx(s * s * s - s * s + 0.5 * s - 2).margin(1e-13));
    }
    // A line with its slope as the derivatives is reproduced by the cubic rule too.
    Trajectory line = cubicTrajectory();
    line.setInputDerivatives(MatrixXd::Constant(1, line.size(), 2.0));
    for (double s : {0.0, 0.3, 1.7}) CHECK(line.input(s)(0) == Approx(2 * s + 1).margin(1e-13));
    // Without derivatives the same knots give the linear rule, which misses the cubic in between.
    Trajectory linear = traj;
    linear.clearInputDerivatives();
    const double s = 0.2;
    CHECK(std::abs(linear.input(s)(0) - (s * s * s - s * s + 0.5 * s - 2)) > 1e-3);
  }
  SECTION("C1 at the knots, and the state derivative of the spline") {
    // Knot values and slopes that no single cubic fits: the two sides of a knot are different
    // cubics, but their values and first derivatives agree there.
    VectorXd t(3);
    t << 0.0, 0.7, 2.0;
    MatrixXd x(2, 3), xd(2, 3), u(1, 3), du(1, 3);
    x << 0.0, 1.0, -0.5, 1.0, 2.0, 0.0;
    xd << 1.0, 2.0, 0.0, -3.0, 0.5, 4.0;
    u << 1.0, -2.0, 3.0;
    du << 0.0, 5.0, -1.0;
    Trajectory traj({"q"}, {"f"}, t, x, u);
    traj.setStateDerivatives(xd);
    traj.setInputDerivatives(du);
    const double tk = t(1), e = 1e-7;
    // One-sided difference quotients from each side (h = 1e-7: error ~ h·|ü| ~ 1e-6).
    const double left = (traj.input(tk)(0) - traj.input(tk - e)(0)) / e;
    const double right = (traj.input(tk + e)(0) - traj.input(tk)(0)) / e;
    CHECK(left == Approx(5.0).margin(1e-5));
    CHECK(right == Approx(5.0).margin(1e-5));
    CHECK(traj.input(tk)(0) == -2.0);
    // evaluate's ẋ(t) is the derivative of the state spline: ẋ_k at a knot, and a central
    // difference of x(t) in between (error ~ h²·|x'''| ~ 1e-10 with h = 1e-5).
    VectorXd xs, us, xdot;
    traj.evaluate(tk, xs, us, xdot);
    CHECK((xdot - xd.col(1)).cwiseAbs().maxCoeff() < 1e-14);
    const double tm = 1.3, h = 1e-5;
    traj.evaluate(tm, xs, us, xdot);
    const VectorXd central = (traj.state(tm + h) - traj.state(tm - h)) / (2 * h);
    CHECK((xdot - central).cwiseAbs().maxCoeff() < 1e-8);
  }
  SECTION("CSV round trip with the rate columns") {
    const Trajectory a = cubicInputTrajectory();
    std::stringstream ss;
    a.writeCsv(ss);
    CHECK(ss.str().rfind("t,q,dq,f,rate_f\n", 0) == 0);
    const Trajectory b = Trajectory::readCsv(ss, "mem");
    REQUIRE(b.hasInputDerivatives());
    CHECK(b.inputNames() == a.inputNames());
    CHECK(b.inputs() == a.inputs());
    CHECK(b.inputDerivatives() == a.inputDerivatives());
    // Two inputs; a configuration whose name begins with "rate_" is a state column, not a rate.
    std::istringstream two("t,rate_x,drate_x,a,b,rate_a,rate_b\n0,1,2,3,4,5,6\n1,1,2,3,4,7,8\n");
    const Trajectory c = Trajectory::readCsv(two);
    CHECK(c.configNames() == std::vector<std::string>{"rate_x"});
    CHECK(c.inputNames() == std::vector<std::string>{"a", "b"});
    REQUIRE(c.hasInputDerivatives());
    CHECK(c.inputDerivatives()(1, 1) == 8.0);
  }
  SECTION("trailing constraint-force columns are skipped; one out of place is refused") {
    // The hand's main job writes each contact's force after the inputs and rates (lambda_…).
    std::istringstream with("t,x,dx,a,rate_a,lambda_pad_n,lambda_pad_t1\n0,1,2,3,4,5,6\n1,1,2,3,7,8,9\n");
    const Trajectory w = Trajectory::readCsv(with);
    CHECK(w.configNames() == std::vector<std::string>{"x"});
    CHECK(w.inputNames() == std::vector<std::string>{"a"});
    REQUIRE(w.hasInputDerivatives());
    CHECK(w.inputDerivatives()(0, 1) == 7.0);
    std::istringstream noRates("t,x,dx,a,b,lambda_n\n0,1,2,3,4,5\n1,1,2,3,4,6\n");
    const Trajectory r = Trajectory::readCsv(noRates);
    CHECK(r.inputNames() == std::vector<std::string>{"a", "b"});
    CHECK_FALSE(r.hasInputDerivatives());
    CHECK(r.inputs()(1, 1) == 4.0);
    // A configuration named lambda_… is a state column (before the inputs), not a force.
    std::istringstream config("t,lambda_q,dlambda_q,a\n0,1,2,3\n1,1,2,3\n");
    CHECK(Trajectory::readCsv(config).configNames() == std::vector<std::string>{"lambda_q"});
    std::istringstream bad("t,x,dx,a,lambda_n,b\n0,1,2,3,4,5\n");
    CHECK_THROWS_WITH(Trajectory::readCsv(bad, "traj.csv"),
                      Contains("traj.csv: line 1: column 6 ('b') after the constraint-force column 'lambda_n'"));
  }
  SECTION("malformed or mismatched rate columns are refused, naming the column and row") {
    auto read = [](const std::string& s) {
      std::istringstream in(s);
      return Trajectory::readCsv(in, "traj.csv");
    };
    CHECK_THROWS_WITH(read("t,x,dx,a,b,rate_b,rate_a\n0,1,2,3,4,5,6\n"),
                      Contains("traj.csv: line 1") && Contains("column 6 ('rate_b'): expected 'rate_a'"));
    CHECK_THROWS_WITH(read("t,x,dx,a,b,rate_a\n0,1,2,3,4,5\n"), Contains("missing the rate column 'rate_b'"));
    CHECK_THROWS_WITH(read("t,x,dx,a,rate_a,rate_c\n0,1,2,3,4,5\n"),
                      Contains("column 6 ('rate_c'): a rate column beyond the 1 inputs"));
    CHECK_THROWS_WITH(read("t,x,dx,rate_a\n0,1,2,3\n"), Contains("column 4 ('rate_a'): a rate column beyond the 0"));
    CHECK_THROWS_WITH(read("t,x,dx,a,rate_a\n0,1,2,3,4\n1,1,2,3,oops\n"),
                      Contains("row 2 (line 3), column 5 ('rate_a')") && Contains("not a number"));
    CHECK_THROWS_WITH(read("t,x,dx,a,rate_a\n0,1,2,3,4\n1,1,2,3,inf\n"),
                      Contains("row 2 (line 3), column 5 ('rate_a')") && Contains("not finite"));
    CHECK_THROWS_WITH(read("t,x,dx,a,rate_a\n0,1,2,3,4\n1,1,2,3\n"),
                      Contains("row 2 (line 3): expected 5 columns, got 4"));
    Trajectory traj = cubicTrajectory();
    CHECK_THROWS_WITH(traj.setInputDerivatives(MatrixXd::Zero(1, 3)), Contains("must be 1x4"));
    MatrixXd bad = MatrixXd::Zero(1, 4);
    bad(0, 2) = std::nan("");
    CHECK_THROWS_WITH(traj.setInputDerivatives(bad), Contains("'f' at knot 3"));
  }
}
