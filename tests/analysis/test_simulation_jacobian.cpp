// Tests of the simulator's integration strategy (simulation.hpp, "Jacobian", "Restarts",
// "Constraints", "Threads"): the exact closed-loop Jacobian A − B S K against central differences
// of the right-hand side, the exact and difference-quotient paths against each other, restarts
// only where the right-hand side jumps, the drift status, and the batch against single runs.
#include "closed_loop_system.hpp"
#include "control_test_support.hpp"

#include <trellis/core/gain_schedule.hpp>
#include <trellis/control/lqr.hpp>
#include <trellis/analysis/simulation.hpp>
#include <trellis/core/trajectory.hpp>
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::GainSchedule;
using trellis::Model;
using trellis::SimulationOptions;
using trellis::SimulationResult;
using trellis::Trajectory;

namespace {

const trellis::Policy zeroInput = [](double, const VectorXd&, VectorXd& u) { u.setZero(); };

/// The paper pendulum (two links closed by a distance constraint, torque u on the first joint)
/// swinging freely from its projected printed state: a constrained reference with many knots, and
/// a time-varying gain K(t) = (1 + ½ sin 3t) K0 (a PD law on the driven joint) at every knot.
struct PaperPendulumLoop {
  trellis::Scene scene =
      trellis::loadScene(TRELLIS_SOURCE_DIR "/examples/scenes/paper_pendulum.json");
  const Model& model = scene.model;
  Trajectory reference;
  GainSchedule gains;
  VectorXd start;

  explicit PaperPendulumLoop(double T = 2.0, double outputStep = 0.01) {
    VectorXd x0(4);
    x0 << scene.q, scene.dq;
    trellis::projectOntoConstraints(model, x0);
    SimulationOptions opt;
    opt.rtol = 1e-10;
    opt.atol = 1e-12;
    opt.outputStep = outputStep;
    const SimulationResult free = trellis::simulate(model, x0, 0.0, T, zeroInput, opt);
    REQUIRE(free.ok());
    reference = free.trajectory;
    const MatrixXd K0 = (MatrixXd(1, 4) << 8.0, 0.0, 3.0, 0.0).finished();
    std::vector<MatrixXd> K;
    for (int k = 0; k < reference.size(); ++k)
      K.push_back((1.0 + 0.5 * std::sin(3.0 * reference.times()(k))) * K0);
    gains = GainSchedule(reference.times(), K);
    // A kick, projected back onto the constraint manifold (the runs start on it).
    start = x0;
    start(0) += 0.05;
    start(2) += 0.3;
    trellis::projectOntoConstraints(model, start);
  }
};

/// Central differences of the closed loop's right-hand side in x: h = ε^(1/3) max(1, |x_j|), error
/// O(h²) ≈ 1e-11 relative on smooth pieces (the saturation switch must not lie within h).
MatrixXd centralDifferenceJacobian(trellis::detail::ClosedLoopSystem& sys, double t,
                                   const VectorXd& x) {
  const Eigen::Index nx = x.size();
  MatrixXd J(nx, nx);
  VectorXd xp = x, xm = x, fp(nx), fm(nx);
  for (Eigen::Index j = 0; j < nx; ++j) {
    const double h = std::cbrt(std::numeric_limits<double>::epsilon()) * std::max(1.0, std::abs(x(j)));
    xp = x;
    xm = x;
    xp(j) += h;
    xm(j) -= h;
    REQUIRE(sys.rhs(t, trellis::detail::ConstVectorMap(xp.data(), nx),
                    trellis::detail::VectorMap(fp.data(), nx)) == 0);
    REQUIRE(sys.rhs(t, trellis::detail::ConstVectorMap(xm.data(), nx),
                    trellis::detail::VectorMap(fm.data(), nx)) == 0);
    J.col(j) = (fp - fm) / (2.0 * h);
  }
  return J;
}

MatrixXd exactJacobian(trellis::detail::ClosedLoopSystem& sys, double t, const VectorXd& x) {
  const Eigen::Index nx = x.size();
  MatrixXd J(nx, nx);
  VectorXd f(nx);
  REQUIRE(sys.jacobian(t, trellis::detail::ConstVectorMap(x.data(), nx),
                       trellis::detail::ConstVectorMap(f.data(), nx),
                       trellis::detail::MatrixMap(J.data(), nx, nx)) == 0);
  return J;
}

}  // namespace

TEST_CASE("simulation: the exact closed-loop Jacobian A − B S K against central differences",
          "[simulation][jacobian]") {
  const PaperPendulumLoop loop;
  trellis::detail::InputLaw law;
  law.kind = trellis::detail::InputLaw::Kind::kFeedback;
  law.reference = &loop.reference;
  law.gains = &loop.gains;
  const double t = 0.537;  // between knots: x_ref, u_ref and K interpolated
  const VectorXd x = loop.reference.state(t) + (VectorXd(4) << 0.02, -0.01, 0.2, 0.1).finished();
  // u = u_ref − K (x − x_ref) = −K δx here (u_ref = 0): about −0.8 at this t and δx.
  VectorXd u(1);
  bool clipped = false;

  // The integrator's state is the deviation y = x − x_ref(t) (closed_loop_system.hpp); ∂ẏ/∂y = ∂f/∂x.
  VectorXd y(4);
  SECTION("unsaturated: A − B K") {
    trellis::detail::ClosedLoopSystem sys(loop.model, law, SimulationOptions{});
    REQUIRE(sys.deviation());
    sys.toIntegrator(t, x, y);
    CHECK((y - (x - loop.reference.state(t))).norm() < 1e-15);
    REQUIRE(sys.control(t, x, u, clipped));
    CHECK_FALSE(clipped);
    const MatrixXd J = exactJacobian(sys, t, y);
    // ε^(2/3) ≈ 4e-11 relative truncation and rounding; 1e-7 leaves the margin of the house rule.
    CONTROL_CHECK_CLOSE(centralDifferenceJacobian(sys, t, y), J, 1e-7, 1.0);
    // ẏ = f(x) − ẋ_ref(t): against the core's dynamics and the reference's spline derivative.
    VectorXd fy(4), xr, ur, xrdot;
    REQUIRE(sys.rhs(t, trellis::detail::ConstVectorMap(y.data(), 4),
                    trellis::detail::VectorMap(fy.data(), 4)) == 0);
    loop.reference.evaluate(t, xr, ur, xrdot);
    trellis::Data dyn(loop.model);
    REQUIRE(trellis::computeDynamics(loop.model, dyn, x.head(2), x.tail(2), u).ok());
    VectorXd f(4);
    f << x.tail(2), dyn.qdd;
    CONTROL_CHECK_CLOSE(f, VectorXd(fy + xrdot), 1e-12, 1.0);
    // Independent path: the plant's A and B at the same (x, u), and the gain at t.
    trellis::Data data(loop.model);
    REQUIRE(trellis::computeLinearization(loop.model, data, x.head(2), x.tail(2), u).ok());
    const MatrixXd expected = data.A - data.B * loop.gains.evaluate(t);
    CONTROL_CHECK_CLOSE(expected, J, 1e-13, 1.0);
    CHECK((J - data.A).norm() > 1.0);  // the feedback term really is there
  }
  SECTION("saturated: the clipped input's row of K drops out") {
    SimulationOptions opt;
    opt.inputLower = VectorXd::Constant(1, -0.1);  // u ≈ −0.8 is clipped to −0.1
    opt.inputUpper = VectorXd::Constant(1, 0.1);
    trellis::detail::ClosedLoopSystem sys(loop.model, law, opt);
    sys.toIntegrator(t, x, y);
    REQUIRE(sys.control(t, x, u, clipped));
    REQUIRE(clipped);
    const MatrixXd J = exactJacobian(sys, t, y);
    CONTROL_CHECK_CLOSE(centralDifferenceJacobian(sys, t, y), J, 1e-7, 1.0);
    trellis::Data data(loop.model);
    REQUIRE(trellis::computeLinearization(loop.model, data, x.head(2), x.tail(2), u).ok());
    CONTROL_CHECK_CLOSE(MatrixXd(data.A), J, 1e-13, 1.0);
  }
}

TEST_CASE("simulation: exact and difference-quotient Jacobians give the same closed loop",
          "[simulation][jacobian]") {
  SimulationOptions exact;
  exact.method = trellis::IntegrationMethod::kBDF;
  exact.rtol = 1e-9;
  exact.atol = 1e-11;
  SimulationOptions quotient = exact;
  quotient.exactJacobian = false;

  auto compare = [&](const Model& model, const Trajectory& reference, const GainSchedule& gains,
                     const VectorXd& x0, const SimulationOptions& a, const SimulationOptions& b) {
    const SimulationResult ra = trellis::simulateClosedLoop(model, reference, gains, x0, a);
    const SimulationResult rb = trellis::simulateClosedLoop(model, reference, gains, x0, b);
    INFO("exact: " << ra.json());
    INFO("difference quotient: " << rb.json());
    REQUIRE(ra.ok());
    REQUIRE(rb.ok());
    // The Newton matrix only changes the iteration, not the solution: both runs are within their
    // global error (~1e-8 at rtol 1e-9 over these horizons) of the exact flow; 1e-6 bounds it.
    REQUIRE(ra.trajectory.size() == rb.trajectory.size());
    CHECK((ra.trajectory.states() - rb.trajectory.states()).cwiseAbs().maxCoeff() < 1e-6);
    // The exact path forms its Jacobians without a single extra right-hand side; the fallback
    // pays 2n per Jacobian (the count says which path ran).
    CHECK(ra.jacobianEvaluations > 0);
    CHECK(ra.linearRhsEvaluations == 0);
    CHECK(rb.jacobianEvaluations > 0);
    CHECK(rb.linearRhsEvaluations >= rb.jacobianEvaluations * x0.size());
    return ra;
  };

  SECTION("constrained: the paper pendulum with a saturating time-varying gain") {
    const PaperPendulumLoop loop;
    SimulationOptions a = exact, b = quotient;
    for (SimulationOptions* o : {&a, &b}) {
      o->inputLower = VectorXd::Constant(1, -0.5);
      o->inputUpper = VectorXd::Constant(1, 0.5);
    }
    const SimulationResult r = compare(loop.model, loop.reference, loop.gains, loop.start, a, b);
    CHECK(r.saturatedSamples > 0);  // the saturation really switched on this run
  }
  SECTION("unconstrained: the cart-pole held upright by a constant gain") {
    const Model model = trellis::ctest::makeCartPole();
    MatrixXd X = MatrixXd::Zero(4, 2), U = MatrixXd::Zero(1, 2);
    Trajectory reference(model.configNames(), model.inputNames(),
                         (VectorXd(2) << 0.0, 3.0).finished(), X, U);
    trellis::Data data(model);
    const VectorXd zero2 = VectorXd::Zero(2), u0 = VectorXd::Zero(1);
    REQUIRE(trellis::computeLinearization(model, data, zero2, zero2, u0).ok());
    const auto care = trellis::solveCare(data.A, data.B, MatrixXd::Identity(4, 4) * 10.0,
                                         MatrixXd::Identity(1, 1));
    REQUIRE(care.ok());
    const MatrixXd K = care.K;
    const GainSchedule gains((VectorXd(2) << 0.0, 3.0).finished(), {K, K});
    SimulationOptions a = exact, b = quotient;
    a.outputStep = b.outputStep = 0.05;
    const VectorXd x0 = (VectorXd(4) << 0.1, 0.15, 0.0, 0.0).finished();
    compare(model, reference, gains, x0, a, b);
  }
}

TEST_CASE("simulation: restarts only where the right-hand side jumps", "[simulation]") {
  SECTION("continuous gains over a 401-knot constrained reference: restarts = projections") {
    const PaperPendulumLoop loop(4.0, 0.01);
    REQUIRE(loop.reference.size() == 401);
    SimulationOptions opt;
    opt.method = trellis::IntegrationMethod::kBDF;
    const SimulationResult r =
        trellis::simulateClosedLoop(loop.model, loop.reference, loop.gains, loop.start, opt);
    REQUIRE(r.ok());
    INFO(r.json());
    // The start is on the manifold; every projection (the drift grew past the tolerance)
    // restarts the integration, nothing else does — not the 399 interior knots.
    REQUIRE(r.constraintDrift(0) < 1e-12);
    CHECK(r.projections >= 1);
    CHECK(r.restarts == r.projections);
    CHECK(r.projections < loop.reference.size() / 4);  // not at every knot
    // After the start the drift stays near the tolerance δ = 10·(atol + rtol) ≈ 1e-7: projection
    // once it is exceeded, so a measured value is δ plus what one 0.01 s interval adds (measured
    // 2.1e-7); 5e-7 bounds it, while unprojected it would grow without bound.
    CHECK(r.constraintDrift.maxCoeff() < 5e-7);
    CHECK(r.trackingError(r.trackingError.size() - 1) < 0.5 * r.trackingError(0));
  }
  SECTION("zero-order hold: a restart at every sample, none at the knots") {
    const PaperPendulumLoop loop(1.0, 0.01);
    SimulationOptions opt;
    opt.sampleRate = 20.0;
    opt.constraints = trellis::ConstraintHandling::kNone;
    const SimulationResult r =
        trellis::simulateClosedLoop(loop.model, loop.reference, loop.gains, loop.start, opt);
    INFO(r.json());
    REQUIRE(r.ok());
    CHECK(r.projections == 0);
    CHECK(r.restarts == 19);  // samples at 0.05, …, 0.95 (the one at 0 is the start)
  }
}

TEST_CASE("simulation: drift above the tolerance after projection is a status", "[simulation]") {
  const PaperPendulumLoop loop(0.5, 0.01);
  SimulationOptions opt;
  opt.driftTolerance = 1e-30;  // below rounding: no projection can meet it
  const SimulationResult r =
      trellis::simulateClosedLoop(loop.model, loop.reference, loop.gains, loop.start, opt);
  CHECK(r.status.code == trellis::SimulationCode::kConstraintDrift);
  CHECK(r.status.t == 0.0);
  CHECK_THAT(r.status.message, Catch::Contains("t = 0") && Catch::Contains("after projection") &&
                            Catch::Contains("tolerance 1e-30"));
  CHECK(std::string(r.status.name()) == "constraint_drift");
}

TEST_CASE("simulation: a batch equals the same runs one by one, on any number of threads",
          "[simulation][batch]") {
  const PaperPendulumLoop loop(1.0, 0.01);
  std::vector<VectorXd> starts;
  for (int k = 0; k < 5; ++k) {
    VectorXd x = loop.start;
    x(0) += 0.01 * k;
    x(3) -= 0.05 * k;
    starts.push_back(x);
  }
  SimulationOptions opt;
  opt.method = trellis::IntegrationMethod::kBDF;
  opt.inputLower = VectorXd::Constant(1, -0.5);
  opt.inputUpper = VectorXd::Constant(1, 0.5);
  const std::vector<SimulationResult> one = trellis::simulateBatch(
      loop.model, loop.reference, loop.gains, starts, opt, 1);
  const std::vector<SimulationResult> two = trellis::simulateBatch(
      loop.model, loop.reference, loop.gains, starts, opt, 2);
  REQUIRE(one.size() == starts.size());
  REQUIRE(two.size() == starts.size());
  for (std::size_t k = 0; k < starts.size(); ++k) {
    INFO("start " << k);
    const SimulationResult alone =
        trellis::simulateClosedLoop(loop.model, loop.reference, loop.gains, starts[k], opt);
    REQUIRE(alone.ok());
    for (const SimulationResult* r : {&one[k], &two[k]}) {
      REQUIRE(r->ok());
      // Bit-identical: the same operations in the same order on private buffers.
      CHECK(r->trajectory.times() == alone.trajectory.times());
      CHECK(r->trajectory.states() == alone.trajectory.states());
      CHECK(r->trajectory.inputs() == alone.trajectory.inputs());
      CHECK(r->trackingError == alone.trackingError);
      CHECK(r->steps == alone.steps);
    }
  }
  CHECK(one[0].trajectory.states() != one[4].trajectory.states());  // distinct starts, distinct runs
  CHECK_THROWS_WITH(trellis::simulateBatch(loop.model, loop.reference, loop.gains,
                                           {VectorXd::Zero(3)}, opt, 2),
                    Catch::Contains("initial state 0") && Catch::Contains("x0 has size 3"));
}

TEST_CASE("simulation: the structured Newton solve equals the dense (I − γJ)⁻¹", "[simulation][jacobian]") {
  // BDF's Newton systems (I − γJ) z = r solved through J = [[0, I], [A_q, A_v]] with one n×n LU
  // (closed_loop_system.hpp), against the dense 2n×2n solve of the same J: at the set-up's γ, at
  // another γ (refactored), and with CVODES's "J still good" (no new Jacobian).
  auto check = [](trellis::detail::ClosedLoopSystem& sys, double t, const VectorXd& y) {
    const Eigen::Index nx = y.size(), n = nx / 2;
    REQUIRE(sys.hasPreconditioner());
    const MatrixXd J = exactJacobian(sys, t, y);
    // The structure the solve relies on: ∂q̇/∂q = 0, ∂q̇/∂q̇ = I.
    CHECK(J.topLeftCorner(n, n).cwiseAbs().maxCoeff() == 0.0);
    CHECK(J.topRightCorner(n, n) == MatrixXd::Identity(n, n));
    VectorXd f(nx), z(nx);
    REQUIRE(sys.rhs(t, trellis::detail::ConstVectorMap(y.data(), nx), trellis::detail::VectorMap(f.data(), nx)) == 0);
    const trellis::detail::ConstVectorMap ym(y.data(), nx), fm(f.data(), nx);
    const VectorXd r = VectorXd::LinSpaced(nx, -1.0, 2.0).array().sin() + 0.1;
    bool updated = false;
    const double gammas[] = {1e-3, 2.7e-4, 5e-2};
    REQUIRE(sys.preconditionerSetup(t, ym, fm, false, &updated, gammas[0]) == 0);
    CHECK(updated);
    const long jacobians = sys.structuredJacobians();
    for (const double gamma : gammas) {
      REQUIRE(sys.preconditionerSolve(t, ym, fm, trellis::detail::ConstVectorMap(r.data(), nx),
                                      trellis::detail::VectorMap(z.data(), nx), gamma) == 0);
      const MatrixXd newton = MatrixXd::Identity(nx, nx) - gamma * J;
      const VectorXd expected = newton.partialPivLu().solve(r);
      INFO("gamma = " << gamma);
      CHECK((z - expected).cwiseAbs().maxCoeff() <= 1e-12 * expected.cwiseAbs().maxCoeff());
      // The residual as a backward error, entry by entry against |N||z| + |r| (what rounding in a
      // stable solve is proportional to; |r| alone is not when γ|J| ≫ 1: the free-ball hand's
      // J has entries to 7e4, and |z| ≈ 100 |r| at γ = 0.05).
      const VectorXd scale = newton.cwiseAbs() * z.cwiseAbs() + r.cwiseAbs();
      CHECK(((newton * z - r).cwiseAbs().array() / scale.array()).maxCoeff() <= 1e-13);
    }
    REQUIRE(sys.preconditionerSetup(t, ym, fm, true, &updated, gammas[2]) == 0);
    CHECK_FALSE(updated);
    CHECK(sys.structuredJacobians() == jacobians);
  };

  SECTION("the paper pendulum under time-varying feedback (constrained, deviation coordinates)") {
    const PaperPendulumLoop loop;
    trellis::detail::InputLaw law;
    law.kind = trellis::detail::InputLaw::Kind::kFeedback;
    law.reference = &loop.reference;
    law.gains = &loop.gains;
    trellis::detail::ClosedLoopSystem sys(loop.model, law, SimulationOptions{});
    const double t = 0.537;
    const VectorXd x = loop.reference.state(t) + (VectorXd(4) << 0.02, -0.01, 0.2, 0.1).finished();
    VectorXd y(4);
    sys.toIntegrator(t, x, y);
    check(sys, t, y);
  }
  SECTION("the hand holding a free ball under a held input (26 coordinates, 15 contact rows)") {
    const trellis::Scene scene = trellis::loadScene(TRELLIS_SOURCE_DIR "/examples/scenes/hand_ball.json");
    const trellis::Policy hold = [&scene](double, const VectorXd&, VectorXd& u) { u = scene.u; };
    trellis::detail::InputLaw law;
    law.kind = trellis::detail::InputLaw::Kind::kPolicy;
    law.policy = &hold;
    SimulationOptions opt;
    opt.sampleRate = 200.0;
    trellis::detail::ClosedLoopSystem sys(scene.model, law, opt);
    VectorXd x(2 * scene.model.nq());
    x << scene.q, VectorXd::LinSpaced(scene.model.nq(), -0.3, 0.4);
    bool clipped = false;
    REQUIRE(sys.sample(0.0, x, clipped));
    check(sys, 0.0, x);
  }
}
