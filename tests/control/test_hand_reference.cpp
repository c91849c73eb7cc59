// tests/control/test_hand_reference.cpp — the hand of issue 5 (examples/scenes/hand.json): its
// linearization reduced to the constraint tangent space is controllable, and its reference motion
// (examples/hand/reference_motion.hpp) stays on the constraint manifold with strictly positive
// tensions (an interior-point distribution) that reproduce the motion through the forward dynamics.
//
// The reference-motion cases need the library trellis_hand_reference (examples/hand/); they are
// compiled only when trellis_control_tests links it (its include directory is then visible).
#include <trellis/control.hpp>
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <Eigen/LU>

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
// (2026-12-01, this test): linear tensions 7.5e-5, cubic tensions 4.5e-9 (1.8e-7 with the former
// regularized, active-set distribution, whose q̈ missed the design by ~1e-7 rad/s²). The cubic
// figure is the input rule's O(h⁴) and the integrator's tolerance; 5e-8 leaves 10× above it and
// sits 1500× below the linear rule.
constexpr double kHandCubicBound = 5e-8;
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

TEST_CASE("The interior-point tension distribution is exact, positive and optimal", "[hand][reference]") {
  // At the stored grasp with a q̇ tangent to the manifold and a demanded q̈ that satisfies the
  // acceleration constraint (both from a 3-knot reference, whose first knots are consistent):
  // the distribution must (1) meet B u + Aᵀλ = M q̈ + b so that the forward dynamics return the
  // demanded q̈, (2) keep every tension > 0, (3) be the barrier problem's minimizer: no feasible
  // direction (Δu in null(NᵀB)) decreases ½‖u − u_rest‖² − μ Σ ln u — checked on random directions
  // against the objective itself, not the solver's KKT residual; (4) report failure, with the
  // residuals, when stopped early.
  const trellis::Scene s = loadHand();
  const trellis::Model& model = s.model;
  trellis::hand::ReferenceMotionOptions options;
  options.knots = 3;
  options.inputRates = false;
  const auto ref = trellis::hand::makeReferenceMotion(model, s.q, options);
  INFO(ref.message);
  REQUIRE(ref.ok);
  const int n = model.nq(), m = model.nu();
  trellis::Data data(model);
  const trellis::hand::TensionDistributionOptions tension;
  for (int k = 0; k < 3; ++k) {
    INFO("knot " << k);
    const Eigen::VectorXd q = ref.trajectory.states().col(k).head(n);
    const Eigen::VectorXd dq = ref.trajectory.states().col(k).tail(n);
    const Eigen::VectorXd qdd = ref.accelerations.col(k);
    const auto td = trellis::hand::distributeTensions(model, data, q, dq, qdd, tension);
    INFO(td.message);
    REQUIRE(td.converged);
    CHECK(td.tension.minCoeff() > 0.0);
    CHECK(td.relativeResidual < 1e-13);
    REQUIRE(trellis::computeDynamics(model, data, q, dq, td.tension).ok());
    const double qddError = (data.qdd - qdd).cwiseAbs().maxCoeff();
    WARN("knot " << k << ": forward dynamics under the distributed tensions miss q'' by " << qddError
                 << " rad/s^2 (|q''| " << qdd.cwiseAbs().maxCoeff() << "), " << td.iterations
                 << " Newton iterations, tensions " << td.tension.minCoeff() << " ... "
                 << td.tension.maxCoeff() << " N");
    CHECK(qddError < 1e-9 * (1.0 + qdd.cwiseAbs().maxCoeff()));
    // Optimality on feasible directions: null space of the tangential equations NᵀB, with N a
    // basis of null(A) (A = constraint Jacobian at q).
    trellis::computeConstraints(model, data, q, dq);
    const Eigen::MatrixXd At = data.constraintJacobian.transpose();
    trellis::computeInputMatrix(model, data, q);
    const Eigen::FullPivLU<Eigen::MatrixXd> luA(At.transpose());
    const Eigen::MatrixXd N = luA.kernel();
    const Eigen::MatrixXd tangential = N.transpose() * data.inputMatrix;
    const Eigen::MatrixXd feasible = Eigen::FullPivLU<Eigen::MatrixXd>(tangential).kernel();
    REQUIRE(feasible.cols() == m - tangential.rows());
    auto objective = [&](const Eigen::VectorXd& u) {
      return 0.5 * (u.array() - tension.restingTension).matrix().squaredNorm() -
             tension.barrier * u.array().log().sum();
    };
    const double f0 = objective(td.tension);
    std::mt19937 rng(static_cast<unsigned>(100 + k));
    std::normal_distribution<double> gauss;
    for (int trial = 0; trial < 50; ++trial) {
      Eigen::VectorXd c(feasible.cols());
      for (Eigen::Index i = 0; i < c.size(); ++i) c(i) = gauss(rng);
      Eigen::VectorXd dir = feasible * c;
      dir *= 1e-3 * td.tension.minCoeff() / dir.cwiseAbs().maxCoeff();  // stays inside u > 0
      // Second-order increase here ~½|Δu|²(1 + μ/u²) ≳ 1e-12; rounding of the objective ~1e-14.
      for (double sign : {1.0, -1.0}) CHECK(objective(td.tension + sign * dir) >= f0 - 1e-13 * (1.0 + std::abs(f0)));
    }
  }
  // Stopped after one Newton iteration from the infeasible start: not converged, and the message
  // says so with the residuals.
  trellis::hand::TensionDistributionOptions early = tension;
  early.maxIterations = 1;
  const Eigen::VectorXd q = ref.trajectory.states().col(1).head(n);
  const Eigen::VectorXd dq = ref.trajectory.states().col(1).tail(n);
  const auto stopped = trellis::hand::distributeTensions(model, data, q, dq, ref.accelerations.col(1), early);
  CHECK_FALSE(stopped.converged);
  CHECK(stopped.message.find("did not converge in 1 Newton iterations") != std::string::npos);
  CHECK(stopped.message.find("tangential residual") != std::string::npos);
}

TEST_CASE("The hand's reference motion stays on the manifold with strictly positive tensions",
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
  // Tensions: strictly positive (interior point), and bounded (a few newtons for a ~160 g hand
  // moving slowly).
  CHECK(traj.inputs().minCoeff() > 0.0);
  CHECK(traj.inputs().maxCoeff() < 50.0);
  // Inverse dynamics: B u + Aᵀλ = M q̈ + b to rounding (the distribution is exact, not
  // regularized).
  CHECK(ref.dynamicsResidual.maxCoeff() < 1e-13);
  // Forward dynamics under the tensions reproduce the designed q̈: rounding amplified by the
  // fingertips' M⁻¹ (~1e6) against q̈ of ~1 rad/s².
  CHECK(ref.forwardDynamicsError.maxCoeff() < 1e-9 * (1.0 + ref.accelerations.cwiseAbs().maxCoeff()));
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
    INFO(r.status.message);
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
