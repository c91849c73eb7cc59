// Tests for trellis/core/numdiff.hpp: the schemes' error against closed forms, differenceDynamics
// against the exact linearization, and checkLinearization naming its worst entry.
#include <catch2/catch.hpp>

#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>
#include <trellis/core/numdiff.hpp>

#include <cmath>

using namespace trellis;
using namespace trellis::test;

TEST_CASE("numdiff: each scheme's error matches its order on a closed form", "[numdiff]") {
  // f(x) = [sin x0 · exp x1; x0³]: J = [[cos x0 e^x1, sin x0 e^x1], [3 x0², 0]].
  const DifferenceFunction f = [](const Eigen::VectorXd& x, Eigen::VectorXd& out) {
    out.resize(2);
    out << std::sin(x(0)) * std::exp(x(1)), x(0) * x(0) * x(0);
  };
  Eigen::VectorXd x(2);
  x << 0.7, -0.3;
  Eigen::MatrixXd exact(2, 2);
  exact << std::cos(0.7) * std::exp(-0.3), std::sin(0.7) * std::exp(-0.3), 3 * 0.49, 0.0;
  // Expected errors (numdiff.hpp): ~eps^(1/2) ≈ 1.5e-8 forward, ~eps^(2/3) ≈ 4e-11 central,
  // ~eps^(4/5) ≈ 3e-13 fourth order, times O(1) derivative constants; the bounds leave ×30.
  struct Case {
    DifferenceScheme scheme;
    double bound;
  };
  for (const Case c : {Case{DifferenceScheme::kForward, 5e-7}, Case{DifferenceScheme::kCentral, 1e-9},
                       Case{DifferenceScheme::kCentralFourthOrder, 1e-11}}) {
    NumDiffOptions o;
    o.scheme = c.scheme;
    const double error = (differenceJacobian(f, x, o) - exact).cwiseAbs().maxCoeff();
    INFO("scheme " << static_cast<int>(c.scheme) << " error " << error);
    CHECK(error < c.bound);
  }
  // A step far too large is visibly worse: the step rule matters.
  NumDiffOptions coarse;
  coarse.relativeStep = 1e-1;
  CHECK((differenceJacobian(f, x, coarse) - exact).cwiseAbs().maxCoeff() > 1e-4);
}

TEST_CASE("numdiff: differences of the dynamics agree with the exact linearization",
          "[numdiff][dynamics]") {
  const auto check = [](const Model& model) {
    std::mt19937 rng(4242);
    const State s = randomState(model, rng);
    const LinearizationCheck central = checkLinearization(model, s.q, s.dq, s.u);
    INFO(central.describe());
    REQUIRE(central.ok());
    CHECK(central.maxError < 1e-7);
    CHECK(central.exactJ.rows() == model.nq());
    CHECK(central.exactJ.cols() == 2 * model.nq() + model.nu());
    CHECK(central.rowName.rfind("dd", 0) == 0);
    CHECK(central.exact == central.exactJ(central.row, central.column));
    CHECK_THAT(central.describe(), Catch::StartsWith("ok: worst entry d(" + central.rowName + ")/d(" +
                                                     central.columnName + ")"));
    CHECK_THAT(central.json(), Catch::Contains("\"status\":\"ok\"") &&
                                   Catch::Contains("\"row_name\":\"" + central.rowName + "\""));
    NumDiffOptions forward;
    forward.scheme = DifferenceScheme::kForward;
    const LinearizationCheck f = checkLinearization(model, s.q, s.dq, s.u, forward);
    REQUIRE(f.ok());
    CHECK(f.maxError < 1e-5);
    CHECK(f.maxError > central.maxError);  // the first-order scheme is the less accurate one
    // The allocation-free entry point gives the same matrix as the check.
    Data data(model);
    NumDiffWorkspace ws(model);
    Eigen::MatrixXd J;
    REQUIRE(differenceDynamics(model, data, s.q, s.dq, s.u, {}, ws, J).ok());
    CHECK((J - central.differenceJ).cwiseAbs().maxCoeff() == 0.0);
  };
  SECTION("paper pendulum (closed chain)") { check(paperPendulum().model); }
  SECTION("planar skate (knife edge)") { check(planarSkate(0.3).model); }
}

TEST_CASE("numdiff: a check whose dynamics fail is a status naming the path", "[numdiff][status]") {
  // A joint that moves no mass: M is singular at every state.
  ModelBuilder b("massless");
  b.addFrame("cart", "world", Transform::tx("x"), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addFrame("spinner", "cart", Transform::rz("phi"));
  b.addConfigForce("x", "push");
  const Model model = std::move(b).finalize();
  const Eigen::VectorXd z = Eigen::VectorXd::Zero(2), u = Eigen::VectorXd::Zero(1);
  LinearizationCheck c;
  REQUIRE_NOTHROW(c = checkLinearization(model, z, z, u));
  CHECK_FALSE(c.ok());
  CHECK(c.status.code == LinearizationCheckCode::kExactFailed);
  CHECK(c.row == -1);
  CHECK_THAT(c.describe(), Catch::StartsWith("exact_failed: computeLinearization: singular_mass_matrix"));
  CHECK_THAT(c.json(), Catch::Contains("\"status\":\"exact_failed\"") && Catch::Contains("\"ok\":false"));
}
