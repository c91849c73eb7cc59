// tests/core/test_input_bounds.cpp — inverse dynamics and holding inputs with input bounds: the
// bounds are honoured (bounded least squares) or the result says which bound the unbounded answer
// violates and by how much.
#include <catch2/catch.hpp>

#include <trellis/core.hpp>

#include <cmath>
#include <limits>

using namespace trellis;
using Catch::Matchers::Contains;

namespace {

/// A unit pendulum (1 kg at 1 m) driven by `inputs` torques on its one angle.
Model pendulum(int inputs) {
  ModelBuilder b;
  b.addFrame("L", "world", Transform::rz("theta"));
  b.addFrame("T", "L", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
  for (int i = 0; i < inputs; ++i) b.addConfigForce("theta", "tau" + std::to_string(i));
  return std::move(b).finalize();
}

}  // namespace

TEST_CASE("Holding inputs: a bound the unbounded answer violates is reported", "[inverse_dynamics][bounds]") {
  const Model model = pendulum(1);
  Data data(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, 0.5);
  const InverseDynamicsResult free = computeHoldingInputs(model, data, q);
  REQUIRE(free.ok());
  // Holding torque m g l sin θ (independent reference).
  REQUIRE(std::abs(std::abs(free.u[0]) - 9.81 * std::sin(0.5)) <= 1e-12);
  const double need = free.u[0];

  InverseDynamicsOptions opt;
  opt.lowerBound = Eigen::VectorXd::Constant(1, -std::abs(need) / 2);
  opt.upperBound = Eigen::VectorXd::Constant(1, std::abs(need) / 2);
  const InverseDynamicsResult r = computeHoldingInputs(model, data, q, opt);
  INFO(r.status.message);
  CHECK_FALSE(r.ok());
  CHECK(r.status.code == InverseDynamicsCode::kInputBounds);
  CHECK_THAT(r.status.message, Contains("input 'tau0'") && Contains(need > 0 ? "upper bound" : "lower bound"));
  // u sits at the violated bound, the excess is what the unbounded answer needed beyond it.
  CHECK(std::abs(r.u[0] - (need > 0 ? opt.upperBound[0] : opt.lowerBound[0])) == 0.0);
  CHECK(std::abs(r.boundExcess[0] - std::abs(need) / 2) <= 1e-12);
  CHECK(std::abs(r.residualNorm - std::abs(need) / 2) <= 1e-12);

  SECTION("bounds that contain the answer change nothing") {
    InverseDynamicsOptions wide;
    wide.lowerBound = Eigen::VectorXd::Constant(1, -2 * std::abs(need));
    wide.upperBound = Eigen::VectorXd::Constant(1, 2 * std::abs(need));
    const InverseDynamicsResult w = computeHoldingInputs(model, data, q, wide);
    CHECK(w.ok());
    CHECK(w.u[0] == need);
    CHECK(w.boundIterations == 0);
  }
  SECTION("malformed bounds are refused by name") {
    InverseDynamicsOptions bad;
    bad.lowerBound = Eigen::VectorXd::Constant(1, 1.0);
    bad.upperBound = Eigen::VectorXd::Constant(1, -1.0);
    CHECK_THROWS_WITH(computeHoldingInputs(model, data, q, bad), Contains("tau0"));
    bad.upperBound = Eigen::VectorXd::Constant(2, 1.0);
    CHECK_THROWS_AS(computeHoldingInputs(model, data, q, bad), std::invalid_argument);
  }
}

TEST_CASE("Holding inputs: redundant actuators share the load within their bounds", "[inverse_dynamics][bounds]") {
  const Model model = pendulum(2);
  Data data(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, 0.7);
  const InverseDynamicsResult free = computeHoldingInputs(model, data, q);
  REQUIRE(free.ok());
  const double need = free.u.sum();
  REQUIRE(std::abs(free.u[0] - free.u[1]) <= 1e-12 * std::abs(need));  // minimum norm: equal shares
  // The first actuator may give at most a quarter in magnitude: the second takes the rest, exactly.
  const double inf = std::numeric_limits<double>::infinity();
  InverseDynamicsOptions opt;
  opt.lowerBound = Eigen::Vector2d(-std::abs(need) / 4, -inf);
  opt.upperBound = Eigen::Vector2d(std::abs(need) / 4, inf);
  const InverseDynamicsResult r = computeHoldingInputs(model, data, q, opt);
  INFO(r.status.message);
  CHECK(r.ok());
  CHECK(r.boundIterations >= 1);
  CHECK(std::abs(r.u[0]) == std::abs(need) / 4);
  CHECK(std::abs(r.u.sum() - need) <= 1e-12 * std::abs(need));
  CHECK(r.residualNorm <= 1e-12 * std::abs(need));
}
