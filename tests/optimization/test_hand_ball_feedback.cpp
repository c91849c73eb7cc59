// Tests for examples/hand/ball_feedback.hpp (issue 26) on the full free-ball hand
// (examples/scenes/hand_ball.json): the contact check on made-up forces, the orientation error,
// the hold reference, and the sampled closed loops on the stored hold over 0.3 s — small
// perturbations keep every contact at every integrator step and decay; a large one breaks the
// friction cone at the index finger and is reported failed with the contact named. No timing.
#if defined(TRELLIS_HAND_BALL)
#include "ball_feedback.hpp"

#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <string>

using Eigen::VectorXd;
using namespace trellis;

namespace {

const std::string kScenes = std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/";
const std::string kLimits = std::string(TRELLIS_SOURCE_DIR) + "/examples/hand/";

struct HandBall {
  Scene s = loadScene(kScenes + "hand_ball.json");
  hand::BallLimits limits = hand::loadBallLimits(kLimits + "hand_ball_limits.json", s.model);
};

}  // namespace

TEST_CASE("hand ball feedback: the contact check names the digit, the condition and the values",
          "[hand_ball]") {
  const HandBall h;
  REQUIRE(h.limits.digits.size() == 5);
  const double mu = h.limits.friction;
  VectorXd lambda = VectorXd::Zero(15);
  for (int d = 0; d < 5; ++d) lambda(3 * d) = 1.0;  // 1 N pressing, no tangential force
  hand::ContactCheck check(h.limits);
  CHECK(check(0.0, lambda).empty());
  CHECK(check.minNormal == 1.0);
  CHECK(check.worstFrictionRatio == 0.0);
  // Friction inside the cone (ratio 0.9) at the ring finger (contact 2).
  lambda(7) = 0.9 * mu * 0.6;
  lambda(8) = 0.9 * mu * 0.8;
  CHECK(check(0.1, lambda).empty());
  CHECK(check.worstFrictionRatio == Approx(0.9));
  CHECK(check.worstFrictionContact == 2);
  CHECK(check.violation == hand::BallRunCode::kOk);
  // Outside it (ratio 1.1).
  lambda(7) = 1.1 * mu * 0.6;
  lambda(8) = 1.1 * mu * 0.8;
  const std::string cone = check(0.2, lambda);
  CHECK(check.violation == hand::BallRunCode::kFrictionCone);
  CHECK(check.violationContact == 2);
  CHECK(check.violationTime == 0.2);
  CHECK_THAT(cone, Catch::Contains("contact " + h.limits.digits[2]) && Catch::Contains("friction cone") &&
                       Catch::Contains("ratio 1.1"));
  // A normal force below the margin wins over the cone (the cone needs λ_n > 0), here the thumb's.
  hand::ContactCheck second(h.limits);
  lambda(12) = 0.5 * h.limits.normalMin;
  const std::string normal = second(0.3, lambda);
  CHECK(second.violation == hand::BallRunCode::kNormalForce);
  CHECK(second.violationContact == 4);
  CHECK(second.minNormal == 0.5 * h.limits.normalMin);
  CHECK_THAT(normal, Catch::Contains("contact " + h.limits.digits[4]) && Catch::Contains("below the margin"));
}

TEST_CASE("hand ball feedback: orientation error and the hold reference", "[hand_ball]") {
  // A turn of 0.1 rad about z composed with the same pitch and roll: the error is 0.1 rad.
  const Eigen::Vector3d a(0.3, 0.2, -0.1), b(0.4, 0.2, -0.1);
  CHECK(hand::ballOrientationError(a, a) == Approx(0.0).margin(1e-12));
  CHECK(hand::ballOrientationError(Eigen::Vector3d(0.3, 0, 0), Eigen::Vector3d(0.4, 0, 0)) == Approx(0.1));
  // Yaw about the fixed z axis before pitch and roll: the relative turn is still 0.1 rad.
  CHECK(hand::ballOrientationError(a, b) == Approx(0.1));
  CHECK(hand::ballOrientationError(Eigen::Vector3d(0, 0, 0.2), Eigen::Vector3d(0, 0, -0.1)) == Approx(0.3));

  const HandBall h;
  const Trajectory ref = hand::holdReference(h.s.model, h.s.q, h.s.u, 0.25, 0.1);
  REQUIRE(ref.size() == 4);  // 0, 0.1, 0.2, 0.25
  CHECK(ref.times()(3) == 0.25);
  CHECK(ref.states().col(3).head(h.s.model.nq()) == h.s.q);
  CHECK(ref.states().bottomRows(h.s.model.nq()).cwiseAbs().maxCoeff() == 0.0);
  CHECK_THROWS_WITH(hand::holdReference(h.s.model, h.s.q, h.s.u, -1.0),
                    Catch::Contains("horizon = -1"));
  // Contact forces for the CSV: named by digit and axis, equal to the core's λ at each row.
  const hand::ContactForces f = hand::contactForces(h.s.model, h.limits, ref);
  REQUIRE(f.names.size() == 15);
  CHECK(f.names[0] == "lambda_index_n");
  CHECK(f.names[1] == "lambda_index_t1");
  CHECK(f.names[14] == "lambda_" + h.limits.digits[4] + "_t2");
  REQUIRE(f.lambda.cols() == 4);
  Data data(h.s.model);
  REQUIRE(computeDynamics(h.s.model, data, h.s.q, VectorXd::Zero(h.s.model.nq()), h.s.u).ok());
  for (int k = 0; k < 4; ++k) CHECK(f.lambda.col(k) == data.lambda);
  hand::BallFeedbackOptions bad;
  bad.perturbation = 0.0;
  CHECK_THROWS_WITH(bad.validate(), Catch::Contains("BallFeedbackOptions.perturbation = 0"));
}

TEST_CASE("hand ball feedback: on the stored hold the 200 Hz closed loops keep the contacts and converge",
          "[hand_ball]") {
  const HandBall h;
  const Trajectory ref = hand::holdReference(h.s.model, h.s.q, h.s.u, 0.3, 0.1);
  hand::BallFeedbackOptions o;
  o.runs = 3;
  o.seed = 1;
  o.perturbation = 0.01;
  const hand::BallFeedbackResult r = hand::runBallFeedback(h.s.model, h.limits, ref, o);
  INFO(r.summary());
  REQUIRE(r.lqr.ok());
  CHECK(r.lqr.sampleRate == 200.0);
  CHECK(r.lqr.constrained);
  CHECK(r.lqr.gains.size() == 61);  // samples 0, 5 ms, …, 0.295 s and the end
  REQUIRE(r.runs.size() == 3);
  for (const hand::BallRun& run : r.runs) {
    INFO(run.describe());
    CHECK(run.ok());
    CHECK(run.simulation.ok());
    CHECK(run.simulation.controlSamples == 60);
    // Every accepted step and every sample was checked.
    CHECK(run.simulation.checks == run.simulation.steps + 60);
    CHECK(run.minNormal >= h.limits.normalMin);
    CHECK(run.worstFrictionRatio <= 1.0);
    // Measured: 0.03–0.39 over 0.3 s (the slowest closed-loop mode); 0.5 is the criterion.
    CHECK(run.errorRatio <= 0.5);
    CHECK(run.initialError == Approx(0.01).epsilon(0.05));
    // Tensions stay in [0, u_max].
    const Eigen::MatrixXd& U = run.simulation.trajectory.inputs();
    CHECK(U.minCoeff() >= 0.0);
    for (int i = 0; i < U.rows(); ++i) CHECK(U.row(i).maxCoeff() <= h.limits.uMax(i));
  }
  CHECK(r.ok());
  CHECK(r.failed == 0);
  // The hold's own contact forces: λ_n ≈ 0.95 N, friction ratio ≈ 0.09 (measured); the small
  // perturbations move them little.
  CHECK(r.minNormal > 0.5);
  CHECK(r.worstFrictionRatio < 0.5);
  CHECK(r.worstOrientationError < 1e-3);
}

TEST_CASE("hand ball feedback: a perturbation that breaks the friction cone is a failed run naming the contact",
          "[hand_ball]") {
  const HandBall h;
  const Trajectory ref = hand::holdReference(h.s.model, h.s.q, h.s.u, 0.3, 0.1);
  hand::BallFeedbackOptions o;
  o.runs = 2;
  o.seed = 1;
  o.perturbation = 0.3;  // run 1's start asks the middle finger for |λ_t| = 1.2 μ λ_n (measured)
  const hand::BallFeedbackResult r = hand::runBallFeedback(h.s.model, h.limits, ref, o);
  INFO(r.summary());
  REQUIRE(r.lqr.ok());
  REQUIRE(r.runs.size() == 2);
  CHECK(r.runs[0].ok());
  const hand::BallRun& broken = r.runs[1];
  CHECK_FALSE(broken.ok());
  CHECK(broken.status.code == hand::BallRunCode::kFrictionCone);
  CHECK(std::string(broken.status.name()) == "friction_cone");
  // Which contact breaks first depends on the hold (measured: the index on the first stored hold,
  // the middle finger on the hold with the tension reserve); the status names the one it is.
  REQUIRE(broken.status.index >= 0);
  REQUIRE(broken.status.index < static_cast<int>(h.limits.digits.size()));
  CHECK_THAT(broken.status.message, Catch::Contains("contact " + h.limits.digits[broken.status.index]) &&
                                        Catch::Contains("outside the friction cone"));
  CHECK(broken.status.t >= 0.0);
  CHECK(broken.simulation.status.code == SimulationCode::kCheckFailed);
  CHECK(broken.worstFrictionRatio > 1.0);
  CHECK_FALSE(r.ok());
  CHECK(r.failed == 1);
  CHECK(r.contactFailures == 1);
  CHECK(r.worstFrictionRatio > 1.0);
}

#endif
