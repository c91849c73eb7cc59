// control_test_support.hpp — helpers for the control tests: a relative matrix comparison that
// names the worst entry, and the small models the tests share (built with ModelBuilder).
#pragma once

#include <trellis/core.hpp>

#include <Eigen/Core>

#include <string>

namespace trellis::ctest {

/// max_ij |got − expected| / max(floor, |expected_ij|) and a message naming the worst entry.
struct Comparison {
  double worst = 0.0;
  std::string message;
};
Comparison compareRelative(const Eigen::MatrixXd& expected, const Eigen::MatrixXd& got,
                           double floor = 1.0);

/// Cart (mass mc, config "x", input "push" on x) with a pole (config "theta", rz) carrying a point
/// mass mp at distance l along the pole's +y; gravity −9.81 y, so θ = 0 is upright.
Model makeCartPole(double mc = 1.0, double mp = 0.2, double l = 0.5);

/// Two carts on x ("x1", "x2", mass 1 each) held together by a point constraint along x; input
/// "push" on x1. The constraint removes one configuration: 4 states, 2 tangent directions.
Model makeConstrainedCarts();

/// The damped hanging chain of bench/chain_scene.py: `links` links rz("q<i>") each carrying a
/// 0.1 kg point mass 0.1 m below its joint (ty −0.1), a torque "u<i>" per joint, damping 0.1
/// per joint, gravity −9.81 y. Its fast modes are stiff (|λ| ≈ 1.4e3 at 6 links).
Model makeDampedChain(int links);

}  // namespace trellis::ctest

#define CONTROL_CHECK_CLOSE(expected, got, tol, floor)                                   \
  do {                                                                                   \
    const auto cmp_ = ::trellis::ctest::compareRelative((expected), (got), (floor));     \
    INFO(#got " vs " #expected ": " << cmp_.message);                                    \
    CHECK(cmp_.worst <= (tol));                                                          \
  } while (false)
