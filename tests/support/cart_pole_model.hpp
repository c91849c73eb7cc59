// support/cart_pole_model.hpp — the cart-pole of the core and control tests (header only).
#pragma once

#include <trellis/core/model_builder.hpp>

namespace trellis::test {

/// Cart (mass mc, config "x", input "push" on x) with a pole (config "theta", rz) carrying a point
/// mass mp at distance l along the pole's +y; gravity −9.81 y, so θ = 0 is upright.
inline Model cartPole(double mc = 1.0, double mp = 0.2, double l = 0.5) {
  ModelBuilder b("cartpole");
  b.addFrame("cart", "world", Transform::tx("x"), Mass{mc, Eigen::Matrix3d::Zero()});
  b.addFrame("pole", "cart", Transform::rz("theta"));
  b.addFrame("bob", "pole", Transform::ty(l), Mass{mp, Eigen::Matrix3d::Zero()});
  b.addGravity({0.0, -9.81, 0.0});
  b.addConfigForce("x", "push");
  return std::move(b).finalize();
}

}  // namespace trellis::test
