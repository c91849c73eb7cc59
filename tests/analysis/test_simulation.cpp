// Tests for trellis/analysis/simulation.hpp: open loop against closed forms (pendulum period and
// energy, spring–mass), constraint drift with and without projection, closed-loop stabilization
// (cart-pole, TV-LQR tracking of a swinging pendulum), sampled feedback, saturation, failures, the
// per-step check.
#include "control_test_support.hpp"

#include <trellis/core/gain_schedule.hpp>
#include <trellis/control/lqr.hpp>
#include <trellis/control/riccati.hpp>
#include <trellis/analysis/simulation.hpp>
#include <trellis/core/trajectory.hpp>
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::ConstraintHandling;
using trellis::GainSchedule;
using trellis::Model;
using trellis::SimulationOptions;
using trellis::SimulationResult;
using trellis::SimulationCode;
using trellis::Trajectory;

namespace {

constexpr double kGravity = 9.81;

/// Point mass m at distance L below a pivot (θ = 0 hanging down); optional torque input "tau".
Model makePendulum(bool withInput, double m = 1.0, double L = 1.0) {
  trellis::ModelBuilder b("pendulum");
  b.addFrame("arm", "world", trellis::Transform::rz("theta"));
  b.addFrame("bob", "arm", trellis::Transform::ty(-L), trellis::Mass{m, Eigen::Matrix3d::Zero()});
  b.addGravity({0.0, -kGravity, 0.0});
  if (withInput) b.addConfigForce("theta", "tau");
  return std::move(b).finalize();
}

/// Cart of mass m on a spring of stiffness k (ω² = k/m) with a force input "f".
Model makeSpringMass(double m, double k) {
  trellis::ModelBuilder b("spring_mass");
  b.addFrame("cart", "world", trellis::Transform::tx("x"),
             trellis::Mass{m, Eigen::Matrix3d::Zero()});
  b.addConfigSpring("x", k, 0.0);
  b.addConfigForce("x", "f");
  return std::move(b).finalize();
}

double energy(const Model& model, const VectorXd& x) {
  trellis::Data data(model);
  const int n = model.nq();
  return trellis::computeEnergy(model, data, x.head(n), x.tail(n)).total();
}

/// A constant reference at state x and input u on [0, T] (two knots).
Trajectory constantReference(const Model& model, const VectorXd& x, const VectorXd& u, double T) {
  MatrixXd X(x.size(), 2), U(u.size(), 2);
  X << x, x;
  U << u, u;
  Trajectory ref(model.configNames(), model.inputNames(), (VectorXd(2) << 0.0, T).finished(), X, U);
  trellis::Data data(model);
  ref.computeStateDerivatives(model, data);
  return ref;
}

const trellis::Policy zeroInput = [](double, const VectorXd&, VectorXd& u) { u.setZero(); };

/// The cart-pole held upright by the CARE gain of its linearization at the upright equilibrium.
struct UprightCartPole {
  Model model = trellis::ctest::makeCartPole();
  Trajectory reference;
  GainSchedule gains;
  VectorXd closedLoopEigenvalueRealParts;

  explicit UprightCartPole(double T) {
    const VectorXd x = VectorXd::Zero(4), u = VectorXd::Zero(1);
    reference = constantReference(model, x, u, T);
    trellis::Data data(model);
    const VectorXd q = VectorXd::Zero(2);
    REQUIRE(trellis::computeLinearization(model, data, q, q, u).ok());
    const MatrixXd Q = VectorXd((VectorXd(4) << 10.0, 10.0, 1.0, 1.0).finished()).asDiagonal();
    const auto care = trellis::solveCare(data.A, data.B, Q, MatrixXd::Identity(1, 1));
    REQUIRE(care.ok());
    closedLoopEigenvalueRealParts = care.closedLoopEigenvalues.real();
    gains = GainSchedule((VectorXd(2) << 0.0, T).finished(), {care.K, care.K});
  }
};

}  // namespace

TEST_CASE("simulation: open-loop pendulum against the elliptic-integral period and energy",
          "[simulation]") {
  const Model model = makePendulum(false);
  const double theta0 = 2.0;  // a large swing: the period is 1.35 × the small-angle one
  const double omega = std::sqrt(kGravity / 1.0);
  // T = 4 K(k) / ω with k = sin(θ0/2): closed form for the frictionless pendulum.
  const double period = 4.0 * std::comp_ellint_1(std::sin(theta0 / 2.0)) / omega;
  const VectorXd x0 = (VectorXd(2) << theta0, 0.0).finished();
  SimulationOptions opt;
  opt.rtol = 1e-10;
  opt.atol = 1e-12;
  opt.outputStep = period / 4.0;
  const SimulationResult r = trellis::simulate(model, x0, 0.0, 3.0 * period, zeroInput, opt);
  REQUIRE(r.ok());
  REQUIRE(r.trajectory.size() == 13);  // t = 0, T/4, …, 3T
  const MatrixXd& X = r.trajectory.states();
  // The global error of an error-controlled run at rtol 1e-10 over ~20 s stays near 1e-8 (it grows
  // about linearly in the number of steps); 1e-6 rad leaves a wide margin yet catches a wrong
  // period (a 1e-6 relative period error would give ~2e-5 rad after three periods).
  for (int k = 0; k < r.trajectory.size(); ++k) {
    const double expected = (k % 4 == 0) ? theta0 : (k % 4 == 2) ? -theta0 : 0.0;
    INFO("t = " << r.trajectory.times()(k));
    if (k % 2 == 0) {
      CHECK(std::abs(X(0, k) - expected) < 1e-6);
      CHECK(std::abs(X(1, k)) < 1e-6 * omega);
    } else {
      CHECK(std::abs(X(0, k)) < 1e-6);  // through the bottom at the quarter periods
    }
  }
  // Energy is conserved to the tolerance: |ΔE| ≤ 1e-7 |E|, same reasoning.
  const double E0 = energy(model, x0);
  for (int k = 0; k < r.trajectory.size(); ++k) {
    CHECK(std::abs(energy(model, X.col(k)) - E0) < 1e-7 * std::abs(E0));
  }
  CHECK(r.constraintDrift.size() == r.trajectory.size());
  CHECK(r.constraintDrift.cwiseAbs().maxCoeff() == 0.0);  // no constraints
  CHECK(r.trackingError.size() == 0);                     // no reference
  CHECK(r.steps > 0);
  CHECK(r.rhsEvaluations >= r.steps);

  SECTION("a looser tolerance gives a larger energy error (the tolerance is really used)") {
    SimulationOptions loose = opt;
    loose.rtol = 1e-5;
    loose.atol = 1e-7;
    const SimulationResult rl = trellis::simulate(model, x0, 0.0, 3.0 * period, zeroInput, loose);
    REQUIRE(rl.ok());
    double worstTight = 0.0, worstLoose = 0.0;
    for (int k = 0; k < r.trajectory.size(); ++k) {
      worstTight = std::max(worstTight, std::abs(energy(model, X.col(k)) - E0));
      worstLoose =
          std::max(worstLoose, std::abs(energy(model, rl.trajectory.states().col(k)) - E0));
    }
    CHECK(worstLoose > 10.0 * worstTight);
    CHECK(rl.steps < r.steps);
  }
  SECTION("BDF agrees with Adams") {
    SimulationOptions bdf = opt;
    bdf.method = trellis::IntegrationMethod::kBDF;
    const SimulationResult rb = trellis::simulate(model, x0, 0.0, 3.0 * period, zeroInput, bdf);
    REQUIRE(rb.ok());
    // Both are within ~1e-8 of the exact solution (above); 1e-6 is the same margin.
    CHECK((rb.trajectory.states() - X).cwiseAbs().maxCoeff() < 1e-6);
  }
}

TEST_CASE("simulation: open-loop spring–mass follows the closed form", "[simulation]") {
  const double mass = 2.0, k = 8.0, omega = std::sqrt(k / mass);  // ω = 2
  const Model model = makeSpringMass(mass, k);
  const double force = 1.5, xs = force / k;  // static deflection under the constant force
  // Reference = the closed-form motion x(t) = xs + (1 − xs) cos ωt with u = force, tabulated at
  // 101 knots over 10 s: the tracking error at the knots is the simulation error itself.
  const int N = 101;
  const double T = 10.0;
  VectorXd t(N);
  MatrixXd X(2, N), U = MatrixXd::Constant(1, N, force);
  for (int i = 0; i < N; ++i) {
    t(i) = T * i / (N - 1);
    X(0, i) = xs + (1.0 - xs) * std::cos(omega * t(i));
    X(1, i) = -(1.0 - xs) * omega * std::sin(omega * t(i));
  }
  const Trajectory reference(model.configNames(), model.inputNames(), t, X, U);
  const VectorXd x0 = X.col(0);

  SECTION("default tolerances, and tighter ones") {
    const SimulationResult r = trellis::simulateOpenLoop(model, reference, x0);
    REQUIRE(r.ok());
    REQUIRE(r.trajectory.size() == N);  // outputs at the knots
    CHECK(r.trajectory.times() == t);
    // rtol 1e-8 on an amplitude-1 motion over ~3 periods: the global error is a few 1e-7;
    // 1e-6 bounds it. A wrong frequency or force would be off by far more (1e-3 and beyond).
    INFO("max error " << r.trackingError.maxCoeff());
    CHECK(r.trackingError.maxCoeff() < 1e-6);
    CHECK(r.trajectory.inputs().cwiseAbs().maxCoeff() == Approx(force).epsilon(1e-15));
    CHECK(r.restarts == 0);  // u_ref is continuous: the knots are outputs, not restarts
    SimulationOptions tight;
    tight.rtol = 1e-11;
    tight.atol = 1e-13;
    const SimulationResult rt = trellis::simulateOpenLoop(model, reference, x0, tight);
    REQUIRE(rt.ok());
    // Same argument, 1000× tighter tolerances: the error must follow (to ~1e-9; 1e-8 bounds it).
    INFO("max error (tight) " << rt.trackingError.maxCoeff());
    CHECK(rt.trackingError.maxCoeff() < 1e-8);
  }
  SECTION("uniform output grid") {
    SimulationOptions opt;
    opt.outputStep = 0.3;
    const SimulationResult r = trellis::simulateOpenLoop(model, reference, x0, opt);
    REQUIRE(r.ok());
    REQUIRE(r.trajectory.size() == 35);  // 0, 0.3, …, 9.9, and 10
    for (int i = 0; i < r.trajectory.size(); ++i) {
      const double ti = r.trajectory.times()(i);
      CHECK(ti == Approx(std::min(0.3 * i, T)).margin(1e-12));
      // Interpolated outputs (no restart there) are CVODES' dense output: same accuracy as above.
      CHECK(std::abs(r.trajectory.states()(0, i) - (xs + (1.0 - xs) * std::cos(omega * ti))) <
            1e-6);
    }
  }
}

TEST_CASE("simulation: constrained paper pendulum keeps its constraint and its energy",
          "[simulation]") {
  const trellis::Scene scene =
      trellis::loadScene(TRELLIS_SOURCE_DIR "/examples/scenes/paper_pendulum.json");
  const Model& model = scene.model;
  REQUIRE(model.nc() == 1);
  VectorXd x0(4);
  x0 << scene.q, scene.dq;
  // The printed state is off the constraint (h = −3.47e-3): project it first.
  VectorXd xp = x0;
  const auto proj = trellis::projectOntoConstraints(model, xp);
  CHECK(proj.driftBefore == Approx(3.47e-3).epsilon(0.01));
  CHECK(proj.driftAfter < 1e-12);  // Gauss–Newton converges quadratically to rounding
  CHECK(proj.iterations >= 1);
  CHECK(proj.ok());
  CHECK_THAT(proj.describe(), Catch::StartsWith("ok (drift "));
  CHECK_THAT(proj.json(), Catch::StartsWith("{\"status\":\"ok\",\"ok\":true,"));

  SECTION("the velocity correction is M-orthogonal: M δq̇ is parallel to A(q)ᵀ") {
    // Isolate the velocity step: q already projected, q̇ the paper's (A q̇ ≠ 0 at this q).
    VectorXd xv(4);
    xv << xp.head(2), x0.tail(2);
    trellis::projectOntoConstraints(model, xv);
    trellis::Data data(model);
    trellis::computeMassMatrix(model, data, xp.head(2));  // the metric of that call
    trellis::computeConstraints(model, data, xv.head(2), xv.tail(2));
    const VectorXd a = data.constraintJacobian.row(0).transpose();
    const VectorXd Md = data.M * (xv.tail(2) - x0.tail(2));
    // M δq̇ = Aᵀ p for some scalar p: the 2-D cross product vanishes up to rounding.
    CHECK(std::abs(Md(0) * a(1) - Md(1) * a(0)) < 1e-12 * Md.norm() * a.norm());
    CHECK(Md.norm() > 1e-3);  // the paper velocity is really corrected
    CHECK(std::abs(a.dot(xv.tail(2))) < 1e-12 * a.norm() * xv.tail(2).norm());
  }

  const double E0 = energy(model, xp);
  const double T = 4.0;
  SimulationOptions opt;
  opt.outputStep = 0.02;
  opt.constraints = ConstraintHandling::kProject;
  const SimulationResult rp = trellis::simulate(model, xp, 0.0, T, zeroInput, opt);
  opt.constraints = ConstraintHandling::kNone;
  const SimulationResult rn = trellis::simulate(model, xp, 0.0, T, zeroInput, opt);
  REQUIRE(rp.ok());
  REQUIRE(rn.ok());
  REQUIRE(rp.trajectory.size() == 201);
  INFO("max drift: projected " << rp.maxConstraintDrift << ", unprojected "
                               << rn.maxConstraintDrift);
  // Drift is integration error only (the dynamics enforce A q̈ + Ȧ q̇ = 0). Projected, it is the
  // error of one 0.02 s interval at rtol 1e-8 on velocities of ~5 (measured 2e-8); 2e-7 bounds
  // it. Unprojected it accumulates over the 200 intervals (measured 4.5e-7); 1e-5 bounds it.
  CHECK(rp.maxConstraintDrift < 2e-7);
  CHECK(rn.maxConstraintDrift < 1e-5);
  // Projecting resets the drift every interval, so it cannot accumulate as it does without.
  CHECK(rp.maxConstraintDrift < rn.maxConstraintDrift);
  CHECK(rp.projections > 0);
  CHECK(rn.projections == 0);
  // Energy: conserved by the exact flow; the M-orthogonal velocity projection never adds kinetic
  // energy. Integration error at rtol 1e-8 over 4 s: ~1e-7 relative (measured 1.0e-7 projected,
  // 1.6e-7 not); 1e-5 leaves a margin and still catches a wrong force or a bad projection.
  for (const SimulationResult* r : {&rp, &rn}) {
    double worst = 0.0;
    for (int k = 0; k < r->trajectory.size(); ++k) {
      worst = std::max(worst, std::abs(energy(model, r->trajectory.states().col(k)) - E0));
    }
    INFO("energy error " << worst << " of " << E0);
    CHECK(worst < 1e-5 * std::abs(E0));
  }
  // The two runs are the same motion to integration accuracy.
  CHECK((rp.trajectory.states() - rn.trajectory.states()).cwiseAbs().maxCoeff() < 1e-4);
}

TEST_CASE("simulation: LQR holds the cart-pole upright from perturbed starts", "[simulation]") {
  const double T = 8.0;
  const UprightCartPole cp(T);
  // The slowest closed-loop mode decays like exp(max Re λ · t); over T it must beat 1e-2.
  const double slowest = cp.closedLoopEigenvalueRealParts.maxCoeff();
  REQUIRE(slowest < 0.0);
  REQUIRE(std::exp(slowest * T) < 1e-3);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> angle(0.1, 0.3), small(-0.3, 0.3);
  SimulationOptions opt;
  opt.outputStep = 0.05;
  for (int trial = 0; trial < 4; ++trial) {
    const double sign = (trial % 2 == 0) ? 1.0 : -1.0;
    const VectorXd x0 =
        (VectorXd(4) << small(rng), sign * angle(rng), small(rng), small(rng)).finished();
    INFO("trial " << trial << ", x0 = " << x0.transpose());
    const SimulationResult r =
        trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, x0, opt);
    REQUIRE(r.ok());
    const double e0 = r.trackingError(0), eT = r.trackingError(r.trackingError.size() - 1);
    CHECK(e0 == Approx(x0.norm()).epsilon(1e-14));
    CHECK(eT < 1e-2 * e0);
    CHECK(r.saturatedSamples == 0);  // no limits given
    // The applied input is the feedback law at the recorded states: u = −K x.
    for (int k = 0; k < r.trajectory.size(); k += 17) {
      const double u = -(cp.gains.gains()[0] * r.trajectory.states().col(k))(0);
      CHECK(r.trajectory.inputs()(0, k) == Approx(u).epsilon(1e-12).margin(1e-12));
    }
    // Without feedback the pole falls from the same start: the open loop diverges.
    const SimulationResult open = trellis::simulateOpenLoop(cp.model, cp.reference, x0, opt);
    CHECK((!open.ok() || open.trackingError.maxCoeff() > 1.0));
  }
}

TEST_CASE("simulation: TV-LQR tracks a swinging pendulum after a kick", "[simulation]") {
  const Model model = makePendulum(true);
  const double T = 4.0;
  // Reference: the free large swing from θ = 1.2 rad (u = 0), produced by simulating it.
  SimulationOptions refOpt;
  refOpt.rtol = 1e-10;
  refOpt.atol = 1e-12;
  refOpt.outputStep = 0.02;
  const SimulationResult swing =
      trellis::simulate(model, (VectorXd(2) << 1.2, 0.0).finished(), 0.0, T, zeroInput, refOpt);
  REQUIRE(swing.ok());
  const Trajectory& reference = swing.trajectory;
  REQUIRE(reference.hasStateDerivatives());

  trellis::LqrWeights w;
  w.Q = MatrixXd::Identity(2, 2) * 10.0;
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = MatrixXd::Identity(2, 2) * 10.0;
  const trellis::RiccatiSolution riccati = trellis::solveRiccati(model, reference, w);
  REQUIRE(riccati.ok());
  const GainSchedule gains =
      GainSchedule::sample([&](double t) { return riccati.K(t); }, reference.times());
  // The gain really varies along the swing (TV-LQR, not a constant gain).
  CHECK((gains.gains().front() - gains.gains()[50]).norm() > 0.1);

  const VectorXd kick = (VectorXd(2) << 0.15, -0.4).finished();
  const VectorXd x0 = reference.states().col(0) + kick;
  const SimulationResult closed = trellis::simulateClosedLoop(model, reference, gains, x0);
  const SimulationResult open = trellis::simulateOpenLoop(model, reference, x0);
  REQUIRE(closed.ok());
  REQUIRE(open.ok());
  const double e0 = closed.trackingError(0);
  CHECK(e0 == Approx(kick.norm()).epsilon(1e-12));
  const double closedFinal = closed.trackingError(closed.trackingError.size() - 1);
  const double openFinal = open.trackingError(open.trackingError.size() - 1);
  INFO("initial " << e0 << ", closed-loop final " << closedFinal << ", open-loop final "
                  << openFinal);
  CHECK(closedFinal < 0.1 * e0);
  // The kicked free pendulum has another energy and period: its phase error does not decay.
  CHECK(openFinal > 0.5 * e0);
}

TEST_CASE("simulation: sampled feedback and input limits", "[simulation]") {
  const double T = 8.0;
  const UprightCartPole cp(T);
  const VectorXd x0 = (VectorXd(4) << 0.2, 0.25, 0.0, 0.0).finished();

  SECTION("zero-order hold at 50 Hz still stabilizes; at 2 Hz it does not") {
    SimulationOptions opt;
    opt.outputStep = 0.005;
    opt.sampleRate = 50.0;
    const SimulationResult r =
        trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, x0, opt);
    REQUIRE(r.ok());
    CHECK(r.trackingError(r.trackingError.size() - 1) < 1e-2 * r.trackingError(0));
    CHECK(r.controlSamples == 400);  // samples at 0, 0.02, …, 7.98
    // u is held: the four outputs inside each 0.02 s sample period carry the sample's value,
    // which is −K x at the sample time (outputs at 0.005 spacing land on every sample).
    const MatrixXd& U = r.trajectory.inputs();
    const MatrixXd& X = r.trajectory.states();
    for (int k = 0; k + 4 < r.trajectory.size(); k += 4) {
      CHECK(U(0, k) == Approx(-(cp.gains.gains()[0] * X.col(k))(0)).epsilon(1e-12).margin(1e-12));
      for (int j = 1; j < 4; ++j) CHECK(U(0, k + j) == U(0, k));
    }
    opt.sampleRate = 2.0;
    opt.maxSteps = 20000;  // the diverging run would otherwise crawl through a huge state
    const SimulationResult slow =
        trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, x0, opt);
    CHECK((!slow.ok() || slow.trackingError.maxCoeff() > 1.0));
  }

  SECTION("saturation clips, is counted and equals a policy that clips itself") {
    const double limit = 5.0;
    SimulationOptions opt;
    opt.outputStep = 0.01;
    opt.inputLower = VectorXd::Constant(1, -limit);
    opt.inputUpper = VectorXd::Constant(1, limit);
    const SimulationResult r =
        trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, x0, opt);
    REQUIRE(r.ok());
    CHECK(r.trajectory.inputs().cwiseAbs().maxCoeff() <= limit);
    CHECK(r.saturatedSamples > 0);
    CHECK(r.controlSamples == r.trajectory.size());  // continuous: one evaluation per output
    CHECK(r.saturatedFraction == Approx(double(r.saturatedSamples) / r.controlSamples));
    CHECK(r.saturatedFraction < 0.5);
    // Independent path: the same law with the clipping written out in the policy.
    const MatrixXd K = cp.gains.gains()[0];
    const trellis::Policy clipped = [&](double, const VectorXd& x, VectorXd& u) {
      u(0) = std::clamp(-(K * x)(0), -limit, limit);
    };
    SimulationOptions plain;
    plain.outputStep = 0.01;
    const SimulationResult manual =
        trellis::simulate(cp.model, x0, 0.0, T, clipped, plain, &cp.reference);
    REQUIRE(manual.ok());
    // Same right-hand side, same restarts: the runs agree to rounding amplified by the steps.
    CHECK((manual.trajectory.states() - r.trajectory.states()).cwiseAbs().maxCoeff() < 1e-9);
    // Unclipped, the same start asks for more than the limit (so clipping was really needed).
    const SimulationResult free = trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, x0);
    CHECK(free.trajectory.inputs().cwiseAbs().maxCoeff() > 1.5 * limit);
    // And clipping still lets the loop recover here (the limit is above the gravity load).
    CHECK(r.trackingError(r.trackingError.size() - 1) < 1e-2 * r.trackingError(0));
  }
}

TEST_CASE("simulation: failures carry the time and the state", "[simulation]") {
  const double T = 2.0;
  const UprightCartPole cp(T);
  const VectorXd x0 = (VectorXd(4) << 0.1, 0.2, 0.0, 0.0).finished();

  SECTION("a tiny step budget: integrator failure") {
    SimulationOptions opt;
    opt.maxSteps = 20;
    opt.outputStep = 0.5;
    const SimulationResult r =
        trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, x0, opt);
    CHECK(r.status.code == SimulationCode::kIntegratorFailure);
    CHECK_FALSE(r.ok());
    CHECK(r.status.t > 0.0);
    CHECK(r.status.t < T);
    REQUIRE(r.failureState.size() == 4);
    CHECK(r.failureState.allFinite());
    CHECK(r.steps <= 20);
    CHECK_THAT(r.status.message, Catch::Contains("t = ") && Catch::Contains("x = [") &&
                              Catch::Contains("maxSteps = 20"));
    // The trajectory holds the outputs reached before the failure.
    CHECK(r.trajectory.size() >= 1);
    CHECK(r.trajectory.endTime() <= r.status.t);
    CHECK(std::string(r.status.name()) == "integrator_failure");
  }
  SECTION("a joint that moves no mass: dynamics failure at the start") {
    trellis::ModelBuilder b("massless");
    b.addFrame("cart", "world", trellis::Transform::tx("x"),
               trellis::Mass{1.0, Eigen::Matrix3d::Zero()});
    b.addFrame("spinner", "cart", trellis::Transform::rz("phi"));
    const Model model = std::move(b).finalize();
    SimulationOptions opt;
    opt.outputStep = 0.1;
    const VectorXd start = (VectorXd(4) << 0.0, 0.3, 1.0, 0.0).finished();
    const SimulationResult r = trellis::simulate(model, start, 0.0, 1.0, zeroInput, opt);
    CHECK(r.status.code == SimulationCode::kDynamicsFailure);
    CHECK(r.status.t == Approx(0.0).margin(1e-12));
    CHECK(r.failureState == start);
    CHECK_THAT(r.status.message,
               Catch::Contains("computeDynamics failed") && Catch::Contains("x = [0, 0.3, 1, 0]"));
  }
  SECTION("a policy that returns NaN after t = 0.75: non-finite, at that time") {
    const trellis::Policy nanAfter = [](double t, const VectorXd&, VectorXd& u) {
      u(0) = t > 0.75 ? std::numeric_limits<double>::quiet_NaN() : 0.0;
    };
    SimulationOptions opt;
    opt.outputStep = 0.1;
    const SimulationResult r = trellis::simulate(cp.model, x0, 0.0, T, nanAfter, opt);
    CHECK(r.status.code == SimulationCode::kNonFinite);
    CHECK(r.status.t > 0.75);
    CHECK(r.status.t < 0.8);
    CHECK_THAT(r.status.message, Catch::Contains("non-finite input"));
    CHECK(r.trajectory.endTime() == Approx(0.7));
  }
  SECTION("a policy that throws: policy failure with its message") {
    const trellis::Policy throwing = [](double t, const VectorXd&, VectorXd& u) {
      if (t > 0.35) throw std::runtime_error("actuator offline");
      u.setZero();
    };
    SimulationOptions opt;
    opt.outputStep = 0.1;
    const SimulationResult r = trellis::simulate(cp.model, x0, 0.0, T, throwing, opt);
    CHECK(r.status.code == SimulationCode::kPolicyFailure);
    CHECK(r.status.t > 0.35);
    CHECK(r.status.t < 0.4);
    CHECK_THAT(r.status.message, Catch::Contains("actuator offline"));
  }
}

TEST_CASE("simulation: the step check sees every integrator step and stops at a violation",
          "[simulation]") {
  // The paper pendulum (one constraint; λ its rod force) swinging from its projected start.
  const trellis::Scene scene =
      trellis::loadScene(TRELLIS_SOURCE_DIR "/examples/scenes/paper_pendulum.json");
  const Model& model = scene.model;
  const int n = model.nq();
  VectorXd x0(2 * n);
  x0 << scene.q, scene.dq;
  trellis::projectOntoConstraints(model, x0);
  const double T = 2.0;
  SimulationOptions plain;
  plain.outputStep = 0.02;
  const SimulationResult free = trellis::simulate(model, x0, 0.0, T, zeroInput, plain);
  REQUIRE(free.ok());
  CHECK(free.checks == 0);
  // λ along the unchecked run at its outputs (an independent computeDynamics).
  trellis::Data data(model);
  VectorXd lambdaAt(free.trajectory.size());
  for (int k = 0; k < free.trajectory.size(); ++k) {
    const VectorXd x = free.trajectory.states().col(k);
    REQUIRE(trellis::computeDynamics(model, data, x.head(n), x.tail(n), VectorXd::Zero(model.nu())).ok());
    lambdaAt(k) = data.lambda(0);
  }
  REQUIRE(lambdaAt.maxCoeff() - lambdaAt.minCoeff() > 1e-3);  // λ really varies over the swing

  SECTION("a check that always passes: called at t0 and every step end with the core's λ, run unchanged") {
    long calls = 0;
    double worstLambdaError = 0.0;
    trellis::Data own(model);
    SimulationOptions opt = plain;
    opt.stepCheck = [&](double, const VectorXd& x, const VectorXd& u, const VectorXd& lambda) {
      ++calls;
      trellis::computeDynamics(model, own, x.head(n), x.tail(n), u);
      worstLambdaError = std::max(worstLambdaError, (lambda - own.lambda).cwiseAbs().maxCoeff());
      return std::string();
    };
    const SimulationResult r = trellis::simulate(model, x0, 0.0, T, zeroInput, opt);
    REQUIRE(r.ok());
    CHECK(r.checks == calls);
    // t0, every accepted step, and every restart after a projection (the start is projected).
    CHECK(r.checks == r.steps + 1 + r.projections);
    CHECK(worstLambdaError == 0.0);  // the same computeDynamics at the same (x, u)
    // The check does not touch the integration: the same outputs to the bit.
    CHECK(r.trajectory.states() == free.trajectory.states());
    CHECK_THAT(r.json(), Catch::Contains("\"checks\":" + std::to_string(r.checks)));
  }
  SECTION("Radau: a step end's λ is the right-hand side's own evaluation there, equal to a fresh one") {
    SimulationOptions opt = plain;
    opt.method = trellis::IntegrationMethod::kRadau;
    opt.sampleRate = 50.0;  // a held (zero) input: the exact Jacobian is known
    const SimulationResult unchecked = trellis::simulate(model, x0, 0.0, T, zeroInput, opt);
    REQUIRE(unchecked.ok());
    long calls = 0;
    double worstLambdaError = 0.0;
    trellis::Data own(model);
    opt.stepCheck = [&](double, const VectorXd& x, const VectorXd& u, const VectorXd& lambda) {
      ++calls;
      trellis::computeDynamics(model, own, x.head(n), x.tail(n), u);
      worstLambdaError = std::max(worstLambdaError, (lambda - own.lambda).cwiseAbs().maxCoeff());
      return std::string();
    };
    const SimulationResult r = trellis::simulate(model, x0, 0.0, T, zeroInput, opt);
    REQUIRE(r.ok());
    CHECK(r.checks == calls);
    CHECK(r.checks >= r.steps + 1);
    CHECK(worstLambdaError == 0.0);  // bit for bit: the same function of (x, u)
    CHECK(r.trajectory.states() == unchecked.trajectory.states());
    // Against BDF's run of the same swing: the same motion to the tolerances.
    CHECK((r.trajectory.states() - free.trajectory.states()).cwiseAbs().maxCoeff() < 1e-5);
  }
  SECTION("a bound that λ crosses mid-swing: check_failed at the first step end beyond it") {
    const double bound = 0.5 * (lambdaAt.maxCoeff() + lambdaAt.minCoeff());
    Eigen::Index first = 0;
    while (lambdaAt(first) <= bound) ++first;  // the first output beyond the bound (λ(0) below it)
    REQUIRE(first > 0);
    SimulationOptions opt = plain;
    opt.stepCheck = [bound](double, const VectorXd&, const VectorXd&, const VectorXd& lambda) {
      return lambda(0) > bound ? "lambda " + std::to_string(lambda(0)) + " > " + std::to_string(bound)
                               : std::string();
    };
    const SimulationResult r = trellis::simulate(model, x0, 0.0, T, zeroInput, opt);
    CHECK_FALSE(r.ok());
    CHECK(r.status.code == SimulationCode::kCheckFailed);
    CHECK(std::string(r.status.name()) == "check_failed");
    CHECK_THAT(r.status.message, Catch::Contains("step check: lambda ") && Catch::Contains("t = "));
    // Between the last output below the bound and one output interval after the first beyond it
    // (step ends are checked, the integrator's steps here are far shorter than 0.02 s).
    const double tFirst = free.trajectory.times()(first);
    CHECK(r.status.t > tFirst - plain.outputStep);
    CHECK(r.status.t < tFirst + plain.outputStep);
    // The failure state really violates the bound, and the outputs before it are the free run's.
    REQUIRE(r.failureState.size() == 2 * n);
    REQUIRE(trellis::computeDynamics(model, data, r.failureState.head(n), r.failureState.tail(n),
                                     VectorXd::Zero(model.nu())).ok());
    CHECK(data.lambda(0) > bound);
    REQUIRE(r.trajectory.size() >= 1);
    CHECK(r.trajectory.endTime() <= r.status.t);
    const int rows = r.trajectory.size();
    CHECK(r.trajectory.states() == free.trajectory.states().leftCols(rows));
  }
  SECTION("a check that throws: check_failed with the exception's text") {
    SimulationOptions opt = plain;
    opt.stepCheck = [](double t, const VectorXd&, const VectorXd&, const VectorXd&) -> std::string {
      if (t > 0.3) throw std::runtime_error("sensor lost");
      return {};
    };
    const SimulationResult r = trellis::simulate(model, x0, 0.0, T, zeroInput, opt);
    CHECK(r.status.code == SimulationCode::kCheckFailed);
    CHECK(r.status.t > 0.3);
    CHECK_THAT(r.status.message, Catch::Contains("sensor lost"));
  }
  SECTION("sampled feedback: the held input, checked again after each new sample; no λ unconstrained") {
    const UprightCartPole cp(1.0);
    const VectorXd start = (VectorXd(4) << 0.1, 0.2, 0.0, 0.0).finished();
    SimulationOptions opt;
    opt.outputStep = 0.01;
    opt.sampleRate = 50.0;
    const SimulationResult unchecked = trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, start, opt);
    bool noLambda = true;
    int newSamples = 0;
    const MatrixXd K = cp.gains.gains()[0];
    opt.stepCheck = [&](double t, const VectorXd& x, const VectorXd& u, const VectorXd& lambda) {
      noLambda = noLambda && lambda.size() == 0;
      // At a sample time t_k the step ending there is checked with the old held input, then the
      // restart with the new sample −K x(t_k): count the latter.
      const double k = std::round(t * 50.0);
      if (std::abs(t - k / 50.0) < 1e-12 && t < 1.0 && std::abs(u(0) + (K * x)(0)) < 1e-12) ++newSamples;
      return std::string();
    };
    const SimulationResult r = trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, start, opt);
    REQUIRE(r.ok());
    REQUIRE(unchecked.ok());
    CHECK(noLambda);
    CHECK(newSamples == 50);
    CHECK(r.controlSamples == 50);
    // Every step end, t0, and each of the 49 samples after t0.
    CHECK(r.checks == r.steps + 1 + 49);
    CHECK(r.trajectory.states() == unchecked.trajectory.states());
  }
}

TEST_CASE("simulation: bad input is rejected with a clear message", "[simulation]") {
  const UprightCartPole cp(1.0);
  const VectorXd x0 = VectorXd::Zero(4);
  SimulationOptions opt;
  SECTION("options") {
    opt.rtol = -1.0;
    CHECK_THROWS_WITH(opt.validate(), Catch::Contains("rtol = -1"));
    opt = {};
    opt.sampleRate = std::numeric_limits<double>::infinity();
    CHECK_THROWS_WITH(opt.validate(), Catch::Contains("sampleRate"));
    opt = {};
    opt.inputLower = VectorXd::Constant(1, 1.0);
    opt.inputUpper = VectorXd::Constant(1, -1.0);
    CHECK_THROWS_WITH(opt.validate(), Catch::Contains("inputLower[0] = 1") &&
                                          Catch::Contains("inputUpper[0] = -1"));
    opt = {};
    opt.maxSteps = 0;
    CHECK_THROWS_WITH(trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, x0, opt),
                      Catch::Contains("maxSteps = 0"));
  }
  SECTION("sizes and spans") {
    opt.inputUpper = VectorXd::Constant(2, 1.0);
    CHECK_THROWS_WITH(trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, x0, opt),
                      Catch::Contains("inputUpper has size 2"));
    CHECK_THROWS_WITH(
        trellis::simulateClosedLoop(cp.model, cp.reference, cp.gains, VectorXd::Zero(3)),
        Catch::Contains("x0 has size 3"));
    const GainSchedule shortGains((VectorXd(2) << 0.0, 0.5).finished(), cp.gains.gains());
    CHECK_THROWS_WITH(trellis::simulateClosedLoop(cp.model, cp.reference, shortGains, x0),
                      Catch::Contains("covers [0, 0.5]"));
    const GainSchedule wrongSize((VectorXd(2) << 0.0, 1.0).finished(),
                                 {MatrixXd::Zero(1, 3), MatrixXd::Zero(1, 3)});
    CHECK_THROWS_WITH(trellis::simulateClosedLoop(cp.model, cp.reference, wrongSize, x0),
                      Catch::Contains("1x3"));
    CHECK_THROWS_WITH(trellis::simulate(cp.model, x0, 0.0, 1.0, zeroInput, SimulationOptions{}),
                      Catch::Contains("outputStep"));
    CHECK_THROWS_WITH(
        trellis::simulate(cp.model, x0, 0.0, 2.0, zeroInput, SimulationOptions{}, &cp.reference),
        Catch::Contains("does not contain"));
    const Model other = makePendulum(true);
    CHECK_THROWS_AS(trellis::simulateOpenLoop(other, cp.reference, VectorXd::Zero(2)),
                    trellis::TrajectoryError);
  }
}
