// tests/core/test_model_questions.cpp — the library helpers that answer a user's questions of a
// model: state files (state.hpp), inverse dynamics (inverse_dynamics.hpp), constraint projection
// (projection.hpp) and static equilibria (equilibrium.hpp). Every check is independent of the
// helper under test: forward dynamics, closed forms, or a direct minimization.
#include <trellis/core.hpp>

#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <random>

using namespace trellis;
using Catch::Matchers::Contains;

namespace {

constexpr double kG = 9.81;

/// Pendulum: rz(theta) pivot, point mass m at distance l; gravity (0, −g, 0); torque input "tau".
Model pendulum(double m, double l, double damping = 0.0) {
  ModelBuilder b("pendulum");
  b.addFrame("pivot", "world", Transform::rz("theta"));
  b.addFrame("bob", "pivot", Transform::ty(-l), Mass{m, Eigen::Matrix3d::Zero()});
  b.addGravity({0.0, -kG, 0.0});
  b.addConfigForce("theta", "tau");
  if (damping > 0.0) b.addDamping(damping);
  return std::move(b).finalize();
}

/// A planar cart-pole: cart tx(x) (mass mc), pole rz(theta), bob ty(−l) (mass mp); force "push"
/// on x only (under-actuated).
Model cartPole() {
  ModelBuilder b("cart_pole");
  b.addFrame("cart", "world", Transform::tx("x"), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addFrame("pole", "cart", Transform::rz("theta"));
  b.addFrame("bob", "pole", Transform::ty(-0.8), Mass{0.3, Eigen::Matrix3d::Zero()});
  b.addGravity({0.0, -kG, 0.0});
  b.addConfigForce("x", "push");
  return std::move(b).finalize();
}

/// A point on a circle of radius r about the origin with anisotropic metric: X tx(x) carries
/// mass mx, its child Y ty(y) carries mass my, so M = diag(mx + my, my); h = x² + y² − r².
/// Optional gravity (0, −g, 0) and a force input "fx" on x.
Model pointOnCircle(double mx, double my, double r, bool gravity) {
  ModelBuilder b("circle");
  b.addFrame("X", "world", Transform::tx("x"), Mass{mx, Eigen::Matrix3d::Zero()});
  b.addFrame("Y", "X", Transform::ty("y"), Mass{my, Eigen::Matrix3d::Zero()});
  b.addFrame("origin", "world", Transform::tx(0.0));
  b.addDistanceConstraint("Y", "origin", r);
  if (gravity) b.addGravity({0.0, -kG, 0.0});
  b.addConfigForce("x", "fx");
  return std::move(b).finalize();
}

}  // namespace

// ---- state files --------------------------------------------------------------------------------

TEST_CASE("A state object overrides the named entries of the defaults and checks every name",
          "[state]") {
  const Model model = cartPole();
  ModelState defaults = zeroState(model);
  defaults.q << 0.5, 0.25;
  const ModelState s = parseState(model, R"({"q": {"theta": 1.5}, "dq": {"x": -2}, "u": {"push": 3},
                                             "ddq": {"theta": 4}})", "s.json", defaults);
  CHECK(s.q(0) == 0.5);  // kept from the defaults
  CHECK(s.q(1) == 1.5);
  CHECK(s.dq(0) == -2.0);
  CHECK(s.u(0) == 3.0);
  CHECK(s.ddq(1) == 4.0);
  CHECK(s.hasAcceleration);
  CHECK_FALSE(parseState(model, "{}", "s.json", defaults).hasAcceleration);

  const auto errorOf = [&](const std::string& text) {
    try {
      parseState(model, text, "s.json", defaults);
    } catch (const ModelError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  CHECK_THAT(errorOf(R"({"q": {"phi": 1}})"), Contains("s.json: state: field 'q.phi'") && Contains("\"phi\"") &&
                                                  Contains("known: x, theta"));
  CHECK_THAT(errorOf(R"({"u": {"x": 1}})"), Contains("field 'u.x'") && Contains("unknown input"));
  CHECK_THAT(errorOf(R"({"qd": {}})"), Contains("field 'qd'") && Contains("unknown key"));
  CHECK_THAT(errorOf(R"({"q": {"x": "a"}})"), Contains("field 'q.x'") && Contains("\"a\""));
  CHECK_THAT(errorOf(R"({"q": [1]})"), Contains("field 'q'"));
  CHECK_THAT(errorOf("{"), Contains("s.json") && Contains("invalid JSON"));
}

// ---- inverse dynamics --------------------------------------------------------------------------

TEST_CASE("Inverse dynamics returns inputs whose forward dynamics reproduce q''", "[inverse_dynamics]") {
  std::mt19937 rng(41);
  SECTION("the paper's constrained pendulum: u and lambda unique, equal to the forward solve") {
    const Model model = test::paperPendulum().model;
    Data data(model);
    for (int trial = 0; trial < 5; ++trial) {
      const test::State x = test::randomConsistentState(model, rng);
      REQUIRE(computeDynamics(model, data, x.q, x.dq, x.u).ok());
      const Eigen::VectorXd qdd = data.qdd, lambda = data.lambda;
      const InverseDynamicsResult r = computeInverseDynamics(model, data, x.q, x.dq, qdd);
      INFO(r.status.message);
      REQUIRE(r.ok());
      CHECK(r.unique);
      CHECK((r.u - x.u).cwiseAbs().maxCoeff() < 1e-9 * (1.0 + x.u.cwiseAbs().maxCoeff()));
      CHECK((r.lambda - lambda).cwiseAbs().maxCoeff() < 1e-9 * (1.0 + lambda.cwiseAbs().maxCoeff()));
    }
  }
  SECTION("every element in 3D with constraints: u not unique, forward dynamics of u reproduces q''") {
    const Model model = test::kitchenSink().model;
    Data data(model);
    for (int trial = 0; trial < 5; ++trial) {
      const test::State x = test::randomConsistentState(model, rng);
      REQUIRE(computeDynamics(model, data, x.q, x.dq, x.u).ok());
      const Eigen::VectorXd qdd = data.qdd;
      const InverseDynamicsResult r = computeInverseDynamics(model, data, x.q, x.dq, qdd);
      INFO(r.status.message);
      REQUIRE(r.ok());
      REQUIRE(computeDynamics(model, data, x.q, x.dq, r.u).ok());
      // q̈ is O(10); the KKT solve and the least squares each lose a few digits to conditioning.
      CHECK((data.qdd - qdd).cwiseAbs().maxCoeff() < 1e-8 * (1.0 + qdd.cwiseAbs().maxCoeff()));
    }
  }
  SECTION("under-actuated cart-pole: feasible q'' exact, infeasible q'' least squares") {
    const Model model = cartPole();
    Data data(model);
    const test::State x = test::randomState(model, rng);
    REQUIRE(computeDynamics(model, data, x.q, x.dq, x.u).ok());
    const InverseDynamicsResult exact = computeInverseDynamics(model, data, x.q, x.dq, data.qdd);
    REQUIRE(exact.ok());
    CHECK(std::abs(exact.u(0) - x.u(0)) < 1e-10 * (1.0 + std::abs(x.u(0))));

    const Eigen::VectorXd qdd = test::uniformVector(rng, 2, -3.0, 3.0);
    const InverseDynamicsResult r = computeInverseDynamics(model, data, x.q, x.dq, qdd);
    CHECK(r.status.code == InverseDynamicsCode::kUnreachable);
    CHECK(r.residualNorm > 1e-3);
    // Independent: the residual of M q̈ + b − B u over u is least squares iff it is orthogonal
    // to B's column; and it is the residual the result reports.
    computeInputMatrix(model, data, x.q);
    const Eigen::VectorXd Bu = data.inputMatrix.col(0);
    computeDynamics(model, data, x.q, x.dq, Eigen::VectorXd::Zero(1));
    const Eigen::VectorXd rhs = data.M * qdd + data.bias;
    const Eigen::VectorXd residual = Bu * r.u(0) - rhs;
    CHECK(std::abs(Bu.dot(residual)) < 1e-10 * (1.0 + rhs.norm()) * Bu.norm());
    CHECK((residual - r.residual).cwiseAbs().maxCoeff() < 1e-12 * (1.0 + rhs.norm()));
    CHECK(r.residualNorm == Approx(residual.cwiseAbs().maxCoeff()).epsilon(1e-12));
  }
  SECTION("an acceleration that violates the constraints is reported") {
    const Model model = test::paperPendulum().model;
    Data data(model);
    const test::State x = test::randomConsistentState(model, rng);
    const InverseDynamicsResult r =
        computeInverseDynamics(model, data, x.q, x.dq, Eigen::VectorXd::Constant(2, 1.0));
    CHECK(r.status.code == InverseDynamicsCode::kInadmissibleAcceleration);
    CHECK(r.constraintResidual > 1e-3);
  }
  SECTION("the torque that holds a pendulum at angle theta is m g l sin(theta)") {
    const double m = 1.3, l = 0.7;
    const Model model = pendulum(m, l);
    Data data(model);
    for (double theta : {-2.0, -0.3, 0.0, 0.9, 3.0}) {
      const InverseDynamicsResult r = computeHoldingInputs(model, data, Eigen::VectorXd::Constant(1, theta));
      REQUIRE(r.ok());
      CHECK(r.u(0) == Approx(m * kG * l * std::sin(theta)).margin(1e-12));
    }
  }
}

// ---- projection --------------------------------------------------------------------------------

TEST_CASE("The projection lands on the constraints at the mass-weighted closest point", "[projection]") {
  SECTION("a point on a circle with metric diag(4, 1): closest point by direct minimization") {
    const double mx = 3.0, my = 1.0, r = 1.0;
    const Model model = pointOnCircle(mx, my, r, false);
    Data data(model);
    const Eigen::Vector2d q0(1.3, 0.4), dq0(0.3, -0.8);
    const ProjectionResult p = projectState(model, data, q0, dq0);
    INFO(p.status.message);
    REQUIRE(p.ok());
    CHECK(p.massWeighted);
    CHECK(p.positionResidual <= 1e-12);
    CHECK(std::abs(p.q.squaredNorm() - r * r) <= 1e-12);
    // Independent: minimize (mx+my)(r cos φ − x0)² + my (r sin φ − y0)² over φ (dense grid, then
    // Newton on the derivative with numerical second derivative).
    const auto f = [&](double phi) {
      return (mx + my) * std::pow(r * std::cos(phi) - q0(0), 2) + my * std::pow(r * std::sin(phi) - q0(1), 2);
    };
    double best = 0.0;
    for (int i = 0; i < 100000; ++i) {
      const double phi = 2.0 * std::numbers::pi * i / 100000.0;
      if (f(phi) < f(best)) best = phi;
    }
    for (int it = 0; it < 50; ++it) {
      const double h = 1e-4;
      const double d1 = (f(best + h) - f(best - h)) / (2 * h), d2 = (f(best + h) - 2 * f(best) + f(best - h)) / (h * h);
      best -= d1 / d2;
    }
    CHECK(p.q(0) == Approx(r * std::cos(best)).margin(1e-8));
    CHECK(p.q(1) == Approx(r * std::sin(best)).margin(1e-8));
    // The Euclidean closest point (q0 / |q0|) is a different point: the metric matters here.
    CHECK((p.q - q0.normalized()).norm() > 1e-2);

    // Velocities: A q̇* = 0, and q̇* − q̇0 is M-orthogonal to the tangent (M (q̇* − q̇0) ∥ ∇h).
    CHECK(p.velocityResidual <= 1e-13);
    const Eigen::Vector2d grad = 2.0 * p.q;
    const Eigen::Vector2d Mdelta = Eigen::Vector2d(mx + my, my).cwiseProduct(p.dq - dq0);
    CHECK(std::abs(grad(0) * Mdelta(1) - grad(1) * Mdelta(0)) < 1e-12);
    const double kinetic0 = 0.5 * ((mx + my) * dq0(0) * dq0(0) + my * dq0(1) * dq0(1));
    const double kinetic1 = 0.5 * ((mx + my) * p.dq(0) * p.dq(0) + my * p.dq(1) * p.dq(1));
    CHECK(kinetic1 <= kinetic0);
  }
  SECTION("random states of every element type in 3D land on h = 0, A q' = 0") {
    const Model model = test::kitchenSink().model;
    Data data(model);
    std::mt19937 rng(17);
    for (int trial = 0; trial < 5; ++trial) {
      test::State x = test::randomConsistentState(model, rng);
      x.q += test::uniformVector(rng, model.nq(), -0.05, 0.05);
      x.dq += test::uniformVector(rng, model.nq(), -0.5, 0.5);
      // The descent to the closest point converges linearly (rate ~ distance × curvature); on
      // this 6-coordinate system 50 steps reach 1e-9, so the step test is 1e-8 here.
      ProjectionOptions o;
      o.stepTolerance = 1e-8;
      const ProjectionResult p = projectState(model, data, x.q, x.dq, o);
      INFO(p.status.message);
      REQUIRE(p.ok());
      CHECK(p.positionResidualBefore > 1e-4);
      computeConstraints(model, data, p.q, p.dq);
      for (int c = 0; c < model.nc(); ++c)
        if (model.constraints()[c].holonomic()) CHECK(std::abs(data.constraintValue(c)) <= 1e-12);
      CHECK((data.constraintJacobian * p.dq).cwiseAbs().maxCoeff() <= 1e-12 * (1.0 + p.dq.cwiseAbs().maxCoeff()));
    }
  }
  SECTION("fixed coordinates keep their value and velocity") {
    const Model model = test::paperPendulum().model;
    Data data(model);
    const Eigen::Vector2d q0(0.4, 0.3), dq0(0.2, 0.5);
    ProjectionOptions o;
    o.fixed = {0};
    const ProjectionResult p = projectState(model, data, q0, dq0, o);
    REQUIRE(p.ok());
    CHECK(p.q(0) == q0(0));
    CHECK(p.dq(0) == dq0(0));
    CHECK(p.positionResidual <= 1e-12);
    CHECK(p.velocityResidual <= 1e-12);
  }
  SECTION("unreachable constraints are a status with the residual, not a success") {
    ModelBuilder b;
    b.addFrame("pivot", "world", Transform::rz("theta"));
    b.addFrame("bob", "pivot", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
    b.addFrame("far", "world", Transform::tx(5.0));
    b.addDistanceConstraint("bob", "far", 1.0);
    const Model model = std::move(b).finalize();
    Data data(model);
    const ProjectionResult p = projectState(model, data, Eigen::VectorXd::Constant(1, 0.3), Eigen::VectorXd::Zero(1));
    CHECK(p.status.code == ProjectionCode::kNotConverged);
    CHECK(p.positionResidual > 1.0);
    CHECK_THAT(p.status.message, Contains("|h|inf"));
  }
  SECTION("without constraints the state is unchanged") {
    const Model model = pendulum(1.0, 1.0);
    Data data(model);
    const ProjectionResult p = projectState(model, data, Eigen::VectorXd::Constant(1, 0.3), Eigen::VectorXd::Constant(1, 2.0));
    CHECK(p.ok());
    CHECK(p.q(0) == 0.3);
    CHECK(p.dq(0) == 2.0);
  }
}

// ---- equilibrium -------------------------------------------------------------------------------

TEST_CASE("Static equilibria match closed forms and have q'' = 0", "[equilibrium]") {
  SECTION("a pendulum under a constant torque: sin(theta) = u / (m g l)") {
    const double m = 0.8, l = 1.2, u = 3.0;
    const Model model = pendulum(m, l, 0.2);
    Data data(model);
    const EquilibriumResult r = findEquilibrium(model, data, Eigen::VectorXd::Constant(1, 0.1), Eigen::VectorXd::Constant(1, u));
    INFO(r.status.message);
    REQUIRE(r.ok());
    CHECK(r.q(0) == Approx(std::asin(u / (m * kG * l))).margin(1e-10));
    REQUIRE(computeDynamics(model, data, r.q, Eigen::VectorXd::Zero(1), r.u).ok());
    CHECK(std::abs(data.qdd(0)) <= 1e-10);
    CHECK(r.isolated);
    CHECK(r.maxRealEigenvalue < 0.0);  // damped, hanging: asymptotically stable
  }
  SECTION("a pendulum pulled by a zero-length spring: tan(theta) = k a_x / (m g - k a_y)") {
    const double m = 1.0, l = 1.0, k = 4.0, ax = 0.7, ay = -0.4;
    ModelBuilder b;
    b.addFrame("pivot", "world", Transform::rz("theta"));
    b.addFrame("bob", "pivot", Transform::ty(-l), Mass{m, Eigen::Matrix3d::Zero()});
    b.addFrame("ax", "world", Transform::tx(ax));
    b.addFrame("anchor", "ax", Transform::ty(ay));
    b.addGravity({0.0, -kG, 0.0});
    b.addLinearSpring("bob", "anchor", k, 0.0);
    const Model model = std::move(b).finalize();
    Data data(model);
    const EquilibriumResult r = findEquilibrium(model, data, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Zero(0));
    INFO(r.status.message);
    REQUIRE(r.ok());
    CHECK(r.q(0) == Approx(std::atan(k * ax / (m * kG - k * ay))).margin(1e-10));
    CHECK(r.maxRealEigenvalue == Approx(0.0).margin(1e-8));  // undamped: ± i ω
  }
  SECTION("a constrained point on a circle pushed sideways: tan(phi) = u / (m g)") {
    const double m = 1.5, r = 0.9, u = 4.0;
    const Model model = pointOnCircle(0.0, m, r, true);
    Data data(model);
    const EquilibriumResult e = findEquilibrium(model, data, Eigen::Vector2d(0.1, -0.8), Eigen::VectorXd::Constant(1, u));
    INFO(e.status.message);
    REQUIRE(e.ok());
    const double phi = std::atan(u / (m * kG));
    CHECK(e.q(0) == Approx(r * std::sin(phi)).margin(1e-10));
    CHECK(e.q(1) == Approx(-r * std::cos(phi)).margin(1e-10));
    CHECK(e.constraintResidual <= 1e-10);
    REQUIRE(computeDynamics(model, data, e.q, Eigen::VectorXd::Zero(2), e.u).ok());
    CHECK(data.qdd.cwiseAbs().maxCoeff() <= 1e-10);
    // Holding that pose needs exactly the same input (inverse dynamics, independently).
    const InverseDynamicsResult hold = computeHoldingInputs(model, data, e.q);
    REQUIRE(hold.ok());
    CHECK(hold.u(0) == Approx(u).margin(1e-9));
  }
  SECTION("a continuum of equilibria (no gravity) converges and is not isolated") {
    ModelBuilder b;
    b.addFrame("pivot", "world", Transform::rz("theta"));
    b.addFrame("bob", "pivot", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
    const Model model = std::move(b).finalize();
    Data data(model);
    const EquilibriumResult r = findEquilibrium(model, data, Eigen::VectorXd::Constant(1, 0.7), Eigen::VectorXd::Zero(0));
    REQUIRE(r.ok());
    CHECK(r.q(0) == 0.7);
    CHECK_FALSE(r.isolated);
  }
  SECTION("the verdict is relative to the model: the same answer in any units") {
    // sin(theta) = u / (m g l) = 0.3 on a 1 mg / 1 mm pendulum, on a unit one and on a 10 000 km
    // one (g/l = 1e-6 s^-2: a fixed floor of 1e-10 on |q''| would accept theta 1e-4 rad off).
    for (const double scale : {1e-3, 1.0, 1e7}) {
      const double m = 1e-3 * scale, l = scale;
      const double u = 0.3 * m * kG * l;
      const Model model = pendulum(m, l, 0.2);
      Data data(model);
      const EquilibriumResult r = findEquilibrium(model, data, Eigen::VectorXd::Constant(1, 0.05), Eigen::VectorXd::Constant(1, u));
      INFO("scale " << scale << ": " << r.describe());
      REQUIRE(r.ok());
      CHECK(r.q(0) == Approx(std::asin(0.3)).margin(1e-9));
      CHECK(r.relativeResidual <= 1e-10);
      // A loose tolerance stops early, by the same relative measure whatever the units.
      EquilibriumOptions loose;
      loose.tolerance = 1e-3;
      const EquilibriumResult early = findEquilibrium(model, data, Eigen::VectorXd::Constant(1, 0.05), Eigen::VectorXd::Constant(1, u), loose);
      REQUIRE(early.ok());
      CHECK(std::abs(early.q(0) - std::asin(0.3)) <= 2e-3);
    }
  }
  SECTION("a tolerance outside (0, 1e-3] is refused, naming its value") {
    const Model model = pendulum(1.0, 1.0);
    Data data(model);
    EquilibriumOptions bad;
    bad.tolerance = 1e300;
    REQUIRE_THROWS_WITH(findEquilibrium(model, data, Eigen::VectorXd::Zero(1), Eigen::VectorXd::Zero(1), bad),
                        Catch::Contains("tolerance = 1e+300"));
  }
  SECTION("a torque larger than m g l has no equilibrium: a status, not a success") {
    const Model model = pendulum(1.0, 1.0);
    Data data(model);
    const EquilibriumResult r = findEquilibrium(model, data, Eigen::VectorXd::Constant(1, 0.2), Eigen::VectorXd::Constant(1, 20.0));
    CHECK(r.status.code == EquilibriumCode::kNotConverged);
    CHECK(r.accelerationResidual > 1.0);
  }
}
