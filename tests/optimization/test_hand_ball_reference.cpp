// Tests for examples/hand/ball_reference.hpp (issue 26): the inverse-dynamics reference made from
// a motion of the free-ball hand (examples/scenes/hand_ball.json: 26 coordinates, 23 tendons, 15
// contact rows) keeps the motion, produces the plant's own
// contact forces, keeps the contacts unilateral and inside the cone, and passes the a-posteriori
// consistency check; a motion the contacts cannot make is refused with the knot, and so is the
// two-pad pinch, whose pads leave the ball's spin about their common axis to no force.
#if defined(TRELLIS_HAND_BALL)
#include "ball_reference.hpp"
#include "ball_turn.hpp"

#include <trellis/analysis/consistency.hpp>
#include <trellis/analysis/simulation.hpp>
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

using Eigen::VectorXd;
using namespace trellis;

namespace {

const std::string kScenes = std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/";
const std::string kLimits = std::string(TRELLIS_SOURCE_DIR) + "/examples/hand/";

/// The quasi-static turn (ball_turn.hpp): a motion on the manifold whose tensions hold
/// each pose at rest — not a solution of the dynamics, which is what the redistribution repairs.
Trajectory turnMotion(const Model& m, const VectorXd& q0, const hand::BallLimits& l, double degrees, int knots) {
  hand::BallTurnOptions o;
  o.angle = degrees * std::numbers::pi / 180.0;
  o.horizon = 1.0;
  o.knots = knots;
  return hand::quasiStaticTurn(m, q0, l, o);
}

/// The plant's own motion from the stored hold (an equilibrium with every contact inside the
/// cone, make_hand_scene.py) under a tension pulse u = s.u + A sin²(πt/T) on the index's FDP:
/// a motion the tensions can make, by construction, on `knots` knots over T.
Trajectory pulseMotion(const Scene& s, double T, int knots) {
  const Model& m = s.model;
  const int n = m.nq(), i = m.inputIndex("FDP_index");
  Eigen::VectorXd x0(2 * n);
  x0 << s.q, Eigen::VectorXd::Zero(n);
  const Eigen::VectorXd u0 = s.u;
  const Policy policy = [u0, i, T](double t, const Eigen::VectorXd&, Eigen::VectorXd& u) {
    const double w = std::sin(std::numbers::pi * t / T);
    u = u0;
    u(i) += 0.05 * w * w;
  };
  SimulationOptions o;
  o.method = IntegrationMethod::kBDF;
  o.rtol = 1e-11;
  o.atol = 1e-13;
  o.outputStep = T / (knots - 1);
  const SimulationResult r = simulate(m, x0, 0.0, T, policy, o);
  if (!r.ok() || r.trajectory.size() != knots) throw std::runtime_error("the pulse motion: " + r.status.describe());
  return r.trajectory;
}

}  // namespace

TEST_CASE("hand ball: the inverse-dynamics reference keeps the motion and is what the plant does",
          "[hand_ball][reference]") {
  const Scene s = loadScene(kScenes + "hand_ball.json");
  const Model& m = s.model;
  const hand::BallLimits l = hand::loadBallLimits(kLimits + "hand_ball_limits.json", m);
  const int n = m.nq();
  const Trajectory motion = pulseMotion(s, 0.2, 11);
  // Its tensions interpolated linearly between the knots, the motion itself is not what the plant
  // does between them (the light phalanges answer within milliseconds): the check refuses it.
  const ConsistencyResult before = checkConsistency(m, motion);
  INFO("the motion: " << before.status.describe());
  CHECK(before.status.code == ConsistencyCode::kInconsistent);

  hand::InverseReferenceOptions o;
  o.knots = 101;  // every 10th is a knot of the motion
  const hand::InverseReference r = hand::inverseDynamicsReference(m, l, motion, o);
  INFO(r.message);
  REQUIRE(r.ok);
  CHECK(static_cast<int>(r.drivers.size()) == n - m.nc());
  CHECK(r.trajectory.size() == 101);
  CHECK(r.trajectory.hasInputDerivatives());
  CHECK(r.maxConstraintResidual <= 1e-12);
  CHECK(r.maxRelativeResidual <= 1e-12);

  // The motion kept: at the motion's knots the configuration is the motion's.
  for (int k = 0; k < motion.size(); ++k) {
    INFO("motion knot " << k);
    const VectorXd q = r.trajectory.states().col(10 * k).head(n), qm = motion.states().col(k).head(n);
    CHECK((q - qm).cwiseAbs().maxCoeff() <= 1e-9);
  }

  // The forces are the plant's: forward dynamics under the reference's tensions gives the
  // distribution's λ (relative to the largest force), and every contact keeps its margins —
  // λ_n ≥ normalMin + margin and ‖λ_t‖ ≤ frictionUse · μ λ_n (the pyramid is inside that cone).
  Data data(m);
  for (int k = 0; k < r.trajectory.size(); ++k) {
    INFO("knot " << k);
    const VectorXd x = r.trajectory.states().col(k);
    REQUIRE(computeDynamics(m, data, x.head(n), x.tail(n), r.trajectory.inputs().col(k)).ok());
    const double scale = r.lambda.col(k).cwiseAbs().maxCoeff();
    CHECK((data.lambda - r.lambda.col(k)).cwiseAbs().maxCoeff() <= 1e-8 * scale);
    const hand::ContactMargins c = hand::contactMargins(data.lambda, l);
    CHECK(c.minNormal >= l.normalMin + o.normalMargin - 1e-9 * scale);
    CHECK(c.worstFrictionRatio <= o.frictionUse + 1e-9);
    CHECK(r.trajectory.inputs().col(k).minCoeff() > 0.0);
    CHECK((l.uMax - r.trajectory.inputs().col(k)).minCoeff() > 0.0);
  }

  // Consistent with the plant between knots, with margin (the default tolerance is 1e-3), and
  // the check's order: twice the knots, ~16× smaller defects (cubic Hermite tensions, O(h⁴)).
  const ConsistencyResult after = checkConsistency(m, r.trajectory);
  INFO("the reference: " << after.status.describe());
  CHECK(after.ok());
  CHECK(after.maxDefect <= 1e-4);
  o.knots = 201;
  const hand::InverseReference fine = hand::inverseDynamicsReference(m, l, motion, o);
  REQUIRE(fine.ok);
  const ConsistencyResult afterFine = checkConsistency(m, fine.trajectory);
  INFO("201 knots: " << afterFine.status.describe());
  CHECK(afterFine.maxDefect <= after.maxDefect / 6.0);
}

TEST_CASE("hand ball: the inverse-dynamics reference refuses what the contacts cannot do", "[hand_ball][reference]") {
  const Scene s = loadScene(kScenes + "hand_ball.json");
  const Model& m = s.model;
  hand::BallLimits l = hand::loadBallLimits(kLimits + "hand_ball_limits.json", m);
  const Trajectory motion = pulseMotion(s, 0.2, 11);
  hand::InverseReferenceOptions o;
  o.knots = 21;
  // Almost no friction: two pads cannot hold the ball against gravity.
  l.friction = 1e-3;
  const hand::InverseReference r = hand::inverseDynamicsReference(m, l, motion, o);
  CHECK_FALSE(r.ok);
  CHECK_THAT(r.message, Catch::Contains("knot 0"));
  // Tensions capped far below what the hold needs.
  l = hand::loadBallLimits(kLimits + "hand_ball_limits.json", m);
  l.uMax.setConstant(1e-3);
  const hand::InverseReference capped = hand::inverseDynamicsReference(m, l, motion, o);
  CHECK_FALSE(capped.ok);
  CHECK_THAT(capped.message, Catch::Contains("knot 0"));
  // Bad options name the field.
  o.knots = 1;
  CHECK_THROWS_WITH(hand::inverseDynamicsReference(m, l, motion, o), Catch::Contains("knots = 1"));
  o.knots = 21;
  o.frictionUse = 1.5;
  CHECK_THROWS_WITH(hand::inverseDynamicsReference(m, l, motion, o), Catch::Contains("frictionUse"));
  o.frictionUse = 0.9;
  // The pinch: two pads exert no moment on the ball about the line through them.
  const Scene p = loadScene(kScenes + "hand_ball_pinch.json");
  const hand::BallLimits lp = hand::loadBallLimits(kLimits + "hand_ball_pinch_limits.json", p.model);
  const hand::InverseReference pinch =
      hand::inverseDynamicsReference(p.model, lp, turnMotion(p.model, p.q, lp, 10.0, 6), o);
  CHECK_FALSE(pinch.ok);
  CHECK_THAT(pinch.message, Catch::Contains("knot 0") && Catch::Contains("span 13 of the 14 generalized forces"));
}
#endif
