// tests/support/test_models.hpp — the systems the tests share, built in C++ with ModelBuilder.
//
// Header-only (inline) so that every test program can use it whatever it links. Every builder is
// deterministic: random parameters (inertias, placements) come from a fixed seed.
#pragma once

#include <trellis/core.hpp>

#include "support/random_state.hpp"

#include <Eigen/Geometry>

#include <cstdint>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace trellis::test {

/// A model plus the masses it was given, for checks that recompute energies from frame data.
struct TestSystem {
  Model model;
  std::vector<std::pair<std::string, Mass>> masses;  ///< frame name → mass as given
};

/// ModelBuilder that also records the masses.
struct SystemBuilder {
  ModelBuilder b;
  std::vector<std::pair<std::string, Mass>> masses;

  void frame(const std::string& name, const std::string& parent, const Transform& t,
             std::optional<Mass> m = {}) {
    b.addFrame(name, parent, t, m);
    if (m) masses.emplace_back(name, *m);
  }
  TestSystem finish() && { return TestSystem{std::move(b).finalize(), std::move(masses)}; }
};

/// The scene-file name of a transform type (the library's table, model.hpp).
inline const char* transformTypeName(TransformType t) { return toString(t); }

/// The tilted unit axis and origin the tests give r_axis / t_axis transforms.
inline Eigen::Vector3d testAxis() { return Eigen::Vector3d(0.3, -0.5, 0.8).normalized(); }
inline Eigen::Matrix4d testAxisOrigin() {
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  g.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.6, Eigen::Vector3d(0.2, 1.0, -0.4).normalized()).toRotationMatrix();
  g.topRightCorner<3, 1>() << 0.1, 0.25, -0.15;
  return g;
}

/// A driven transform of one of the six primitive types.
inline Transform drivenTransform(TransformType t, const std::string& config) {
  switch (t) {
    case TransformType::kTx:
      return Transform::tx(config);
    case TransformType::kTy:
      return Transform::ty(config);
    case TransformType::kTz:
      return Transform::tz(config);
    case TransformType::kRx:
      return Transform::rx(config);
    case TransformType::kRy:
      return Transform::ry(config);
    case TransformType::kRz:
      return Transform::rz(config);
    case TransformType::kRotAxis:
      return Transform::rotAxis(testAxis(), config, testAxisOrigin());
    case TransformType::kTransAxis:
      return Transform::transAxis(testAxis(), config, testAxisOrigin());
    case TransformType::kConstSE3:
      break;
  }
  throw std::logic_error("drivenTransform: const_se3 cannot be driven");
}

/// A constant transform of type t (const_se3: `se3`, the others: `value`).
inline Transform constantTransform(TransformType t, double value, const Eigen::Matrix4d& se3) {
  switch (t) {
    case TransformType::kTx:
      return Transform::tx(value);
    case TransformType::kTy:
      return Transform::ty(value);
    case TransformType::kTz:
      return Transform::tz(value);
    case TransformType::kRx:
      return Transform::rx(value);
    case TransformType::kRy:
      return Transform::ry(value);
    case TransformType::kRz:
      return Transform::rz(value);
    case TransformType::kRotAxis:
      return Transform::rotAxis(testAxis(), value, testAxisOrigin());
    case TransformType::kTransAxis:
      return Transform::transAxis(testAxis(), value, testAxisOrigin());
    case TransformType::kConstSE3:
      return Transform::constSE3(se3);
  }
  return Transform::constSE3(se3);
}

/// A fixed, non-trivial rigid transform: rotation `angle` about `axis`, then translation `p`.
inline Eigen::Matrix4d se3(double angle, const Eigen::Vector3d& axis, const Eigen::Vector3d& p) {
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  g.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  g.topRightCorner<3, 1>() = p;
  return g;
}

/// The paper's example (Sec. IV, tree as in docs/paper_errata.md): world→Link1 rz(θ1)→A ty(−1), mass 1 at A
/// →Link2 rz(θ2)→B ty(−1), mass 1 at B; world→C tx(2); gravity (0, −9.8, 0); torque u on θ1;
/// h = ‖p_B − p_C‖² − 1, added `distanceCopies` times (0: unconstrained double pendulum).
inline TestSystem paperPendulum(int distanceCopies = 1) {
  SystemBuilder s;
  s.frame("Link1", "world", Transform::rz("theta1"));
  s.frame("A", "Link1", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
  s.frame("Link2", "A", Transform::rz("theta2"));
  s.frame("B", "Link2", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
  s.frame("C", "world", Transform::tx(2.0));
  s.b.addGravity(Eigen::Vector3d(0.0, -9.8, 0.0));
  s.b.addConfigForce("theta1", "u");
  for (int i = 0; i < distanceCopies; ++i) s.b.addDistanceConstraint("B", "C", 1.0);
  return std::move(s).finish();
}

/// A 3D four-joint arm (rz, ry, rx, tz joints, full inertias, constant rotations between them)
/// with a few world-fixed frames, and nothing else: tests add the element under test to `s.b`.
/// Frames: j1 (rz a, mass) → l1 (const_se3) → j2 (ry b) → l2 (tx .8, mass) → j3 (rx c) →
/// l3 (ty .4, mass) → j4 (tz d, mass) → l4 (tx .3, mass); world → w1 (const_se3), w2 (tx 1) → w3
/// (tz .5).
inline SystemBuilder armBase(std::uint32_t seed = 7) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  s.frame("j1", "world", Transform::rz("a"), Mass{1.0, randomInertia(rng)});
  s.frame("l1", "j1", Transform::constSE3(se3(0.7, {1.0, 2.0, 0.5}, {0.1, -0.2, 0.3})));
  s.frame("j2", "l1", Transform::ry("b"));
  s.frame("l2", "j2", Transform::tx(0.8), Mass{0.9, randomInertia(rng)});
  s.frame("j3", "l2", Transform::rx("c"));
  s.frame("l3", "j3", Transform::ty(0.4), Mass{0.6, randomInertia(rng)});
  s.frame("j4", "l3", Transform::tz("d"), Mass{0.4, randomInertia(rng)});
  s.frame("l4", "j4", Transform::tx(0.3), Mass{0.2, randomInertia(rng)});
  s.frame("w1", "world", Transform::constSE3(se3(-0.4, {0.0, 1.0, 1.0}, {0.6, 0.5, -0.4})));
  s.frame("w2", "world", Transform::tx(1.0));
  s.frame("w3", "w2", Transform::tz(0.5));
  return s;
}

/// A chain exercising transform type `t`: j1 rz(a) (mass) → c1 const_se3 → test: t driven by "t"
/// (const_se3: a constant placement) with a mass → test_const: t constant → j2 ry(b) → end tz(.5)
/// with a mass; skewed gravity so that every coordinate is loaded.
inline TestSystem transformChain(TransformType t, std::uint32_t seed = 11) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  s.frame("j1", "world", Transform::rz("a"), Mass{0.8, randomInertia(rng)});
  s.frame("c1", "j1", Transform::constSE3(se3(0.5, {1.0, 0.0, 1.0}, {0.3, 0.1, -0.2})));
  if (t == TransformType::kConstSE3) {
    s.frame("test", "c1", Transform::constSE3(se3(-0.9, {0.2, 1.0, 0.3}, {0.0, 0.4, 0.1})),
            Mass{0.7, randomInertia(rng)});
  } else {
    s.frame("test", "c1", drivenTransform(t, "t"), Mass{0.7, randomInertia(rng)});
  }
  s.frame("test_const", "test",
          constantTransform(t, 0.35, se3(1.1, {1.0, -1.0, 0.5}, {0.2, -0.3, 0.25})));
  s.frame("j2", "test_const", Transform::ry("b"));
  s.frame("end", "j2", Transform::tz(0.5), Mass{0.5, randomInertia(rng)});
  s.b.addGravity(Eigen::Vector3d(0.7, -9.6, 1.9));
  return std::move(s).finish();
}

/// A planar skate: world → sx tx(x) → sy ty(y) → body rz(theta) (mass, full inertia) → blade
/// tx(bladeOffset); knife edge at the blade: no velocity along the body's y axis. Inputs: a
/// torque on theta ("steer") and a thrust along the body's x axis ("thrust", a body wrench).
inline TestSystem planarSkate(double bladeOffset = 0.3, std::uint32_t seed = 5) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  s.frame("sx", "world", Transform::tx("x"));
  s.frame("sy", "sx", Transform::ty("y"));
  s.frame("body", "sy", Transform::rz("theta"), Mass{1.5, randomInertia(rng)});
  s.frame("blade", "body", Transform::tx(bladeOffset));
  s.b.addKnifeEdgeConstraint("blade", Eigen::Vector3d(0.0, 1.0, 0.0));
  s.b.addConfigForce("theta", "steer");
  s.b.addBodyWrench("body", {WrenchEntry{std::string("thrust")}, WrenchEntry{0.0}, WrenchEntry{0.0},
                             WrenchEntry{0.0}, WrenchEntry{0.0}, WrenchEntry{0.0}});
  return std::move(s).finish();
}

/// Every element type in one 3D system (6 coordinates, 5 inputs, 4 constraints):
/// cart_x tx(x) → cart_y ty(y) (mass) → turret rz(yaw) (mass) → blade tx(.25) [knife edge],
/// turret → mount const_se3 → shoulder ry(pitch) → upper tz(.6) (mass) → elbow rx(roll) →
/// lower ty(.5) (mass) → slider tz(ext) (mass) → tip tx(.2) (mass); world frames anchor
/// (const_se3), post tz(.3) → post_top ry(.3) → pulley tx(.4), floor rx(.1).
/// Gravity, two linear springs, a config spring, config forces on x and yaw, damping, a body wrench
/// (constant and input entries), a tendon pulley→upper→lower→tip, and the constraints: knife edge
/// (blade, body y), distance tip–anchor 1.3, point lower–post along z, point upper on the floor.
/// A consistent state exists (the cart can always move to satisfy the distance).
inline TestSystem kitchenSink(std::uint32_t seed = 3, bool withConstraints = true) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  s.frame("cart_x", "world", Transform::tx("x"));
  s.frame("cart_y", "cart_x", Transform::ty("y"), Mass{2.0, randomInertia(rng, 0.1, 0.3)});
  s.frame("turret", "cart_y", Transform::rz("yaw"), Mass{1.0, randomInertia(rng)});
  s.frame("blade", "turret", Transform::tx(0.25));
  s.frame("mount", "turret", Transform::constSE3(se3(0.4, {1.0, 1.0, 0.0}, {0.1, -0.05, 0.3})));
  s.frame("shoulder", "mount", Transform::ry("pitch"));
  s.frame("upper", "shoulder", Transform::tz(0.6), Mass{0.7, randomInertia(rng)});
  s.frame("elbow", "upper", Transform::rx("roll"));
  s.frame("lower", "elbow", Transform::ty(0.5), Mass{0.5, randomInertia(rng)});
  s.frame("slider", "lower", Transform::tz("ext"), Mass{0.3, randomInertia(rng)});
  s.frame("tip", "slider", Transform::tx(0.2), Mass{0.2, randomInertia(rng, 0.01, 0.05)});
  s.frame("anchor", "world", Transform::constSE3(se3(0.3, {0.0, 0.0, 1.0}, {1.0, 0.5, 0.2})));
  s.frame("post", "world", Transform::tz(0.3));
  s.frame("post_top", "post", Transform::ry(0.3));
  s.frame("pulley", "post_top", Transform::tx(0.4));
  s.frame("floor", "world", Transform::rx(0.1));

  s.b.addGravity(Eigen::Vector3d(0.4, -1.1, -9.7));
  s.b.addLinearSpring("tip", "pulley", 3.0, 0.4);
  s.b.addLinearSpring("upper", "cart_y", 2.0, 0.1);
  s.b.addConfigSpring("pitch", 1.5, 0.2);
  s.b.addConfigForce("x", "push");
  s.b.addConfigForce("yaw", "steer");
  s.b.addDamping(0.1, {{"ext", 0.5}});
  s.b.addBodyWrench("lower",
                    {WrenchEntry{std::string("fx_in")}, WrenchEntry{0.3}, WrenchEntry{-0.2},
                     WrenchEntry{0.05}, WrenchEntry{std::string("tau_in")}, WrenchEntry{0.1}});
  s.b.addTendon({"pulley", "upper", "lower", "tip"}, "tension");
  if (withConstraints) {
    s.b.addKnifeEdgeConstraint("blade", Eigen::Vector3d(0.0, 1.0, 0.0));
    s.b.addDistanceConstraint("tip", "anchor", 1.3);
    s.b.addPointConstraint("lower", "post", 2);
    s.b.addPointOnPlaneConstraint("floor", Eigen::Vector3d(0.0, 0.0, 1.0), "upper");
  }
  return std::move(s).finish();
}

/// A planar chain of `links` revolute joints (rz) hanging in gravity (0, −9.81, 0): joint k →
/// mass frame ty(−length) with mass `mass` and a small rotational inertia; the next joint hangs
/// from the mass frame.
inline TestSystem planarChain(int links, double length = 0.1, double mass = 0.1) {
  SystemBuilder s;
  std::string parent = "world";
  for (int k = 0; k < links; ++k) {
    // (append rather than "literal" + std::string: GCC 12 warns falsely, -Wrestrict, on the latter)
    const std::string index = std::to_string(k);
    const std::string joint = std::string("joint").append(index);
    const std::string bob = std::string("bob").append(index);
    s.frame(joint, parent, Transform::rz(std::string("q").append(index)));
    Eigen::Matrix3d I = Eigen::Matrix3d::Zero();
    I.diagonal() << 1e-4, 1e-4, 2e-4;
    I *= mass;
    s.frame(bob, joint, Transform::ty(-length), Mass{mass, I});
    parent = bob;
  }
  s.b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
  s.b.addConfigForce("q0", "torque0");
  s.b.addConfigForce(std::string("q").append(std::to_string(links - 1)), "torque_end");
  return std::move(s).finish();
}

/// A 3D chain with gravity and two coordinate couplings (URDF <mimic>): a prismatic joint coupled
/// to a revolute one two levels up (s3 = 0.5 j1 + 0.1) and a revolute one coupled to its parent's
/// joint (j4 = −j2); inputs on j1 and j2.
inline Model mimicChain() {
  const auto offset = [](double x, double y, double z) {
    Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
    g.topRightCorner<3, 1>() << x, y, z;
    return Transform::constSE3(g);
  };
  const auto body = [](double m, double ixx, double iyy, double izz) {
    return Mass{m, Eigen::Vector3d(ixx, iyy, izz).asDiagonal().toDenseMatrix()};
  };
  ModelBuilder b("mimic chain");
  b.addFrame("l1", "world", Transform::ry("j1"));
  b.addFrame("c1", "l1", offset(0.1, 0, -0.2), body(1.2, 0.02, 0.03, 0.025));
  b.addFrame("o2", "l1", offset(0.1, 0, -0.4));
  b.addFrame("l2", "o2", Transform::rx("j2"));
  b.addFrame("c2", "l2", offset(0, 0.05, -0.15), body(0.8, 0.01, 0.015, 0.012));
  b.addFrame("l3", "l2", Transform::transAxis(Eigen::Vector3d(0, 0.6, 0.8), "s3", poseFromXyzRpy({0, 0, -0.3}, {0, 0, 0})),
             body(0.5, 0.004, 0.005, 0.006));
  b.addFrame("l4", "l2", Transform::rotAxis(Eigen::Vector3d(0, 0, 1), "j4", poseFromXyzRpy({0.05, 0, -0.3}, {0, 0.4, 0})));
  b.addFrame("c4", "l4", offset(0, 0, -0.1), body(0.3, 0.002, 0.003, 0.001));
  b.addConfigForce("j1", "j1");
  b.addConfigForce("j2", "j2");
  b.addGravity(Eigen::Vector3d(0, 0, -9.81));
  b.addCoordinateCoupling("s3", "j1", 0.5, 0.1);
  b.addCoordinateCoupling("j4", "j2", -1.0, 0.0);
  return b.finalize();
}

}  // namespace trellis::test
