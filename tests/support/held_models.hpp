// tests/support/held_models.hpp — models whose constraint loops run between two top-level trees
// of the joint tree (issue 25): a free body held by several arms, two arms pinned tip to tip with
// an unrelated block between them. Header-only and deterministic, as test_models.hpp.
#pragma once

#include "support/test_models.hpp"

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace trellis::test {

/// A 3D arm of `links` revolute joints (rz, ry, rx in turn, skewed placements, full inertias)
/// from `base` (a world frame), named prefix + "0" …; returns the name of its tip frame.
inline std::string spatialArm(SystemBuilder& s, std::mt19937& rng, const std::string& prefix, const std::string& base,
                              int links) {
  std::string parent = base;
  for (int k = 0; k < links; ++k) {
    const std::string name = std::string(prefix).append(std::to_string(k));
    const Transform joint = k % 3 == 0 ? Transform::rz(name) : k % 3 == 1 ? Transform::ry(name) : Transform::rx(name);
    s.frame(name, parent, joint, Mass{0.3, randomInertia(rng, 0.005, 0.02)});
    s.frame(name + "_end", name, Transform::constSE3(se3(0.3 + 0.1 * k, {1.0, 0.5, -0.3}, {0.05, 0.12, 0.02})));
    parent = name + "_end";
  }
  return parent;
}

/// `chains` spatial arms of `links` joints on a circle of radius 0.4 m around the world's z axis
/// (an input "tau<c>" on each arm's first joint), then a free 6-DOF body "body" (tx, ty, tz, then
/// rz, ry, rx about its centre; 0.8 kg, random inertia): the common part of heldBody and
/// bodyHeldByContacts. Returns the arms' tip frames.
inline std::vector<std::string> armsAroundFreeBody(SystemBuilder& s, std::mt19937& rng, int chains, int links) {
  std::vector<std::string> tips;
  for (int c = 0; c < chains; ++c) {
    const std::string base = std::string("base").append(std::to_string(c));
    const double angle = 2.0 * 3.14159265358979 * c / chains;
    s.frame(base, "world", Transform::constSE3(se3(angle, {0.0, 0.0, 1.0}, {0.4 * std::cos(angle), 0.4 * std::sin(angle), 0.0})));
    tips.push_back(spatialArm(s, rng, std::string("arm").append(std::to_string(c)).append("_"), base, links));
    s.b.addConfigForce(std::string("arm").append(std::to_string(c)).append("_0"), std::string("tau").append(std::to_string(c)));
  }
  s.frame("body_x", "world", Transform::tx("body_x"));
  s.frame("body_y", "body_x", Transform::ty("body_y"));
  s.frame("body_z", "body_y", Transform::tz("body_z"));
  s.frame("body_yaw", "body_z", Transform::rz("body_yaw"));
  s.frame("body_pitch", "body_yaw", Transform::ry("body_pitch"));
  s.frame("body", "body_pitch", Transform::rx("body_roll"), Mass{0.8, randomInertia(rng, 0.002, 0.01)});
  return tips;
}

/// A free 6-DOF body (tx, ty, tz, then rz, ry, rx about its centre; 0.8 kg) held by `chains`
/// spatial arms of `links` joints each, every arm's tip pinned to its own grip point on the
/// body (3 point rows per arm): loops between each arm and the body, across the top-level
/// trees (the arms' blocks come first, the body's last, so all but the last arm's rows skip the
/// blocks between). Gravity, an input on each arm's first joint.
inline TestSystem heldBody(int chains, int links, std::uint32_t seed = 41) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  const std::vector<std::string> tips = armsAroundFreeBody(s, rng, chains, links);
  for (int c = 0; c < chains; ++c) {
    const double angle = 2.0 * 3.14159265358979 * c / chains;
    const std::string grip = std::string("grip").append(std::to_string(c));
    s.frame(grip, "body", Transform::constSE3(se3(0.0, {0.0, 0.0, 1.0}, {0.06 * std::cos(angle), 0.06 * std::sin(angle), 0.01 * c})));
    for (int axis = 0; axis < 3; ++axis) s.b.addPointConstraint(tips[static_cast<size_t>(c)], grip, axis);
  }
  s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
  return std::move(s).finish();
}

/// A free 6-DOF body (heldBody's) touched by three spatial arms of 4 joints through contacts of
/// point-on-plane rows of different sizes: arm 0's tip on a plane of the body with 3 rows (a
/// sticking contact), arm 1's with 2, the body's grip point on a plane of arm 2's tip with 1
/// (the plane body is the arm: it turns the normal in the arm's directions, not the body's), and
/// a third row of arm 1's contact declared after it (not next to its pair's rows). Covers the
/// contact grouping of the tangent passes (PointOnPlaneKind::contactTangents) for every size and
/// both orientations. Gravity, an input on each arm's first joint.
inline TestSystem bodyHeldByContacts(std::uint32_t seed = 47) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  const std::vector<std::string> tips = armsAroundFreeBody(s, rng, 3, 4);
  for (int c = 0; c < 3; ++c) {
    const double angle = 2.0 * 3.14159265358979 * c / 3;
    s.frame(std::string("grip").append(std::to_string(c)), "body",
            Transform::constSE3(se3(0.3 * c, {1.0, 0.0, 0.0}, {0.06 * std::cos(angle), 0.06 * std::sin(angle), 0.01 * c})));
  }
  const Eigen::Vector3d n0(0.3, -0.2, 0.9), n1(0.8, 0.5, -0.1), n2(-0.2, 0.9, 0.4);
  s.b.addPointOnPlaneConstraint("grip0", n0, tips[0]);
  s.b.addPointOnPlaneConstraint("grip0", n1, tips[0]);
  s.b.addPointOnPlaneConstraint("grip0", n2, tips[0]);
  s.b.addPointOnPlaneConstraint("grip1", n1, tips[1]);
  s.b.addPointOnPlaneConstraint("grip1", n2, tips[1]);
  s.b.addPointOnPlaneConstraint(tips[2], n0, "grip2");
  s.b.addPointOnPlaneConstraint("grip1", n0, tips[1]);
  s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
  return std::move(s).finish();
}

/// Two spatial arms of `links` joints whose tips are pinned together (3 point rows), with an
/// unconstrained 2-joint pendulum declared between them: the loop runs across two top-level
/// trees and skips the block between them. Gravity, an input on each arm's first joint.
inline TestSystem twoArmClosedChain(int links, std::uint32_t seed = 43) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  s.frame("left_base", "world", Transform::constSE3(se3(0.3, {0.0, 0.0, 1.0}, {0.0, 0.3, 0.0})));
  const std::string left = spatialArm(s, rng, "left", "left_base", links);
  s.frame("head1", "world", Transform::rx("head1"), Mass{0.2, randomInertia(rng, 0.005, 0.02)});
  s.frame("head1_end", "head1", Transform::tz(0.1));
  s.frame("head2", "head1_end", Transform::ry("head2"), Mass{0.1, randomInertia(rng, 0.005, 0.02)});
  s.frame("right_base", "world", Transform::constSE3(se3(-0.3, {0.0, 0.0, 1.0}, {0.0, -0.3, 0.0})));
  const std::string right = spatialArm(s, rng, "right", "right_base", links);
  for (int axis = 0; axis < 3; ++axis) s.b.addPointConstraint(left, right, axis);
  s.b.addConfigForce("left0", "tau_left");
  s.b.addConfigForce("right0", "tau_right");
  s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
  return std::move(s).finish();
}

}  // namespace trellis::test
