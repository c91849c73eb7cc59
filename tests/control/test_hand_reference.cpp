// tests/control/test_hand_reference.cpp — the hand of issue 5 (examples/scenes/hand.json): its
// linearization reduced to the constraint tangent space is controllable, and its reference motion
// (examples/hand/reference_motion.hpp) stays on the constraint manifold with non-negative tensions
// that reproduce the motion through the forward dynamics.
//
// The reference-motion cases need the library trellis_hand_reference (examples/hand/); they are
// compiled only when trellis_control_tests links it (its include directory is then visible).
#include <trellis/control.hpp>
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <string>

namespace {

trellis::Scene loadHand() {
  return trellis::loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand.json");
}

}  // namespace

TEST_CASE("The hand is controllable on its constraint manifold at the stored grasp",
          "[hand][controllability]") {
  const trellis::Scene s = loadHand();
  trellis::Data data(s.model);
  // Tensions 0: gravity and the joint springs alone act; the pads are held by the constraints.
  const auto r = trellis::computeControllabilityAt(s.model, data, s.q, s.dq, s.u);
  CHECK(r.dimension == 10);  // 2 (20 − 15)
  CHECK(r.rank == 10);
  // σ_min of the scaled Krylov matrix is ~7e-3 against σ_max ~1e4: small because the hand's
  // inertias are small (B = M⁻¹-weighted, A/α with α ~ 1e5), but ~1e6 times the rank threshold
  // 1e-10·σ_max, so rank 10 is not a rounding artefact.
  CHECK(r.smallestSingularValue > 1e3 * 1e-10 * r.largestSingularValue);
}

#if __has_include("reference_motion.hpp")
#include "reference_motion.hpp"

#include <random>

namespace {
// Max deviation (rad, rad/s) of the open-loop hand from its reference at the knots. Measured
// (2026-12-01, this test): linear tensions 7.5e-5, cubic tensions 1.8e-7. The cubic figure is not
// the input rule's error (~h⁴|u⁗|/384 ~ 1e-10 N) but the distribution's own: the forward dynamics
// under u_k miss the designed q̈_k by ~1e-7 rad/s² (the O(ε²) tangential residual times M⁻¹;
// forwardDynamicsError, examples/hand/README.md), and that integrates to ~1e-7 over 3 s. 1e-6 leaves 5× above it and
// sits 75× below the linear rule.
constexpr double kHandCubicBound = 1e-6;
}  // namespace

TEST_CASE("Lawson-Hanson NNLS meets the KKT conditions of min ||Cx - d||, x >= 0",
          "[hand][nnls]") {
  std::mt19937 rng(77);
  std::normal_distribution<double> gauss;
  for (int trial = 0; trial < 20; ++trial) {
    const int rows = 4 + trial % 9, cols = 3 + (trial * 7) % 11;
    Eigen::MatrixXd C(rows, cols);
    Eigen::VectorXd d(rows);
    for (int i = 0; i < rows; ++i) {
      d(i) = gauss(rng);
      for (int j = 0; j < cols; ++j) C(i, j) = gauss(rng);
    }
    const auto r = trellis::hand::solveNonNegativeLeastSquares(C, d);
    INFO("trial " << trial);
    REQUIRE(r.converged);
    CHECK(r.x.minCoeff() >= 0.0);
    // KKT: w = Cᵀ(d − Cx) ≤ 0 on the bound (x_j = 0), = 0 on the free set; 1e-10 is ~1e5 eps for
    // these O(1) data (least squares on the free columns is accurate to ~cond · eps).
    const Eigen::VectorXd w = C.transpose() * (d - C * r.x);
    for (int j = 0; j < cols; ++j) {
      if (r.x(j) > 0.0) CHECK(std::abs(w(j)) < 1e-10);
      else CHECK(w(j) < 1e-10);
    }
  }
  // A closed form: C = I, the solution is max(d, 0).
  Eigen::VectorXd d(4);
  d << 1.0, -2.0, 3.0, -0.5;
  const auto r = trellis::hand::solveNonNegativeLeastSquares(Eigen::MatrixXd::Identity(4, 4), d);
  CHECK((r.x - d.cwiseMax(0.0)).norm() < 1e-15);
  CHECK_THROWS_AS(trellis::hand::solveNonNegativeLeastSquares(Eigen::MatrixXd::Identity(3, 3), d),
                  std::invalid_argument);
}

TEST_CASE("The hand's reference motion stays on the manifold with non-negative tensions",
          "[hand][reference]") {
  const trellis::Scene s = loadHand();
  const trellis::Model& model = s.model;
  trellis::hand::ReferenceMotionOptions options;
  options.knots = 61;  // 3 s at 50 ms: the checks are per knot, the spacing does not matter
  const auto ref = trellis::hand::makeReferenceMotion(model, s.q, options);
  INFO(ref.message);
  REQUIRE(ref.ok);
  const trellis::Trajectory& traj = ref.trajectory;
  REQUIRE(traj.size() == 61);
  CHECK(traj.nq() == 20);
  CHECK(traj.nu() == 23);
  CHECK_NOTHROW(traj.checkCompatible(model));
  // Constraints at every knot: Newton stops at 1e-14 m; A q̇ and A q̈ + Ȧ q̇ are solved to
  // rounding (entries of A ~0.1 m, q̇ ~0.3 rad/s).
  CHECK(ref.constraintResidual.maxCoeff() < 1e-13);
  CHECK(ref.velocityResidual.maxCoeff() < 1e-13);
  CHECK(ref.accelerationResidual.maxCoeff() < 1e-12);
  trellis::Data data(model);
  for (int k = 0; k < traj.size(); k += 10) {
    const Eigen::VectorXd q = traj.states().col(k).head(20);
    trellis::computeConstraints(model, data, q, traj.states().col(k).tail(20));
    CHECK(data.constraintValue.cwiseAbs().maxCoeff() < 1e-13);
  }
  // The drivers actually move (the motion is not trivially the start state).
  const int mcp = model.configIndex("index_mcp_flex");
  CHECK(traj.states().row(mcp).maxCoeff() - traj.states().row(mcp).minCoeff() ==
        Approx(options.amplitudes[0]).epsilon(1e-9));
  // Tensions: non-negative by construction of the NNLS, and bounded (a few newtons for a ~160 g
  // hand moving slowly).
  CHECK(traj.inputs().minCoeff() >= 0.0);
  CHECK(traj.inputs().maxCoeff() < 50.0);
  // Inverse dynamics: B u + Aᵀλ = M q̈ + b to ~ε² = 1e-12 relative (regularization 1e-6).
  CHECK(ref.dynamicsResidual.maxCoeff() < 1e-10);
  // Forward dynamics under the tensions reproduce the designed q̈: the residual above is amplified
  // by M⁻¹ (~1e6) — ~1e-6 rad/s² at worst against q̈ of ~1 rad/s².
  CHECK(ref.forwardDynamicsError.maxCoeff() < 1e-5 * (1.0 + ref.accelerations.cwiseAbs().maxCoeff()));
}

TEST_CASE("Integrating the hand under the reference tensions follows the reference",
          "[hand][reference]") {
  const trellis::Scene s = loadHand();
  const trellis::Model& model = s.model;
  trellis::hand::ReferenceMotionOptions options;
  options.knots = 61;
  const auto ref = trellis::hand::makeReferenceMotion(model, s.q, options);
  REQUIRE(ref.ok);
  // RK4 over the first 0.5 s with the trajectory's (piecewise linear) tensions. The hand is stiff:
  // damping over inertia reaches ~5e3 1/s, so explicit RK4 needs h below ~2.8/5e3 ≈ 5e-4 s; 1e-4 s
  // is stable and its error negligible. The reference is then reproduced to the linear
  // interpolation of u between knots (50 ms: ~h²/8 · |ü|/|u| ~1e-3 of the tensions) and to the
  // growth of that error along the (damped) dynamics.
  trellis::Data data(model);
  const int n = 20;
  Eigen::VectorXd x = ref.trajectory.states().col(0);
  bool dynamicsOk = true;
  auto f = [&](double t, const Eigen::VectorXd& xs) {
    const Eigen::VectorXd u = ref.trajectory.input(t);
    dynamicsOk = trellis::computeDynamics(model, data, xs.head(n), xs.tail(n), u).ok() && dynamicsOk;
    Eigen::VectorXd dx(2 * n);
    dx << xs.tail(n), data.qdd;
    return dx;
  };
  const double h = 1e-4, horizon = 0.5;
  double t = 0.0;
  while (t < horizon - 1e-12) {
    const Eigen::VectorXd k1 = f(t, x), k2 = f(t + h / 2, x + h / 2 * k1), k3 = f(t + h / 2, x + h / 2 * k2),
                          k4 = f(t + h, x + h * k3);
    x += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
    t += h;
  }
  REQUIRE(dynamicsOk);
  const Eigen::VectorXd xref = ref.trajectory.state(horizon);
  const double qMotion = (ref.trajectory.states().col(10).head(n) - ref.trajectory.states().col(0).head(n))
                             .cwiseAbs().maxCoeff();
  INFO("q error " << (x.head(n) - xref.head(n)).cwiseAbs().maxCoeff() << " against motion " << qMotion);
  // Against the largest coordinate change of the reference over the same time (~0.14 rad): the
  // error is ~1e-4 rad (0.1 %); 5 % would mean the tensions do not produce this motion.
  CHECK((x.head(n) - xref.head(n)).cwiseAbs().maxCoeff() < 0.05 * qMotion);
  // The integrated state stays on the manifold (drift of an unstabilized integration only).
  trellis::computeConstraints(model, data, x.head(n), x.tail(n));
  CHECK(data.constraintValue.cwiseAbs().maxCoeff() < 1e-6);
}

TEST_CASE("The hand's tensions with their rates reproduce the motion between knots (cubic input rule)",
          "[hand][reference][input_rule]") {
  // The main job's reference (301 knots over 3 s, h = 10 ms) integrated open loop with the exact
  // dynamics from its first knot (CVODES BDF, rtol 1e-10, atol 1e-12; constraint projection) under
  // each input rule, and compared with the reference states at every knot. Linear tensions miss
  // the designed u*(t) by ~h²|ü*|/8 between knots, and the motion follows that error; the cubic
  // Hermite tensions through (u_k, u̇_k) miss it by ~h⁴|u*⁗|/384, and the motion stays with the
  // reference to about the integrator's tolerance. The bound sits between the two (see the
  // figures printed with -s), so the linear rule fails it.
  const trellis::Scene s = loadHand();
  const trellis::Model& model = s.model;
  const auto ref = trellis::hand::makeReferenceMotion(model, s.q);
  INFO(ref.message);
  REQUIRE(ref.ok);
  REQUIRE(ref.trajectory.hasInputDerivatives());
  // The rates: the exact correction makes the dynamically relevant part exact (residual at
  // rounding); the difference quotient's own error estimate is small against the rates.
  CHECK(ref.rateResidual.maxCoeff() < 1e-8);
  const double rateScale = ref.inputRates.cwiseAbs().maxCoeff();
  WARN("hand rates: max |u'| " << rateScale << " N/s, max quotient error estimate "
                               << ref.rateDifferenceEstimate.maxCoeff() << " N/s, max exact correction "
                               << ref.rateCorrection.maxCoeff() << " N/s, max residual "
                               << ref.rateResidual.maxCoeff());
  CHECK(ref.rateDifferenceEstimate.maxCoeff() < 1e-4 * rateScale);

  trellis::SimulationOptions options;
  options.method = trellis::IntegrationMethod::kBDF;
  options.rtol = 1e-10;
  options.atol = 1e-12;
  const Eigen::VectorXd x0 = ref.trajectory.states().col(0);
  auto deviation = [&](const trellis::Trajectory& reference) {
    const trellis::SimulationResult r = trellis::simulateOpenLoop(model, reference, x0, options);
    INFO(r.message);
    REQUIRE(r.ok());
    REQUIRE(r.trajectory.size() == reference.size());
    return (r.trajectory.states() - reference.states()).cwiseAbs().maxCoeff();
  };
  trellis::Trajectory linear = ref.trajectory;
  linear.clearInputDerivatives();
  const double cubicDeviation = deviation(ref.trajectory);
  const double linearDeviation = deviation(linear);
  WARN("hand open loop over 3 s, max |x - x_ref| at the knots: linear tensions " << linearDeviation
       << ", cubic tensions " << cubicDeviation);
  CHECK(cubicDeviation < kHandCubicBound);
  CHECK_FALSE(linearDeviation < kHandCubicBound);
}

TEST_CASE("The hand is controllable on its manifold at the reference start", "[hand][reference]") {
  const trellis::Scene s = loadHand();
  trellis::hand::ReferenceMotionOptions options;
  options.knots = 11;
  const auto ref = trellis::hand::makeReferenceMotion(s.model, s.q, options);
  REQUIRE(ref.ok);
  trellis::Data data(s.model);
  const Eigen::VectorXd x0 = ref.trajectory.states().col(0);
  const auto r = trellis::computeControllabilityAt(s.model, data, x0.head(20), x0.tail(20),
                                                   ref.trajectory.inputs().col(0));
  CHECK(r.dimension == 10);
  CHECK(r.rank == 10);
  CHECK(r.smallestSingularValue > 1e3 * 1e-10 * r.largestSingularValue);
}
#endif
