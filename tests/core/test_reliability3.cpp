// tests/core/test_reliability3.cpp — issue 24 in the library: residual checks relative to the
// quantities they compare (the same verdict when a model's units change), and the projection's
// checks (the velocity row it cannot cancel, every coordinate fixed).
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <string>

using namespace trellis;
using Catch::Matchers::Contains;

namespace {

/// A cart-pole with every mass times `massScale` and every length times `lengthScale`: a cart
/// force only (the pole is passive), a point mass at the pole's tip; optionally a spring on the
/// pole (stiffness in the same units) whose rest angle balances gravity at θ = θ*.
Model cartPole(double massScale, double lengthScale, double springAt = 0.0) {
  ModelBuilder b;
  b.addFrame("cart", "world", Transform::tx("x"), Mass{1.0 * massScale});
  b.addFrame("pin", "cart", Transform::rz("theta"));
  b.addFrame("tip", "pin", Transform::ty(0.5 * lengthScale), Mass{0.1 * massScale});
  b.addGravity({0.0, -9.81, 0.0});
  b.addConfigForce("x", "push");
  if (springAt != 0.0) {
    // Gravity torque on the pole at θ: m g l sin θ (it tips the upright pole over). A spring
    // k (θ* − θ) with k = m g l sin θ* / θ* ... written as k (q0 − θ) with q0 chosen so that the
    // spring torque at θ* equals the gravity torque: k θ* − k q0 = −m g l sin θ*.
    const double mgl = 0.1 * massScale * 9.81 * 0.5 * lengthScale;
    const double k = 10.0 * mgl;
    b.addConfigSpring("theta", k, springAt - mgl * std::sin(springAt) / k);
  }
  return std::move(b).finalize();
}

}  // namespace

TEST_CASE("inverse dynamics judges residuals against the terms compared: the verdict survives a change of units",
          "[reliability][inverse_dynamics]") {
  for (const auto& [mass, length] : {std::pair{1.0, 1.0}, std::pair{1e-6, 1e-3}, std::pair{1e6, 1e3}, std::pair{1e-6, 1e3}}) {
    INFO("mass scale " << mass << ", length scale " << length);
    const Model model = cartPole(mass, length);
    Data data(model);
    const Eigen::VectorXd tilted = Eigen::Vector2d(0.0, 0.3), upright = Eigen::Vector2d(0.0, 0.0);
    // The pole tilted: no cart force holds it (a fixed floor of 1 N·m held the mg/mm one).
    const InverseDynamicsResult r = computeHoldingInputs(model, data, tilted);
    CHECK(r.status.code == InverseDynamicsCode::kUnreachable);
    CHECK_THAT(r.status.message, Contains("no inputs produce this"));
    // Upright: held with u = 0 exactly.
    const InverseDynamicsResult h = computeHoldingInputs(model, data, upright);
    CHECK(h.ok());
    CHECK(h.u.cwiseAbs().maxCoeff() == 0.0);
    // Held by a spring at θ = 0.3: the gravity and spring torques cancel; the residual is the
    // rounding of that cancellation, judged against the two torques, not against their sum.
    const Model sprung = cartPole(mass, length, 0.3);
    Data sprungData(sprung);
    const InverseDynamicsResult s = computeHoldingInputs(sprung, sprungData, tilted);
    CHECK(s.ok());
    // Reachable accelerations: the forward dynamics' q̈ is reproduced with its own input.
    const Eigen::VectorXd dq = Eigen::Vector2d(0.2, -0.4);
    REQUIRE(computeDynamics(model, data, tilted, dq, Eigen::VectorXd::Constant(1, 0.7 * mass)).ok());
    const Eigen::VectorXd qdd = data.qdd;
    const InverseDynamicsResult f = computeInverseDynamics(model, data, tilted, dq, qdd);
    CHECK(f.ok());
    CHECK(std::abs(f.u[0] - 0.7 * mass) <= 1e-9 * mass);
  }
  // Tolerances: relative, in (0, 0.1].
  const Model model = cartPole(1.0, 1.0);
  Data data(model);
  InverseDynamicsOptions loose;
  loose.tolerance = 1e300;
  CHECK_THROWS_WITH(computeHoldingInputs(model, data, Eigen::Vector2d(0.0, 0.3), loose), Contains("must be in (0, 0.1]"));
}

TEST_CASE("projection checks the velocity row it corrects and survives every coordinate fixed",
          "[reliability][projection]") {
  ModelBuilder b;
  b.addFrame("s", "world", Transform::tx("x"), Mass{1.0});
  b.addFrame("l", "world", Transform::ty("y"), Mass{1.0});
  b.addFrame("C", "world", Transform::tx(2.0));
  b.addDistanceConstraint("s", "C", 1.0);
  const Model model = std::move(b).finalize();
  Data data(model);
  const Eigen::VectorXd q = Eigen::Vector2d(1.0, 0.0), dq = Eigen::Vector2d(0.5, 0.1);
  ProjectionOptions free;
  const ProjectionResult ok = projectState(model, data, q, dq, free);
  REQUIRE(ok.ok());
  CHECK(ok.velocityResidual <= 1e-12);
  // x fixed: the constraint row A q̇ = A_x ẋ cannot be cancelled by y.
  ProjectionOptions fixX;
  fixX.fixed = {0};
  const ProjectionResult r = projectState(model, data, q, dq, fixX);
  CHECK(r.status.code == ProjectionCode::kNotConverged);
  CHECK_THAT(r.status.message, Contains("is still violated after the projection"));
  // Every coordinate fixed: on the manifold, the velocity row fails; off it, the position fails.
  ProjectionOptions all;
  all.fixed = {0, 1};
  CHECK(projectState(model, data, q, dq, all).status.code == ProjectionCode::kNotConverged);
  const ProjectionResult off = projectState(model, data, Eigen::Vector2d(1.2, 0.0), dq, all);
  CHECK(off.status.code == ProjectionCode::kNotConverged);
  CHECK_THAT(off.status.message, Contains("every coordinate is fixed"));
  // With velocities off, a position-only projection with x fixed is fine on the manifold.
  ProjectionOptions positions;
  positions.fixed = {0};
  positions.velocities = false;
  CHECK(projectState(model, data, q, dq, positions).ok());
}
