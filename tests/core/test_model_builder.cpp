// tests/core/test_model_builder.cpp — the builder rejects invalid descriptions with a ModelError
// whose message names the offending element (model_builder.hpp, SCENE_FORMAT.md "Errors").
// Whether a check fires in add*() or in finalize() is the builder's choice; each case runs both.
#include <catch2/catch.hpp>

#include <trellis/core.hpp>

#include <functional>
#include <limits>
#include <string>

using namespace trellis;

namespace {

/// Runs `describe` on a fresh builder with a valid two-frame base, then finalizes; returns the
/// ModelError message, or "" if nothing was thrown.
std::string errorOf(const std::function<void(ModelBuilder&)>& describe) {
  try {
    ModelBuilder b;
    b.addFrame("link", "world", Transform::rz("theta"), Mass{1.0, Eigen::Matrix3d::Identity()});
    b.addFrame("tip", "link", Transform::ty(-1.0), Mass{0.5, Eigen::Matrix3d::Zero()});
    describe(b);
    (void)std::move(b).finalize();
  } catch (const ModelError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("Model builder: a valid description builds", "[model][builder]") {
  CHECK(errorOf([](ModelBuilder&) {}).empty());
}

TEST_CASE("Model builder: invalid descriptions throw ModelError naming the offender",
          "[model][builder]") {
  using Catch::Matchers::Contains;
  SECTION("negative mass") {
    const std::string msg = errorOf([](ModelBuilder& b) {
      b.addFrame("bob", "tip", Transform::tx(0.1), Mass{-1.0, Eigen::Matrix3d::Zero()});
    });
    CHECK_THAT(msg, Contains("bob"));
  }
  SECTION("inertia tensor not positive semidefinite") {
    Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
    I(0, 0) = -0.5;
    const std::string msg = errorOf([&](ModelBuilder& b) {
      b.addFrame("bob", "tip", Transform::tx(0.1), Mass{1.0, I});
    });
    CHECK_THAT(msg, Contains("bob"));
  }
  SECTION("inertia tensor not symmetric") {
    Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
    I(0, 1) = 0.3;
    const std::string msg = errorOf([&](ModelBuilder& b) {
      b.addFrame("bob", "tip", Transform::tx(0.1), Mass{1.0, I});
    });
    CHECK_THAT(msg, Contains("bob"));
  }
  SECTION("duplicate frame name") {
    const std::string msg =
        errorOf([](ModelBuilder& b) { b.addFrame("tip", "link", Transform::tx(0.1)); });
    CHECK_THAT(msg, Contains("tip"));
  }
  SECTION("reserved name world") {
    const std::string msg =
        errorOf([](ModelBuilder& b) { b.addFrame("world", "link", Transform::tx(0.1)); });
    CHECK_THAT(msg, Contains("world"));
  }
  SECTION("unknown parent") {
    const std::string msg =
        errorOf([](ModelBuilder& b) { b.addFrame("bob", "nowhere", Transform::tx(0.1)); });
    CHECK_THAT(msg, Contains("nowhere"));
  }
  SECTION("configuration name used twice") {
    const std::string msg =
        errorOf([](ModelBuilder& b) { b.addFrame("bob", "tip", Transform::rx("theta")); });
    CHECK_THAT(msg, Contains("theta"));
  }
  SECTION("const_se3 whose rotation is not orthonormal") {
    Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
    g(0, 0) = 2.0;
    const std::string msg =
        errorOf([&](ModelBuilder& b) { b.addFrame("bob", "tip", Transform::constSE3(g)); });
    CHECK_THAT(msg, Contains("bob"));
  }
  SECTION("non-finite constant") {
    const std::string msg = errorOf([](ModelBuilder& b) {
      b.addFrame("bob", "tip", Transform::tx(std::numeric_limits<double>::quiet_NaN()));
    });
    CHECK_THAT(msg, Contains("bob"));
  }
  SECTION("constraint naming a missing frame") {
    const std::string msg =
        errorOf([](ModelBuilder& b) { b.addDistanceConstraint("tip", "ghost", 1.0); });
    CHECK_THAT(msg, Contains("ghost"));
  }
  SECTION("force naming a missing configuration") {
    const std::string msg = errorOf([](ModelBuilder& b) { b.addConfigForce("phi", "u"); });
    CHECK_THAT(msg, Contains("phi"));
  }
  SECTION("spring naming a missing configuration") {
    const std::string msg = errorOf([](ModelBuilder& b) { b.addConfigSpring("phi", 1.0, 0.0); });
    CHECK_THAT(msg, Contains("phi"));
  }
  SECTION("damping coefficient for a missing configuration") {
    const std::string msg = errorOf([](ModelBuilder& b) { b.addDamping(0.1, {{"phi", 1.0}}); });
    CHECK_THAT(msg, Contains("phi"));
  }
  SECTION("tendon through fewer than two frames") {
    const std::string msg = errorOf([](ModelBuilder& b) { b.addTendon({"tip"}, "pull"); });
    CHECK_FALSE(msg.empty());
  }
  SECTION("tendon through a missing frame") {
    const std::string msg =
        errorOf([](ModelBuilder& b) { b.addTendon({"tip", "ghost", "link"}, "pull"); });
    CHECK_THAT(msg, Contains("ghost"));
  }
  SECTION("body wrench on a missing frame") {
    const std::string msg = errorOf([](ModelBuilder& b) {
      b.addBodyWrench("ghost", {WrenchEntry{0.0}, WrenchEntry{0.0}, WrenchEntry{0.0},
                                WrenchEntry{0.0}, WrenchEntry{0.0}, WrenchEntry{0.0}});
    });
    CHECK_THAT(msg, Contains("ghost"));
  }
}
