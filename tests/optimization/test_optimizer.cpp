// Tests for trellis/optimization/optimizer.hpp: Ipopt solves of the example problems — swing-ups
// converge from the default guess to a repeatable cost, the optimized trajectories are dynamically
// consistent, the closed chain keeps its constraints at the knots, a minimum-time problem
// reproduces its closed form, infeasibility and bad problem files are reported clearly.
#include <trellis/core.hpp>
#include <trellis/optimization.hpp>

#include <catch2/catch.hpp>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::CollocationMethod;
using trellis::OptimalControlProblem;
using trellis::OptimizationResult;
using trellis::OptimizationCode;

namespace {

std::string problemPath(const std::string& name) {
  return std::string(TRELLIS_SOURCE_DIR) + "/examples/problems/" + name + ".json";
}

std::string readText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// ẋ = f(x, u) with the core's forward dynamics.
VectorXd stateDerivative(const trellis::Model& model, trellis::Data& data, const VectorXd& x,
                         const VectorXd& u) {
  const int n = model.nq();
  const trellis::DynamicsStatus status = trellis::computeDynamics(model, data, x.head(n), x.tail(n), u);
  REQUIRE(status.ok());
  VectorXd dx(2 * n);
  dx << x.tail(n), data.qdd;
  return dx;
}

/// The collocation's input on interval k at τ ∈ [0, 1]: the quadratic through u_a, u_m, u_b
/// (Hermite–Simpson; u_m is constrained to the knot average, so this is the line as well, rebuilt
/// from the returned u_m as an independent check) or the line through u_a, u_b (trapezoidal).
VectorXd inputAt(const OptimizationResult& r, int k, double tau, bool hermiteSimpson) {
  const VectorXd ua = r.trajectory.inputs().col(k), ub = r.trajectory.inputs().col(k + 1);
  if (!hermiteSimpson) return (1 - tau) * ua + tau * ub;
  const VectorXd um = r.midpointInputs.col(k);
  return 2 * (tau - 0.5) * (tau - 1) * ua - 4 * tau * (tau - 1) * um + 2 * tau * (tau - 0.5) * ub;
}

/// For each interval, integrates the nonlinear dynamics from the collocation state x_k under the
/// collocation's input with fixed-step RK4 (200 steps, error ~(h/200)⁴ — negligible next to the
/// collocation error) and returns max_k ‖x(t_{k+1}) − x_{k+1}‖∞: the one-interval (local) error of
/// the transcription. Short windows, since a swing-up is unstable and errors grow along it.
double maxLocalError(const trellis::Model& model, const OptimizationResult& r, bool hermiteSimpson) {
  trellis::Data data(model);
  const int N = r.trajectory.size();
  double worst = 0.0;
  for (int k = 0; k + 1 < N; ++k) {
    const double h = r.trajectory.times()(k + 1) - r.trajectory.times()(k);
    const int steps = 200;
    const double dt = h / steps;
    VectorXd x = r.trajectory.states().col(k);
    for (int s = 0; s < steps; ++s) {
      const double t0 = static_cast<double>(s) / steps, t1 = static_cast<double>(s + 1) / steps;
      const double tm = 0.5 * (t0 + t1);
      const VectorXd k1 = stateDerivative(model, data, x, inputAt(r, k, t0, hermiteSimpson));
      const VectorXd k2 = stateDerivative(model, data, x + 0.5 * dt * k1, inputAt(r, k, tm, hermiteSimpson));
      const VectorXd k3 = stateDerivative(model, data, x + 0.5 * dt * k2, inputAt(r, k, tm, hermiteSimpson));
      const VectorXd k4 = stateDerivative(model, data, x + dt * k3, inputAt(r, k, t1, hermiteSimpson));
      x += dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
    }
    worst = std::max(worst, (x - r.trajectory.states().col(k + 1)).cwiseAbs().maxCoeff());
  }
  return worst;
}

/// One Ipopt solve, no refinement, and a consistency tolerance any result meets (for tests of a
/// single solve's properties: repeatability, order, warm starts).
trellis::OptimizerOptions singleSolve() {
  trellis::OptimizerOptions o;
  o.maxRefinements = 0;
  o.consistencyTolerance = 1e30;
  return o;
}

void checkSolved(const OptimalControlProblem& p, const OptimizationResult& r) {
  INFO(r.describe());
  REQUIRE(r.ok());
  CHECK(r.status.code == OptimizationCode::kSolved);
  CHECK(r.ipoptStatus == "Solve_Succeeded");
  // Ipopt stops when the scaled violation is below constr_viol_tol = 1e-8; unscaled defects of
  // O(1) states stay within a decade of it.
  CHECK(r.constraintViolation < 1e-7);
  CHECK(r.boundViolation <= 1e-8);  // Ipopt's bound relaxation (bound_relax_factor 1e-8)
  const MatrixXd& X = r.trajectory.states();
  for (int i = 0; i < p.nx(); ++i) {
    if (p.initialFixed[i]) CHECK(X(i, 0) == Approx(p.initialState(i)).margin(1e-9));
    if (p.finalFixed[i]) CHECK(X(i, X.cols() - 1) == Approx(p.finalState(i)).margin(1e-9));
  }
  // Refinement may add knots; the first round starts from the problem's.
  REQUIRE_FALSE(r.rounds.empty());
  CHECK(r.rounds.front().knots == p.knots);
  CHECK(r.trajectory.size() == r.rounds.back().knots);
  CHECK(r.trajectory.endTime() == Approx(r.horizon).epsilon(1e-14));
  CHECK(r.consistency.ok());
}

}  // namespace

TEST_CASE("optimizer: swing-ups converge from the default guess to a repeatable cost",
          "[optimizer][swingup]") {
  for (const char* name : {"cart_pole_swingup", "acrobot_swingup"}) {
    DYNAMIC_SECTION(name) {
      const OptimalControlProblem p = trellis::loadProblem(problemPath(name));
      const OptimizationResult first = trellis::optimizeTrajectory(p, singleSolve());
      checkSolved(p, first);
      // The input bounds hold (to Ipopt's bound relaxation) and the swing-up uses them: a
      // swing-up from rest needs a non-zero input.
      CHECK(first.trajectory.inputs().maxCoeff() <= p.inputUpper(0) + 1e-6);
      CHECK(first.trajectory.inputs().minCoeff() >= p.inputLower(0) - 1e-6);
      CHECK(first.cost > 0.0);
      const OptimizationResult second = trellis::optimizeTrajectory(p, singleSolve());
      checkSolved(p, second);
      // Same problem, same guess, same deterministic solver: the same local optimum. Allow
      // rounding-level differences only (Ipopt's tol 1e-8 is on the KKT error, the cost at
      // two runs of the same iterates agrees far more closely).
      CHECK(second.cost == Approx(first.cost).epsilon(1e-9));
      CHECK(second.iterations == first.iterations);
    }
  }
}

TEST_CASE("optimizer: optimized trajectories are dynamically consistent", "[optimizer][consistency]") {
  // The local error of one interval is O(h⁵) for Hermite–Simpson and O(h³) for the trapezoidal
  // rule (with the collocation's own input interpolant). Doubling the knots must divide it by
  // about 2⁵ = 32 and 2³ = 8; the checks ask for ratios above 12 and 4 (the two solutions are
  // different trajectories, so the constants differ somewhat), and an absolute bound that the
  // error estimate C h^p with the measured constant respects.
  const OptimalControlProblem base = trellis::loadProblem(problemPath("cart_pole_swingup"));
  for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
    const bool hs = method == CollocationMethod::kHermiteSimpson, radau = method == CollocationMethod::kRadau;
    DYNAMIC_SECTION((hs ? "hermite_simpson" : radau ? "radau" : "trapezoidal")) {
      double errors[2];
      for (int level = 0; level < 2; ++level) {
        OptimalControlProblem p = base;
        p.method = method;
        p.knots = level == 0 ? 26 : 51;
        const OptimizationResult r = trellis::optimizeTrajectory(p, singleSolve());
        checkSolved(p, r);
        errors[level] = maxLocalError(*p.model, r, hs);
      }
      INFO("local error at 25 intervals " << errors[0] << ", at 50 intervals " << errors[1]);
      // Radau IIA (3 stages): local error O(h⁶) at the knots, 2⁶ = 64 per doubling.
      CHECK(errors[0] / errors[1] > (hs ? 12.0 : radau ? 20.0 : 4.0));
      // Sanity bounds on the coarse grid (h = 0.08 s): about 3x the values measured when the
      // test was written (7.3e-4 and 0.116; Radau 1.23e-4, ratio 45.6 per doubling), against a state
      // change per interval of order h·|x'| ~ 1; the order checks above are the sharp ones.
      CHECK(errors[0] < (hs ? 2e-3 : radau ? 4e-4 : 0.3));
    }
  }
}

TEST_CASE("optimizer: the time split adds up within the solve's time", "[optimizer]") {
  // evaluationTime (the callbacks), hessianTime (a part of it) and checkTime (the a-posteriori
  // check) are disjoint parts of solveTime, each measured, none zero on a solve that did all three.
  OptimalControlProblem p = trellis::loadProblem(problemPath("cart_pole_swingup"));
  p.knots = 26;
  trellis::OptimizerOptions o = singleSolve();
  const OptimizationResult r = trellis::optimizeTrajectory(p, o);
  checkSolved(p, r);
  CHECK(r.evaluationTime > 0.0);
  CHECK(r.hessianTime > 0.0);
  CHECK(r.checkTime > 0.0);
  CHECK(r.hessianTime < r.evaluationTime);
  CHECK(r.evaluationTime + r.checkTime < r.solveTime);
  const std::string j = r.json();
  for (const char* key : {"\"evaluation_time_ms\"", "\"hessian_time_ms\"", "\"check_time_ms\""}) CHECK(j.find(key) != std::string::npos);
  // L-BFGS: no Hessian evaluated, none timed.
  o.hessian = trellis::HessianMode::kLimitedMemory;
  const OptimizationResult l = trellis::optimizeTrajectory(p, o);
  CHECK(l.hessianTime == 0.0);
  CHECK(l.evaluationTime > 0.0);
}

TEST_CASE("optimizer: the closed chain keeps h = 0 and A q' = 0 at the knots", "[optimizer][constrained]") {
  const OptimalControlProblem p = trellis::loadProblem(problemPath("paper_pendulum_transfer"));
  const OptimizationResult r = trellis::optimizeTrajectory(p);
  checkSolved(p, r);
  // Recomputed with the core at the returned knots (independent of the NLP's own g):
  // |h|, |A q̇| within Ipopt's constr_viol_tol (1e-8) times a small factor for scaling.
  trellis::Data data(*p.model);
  const int n = p.nq();
  double worstH = 0.0, worstV = 0.0;
  for (int k = 0; k < r.trajectory.size(); ++k) {
    const VectorXd x = r.trajectory.states().col(k);
    trellis::computeConstraints(*p.model, data, x.head(n), x.tail(n));
    worstH = std::max(worstH, data.constraintValue.cwiseAbs().maxCoeff());
    worstV = std::max(worstV, (data.constraintJacobian * x.tail(n)).cwiseAbs().maxCoeff());
  }
  INFO("max |h| = " << worstH << ", max |A q'| = " << worstV << ", max slack = " << r.maxSlack);
  CHECK(worstH < 1e-8);
  CHECK(worstV < 1e-8);
  // The slack absorbs only the collocation's drift off the manifold: small, but not zero.
  CHECK(r.maxSlack < 1e-3);
  // The free theta2 ended on the branch of the guess (the other branch is ~1.9 rad away).
  CHECK(r.trajectory.states()(1, r.trajectory.size() - 1) == Approx(p.finalState(1)).margin(1e-3));
  CHECK(maxLocalError(*p.model, r, true) < 1e-3);
}

TEST_CASE("optimizer: the implicit dynamics form reaches the explicit form's optimum", "[optimizer][implicit]") {
  // The two forms are the same NLP in (x, u) once q̈ and λ are eliminated: the same local optimum
  // from the same guess (the iterates differ, both with exact Hessians, but not the point they
  // converge to). The knots must also pass the
  // independent checks: the forward dynamics between knots (local error) and, on the closed
  // chain, h = 0 at the knots.
  for (const char* name : {"cart_pole_swingup", "paper_pendulum_transfer"}) {
    DYNAMIC_SECTION(name) {
      OptimalControlProblem p = trellis::loadProblem(problemPath(name));
      const OptimizationResult explicitForm = trellis::optimizeTrajectory(p, singleSolve());
      checkSolved(p, explicitForm);
      p.dynamics = trellis::DynamicsForm::kImplicit;
      const OptimizationResult implicitForm = trellis::optimizeTrajectory(p, singleSolve());
      checkSolved(p, implicitForm);
      CHECK(implicitForm.hessian == trellis::HessianMode::kExact);
      CHECK(implicitForm.cost == Approx(explicitForm.cost).epsilon(1e-5));
      const double dx = (implicitForm.trajectory.states() - explicitForm.trajectory.states()).cwiseAbs().maxCoeff();
      INFO("max |x_implicit − x_explicit| at the knots " << dx);
      CHECK(dx < 1e-3);
      CHECK(maxLocalError(*p.model, implicitForm, true) < 2.0 * maxLocalError(*p.model, explicitForm, true) + 1e-6);
    }
  }
}

TEST_CASE("optimizer: minimum time of a double integrator matches bang-bang", "[optimizer][closed_form]") {
  // m ẍ = u, |u| ≤ u_max, rest to rest over distance d: T* = 2 √(m d / u_max) (accelerate half
  // way, brake half way). Minimize T (time weight 1, a tiny input weight for regularity).
  const double mass = 1.0, umax = 1.0, d = 1.0;
  trellis::ModelBuilder b("block");
  b.addFrame("block", "world", trellis::Transform::tx("x"), trellis::Mass{mass});
  b.addConfigForce("x", "push");
  OptimalControlProblem p(std::make_shared<const trellis::Model>(std::move(b).finalize()));
  p.knots = 41;
  p.minHorizon = 0.5;
  p.maxHorizon = 5.0;
  p.horizon = 3.0;
  p.finalState << d, 0.0;
  p.inputLower << -umax;
  p.inputUpper << umax;
  p.R << 1e-6;
  p.timeWeight = 1.0;
  const OptimizationResult r = trellis::optimizeTrajectory(p);
  checkSolved(p, r);
  // The bang-bang switch falls inside one interval, where the quadratic input cannot follow it;
  // the horizon error is then a fraction of one interval's effect, well below h = 0.05 (and the
  // tiny R adds ~1e-6).
  CHECK(r.horizon == Approx(2.0 * std::sqrt(mass * d / umax)).margin(0.02));
}

TEST_CASE("optimizer: an impossible bound is reported as infeasible", "[optimizer][infeasible]") {
  // The cart must travel 1 m in 1 s but the push is limited to 0.1 N: at most ½ (0.1/1.1)·1² ≈
  // 0.045 m is reachable.
  OptimalControlProblem p = trellis::loadProblem(problemPath("cart_pole_swingup"));
  p.knots = 11;
  p.setFixedHorizon(1.0);
  p.initialState << 0.0, 0.0, 0.0, 0.0;
  p.finalState << 1.0, 0.0, 0.0, 0.0;
  p.stateLower.setConstant(-10.0);
  p.stateUpper.setConstant(10.0);
  p.inputLower << -0.1;
  p.inputUpper << 0.1;
  trellis::OptimizerOptions options;
  options.maxIterations = 300;
  const OptimizationResult r = trellis::optimizeTrajectory(p, options);
  INFO(r.describe());
  CHECK_FALSE(r.ok());
  CHECK(r.status.code == OptimizationCode::kInfeasible);
  CHECK(r.ipoptStatus == "Infeasible_Problem_Detected");
  CHECK(r.status.message.find("infeasib") != std::string::npos);
  // The last iterate is still returned, and it does violate the dynamics.
  CHECK(r.trajectory.size() == p.knots);
  CHECK(r.constraintViolation > 1e-3);
}

TEST_CASE("optimizer: bad problems and files name the field", "[optimizer][errors]") {
  const std::string dir = std::string(TRELLIS_SOURCE_DIR) + "/examples/problems";
  const std::string text = readText(problemPath("cart_pole_swingup"));
  auto expectError = [&](const std::string& from, const std::string& to, const std::string& fragment) {
    std::string bad = text;
    const auto at = bad.find(from);
    REQUIRE(at != std::string::npos);
    bad.replace(at, from.size(), to);
    INFO("replacing " << from << " by " << to);
    CHECK_THROWS_WITH(trellis::parseProblem(bad, "bad.json", dir), Catch::Contains(fragment));
  };
  expectError("\"knots\": 31", "\"knots\": \"many\"", "field 'knots': expected an integer");
  expectError("\"knots\": 31", "\"knots\": 1", "field 'knots': 1 is out of the range [2, 100000]");
  expectError("\"knots\": 31", "\"knots\": 4294967298", "field 'knots': 4294967298 is out of the range [2, 100000]");
  expectError("\"horizon\": 2.0", "\"horizn\": 2.0", "field 'horizn': unknown field");
  expectError("\"theta\": 0.0, \"dx\"", "\"thetaa\": 0.0, \"dx\"", "field 'final_state.thetaa': unknown state 'thetaa'");
  expectError("\"push\": [-20.0, 20.0]", "\"push\": [20.0, -20.0]", "field 'input_bounds.push'");
  expectError("{\"push\": 0.1}", "{\"push\": -0.1}", "field 'cost.R.push': -0.1 must be >= 0");
  expectError("\"hermite_simpson\"", "\"euler\"", "field 'method': 'euler'");
  expectError("../scenes/cart_pole.json", "../scenes/no_such_scene.json", "no_such_scene.json");
  expectError("[-1.5, 1.5]", "[-1.5, -0.5]", "initialState.x = 0 is fixed outside its bounds");

  // The C++ API: validate() names the field.
  OptimalControlProblem p = trellis::loadProblem(problemPath("cart_pole_swingup"));
  p.Q = MatrixXd::Identity(3, 3);
  CHECK_THROWS_WITH(p.validate(), Catch::Contains("Q is 3x3, expected 4x4"));
  p = trellis::loadProblem(problemPath("cart_pole_swingup"));
  p.R(0, 0) = -1.0;
  CHECK_THROWS_WITH(p.validate(), Catch::Contains("R is not positive semidefinite"));
  p = trellis::loadProblem(problemPath("cart_pole_swingup"));
  p.horizon = 5.0;
  CHECK_THROWS_WITH(trellis::optimizeTrajectory(p), Catch::Contains("horizon = 5"));
  trellis::OptimizerOptions options;
  options.tolerance = -1.0;
  CHECK_THROWS_WITH(trellis::optimizeTrajectory(p, options), Catch::Contains("OptimizerOptions.tolerance"));
  options = {};
  options.initialBarrier = 0.0;
  CHECK_THROWS_WITH(trellis::optimizeTrajectory(p, options), Catch::Contains("initialBarrier = 0"));
  options = {};
  options.initialBoundPush = 1.0;
  CHECK_THROWS_WITH(trellis::optimizeTrajectory(p, options), Catch::Contains("initialBoundPush = 1"));
}

TEST_CASE("optimizer: a guess at a solution, started with a small barrier and bound push", "[optimizer]") {
  // Ipopt's default first barrier (0.1) and bound push (0.01) move a guess that is already a
  // solution back towards the centre of its bounds; with small ones the solve stays there.
  OptimalControlProblem p = trellis::loadProblem(problemPath("cart_pole_swingup"));
  const OptimizationResult first = trellis::optimizeTrajectory(p, singleSolve());
  REQUIRE(first.ok());
  p.initialGuess = first.trajectory;
  const OptimizationResult plain = trellis::optimizeTrajectory(p, singleSolve());
  trellis::OptimizerOptions close = singleSolve();
  close.initialBarrier = 1e-7;
  close.initialBoundPush = 1e-9;
  const OptimizationResult near = trellis::optimizeTrajectory(p, close);
  INFO(plain.describe() << "\n" << near.describe());
  REQUIRE(plain.ok());
  REQUIRE(near.ok());
  CHECK(near.iterations < plain.iterations);
  CHECK(std::abs(near.cost - first.cost) <= 1e-6 * std::abs(first.cost));
}

TEST_CASE("optimizer: problem-file horizon bounds and a CSV initial guess", "[optimizer][file]") {
  const std::string dir = std::string(TRELLIS_SOURCE_DIR) + "/examples/problems";
  std::string text = readText(problemPath("cart_pole_swingup"));
  const std::string fixed = "\"horizon\": 2.0";
  REQUIRE(text.find(fixed) != std::string::npos);

  SECTION("a free horizon") {
    std::string freeText = text;
    freeText.replace(freeText.find(fixed), fixed.size(), "\"horizon\": {\"min\": 1.5, \"max\": 3.0}");
    const OptimalControlProblem p = trellis::parseProblem(freeText, "free.json", dir);
    CHECK(p.freeHorizon());
    CHECK(p.minHorizon == 1.5);
    CHECK(p.maxHorizon == 3.0);
    CHECK(p.horizon == 2.25);  // the guess defaults to the middle
  }

  SECTION("the solution as the guess of the same problem converges at once") {
    const OptimalControlProblem p = trellis::loadProblem(problemPath("cart_pole_swingup"));
    const OptimizationResult cold = trellis::optimizeTrajectory(p, singleSolve());
    REQUIRE(cold.ok());
    const std::string csv =
        (std::filesystem::temp_directory_path() / ("trellis_optimization_guess_" + std::to_string(::getpid()) + ".csv")).string();
    cold.trajectory.writeCsvFile(csv);
    std::string warmText = text;
    warmText.replace(warmText.rfind('}'), 1, ", \"initial_guess\": \"" + csv + "\"}");
    const OptimalControlProblem warmProblem = trellis::parseProblem(warmText, "warm.json", dir);
    REQUIRE(warmProblem.initialGuess.has_value());
    const OptimizationResult warm = trellis::optimizeTrajectory(warmProblem, singleSolve());
    std::filesystem::remove(csv);
    checkSolved(warmProblem, warm);
    // The guess is the solution at the knots (the midpoints are interpolated linearly, so not
    // exactly): the same optimum, in fewer iterations than from the straight-line guess.
    CHECK(warm.cost == Approx(cold.cost).epsilon(1e-6));
    CHECK(warm.iterations < cold.iterations);
  }
}

TEST_CASE("optimizer: dynamics that cannot be evaluated are a status, not a crash",
          "[optimizer][failure]") {
  // A point mass at a joint's axis: rotating it moves no mass, M is singular at every state.
  trellis::Scene scene = trellis::loadScene(std::string(TRELLIS_SOURCE_DIR) + "/tests/cli/data/singular.json");
  OptimalControlProblem p(std::make_shared<const trellis::Model>(std::move(scene.model)));
  p.knots = 4;
  p.finalState(0) = 1.0;
  trellis::Transcription t(p);
  VectorXd z = t.initialGuess(), g(t.numConstraints());
  CHECK_FALSE(t.evalConstraints(z.data(), g.data()));
  CHECK_THAT(t.lastError(), Catch::Contains("knot 0 (t = 0)"));
  const OptimizationResult r = trellis::optimizeTrajectory(p);
  INFO(r.describe());
  CHECK_FALSE(r.ok());
  CHECK(r.status.message.find("the dynamics failed at knot 0") != std::string::npos);
  CHECK(r.trajectory.size() == p.knots);  // the initial guess, returned as the last iterate
}
