// tests/core/test_degenerate_constraints.cpp — a constraint row whose gradient vanishes (or that
// depends on the other rows) is reported by name, row and state, never an ok status; the test is
// relative to the row's natural scale, so it does not depend on the units of the model.
#include <catch2/catch.hpp>

#include "support/test_models.hpp"

#include <trellis/core.hpp>

#include <cmath>
#include <filesystem>
#include <string>

using namespace trellis;
using namespace trellis::test;
using Catch::Matchers::Contains;

namespace {

/// Two pendulums of length s on one pivot, their tips joined by a distance constraint of length
/// s/2 (lengths scaled by s). With θ1 = θ2 the tips coincide: h = −ℓ² ≠ 0 and ∂h/∂q = 0.
Model twoTips(double s) {
  ModelBuilder b;
  b.addFrame("L1", "world", Transform::rz("theta1"));
  b.addFrame("T1", "L1", Transform::ty(-s), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addFrame("L2", "world", Transform::rz("theta2"));
  b.addFrame("T2", "L2", Transform::ty(-s), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
  b.addConfigForce("theta1", "u");
  b.addDistanceConstraint("T1", "T2", 0.5 * s);
  return std::move(b).finalize();
}

/// `rowHolds`: the degenerate row is exactly zero and holds (h = 0, Ȧ q̇ = 0), so it constrains nothing
/// and the message says so without the state; otherwise the message names the state.
void expectDegenerate(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                      const std::string& constraintName, bool rowHolds = false) {
  Data data(model);
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(model.nu());
  for (int pass = 0; pass < 2; ++pass) {
    const DynamicsStatus st = pass == 0 ? computeDynamics(model, data, q, dq, u)
                                        : computeLinearization(model, data, q, dq, u);
    INFO("pass " << pass << ": code " << static_cast<int>(st.code) << ": " << st.message);
    CHECK_FALSE(st.ok());
    CHECK(st.code == DynamicsStatus::Code::kSingularConstraints);
    CHECK_THAT(st.message, Contains("degenerate constraint row 0"));
    CHECK_THAT(st.message, Contains(constraintName));
    if (rowHolds) {
      CHECK_THAT(st.message, Contains("the row holds"));
    } else {
      CHECK_THAT(st.message, Contains("q = (" + model.configNames()[0] + "="));
    }
    CHECK(st.constraintConditioning < 1e-5);
    // Not ok, but finite: the row is dropped, not turned into λ = ±1e16.
    CHECK(data.qdd.allFinite());
    CHECK(data.lambda.allFinite());
  }
}

}  // namespace

TEST_CASE("Degenerate rows: a distance constraint whose points coincide", "[degenerate]") {
  for (double s : {1e-3, 1.0, 1e3}) {
    INFO("length scale " << s);
    const Model model = twoTips(s);
    const std::string name = model.constraints()[0].name;
    SECTION("coincident, s = " + std::to_string(s)) {
      expectDegenerate(model, Eigen::Vector2d(0.3, 0.3), Eigen::Vector2d(0.5, -0.2), name);
    }
    SECTION("1e-9 apart (relative to the length), s = " + std::to_string(s)) {
      // ‖∇h‖ is 1e-9 of its natural size 2ℓ: the old test, relative to ‖∇h‖ itself, called this ok
      // with λ ~ 1e9 times too large.
      expectDegenerate(model, Eigen::Vector2d(0.3, 0.3 + 1e-9), Eigen::Vector2d(0.5, -0.2), name);
    }
    SECTION("regular configuration: ok, and the conditioning does not depend on the units, s = " +
            std::to_string(s)) {
      // θ2 − θ1 = 2 asin(1/4): the tips are ℓ = s/2 apart, the constraint holds.
      const double gap = 2.0 * std::asin(0.25);
      const Eigen::Vector2d q(0.3, 0.3 + gap), dq(0.5, 0.5);
      Data data(model);
      const DynamicsStatus st = computeLinearization(model, data, q, dq, Eigen::VectorXd::Zero(1));
      INFO(st.message);
      CHECK(st.ok());
      const Model unitModel = twoTips(1.0);
      Data d1(unitModel);
      REQUIRE(computeDynamics(unitModel, d1, q, dq, Eigen::VectorXd::Zero(1)).ok());
      CHECK(std::abs(st.constraintConditioning - d1.status.constraintConditioning) <= 1e-12);
      CHECK(st.constraintConditioning > 0.1);
    }
  }
}

TEST_CASE("Degenerate rows: a row no motion can change", "[degenerate]") {
  SECTION("point constraint along z on a planar pendulum") {
    ModelBuilder b;
    b.addFrame("L", "world", Transform::rz("theta"));
    b.addFrame("T", "L", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
    b.addFrame("P", "world", Transform::ty(-1.0));
    b.addPointConstraint("T", "P", 2);  // z: holds everywhere, its row is identically zero
    const Model model = std::move(b).finalize();
    expectDegenerate(model, Eigen::VectorXd::Constant(1, 0.4), Eigen::VectorXd::Constant(1, 0.1),
                     model.constraints()[0].name, /*rowHolds=*/true);
  }
  SECTION("knife edge at the rotation axis (its point cannot move)") {
    ModelBuilder b;
    b.addFrame("sx", "world", Transform::tx("x"));
    b.addFrame("body", "sx", Transform::rz("phi"), Mass{1.0, Eigen::Matrix3d::Identity() * 0.1});
    b.addFrame("blade", "body", Transform::tx(0.0));
    b.addKnifeEdgeConstraint("blade", Eigen::Vector3d::UnitY());
    b.addConfigForce("x", "u");
    const Model model = std::move(b).finalize();
    // ṗ = (ẋ, 0, 0) and e = R_z(φ) e_y: at φ = 0 the row (e·∂ṗ/∂q̇) = (0, 0) vanishes.
    expectDegenerate(model, Eigen::Vector2d(0.2, 0.0), Eigen::Vector2d(0.3, 0.1), model.constraints()[0].name);
    // At φ = 0.7 it is regular.
    Data data(model);
    const DynamicsStatus st = computeDynamics(model, data, Eigen::Vector2d(0.2, 0.7), Eigen::Vector2d(0.3, 0.0),
                                              Eigen::VectorXd::Zero(1));
    INFO(st.message);
    CHECK(st.ok());
  }
}

TEST_CASE("Degenerate rows: two identical constraints are redundant, not ok", "[degenerate][redundant]") {
  const Model once = paperPendulum(1).model, twice = paperPendulum(2).model;
  const Eigen::Vector2d q(0.5, 1.0), dq(0.5, -1.0);
  const Eigen::VectorXd u = Eigen::VectorXd::Constant(1, 2.0);
  Data d1(once), d2(twice);
  REQUIRE(computeDynamics(once, d1, q, dq, u).ok());
  const DynamicsStatus st = computeDynamics(twice, d2, q, dq, u);
  INFO(st.message);
  CHECK_FALSE(st.ok());
  CHECK(st.code == DynamicsStatus::Code::kRedundantConstraints);
  CHECK(st.constraintRank == 1);
  // Which of the two copies is named depends on the pivoting; one of them is.
  CHECK_THAT(st.message, Contains("depends on the others"));
  CHECK_THAT(st.message, Contains(twice.constraints()[0].name) || Contains(twice.constraints()[1].name));
  CHECK_THAT(st.message, Contains("theta1="));
  // q̈ is still computed (and the same as with one copy).
  CHECK((d1.qdd - d2.qdd).cwiseAbs().maxCoeff() <= 1e-10 * std::max(1.0, d1.qdd.cwiseAbs().maxCoeff()));
}

TEST_CASE("Degenerate rows: every example scene stays ok at its stored state", "[degenerate][scenes]") {
  int checked = 0;
  for (const auto& entry : std::filesystem::directory_iterator(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes")) {
    if (entry.path().extension() != ".json") continue;
    const Scene scene = loadScene(entry.path().string());
    Data data(scene.model);
    const DynamicsStatus st = computeLinearization(scene.model, data, scene.q, scene.dq, scene.u);
    INFO(entry.path().filename().string() << ": " << st.message);
    CHECK(st.ok());
    ++checked;
  }
  CHECK(checked >= 6);
}

TEST_CASE("ModelBuilder: the size limits of scene files, checked in finalize", "[model_builder][limits]") {
  using Catch::Matchers::Contains;
  SECTION("configuration variables") {
    ModelBuilder b("long chain");
    std::string parent = "world";
    for (int i = 0; i <= ModelBuilder::kMaxConfigs; ++i) {  // one more than the limit
      const std::string name = "l" + std::to_string(i);
      b.addFrame(name, parent, Transform::rz("q" + std::to_string(i)), Mass{1.0, Eigen::Matrix3d::Identity()});
      parent = name;
    }
    try {
      (void)std::move(b).finalize();
      FAIL("finalize accepted " << ModelBuilder::kMaxConfigs + 1 << " configuration variables");
    } catch (const ModelError& e) {
      CHECK_THAT(e.what(), Contains("1001 configuration variables") && Contains("limit of 1000") &&
                               Contains("long chain"));
    }
  }
  SECTION("at the limit it builds") {
    ModelBuilder b;
    std::string parent = "world";
    for (int i = 0; i < ModelBuilder::kMaxConfigs; ++i) {
      const std::string name = "l" + std::to_string(i);
      b.addFrame(name, parent, Transform::rz("q" + std::to_string(i)), Mass{1.0, Eigen::Matrix3d::Identity()});
      parent = name;
    }
    CHECK(std::move(b).finalize().nq() == ModelBuilder::kMaxConfigs);
  }
  SECTION("frames") {
    ModelBuilder b;
    for (int i = 0; i <= ModelBuilder::kMaxFrames; ++i) b.addFrame("f" + std::to_string(i), "world", Transform::tx(0.1 * i));
    try {
      (void)std::move(b).finalize();
      FAIL("finalize accepted " << ModelBuilder::kMaxFrames + 1 << " frames");
    } catch (const ModelError& e) {
      CHECK_THAT(e.what(), Contains("20001 frames") && Contains("limit of 20000"));
    }
  }
}

namespace {

/// A planar chain of `links` rz joints in gravity −y, its tip held on a world point by the rows
/// x, y and, with `zRow`, also z (which holds everywhere: its row of A is identically zero).
Model pinnedPlanarChain(int links, bool zRow, double anchorZ = 0.0) {
  ModelBuilder b;
  std::string parent = "world";
  for (int k = 0; k < links; ++k) {
    const std::string index = std::to_string(k);
    b.addFrame(std::string("j").append(index), parent, Transform::rz(std::string("q").append(index)));
    parent = std::string("b").append(index);
    b.addFrame(parent, std::string("j").append(index), Transform::ty(-0.3),
               Mass{0.5, Eigen::Vector3d(1e-3, 1e-3, 2e-3).asDiagonal()});
    b.addConfigForce(std::string("q").append(index), std::string("u").append(index));
  }
  b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
  // The tip at q = (0.4, −0.3, 0.4, …) (its y sums the links' −0.3 cos of the running angle).
  double angle = 0.0, x = 0.0, y = 0.0;
  for (int k = 0; k < links; ++k) {
    angle += k % 2 == 0 ? 0.4 : -0.3;
    x += 0.3 * std::sin(angle);
    y -= 0.3 * std::cos(angle);
  }
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  g(0, 3) = x;
  g(1, 3) = y;
  g(2, 3) = anchorZ;  // ≠ 0: the z row cannot hold (h_z = −anchorZ at every state)
  b.addFrame("anchor", "world", Transform::constSE3(g));
  for (int axis = 0; axis < (zRow ? 3 : 2); ++axis) b.addPointConstraint(parent, "anchor", axis);
  return std::move(b).finalize();
}

}  // namespace

// The z row of a point on a planar chain is zero at every state: it is reported (a degenerate
// row, never ok) and dropped — q̈, A, B and the x, y rows of λ and ∂λ/∂x are those of the model
// without the row (to rounding), its λ and ∂λ/∂x are 0 (the minimum-norm choice), and the rank
// is 2. On the tree factor (5 joints) and the articulated one (12 joints).
TEST_CASE("Degenerate rows: a zero row is dropped, the rest is the model without it", "[degenerate][redundant]") {
  for (const int links : {5, 12}) {
    INFO(links << " links");
    const Model with = pinnedPlanarChain(links, true), without = pinnedPlanarChain(links, false);
    const int n = with.nq();
    Eigen::VectorXd q(n), dq(n), u(n);
    for (int k = 0; k < n; ++k) {
      q[k] = k % 2 == 0 ? 0.4 : -0.3;
      u[k] = 0.1 * std::sin(1.0 + k);
    }
    q[0] = 0.4;
    // A velocity along the constraint manifold: the tip still, from a null vector of the x, y rows.
    Data dw(without), d3(with);
    computeConstraints(without, dw, q, Eigen::VectorXd::Zero(n));
    const Eigen::MatrixXd J = dw.constraintJacobian;
    const Eigen::MatrixXd nullBasis = Eigen::FullPivLU<Eigen::MatrixXd>(J).kernel();
    dq = nullBasis * Eigen::VectorXd::LinSpaced(nullBasis.cols(), 0.5, -0.5);
    REQUIRE(computeLinearization(without, dw, q, dq, u).ok());
    const DynamicsStatus st = computeLinearization(with, d3, q, dq, u);
    INFO(st.message);
    CHECK(st.code == DynamicsStatus::Code::kSingularConstraints);
    CHECK_THAT(st.message, Contains("degenerate constraint row 2"));
    CHECK(st.constraintRank == 2);
    const auto close = [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
      return (a - b).cwiseAbs().maxCoeff() <= 1e-12 * std::max(1.0, b.cwiseAbs().maxCoeff());
    };
    CHECK(close(d3.qdd, dw.qdd));
    CHECK(close(d3.A, dw.A));
    CHECK(close(d3.B, dw.B));
    CHECK(close(d3.lambda.head(2), dw.lambda));
    CHECK(close(d3.dlambda_dx.topRows(2), dw.dlambda_dx));
    CHECK(d3.lambda[2] == 0.0);
    CHECK(d3.dlambda_dx.row(2).cwiseAbs().maxCoeff() == 0.0);
    // The row holds (h_z = 0, Ȧ_z q̇ = 0): its report is the same at every state, without the state
    // (formatted once, copied afterwards), through forward dynamics as through the linearization.
    CHECK_THAT(st.message, Contains("the row holds"));
    CHECK_THAT(st.message, !Contains("q = ("));
    const Eigen::VectorXd q2 = q.array() + 0.1, dq2 = -dq;
    const DynamicsStatus again = computeDynamics(with, d3, q2, dq2, u);
    CHECK(again.code == DynamicsStatus::Code::kSingularConstraints);
    CHECK(again.message == st.message);
  }
}

// The same zero row where it cannot hold (the anchor off the chain's plane: h_z ≠ 0): reported
// with the state, not as a row that constrains nothing.
TEST_CASE("Degenerate rows: a zero row that does not hold is reported with the state", "[degenerate]") {
  const Model off = pinnedPlanarChain(5, true, 0.01);
  const int n = off.nq();
  Data data(off);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(n, 0.2), dq = Eigen::VectorXd::Zero(n),
                        u = Eigen::VectorXd::Zero(n);
  for (int pass = 0; pass < 2; ++pass) {
    const DynamicsStatus st = pass == 0 ? computeDynamics(off, data, q, dq, u) : computeLinearization(off, data, q, dq, u);
    INFO(st.message);
    CHECK(st.code == DynamicsStatus::Code::kSingularConstraints);
    CHECK_THAT(st.message, Contains("degenerate constraint row 2"));
    CHECK_THAT(st.message, !Contains("the row holds"));
    CHECK_THAT(st.message, Contains("q = (q0="));
  }
}
