// Tests for trellis/control/controllability.hpp.
#include "control_test_support.hpp"

#include <trellis/control.hpp>

#include <catch2/catch.hpp>

using Eigen::MatrixXd;
using Eigen::VectorXd;

TEST_CASE("controllability rank and singular values", "[controllability]") {
  MatrixXd A(2, 2), B(2, 1);
  A << 0, 1, 0, 0;
  B << 0, 1;
  auto r = trellis::computeControllability(A, B);
  CHECK(r.controllable());
  CHECK(r.smallestSingularValue == Approx(1.0));  // C = [[0, 1], [1, 0]]
  A << 1, 0, 0, -1;
  r = trellis::computeControllability(A, B);
  CHECK(r.rank == 1);
  CHECK(!r.controllable());
  CHECK(r.smallestSingularValue == 0.0);
}

TEST_CASE("controllability at a point, reduced to the constraint manifold", "[controllability][model]") {
  SECTION("cart-pole upright") {
    const trellis::Model model = trellis::ctest::makeCartPole();
    trellis::Data data(model);
    const VectorXd z = VectorXd::Zero(2), u = VectorXd::Zero(1);
    const auto r = trellis::computeControllabilityAt(model, data, z, z, u);
    CHECK(r.dimension == 4);
    CHECK(r.rank == 4);
    CHECK(r.smallestSingularValue > 1e-3);
  }
  SECTION("two carts tied by a constraint: full state uncontrollable, tangent space controllable") {
    const trellis::Model model = trellis::ctest::makeConstrainedCarts();
    trellis::Data data(model);
    const VectorXd z = VectorXd::Zero(2), u = VectorXd::Zero(1);
    REQUIRE(trellis::computeLinearization(model, data, z, z, u).ok());
    const auto full = trellis::computeControllability(data.A, data.B);
    CHECK(full.rank == 2);
    CHECK(!full.controllable());
    const auto r = trellis::computeControllabilityAt(model, data, z, z, u);
    CHECK(r.dimension == 2);
    CHECK(r.rank == 2);
    CHECK(r.controllable());
  }
}

TEST_CASE("a failing linearization is the report's status, not an exception", "[controllability][status]") {
  // A joint that moves no mass: M is singular at every state (core's kSingularMassMatrix).
  trellis::ModelBuilder b("massless");
  b.addFrame("cart", "world", trellis::Transform::tx("x"), trellis::Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addFrame("spinner", "cart", trellis::Transform::rz("phi"));
  b.addConfigForce("x", "push");
  const trellis::Model model = std::move(b).finalize();
  trellis::Data data(model);
  const VectorXd z = VectorXd::Zero(2), u = VectorXd::Zero(1);
  trellis::ControllabilityReport r;
  REQUIRE_NOTHROW(r = trellis::computeControllabilityAt(model, data, z, z, u));
  CHECK_FALSE(r.ok());
  CHECK_FALSE(r.controllable());
  CHECK(r.status.code == trellis::ControllabilityCode::kLinearizationFailed);
  CHECK(std::string(r.status.name()) == "linearization_failed");
  CHECK_THAT(r.status.message, Catch::Contains("singular_mass_matrix"));
  CHECK_THAT(r.describe(), Catch::StartsWith("linearization_failed: "));
  CHECK_THAT(r.json(), Catch::Contains("\"status\":\"linearization_failed\"") &&
                           Catch::Contains("\"ok\":false"));
  // Along a trajectory: every knot's report names the knot (t and index).
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(4, 3), U = Eigen::MatrixXd::Zero(1, 3);
  const trellis::Trajectory traj(model.configNames(), model.inputNames(),
                                 (VectorXd(3) << 0.0, 0.5, 1.0).finished(), X, U);
  const auto reports = trellis::controllabilityAtKnots(model, traj);
  REQUIRE(reports.size() == 3);
  CHECK(reports[1].status.index == 1);
  CHECK(reports[1].status.t == 0.5);
  CHECK_THAT(reports[1].status.message, Catch::StartsWith("knot 2 (t = 0.5): "));
  // Sizes stay bad input.
  CHECK_THROWS_AS(trellis::computeControllabilityAt(model, data, VectorXd::Zero(3), z, u),
                  std::invalid_argument);
}
