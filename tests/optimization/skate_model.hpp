// tests/optimization/skate_model.hpp — the knife-edge skate of the optimization tests: x, y and
// heading θ of a body (1.2 kg, inertia 0.1) whose blade sits 0.3 m ahead of its centre and cannot
// slide sideways (so the knife-edge row's ∂A/∂q is not symmetric, unlike a Hessian); a steering
// torque and a thrust along the heading. With `arm`: a link rz(φ) on the body whose tip (0.4 kg,
// 0.5 m out) keeps 0.8 m from the world point (1, 0, 0) — a holonomic row beside the knife edge —
// and an elbow torque.
#pragma once

#include <trellis/core/model.hpp>
#include <trellis/core/model_builder.hpp>

#include <memory>
#include <string>
#include <utility>

namespace trellis::test {

inline std::shared_ptr<const Model> skateModel(bool arm = false) {
  ModelBuilder b("skate");
  b.addFrame("sx", "world", Transform::tx("x"));
  b.addFrame("sy", "sx", Transform::ty("y"));
  b.addFrame("body", "sy", Transform::rz("theta"), Mass{1.2, Eigen::Matrix3d::Identity() * 0.1});
  b.addFrame("blade", "body", Transform::tx(0.3));
  b.addKnifeEdgeConstraint("blade", Eigen::Vector3d(0.0, 1.0, 0.0));
  b.addConfigForce("theta", "steer");
  b.addBodyWrench("body", {WrenchEntry{std::string("thrust")}, WrenchEntry{0.0}, WrenchEntry{0.0}, WrenchEntry{0.0},
                           WrenchEntry{0.0}, WrenchEntry{0.0}});
  if (arm) {
    b.addFrame("arm", "body", Transform::rz("phi"));
    b.addFrame("tip", "arm", Transform::tx(0.5), Mass{0.4, Eigen::Matrix3d::Identity() * 0.01});
    b.addFrame("anchor", "world", Transform::tx(1.0));
    b.addDistanceConstraint("tip", "anchor", 0.8);
    b.addConfigForce("phi", "elbow");
  }
  return std::make_shared<const Model>(std::move(b).finalize());
}

}  // namespace trellis::test
