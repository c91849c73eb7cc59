// tests/core/test_model_builder.cpp — the builder rejects invalid descriptions with a ModelError
// whose message names the offending element (model_builder.hpp, SCENE_FORMAT.md "Errors").
// Whether a check fires in add*() or in finalize() is the builder's choice; each case runs both.
#include <catch2/catch.hpp>

#include <trellis/core.hpp>

#include <pthread.h>

#include <functional>
#include <optional>
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

namespace {

/// Runs f on a thread whose stack is `bytes` long (pthread), so that a recursion per frame shows
/// as a crash here rather than passing on the main thread's 8 MiB.
void runOnSmallStack(std::size_t bytes, const std::function<void()>& f) {
  pthread_attr_t attr;
  REQUIRE(pthread_attr_init(&attr) == 0);
  REQUIRE(pthread_attr_setstacksize(&attr, bytes) == 0);
  pthread_t thread;
  auto body = [](void* arg) -> void* {
    (*static_cast<const std::function<void()>*>(arg))();
    return nullptr;
  };
  REQUIRE(pthread_create(&thread, &attr, body, const_cast<std::function<void()>*>(&f)) == 0);
  REQUIRE(pthread_join(thread, nullptr) == 0);
  pthread_attr_destroy(&attr);
}

}  // namespace

TEST_CASE("Model builder: a chain at the 20,000-frame limit builds on a 512 KiB stack",
          "[model][builder][limits]") {
  // Issue 24: the builder walked the frame tree recursively and overflowed small stacks (Python
  // threads, ASan) on a 19,999-frame chain. 20 joints (rz every 1000 frames) and 19,980 constant
  // links of 1 mm, 1 kg at the end of each link: folded to 20 joints, the tip hangs 19.98 m below
  // the origin at q = 0.
  const int nf = ModelBuilder::kMaxFrames;
  std::string error;
  int nq = -1, nframes = -1;
  double tipY = 0.0;
  bool ok = false;
  std::vector<int> parents;
  runOnSmallStack(512 * 1024, [&] {
    try {
      ModelBuilder b;
      std::string parent = "world";
      for (int k = 0; k < nf; ++k) {
        const std::string name = "f" + std::to_string(k);
        const Transform t = k % 1000 == 0 ? Transform::rz("q" + std::to_string(k / 1000)) : Transform::ty(-1e-3);
        // 1 kg at the end of every 1000-frame link (the last frame before the next joint).
        const bool linkEnd = k % 1000 == 999;
        b.addFrame(name, parent, t, linkEnd ? std::optional<Mass>(Mass{1.0, Eigen::Matrix3d::Identity()}) : std::nullopt);
        parent = name;
      }
      b.addGravity({0.0, -9.81, 0.0});
      const Model model = std::move(b).finalize();
      nq = model.nq();
      nframes = model.nframes();
      parents = model.topology().parent;
      Data data(model);
      const Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq());
      ok = computeDynamics(model, data, q, q, Eigen::VectorXd::Zero(model.nu())).ok();
      computeKinematics(model, data, q, q);
      tipY = data.framePose[static_cast<size_t>(model.frameIndex("f" + std::to_string(nf - 1)))].translation().y();
    } catch (const std::exception& e) {
      error = e.what();
    }
  });
  REQUIRE(error.empty());
  CHECK(nframes == nf);
  REQUIRE(nq == 20);
  for (int i = 0; i < nq; ++i) CHECK(parents[static_cast<size_t>(i)] == i - 1);
  CHECK(ok);
  // 19,980 additions of 1e-3: rounding below 1e-12 relative per step.
  CHECK(tipY == Approx(-19.98).epsilon(1e-10));
}

TEST_CASE("Model builder: the topology is computed once, at finalize", "[model][builder][topology]") {
  // Two trees: a (b (c), d) and e (f). Pre-order: a=0 b=1 c=2 d=3 e=4 f=5.
  ModelBuilder b;
  const Mass unit{1.0, Eigen::Matrix3d::Identity()};
  b.addFrame("a", "world", Transform::rz("a"), unit);
  b.addFrame("b", "a", Transform::rx("b"), unit);
  b.addFrame("c", "b", Transform::ry("c"), unit);
  b.addFrame("d", "a", Transform::tx("d"), unit);
  b.addFrame("e", "world", Transform::rz("e"), unit);
  b.addFrame("f", "e", Transform::rz("f"), unit);
  b.addFrame("tip_d", "d", Transform::tx(0.5));
  b.addFrame("tip_f", "f", Transform::tx(0.5));
  b.addPointConstraint("tip_d", "world", 0);  // touches the first tree only
  b.addPointConstraint("tip_f", "world", 1);  // the second only
  b.addConfigForce("c", "uc");
  b.addTendon({"tip_d", "tip_f"}, "ut");
  const Model model = std::move(b).finalize();
  const ModelTopology& t = model.topology();
  CHECK(t.parent == std::vector<int>{kWorld, 0, 1, 0, kWorld, 4});
  CHECK(t.runStart == std::vector<int>{0, 0, 0, 3, 4, 4});
  CHECK(t.treeRoot == std::vector<int>{0, 0, 0, 0, 4, 4});
  CHECK(t.blockStart == std::vector<int>{0, 4, 6});
  CHECK(t.rowLo == std::vector<int>{0, 4});
  CHECK(t.rowHi == std::vector<int>{4, 6});
  CHECK(t.rowGroupStart == std::vector<int>{0, 1, 2});
  CHECK(t.unitInputConfig == std::vector<int>{2, -1});  // uc acts on c alone; the tendon does not
  CHECK(t.tendonFirst == std::vector<int>{0, 2});
  CHECK(t.tendonPointJoint == std::vector<int>{3, 5});
  CHECK(t.tendonSegmentPoint == std::vector<int>{0});
  for (int i = 0; i < model.nq(); ++i) CHECK(t.parent[static_cast<size_t>(i)] == model.joints()[static_cast<size_t>(i)].parent);
}
