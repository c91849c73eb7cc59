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
