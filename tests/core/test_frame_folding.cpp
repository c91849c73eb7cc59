// tests/core/test_frame_folding.cpp — chains of constant transforms are folded when a model is
// finalized (model.hpp). Folding must not change anything observable: a model with a long chain of
// constant frames behaves exactly like one where the chain is pre-multiplied, by this test, into
// single const_se3 placements.
//
// Tolerance: 1e-12 relative to max(1, largest entry). The two models compute the same quantities
// from constant placements that differ only by the rounding of a product of eight 4×4 matrices
// (~1e-15 relative), propagated through a few hundred operations.
#include <catch2/catch.hpp>

#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"

#include <trellis/core.hpp>

#include <Eigen/Geometry>

#include <vector>

using namespace trellis;
using namespace trellis::test;

namespace {

constexpr double kFoldTolerance = 1e-12;

Eigen::Matrix4d translation(const Eigen::Vector3d& p) {
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  g.topRightCorner<3, 1>() = p;
  return g;
}
Eigen::Matrix4d rotation(double angle, const Eigen::Vector3d& axis) {
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  g.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
  return g;
}

/// The constant chain k1 … k8 between joint j1 and joint j2, as (frame, transform, its matrix).
struct Link {
  const char* name;
  Transform transform;
  Eigen::Matrix4d matrix;
};

std::vector<Link> chain() {
  const Eigen::Matrix4d se3 =
      translation({0.05, -0.1, 0.2}) * rotation(0.8, Eigen::Vector3d(1, 2, 3).normalized());
  // The spec's primitive matrices: tx/ty/tz translate along the parent's axis, rx/ry/rz rotate
  // right-handedly about it (SCENE_FORMAT.md), i.e. AngleAxis about the unit axis.
  return {
      {"k1", Transform::tx(0.3), translation({0.3, 0, 0})},
      {"k2", Transform::rx(0.4), rotation(0.4, Eigen::Vector3d::UnitX())},
      {"k3", Transform::constSE3(se3), se3},
      {"k4", Transform::tz(-0.2), translation({0, 0, -0.2})},
      {"k5", Transform::ry(-0.7), rotation(-0.7, Eigen::Vector3d::UnitY())},
      {"k6", Transform::ty(0.25), translation({0, 0.25, 0})},
      {"k7", Transform::rz(1.1), rotation(1.1, Eigen::Vector3d::UnitZ())},
      {"k8", Transform::tx(-0.15), translation({-0.15, 0, 0})},
  };
}

/// Frames that carry something (a mass, a spring end, a constraint, a wrench) in the chain.
const std::vector<const char*> kLoaded = {"k3", "k4", "k6", "k8"};

struct Pair {
  Model chained, folded;
};

Pair build(bool withConstraint) {
  std::mt19937 rng(5101);
  const Mass m1{0.9, randomInertia(rng)}, m3{0.4, randomInertia(rng)}, m6{0.3, randomInertia(rng)},
      mEnd{0.5, randomInertia(rng)};
  const std::vector<Link> links = chain();
  const auto common = [&](ModelBuilder& b) {
    b.addGravity(Eigen::Vector3d(0.3, -9.8, 0.6));
    b.addLinearSpring("k4", "w", 2.0, 0.1);
    b.addBodyWrench("k8", {WrenchEntry{std::string("f")}, WrenchEntry{0.1}, WrenchEntry{0.0},
                           WrenchEntry{0.0}, WrenchEntry{0.2}, WrenchEntry{std::string("t")}});
    b.addTendon({"w", "k6", "end"}, "pull");
    b.addConfigForce("a", "ua");
    if (withConstraint) b.addDistanceConstraint("end", "w", 1.1);
  };

  ModelBuilder chained;
  chained.addFrame("j1", "world", Transform::rz("a"), m1);
  std::string parent = "j1";
  for (const Link& l : links) {
    std::optional<Mass> m;
    if (std::string(l.name) == "k3") m = m3;
    if (std::string(l.name) == "k6") m = m6;
    chained.addFrame(l.name, parent, l.transform, m);
    parent = l.name;
  }
  chained.addFrame("j2", parent, Transform::ry("b"));
  chained.addFrame("end", "j2", Transform::tz(0.5), mEnd);
  chained.addFrame("w", "world", Transform::tx(0.7));
  common(chained);

  // Folded: every loaded frame hangs directly from j1 with the product of the chain up to it, and
  // j2 hangs from the product of the whole chain.
  ModelBuilder folded;
  folded.addFrame("j1", "world", Transform::rz("a"), m1);
  Eigen::Matrix4d product = Eigen::Matrix4d::Identity();
  for (const Link& l : links) {
    product = product * l.matrix;
    for (const char* loaded : kLoaded) {
      if (std::string(l.name) != loaded) continue;
      std::optional<Mass> m;
      if (std::string(l.name) == "k3") m = m3;
      if (std::string(l.name) == "k6") m = m6;
      folded.addFrame(l.name, "j1", Transform::constSE3(product), m);
    }
  }
  folded.addFrame("fold", "j1", Transform::constSE3(product));
  folded.addFrame("j2", "fold", Transform::ry("b"));
  folded.addFrame("end", "j2", Transform::tz(0.5), mEnd);
  folded.addFrame("w", "world", Transform::tx(0.7));
  common(folded);
  return Pair{std::move(chained).finalize(), std::move(folded).finalize()};
}

void compareAt(const Pair& p, const State& s) {
  Data dc(p.chained), df(p.folded);
  const DynamicsStatus sc = computeLinearization(p.chained, dc, s.q, s.dq, s.u);
  const DynamicsStatus sf = computeLinearization(p.folded, df, s.q, s.dq, s.u);
  INFO(sc.message << " / " << sf.message);
  REQUIRE(sc.ok());
  REQUIRE(sf.ok());
  TRELLIS_CHECK_MATRIX(df.M, dc.M, kFoldTolerance, Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(df.qdd), Eigen::MatrixXd(dc.qdd), kFoldTolerance,
                       Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(df.lambda), Eigen::MatrixXd(dc.lambda), kFoldTolerance,
                       Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(df.A, dc.A, kFoldTolerance, Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(df.B, dc.B, kFoldTolerance, Scale::kMatrix);
  // Poses and body velocities of the frames both models have.
  computeKinematics(p.chained, dc, s.q, s.dq);
  computeKinematics(p.folded, df, s.q, s.dq);
  for (const char* name : {"k3", "k4", "k6", "k8", "end"}) {
    INFO("frame " << name);
    const auto ic = static_cast<std::size_t>(p.chained.frameIndex(name));
    const auto jf = static_cast<std::size_t>(p.folded.frameIndex(name));
    TRELLIS_CHECK_MATRIX(df.framePose[jf].matrix(), dc.framePose[ic].matrix(), kFoldTolerance,
                         Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(df.frameVelocity[jf]),
                         Eigen::MatrixXd(dc.frameVelocity[ic]), kFoldTolerance, Scale::kMatrix);
  }
}

}  // namespace

TEST_CASE("Frame-tree folding: a chain of constant transforms equals its product",
          "[model][folding]") {
  SECTION("unconstrained") {
    const Pair p = build(false);
    REQUIRE(p.chained.nq() == 2);
    REQUIRE(p.folded.nq() == 2);
    // Folding leaves one joint per configuration variable, whatever the number of frames.
    CHECK(p.chained.joints().size() == p.folded.joints().size());
    std::mt19937 rng(5102);
    for (int k = 0; k < 3; ++k) compareAt(p, randomState(p.chained, rng));
  }
  SECTION("with a constraint") {
    const Pair p = build(true);
    std::mt19937 rng(5103);
    for (int k = 0; k < 3; ++k) compareAt(p, randomState(p.chained, rng));
  }
}
