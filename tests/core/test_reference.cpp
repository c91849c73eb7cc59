// Tests for trellis/core/reference.hpp: the checks once, x/u/ẋ and the exact linearization at any t.
#include "support/cart_pole_model.hpp"

#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <cmath>

using Catch::Matchers::Contains;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::ReferenceEvaluator;
using trellis::ReferenceOptions;
using trellis::Trajectory;
using trellis::TrajectoryError;

namespace {

// A swinging cart-pole (not a solution of the dynamics: the evaluator only interpolates it).
Trajectory swing(const trellis::Model& model, int N = 6) {
  VectorXd t = VectorXd::LinSpaced(N, 0.0, 1.0);
  MatrixXd x(4, N), u(1, N);
  for (int k = 0; k < N; ++k) {
    const double s = t(k);
    x.col(k) << 0.3 * s, 0.2 * std::sin(3 * s), 0.3, 0.6 * std::cos(3 * s);
    u(0, k) = std::cos(2 * s);
  }
  return Trajectory(model.configNames(), model.inputNames(), t, x, u);
}

}  // namespace

TEST_CASE("reference evaluator: checks once, then x, u, xdot and A, B at any t", "[reference]") {
  const trellis::Model model = trellis::test::cartPole();
  const Trajectory traj = swing(model);
  ReferenceEvaluator ref(model, traj);
  REQUIRE(ref.trajectory().hasStateDerivatives());

  SECTION("knot derivatives from the core's dynamics") {
    trellis::Data data(model);
    for (int k = 0; k < traj.size(); ++k) {
      const VectorXd q = traj.states().col(k).head(2), dq = traj.states().col(k).tail(2);
      REQUIRE(trellis::computeDynamics(model, data, q, dq, traj.inputs().col(k)).ok());
      CHECK(ref.trajectory().stateDerivatives().col(k).tail(2) == data.qdd);
      CHECK(ref.trajectory().stateDerivatives().col(k).head(2) == dq);
    }
  }
  SECTION("the same interpolation as the trajectory, and the exact linearization there") {
    Trajectory copy = traj;
    trellis::Data data(model);
    copy.computeStateDerivatives(model, data);
    for (double t : {0.0, 0.13, 0.5, 0.91, 1.0}) {
      const trellis::ReferenceStatus st = ref.linearize(t);
      REQUIRE(st.ok);
      VectorXd x, u, xdot;
      copy.evaluate(t, x, u, xdot);
      CHECK(ref.x() == x);
      CHECK(ref.u() == u);
      CHECK(ref.xdot() == xdot);
      REQUIRE(trellis::computeLinearization(model, data, x.head(2), x.tail(2), u).ok());
      CHECK(ref.A() == data.A);
      CHECK(ref.B() == data.B);
    }
    CHECK_THROWS_AS(ref.evaluate(1.5), std::out_of_range);
  }
  SECTION("supplied derivatives are kept or replaced, as asked") {
    Trajectory supplied = traj;
    supplied.setStateDerivatives(MatrixXd::Constant(4, traj.size(), 7.0));
    const ReferenceEvaluator keep(model, supplied);
    CHECK(keep.trajectory().stateDerivatives()(3, 2) == 7.0);
    ReferenceOptions options;
    options.stateDerivatives = ReferenceOptions::StateDerivatives::kFromDynamics;
    const ReferenceEvaluator recompute(model, supplied, options);
    CHECK(recompute.trajectory().stateDerivatives() == ref.trajectory().stateDerivatives());
  }
  SECTION("refusals name the mismatch, the knot count") {
    Trajectory wrong({"x", "phi"}, {"push"}, traj.times(), traj.states(), traj.inputs());
    CHECK_THROWS_WITH(ReferenceEvaluator(model, wrong), Contains("configuration names do not match") && Contains("phi"));
    Trajectory one(model.configNames(), model.inputNames(), traj.times().head(1), traj.states().leftCols(1),
                   traj.inputs().leftCols(1));
    ReferenceOptions two;
    two.minimumKnots = 2;
    CHECK_THROWS_WITH(ReferenceEvaluator(model, one, two), Contains("1 knot, need at least 2"));
  }
}

TEST_CASE("reference evaluator: a dynamics failure is named (knot at construction, t at a query)", "[reference]") {
  // A pendulum whose only mass sits on a frame driven by a config whose coordinate moves no mass
  // at the knots: M singular. Built as a free "y" with no mass and a mass-less pole.
  trellis::ModelBuilder b("massless");
  b.addFrame("slider", "world", trellis::Transform::tx("y"));
  b.addConfigForce("y", "f");
  const trellis::Model model = std::move(b).finalize();
  VectorXd t(2);
  t << 0.0, 1.0;
  const Trajectory traj(model.configNames(), model.inputNames(), t, MatrixXd::Zero(2, 2), MatrixXd::Zero(1, 2));
  CHECK_THROWS_WITH(ReferenceEvaluator(model, traj), Contains("dynamics failed at knot 1 (t = 0)"));
  // Kept (supplied) derivatives skip the knot check; the query then reports t in its status.
  Trajectory supplied = traj;
  supplied.setStateDerivatives(MatrixXd::Zero(2, 2));
  ReferenceEvaluator ref(model, supplied);
  const trellis::ReferenceStatus st = ref.linearize(0.25);
  CHECK_FALSE(st.ok);
  CHECK(st.t == 0.25);
  CHECK_THAT(st.message, Contains("linearization failed at t = 0.25"));
}
