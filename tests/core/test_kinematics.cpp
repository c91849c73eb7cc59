// tests/core/test_kinematics.cpp — frame poses follow SCENE_FORMAT.md's conventions exactly:
// g_world,k = g_world,parent · g_local; tx/ty/tz translate along the parent's axis; rx/ry/rz rotate
// right-handedly, rz(t) = [[c, −s, 0], [s, c, 0], [0, 0, 1]], rx(t) = [[1, 0, 0], [0, c, −s],
// [0, s, c]], ry(t) = [[c, 0, s], [0, 1, 0], [−s, 0, c]]; const_se3 is the given matrix.
// (The derivative tests only check self-consistency; these pin the conventions.)
//
// Tolerance: 1e-14 absolute on entries of size ≤ 2 — a handful of rounded products.
#include <catch2/catch.hpp>

#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>

#include <cmath>

using namespace trellis;
using namespace trellis::test;

namespace {

constexpr double kPoseTolerance = 1e-14;

/// The spec's matrix of a primitive transform with parameter t.
Eigen::Matrix4d specMatrix(TransformType type, double t) {
  const double c = std::cos(t), s = std::sin(t);
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  switch (type) {
    case TransformType::kTx:
      g(0, 3) = t;
      break;
    case TransformType::kTy:
      g(1, 3) = t;
      break;
    case TransformType::kTz:
      g(2, 3) = t;
      break;
    case TransformType::kRx:
      g.block<3, 3>(0, 0) << 1, 0, 0, 0, c, -s, 0, s, c;
      break;
    case TransformType::kRy:
      g.block<3, 3>(0, 0) << c, 0, s, 0, 1, 0, -s, 0, c;
      break;
    case TransformType::kRz:
      g.block<3, 3>(0, 0) << c, -s, 0, s, c, 0, 0, 0, 1;
      break;
    case TransformType::kConstSE3:
    case TransformType::kRotAxis:  // not primitives of the spec (test_axis_transforms.cpp)
    case TransformType::kTransAxis:
      break;
  }
  return g;
}

const TransformType kPrimitives[] = {TransformType::kTx, TransformType::kTy, TransformType::kTz,
                                     TransformType::kRx, TransformType::kRy, TransformType::kRz};

}  // namespace

TEST_CASE("Frame poses follow the transform conventions", "[kinematics]") {
  std::mt19937 rng(6101);
  for (TransformType type : kPrimitives) {
    SECTION(
        std::string(transformTypeName(type)).append(": driven and constant, under a const_se3")) {
      // world → base const_se3(G) → driven type(q) → fixed type(0.37) → leaf tx(0.2), mass on leaf
      const Eigen::Matrix4d G = randomSE3(rng);
      ModelBuilder b;
      b.addFrame("base", "world", Transform::constSE3(G));
      b.addFrame("driven", "base", drivenTransform(type, "q"));
      b.addFrame("fixed", "driven", constantTransform(type, 0.37, Eigen::Matrix4d::Identity()));
      b.addFrame("leaf", "fixed", Transform::tx(0.2), Mass{1.0, Eigen::Matrix3d::Identity()});
      const Model model = std::move(b).finalize();
      Data data(model);
      for (double q : {0.0, 0.7, -2.1}) {
        computeKinematics(model, data, Eigen::VectorXd::Constant(1, q), Eigen::VectorXd::Zero(1));
        const Eigen::Matrix4d base = G, driven = base * specMatrix(type, q),
                              fixed = driven * specMatrix(type, 0.37),
                              leaf = fixed * specMatrix(TransformType::kTx, 0.2);
        INFO("q = " << q);
        TRELLIS_CHECK_MATRIX(base, data.framePose[model.frameIndex("base")].matrix(),
                             kPoseTolerance, Scale::kAbsolute);
        TRELLIS_CHECK_MATRIX(driven, data.framePose[model.frameIndex("driven")].matrix(),
                             kPoseTolerance, Scale::kAbsolute);
        TRELLIS_CHECK_MATRIX(fixed, data.framePose[model.frameIndex("fixed")].matrix(),
                             kPoseTolerance, Scale::kAbsolute);
        TRELLIS_CHECK_MATRIX(leaf, data.framePose[model.frameIndex("leaf")].matrix(),
                             kPoseTolerance, Scale::kAbsolute);
      }
    }
  }
}

TEST_CASE("Body velocity of a driven frame is its joint's unit twist times the rate",
          "[kinematics]") {
  // A frame driven directly by q under the world: body velocity [v_b; ω_b] = q̇·(e_axis; 0) for a
  // translation, q̇·(0; e_axis) for a rotation (the frame's own axis equals the parent's axis).
  for (TransformType type : kPrimitives) {
    SECTION(transformTypeName(type)) {
      ModelBuilder b;
      b.addFrame("driven", "world", drivenTransform(type, "q"),
                 Mass{1.0, Eigen::Matrix3d::Identity()});
      const Model model = std::move(b).finalize();
      Data data(model);
      computeKinematics(model, data, Eigen::VectorXd::Constant(1, 0.4),
                        Eigen::VectorXd::Constant(1, 1.5));
      const int axis = static_cast<int>(type) % 3;
      const bool rotation = static_cast<int>(type) >= 3;
      Eigen::Matrix<double, 6, 1> expected = Eigen::Matrix<double, 6, 1>::Zero();
      expected[(rotation ? 3 : 0) + axis] = 1.5;
      TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(expected),
                           Eigen::MatrixXd(data.frameVelocity[model.frameIndex("driven")]),
                           kPoseTolerance, Scale::kAbsolute);
    }
  }
}

TEST_CASE("Model layout: configuration and input order", "[model]") {
  // SCENE_FORMAT.md: configurations in pre-order of the frame tree (children in the order added),
  // inputs in order of first appearance (inside a body wrench, its entries in order).
  ModelBuilder b;
  b.addFrame("a", "world", Transform::rz("qa"));
  b.addFrame("b", "world", Transform::tx("qb"));
  b.addFrame("a1", "a", Transform::ry("qa1"));
  b.addFrame("a2", "a", Transform::rx("qa2"), Mass{1.0, Eigen::Matrix3d::Identity()});
  b.addFrame("a11", "a1", Transform::tz("qa11"), Mass{1.0, Eigen::Matrix3d::Identity()});
  b.addFrame("b1", "b", Transform::ty("qb1"), Mass{1.0, Eigen::Matrix3d::Identity()});
  b.addConfigForce("qb", "second");
  b.addBodyWrench("a2", {WrenchEntry{0.0}, WrenchEntry{std::string("third")}, WrenchEntry{0.0},
                         WrenchEntry{std::string("second")}, WrenchEntry{std::string("fourth")},
                         WrenchEntry{1.0}});
  b.addTendon({"a11", "b1"}, "fifth");
  b.addConfigForce("qa", "sixth");
  const Model model = std::move(b).finalize();
  CHECK(model.configNames() == std::vector<std::string>{"qa", "qa1", "qa11", "qa2", "qb", "qb1"});
  CHECK(model.inputNames() ==
        std::vector<std::string>{"second", "third", "fourth", "fifth", "sixth"});
}
