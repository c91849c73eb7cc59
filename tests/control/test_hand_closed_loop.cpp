// tests/control/test_hand_closed_loop.cpp — the hand's closed loop (examples/main_job's design,
// examples/hand/hand_feedback.hpp) tracks its reference to below 1e-7 once the perturbation has
// decayed.
//
// Needs trellis_hand_reference (examples/hand/); compiled only when trellis_control_tests links it.
#if __has_include("hand_feedback.hpp")
#include "hand_feedback.hpp"
#include "reference_motion.hpp"

#include <trellis/control.hpp>
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <string>

TEST_CASE("The hand's closed-loop error falls below 1e-7 once the perturbation has decayed",
          "[hand][simulation]") {
  // Run 0 of the main job: perturbation 0.05 along a seeded tangent direction, manifold TV-LQR
  // gains (knots + Riccati steps, cubic rule), tensions clipped at 0, BDF rtol 1e-7, atol 5e-10.
  // The error decays like e^{-7t}; the reference itself is not exactly consistent where a
  // tension's active set changes between two knots (t ≈ 1.81, 2.50, 2.56, 2.69 s; the cubic input
  // rule cannot follow the kink of the NNLS tensions inside the interval), which kicks the error
  // back to ~2e-6 at 1.82 s. Between 2.3 s and the kink at 2.50 s the error sits at 3–6e-8
  // (measured); integrating x itself at rtol 1e-7 (before issue 11) it stalled at ~1e-5.
  const trellis::Scene s = trellis::loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand.json");
  const trellis::Model& model = s.model;
  const trellis::hand::ReferenceMotion motion = trellis::hand::makeReferenceMotion(model, s.q);
  INFO(motion.message);
  REQUIRE(motion.ok);
  const trellis::Trajectory& reference = motion.trajectory;
  const trellis::ManifoldRiccatiSolution lqr = trellis::solveManifoldRiccati(
      model, reference, trellis::hand::feedbackWeights(model),
      trellis::hand::feedbackRiccatiOptions(), trellis::hand::feedbackTransport());
  INFO(lqr.message());
  REQUIRE(lqr.ok());
  const trellis::GainSchedule gains = trellis::hand::feedbackGains(lqr, reference);
  CHECK(gains.interpolation() == trellis::GainInterpolation::kCubic);
  const Eigen::VectorXd x0 = trellis::hand::perturbedStarts(
      lqr.basis.basis(reference.startTime()), reference.states().col(0), 1, 1, 0.05)[0];
  const trellis::SimulationResult r = trellis::simulateClosedLoop(
      model, reference, gains, x0, trellis::hand::closedLoopOptions(model.nu()));
  INFO(r.message);
  REQUIRE(r.ok());
  CHECK(r.restarts <= r.projections);  // no restart at the knots or the gain rows

  double settled = 0.0, end = 0.0;  // max error on [2.3, 2.5) s and on [2.9, 3] s
  const Eigen::VectorXd& t = r.trajectory.times();
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    if (t(k) >= 2.3 && t(k) < 2.495) settled = std::max(settled, r.trackingError(k));
    if (t(k) >= 2.9) end = std::max(end, r.trackingError(k));
  }
  WARN("hand closed loop: initial error " << r.trackingError(0) << ", max on [2.3, 2.5) s " << settled
                                          << ", max on [2.9, 3] s " << end << ", final "
                                          << r.trackingError(t.size() - 1) << "; " << r.steps
                                          << " steps");
  CHECK(r.trackingError(0) > 0.04);
  CHECK(settled < 1e-7);
  CHECK(end < 1e-6);  // after the reference's own kinks at 2.50–2.69 s, still decaying
}
#endif
