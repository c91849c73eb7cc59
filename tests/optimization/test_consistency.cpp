// Tests of "solved means the plant can follow it": the a-posteriori consistency check
// (trellis/analysis/consistency.hpp) as the optimizer uses it, mesh refinement, closed chains
// (slack, boundary states off the manifold), a knife edge in the optimizer.
#include <trellis/analysis.hpp>
#include <trellis/core.hpp>
#include <trellis/optimization.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <string>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::CollocationMethod;
using trellis::OptimalControlProblem;
using trellis::OptimizationResult;
using trellis::OptimizationCode;
using trellis::OptimizerOptions;

namespace {

std::string problemPath(const std::string& name) {
  return std::string(TRELLIS_SOURCE_DIR) + "/examples/problems/" + name + ".json";
}

std::shared_ptr<const trellis::Model> doubleIntegrator() {
  trellis::ModelBuilder b("block");
  b.addFrame("block", "world", trellis::Transform::tx("x"), trellis::Mass{1.0});
  b.addConfigForce("x", "push");
  return std::make_shared<const trellis::Model>(std::move(b).finalize());
}

/// A planar five-bar: two 2-link arms (links of 1 m, 0.5 kg at each joint-to-joint midpoint is
/// approximated by point masses at the link ends) from the base points (∓0.5, 0), tips joined by
/// a point constraint in x and y; torques on the two base joints; gravity along −y.
std::shared_ptr<const trellis::Model> fiveBar() {
  using trellis::Transform;
  const trellis::Mass link{0.5, Eigen::Matrix3d::Identity() * 1e-3};
  trellis::ModelBuilder b("five_bar");
  b.addFrame("left_base", "world", Transform::tx(-0.5));
  b.addFrame("left_1", "left_base", Transform::rz("a1"));
  b.addFrame("left_elbow", "left_1", Transform::tx(1.0), link);
  b.addFrame("left_2", "left_elbow", Transform::rz("a2"));
  b.addFrame("left_tip", "left_2", Transform::tx(1.0), link);
  b.addFrame("right_base", "world", Transform::tx(0.5));
  b.addFrame("right_1", "right_base", Transform::rz("b1"));
  b.addFrame("right_elbow", "right_1", Transform::tx(1.0), link);
  b.addFrame("right_2", "right_elbow", Transform::rz("b2"));
  b.addFrame("right_tip", "right_2", Transform::tx(1.0), link);
  b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
  b.addConfigForce("a1", "tau_left");
  b.addConfigForce("b1", "tau_right");
  b.addPointConstraint("left_tip", "right_tip", 0);
  b.addPointConstraint("left_tip", "right_tip", 1);
  return std::make_shared<const trellis::Model>(std::move(b).finalize());
}

/// q = [a1, a2, b1, b2] with base angles a1, b1 and the tip in the upper (up = true) or lower
/// assembly mode: the two intersections of the unit circles around the elbows.
VectorXd fiveBarConfiguration(double a1, double b1, bool up) {
  const Eigen::Vector2d e1(-0.5 + std::cos(a1), std::sin(a1)), e2(0.5 + std::cos(b1), std::sin(b1));
  const Eigen::Vector2d mid = 0.5 * (e1 + e2), d = e2 - e1;
  const double half = 0.5 * d.norm(), off = std::sqrt(1.0 - half * half);
  const Eigen::Vector2d normal = Eigen::Vector2d(-d.y(), d.x()).normalized();
  const Eigen::Vector2d p = mid + (up ? off : -off) * normal;
  VectorXd q(4);
  q << a1, std::atan2(p.y() - e1.y(), p.x() - e1.x()) - a1, b1, std::atan2(p.y() - e2.y(), p.x() - e2.x()) - b1;
  return q;
}

/// The consistency of a result recomputed from its trajectory alone (independent of the optimizer).
trellis::ConsistencyResult recheck(const OptimalControlProblem& p, const OptimizationResult& r, double tol) {
  trellis::ConsistencyOptions o;
  o.tolerance = tol;
  return trellis::checkConsistency(*p.model, r.trajectory, o);
}

}  // namespace

TEST_CASE("consistency: minimum-energy transfer of a double integrator matches its closed form",
          "[consistency][closed_form]") {
  // min ∫ u² dt, ẍ = u, rest to rest over d in T: u*(t) = 6d/T² (1 − 2t/T), x*(t) = d (3s² − 2s³).
  // The optimal input is linear, so Hermite–Simpson with the linear-input rule represents it
  // exactly (the state is a cubic): the knots equal the closed form up to Ipopt's tolerance,
  // and the exact dynamics under the CSV's input rule meet every knot.
  const double d = 1.0, T = 2.0;
  OptimalControlProblem p(doubleIntegrator());
  p.knots = 11;
  p.setFixedHorizon(T);
  p.finalState << d, 0.0;
  p.goalState = p.finalState;
  const OptimizationResult r = trellis::optimizeTrajectory(p);
  INFO(r.describe());
  REQUIRE(r.status.code == OptimizationCode::kSolved);
  for (int k = 0; k < r.trajectory.size(); ++k) {
    const double t = r.trajectory.times()(k), s = t / T;
    CHECK(r.trajectory.inputs()(0, k) == Approx(6 * d / (T * T) * (1 - 2 * s)).margin(1e-6));
    CHECK(r.trajectory.states()(0, k) == Approx(d * (3 * s * s - 2 * s * s * s)).margin(1e-7));
  }
  CHECK(r.cost == Approx(12 * d * d / (T * T * T)).epsilon(1e-6));
  CHECK(r.rounds.size() == 1);
  CHECK(r.consistency.checked());
  CHECK(r.consistency.maxDefect < 1e-6);
  CHECK(recheck(p, r, 1e-6).ok());
  // The midpoint inputs are the knot averages (the rule the CSV readers apply).
  for (int k = 0; k + 1 < r.trajectory.size(); ++k) {
    CHECK(r.midpointInputs(0, k) ==
          Approx(0.5 * (r.trajectory.inputs()(0, k) + r.trajectory.inputs()(0, k + 1))).margin(1e-9));
  }
}

TEST_CASE("consistency: the defect falls at the transcription's order", "[consistency][order]") {
  // Without refinement, doubling the knots divides the relative defect by ~2⁴ (Hermite–Simpson:
  // local error O(h⁵) at the knots, the Hermite reference O(h⁴) at the midpoints) or ~2³
  // (trapezoidal, O(h³)). The checks ask for 10 and 5 (two different optimal trajectories).
  const OptimalControlProblem base = trellis::loadProblem(problemPath("cart_pole_swingup"));
  OptimizerOptions o;
  o.maxRefinements = 0;
  o.consistencyTolerance = 1.0;  // report the defect, do not judge it
  for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal}) {
    const bool hs = method == CollocationMethod::kHermiteSimpson;
    DYNAMIC_SECTION((hs ? "hermite_simpson" : "trapezoidal")) {
      double defect[2];
      for (int level = 0; level < 2; ++level) {
        OptimalControlProblem p = base;
        p.method = method;
        p.knots = level == 0 ? 26 : 51;
        const OptimizationResult r = trellis::optimizeTrajectory(p, o);
        INFO(r.describe());
        REQUIRE(r.status.code == OptimizationCode::kSolved);
        defect[level] = r.consistency.maxDefect;
        CHECK(recheck(p, r, 1.0).maxDefect == Approx(defect[level]).epsilon(1e-6));
      }
      INFO("relative defect at 25 intervals " << defect[0] << ", at 50 intervals " << defect[1]);
      CHECK(defect[0] / defect[1] > (hs ? 10.0 : 5.0));
    }
  }
}

TEST_CASE("consistency: mesh refinement reaches the tolerance", "[consistency][refinement]") {
  OptimalControlProblem p = trellis::loadProblem(problemPath("cart_pole_swingup"));
  p.knots = 11;
  OptimizerOptions o;
  o.consistencyTolerance = 1e-4;
  SECTION("with refinement: solved, consistent by an independent check, defects falling") {
    const OptimizationResult r = trellis::optimizeTrajectory(p, o);
    INFO(r.describe());
    REQUIRE(r.status.code == OptimizationCode::kSolved);
    REQUIRE(r.rounds.size() >= 2);
    CHECK(r.rounds.front().knots == 11);
    CHECK(r.rounds.back().knots == r.trajectory.size());
    CHECK(r.rounds.front().maxDefect > 1e-4);
    CHECK(r.rounds.back().maxDefect <= 1e-4);
    CHECK(recheck(p, r, 1e-4).ok());
    CHECK(r.mesh.size() == r.trajectory.size());
    // The mesh is non-uniform: refinement added knots where the defect was large only.
    const VectorXd h = r.mesh.tail(r.mesh.size() - 1) - r.mesh.head(r.mesh.size() - 1);
    CHECK(h.maxCoeff() > 1.5 * h.minCoeff());
  }
  SECTION("without refinement the same solve is reported as inconsistent, with where") {
    o.maxRefinements = 0;
    const OptimizationResult r = trellis::optimizeTrajectory(p, o);
    CHECK(r.status.code == OptimizationCode::kInconsistent);
    CHECK_FALSE(r.ok());
    CHECK(r.ipoptStatus == "Solve_Succeeded");
    CHECK_THAT(r.describe(), Catch::Contains("inconsistent") && Catch::Contains("interval") &&
                              Catch::Contains("refinement limit 0"));
    CHECK(r.trajectory.size() == 11);
  }
}

TEST_CASE("consistency: a fixed boundary state off the constraint manifold is named before solving",
          "[consistency][constrained]") {
  OptimalControlProblem p = trellis::loadProblem(problemPath("paper_pendulum_transfer"));
  SECTION("final configuration") {
    p.finalFixed.assign(p.nx(), true);  // "forgot free_final": theta2 = its guess, fixed
    p.finalState(1) += 0.3;
    try {
      p.validate();
      FAIL("validate accepted a final state off the manifold");
    } catch (const trellis::ProblemError& e) {
      const std::string m = e.what();
      CHECK_THAT(m, Catch::Contains("fixed final configuration") && Catch::Contains("row 0") &&
                        Catch::Contains("h = ") && Catch::Contains("free_final"));
    }
    CHECK_THROWS_AS(trellis::optimizeTrajectory(p), trellis::ProblemError);
  }
  SECTION("initial velocity") {
    p.initialFixed.assign(p.nx(), true);
    trellis::Data data(*p.model);
    // A consistent configuration (theta2 from the file is on the manifold), a velocity that is not.
    p.initialState(2) = 1.0;
    p.initialState(3) = 1.0;
    CHECK_THROWS_WITH(p.validate(), Catch::Contains("fixed initial velocity") && Catch::Contains("A q' = "));
  }
}

TEST_CASE("consistency: a five-bar crossing its parallel singularity is refined or reported",
          "[consistency][constrained][five_bar]") {
  // From the upper to the lower assembly mode at the same base angles, rest to rest: every such
  // motion crosses the singularity where the distal links are collinear. Coarse knots let the
  // slack hide the crossing; the optimizer must either refine until consistent or say where not.
  OptimalControlProblem p(fiveBar());
  p.knots = 21;
  p.setFixedHorizon(2.0);
  const double a1 = 110.0 * M_PI / 180.0, b1 = 70.0 * M_PI / 180.0;
  p.initialState.head(4) = fiveBarConfiguration(a1, b1, true);
  p.finalState.head(4) = fiveBarConfiguration(a1, b1, false);
  p.goalState = p.finalState;
  p.R *= 0.01;
  OptimizerOptions o;
  o.maxRefinements = 3;
  const OptimizationResult r = trellis::optimizeTrajectory(p, o);
  INFO(r.describe());
  CHECK(r.rounds.size() >= 1);
  if (r.status.code == OptimizationCode::kSolved || r.status.code == OptimizationCode::kSolvedAcceptable) {
    CHECK(r.maxSlackDefect <= o.consistencyTolerance);
    CHECK(recheck(p, r, o.consistencyTolerance).ok());
  } else if (r.status.code == OptimizationCode::kInconsistent) {
    CHECK_THAT(r.describe(), Catch::Contains("interval"));
  } else {
    CHECK_FALSE(r.ok());  // an Ipopt failure is reported as such, not as solved
  }
}

TEST_CASE("consistency: a knife edge in the optimizer keeps A q' = 0", "[consistency][knife_edge]") {
  // A planar skate: x, y, heading theta; thrust along the body's x axis, a steering torque; the
  // blade forbids sliding sideways (ẏ cos θ − ẋ sin θ = 0). Rest at the origin heading +x to
  // rest at (1, 0.5), heading free: the skate must turn while moving.
  using trellis::Transform;
  trellis::ModelBuilder b("skate");
  b.addFrame("sx", "world", Transform::tx("x"));
  b.addFrame("sy", "sx", Transform::ty("y"));
  b.addFrame("body", "sy", Transform::rz("theta"), trellis::Mass{1.0, Eigen::Matrix3d::Identity() * 0.1});
  b.addKnifeEdgeConstraint("body", Eigen::Vector3d(0.0, 1.0, 0.0));
  b.addConfigForce("theta", "steer");
  b.addBodyWrench("body", {trellis::WrenchEntry{std::string("thrust")}, trellis::WrenchEntry{0.0},
                           trellis::WrenchEntry{0.0}, trellis::WrenchEntry{0.0},
                           trellis::WrenchEntry{0.0}, trellis::WrenchEntry{0.0}});
  OptimalControlProblem p(std::make_shared<const trellis::Model>(std::move(b).finalize()));
  p.knots = 31;
  p.setFixedHorizon(3.0);
  p.finalState << 1.0, 0.5, 0.0, 0.0, 0.0, 0.0;
  p.finalFixed[2] = false;  // heading free
  p.goalState = p.finalState;
  const OptimizationResult r = trellis::optimizeTrajectory(p);
  INFO(r.describe());
  REQUIRE(r.status.code == OptimizationCode::kSolved);
  trellis::Data data(*p.model);
  double worst = 0.0;
  for (int k = 0; k < r.trajectory.size(); ++k) {
    const VectorXd x = r.trajectory.states().col(k);
    trellis::computeConstraints(*p.model, data, x.head(3), x.tail(3));
    worst = std::max(worst, (data.constraintJacobian * x.tail(3)).cwiseAbs().maxCoeff());
  }
  INFO("max |A q'| at the knots " << worst);
  CHECK(worst < 1e-8);
  CHECK(r.trajectory.states()(0, p.knots - 1) == Approx(1.0).margin(1e-9));
  CHECK(r.trajectory.states()(1, p.knots - 1) == Approx(0.5).margin(1e-9));
  CHECK(recheck(p, r, 1e-3).ok());
  // The skate turned (a straight push cannot reach y = 0.5).
  CHECK(r.trajectory.states().row(2).cwiseAbs().maxCoeff() > 0.1);
  // The exact Hessian (the knife edge's third-derivative terms from the recorded implicit
  // residual, transcription.cpp) reaches L-BFGS's optimum.
  CHECK(r.hessian == trellis::HessianMode::kExact);
  CHECK(r.hessianNote.empty());
  trellis::OptimizerOptions lbfgs;
  lbfgs.hessian = trellis::HessianMode::kLimitedMemory;
  const OptimizationResult rl = trellis::optimizeTrajectory(p, lbfgs);
  INFO(rl.describe());
  REQUIRE(rl.status.code == OptimizationCode::kSolved);
  CHECK(r.cost == Approx(rl.cost).epsilon(1e-6));
  // Measured 15 against 31 iterations: the margin is wide enough for another platform's rounding.
  CHECK(r.iterations < rl.iterations);
}

TEST_CASE("consistency: checkConsistency on a hand-made trajectory file names a corrupted knot",
          "[consistency][check]") {
  // The closed-form minimum-energy transfer written as a trajectory by hand (no optimizer): with
  // its linear input the exact dynamics meet every knot (defect at CVODES' tolerance). A 0.01
  // error in one knot's velocity is then found, in 'dx', next to that knot, with the size
  // 0.01 / range(dx) = 0.01 / 0.75 (range of ẋ = 6d/T (s − s²): 0 … 1.5 d/T).
  const auto model = doubleIntegrator();
  const double d = 1.0, T = 2.0;
  const int N = 11;
  VectorXd times = VectorXd::LinSpaced(N, 0.0, T);
  MatrixXd X(2, N), U(1, N);
  for (int k = 0; k < N; ++k) {
    const double s = times(k) / T;
    X(0, k) = d * (3 * s * s - 2 * s * s * s);
    X(1, k) = 6 * d / T * (s - s * s);
    U(0, k) = 6 * d / (T * T) * (1 - 2 * s);
  }
  const trellis::Trajectory exact(model->configNames(), model->inputNames(), times, X, U);
  const trellis::ConsistencyResult good = trellis::checkConsistency(*model, exact);
  INFO(good.describe());
  CHECK(good.checked());
  CHECK(good.ok());
  CHECK(good.maxDefect < 1e-8);
  CHECK(good.intervalDefects.size() == N - 1);

  MatrixXd Xbad = X;
  Xbad(1, 6) += 0.01;
  const trellis::Trajectory corrupted(model->configNames(), model->inputNames(), times, Xbad, U);
  const trellis::ConsistencyResult bad = trellis::checkConsistency(*model, corrupted);
  INFO(bad.describe());
  CHECK(bad.checked());
  CHECK_FALSE(bad.ok());
  CHECK((bad.worstInterval == 5 || bad.worstInterval == 6));
  CHECK(bad.worstStateName == "dx");
  CHECK(bad.maxDefect == Approx(0.01 / 0.75).epsilon(1e-3));
  CHECK(bad.status.code == trellis::ConsistencyCode::kInconsistent);
  CHECK(bad.status.index == bad.worstInterval);
  CHECK(bad.status.t == bad.worstTime);
  CHECK_THAT(bad.status.message, Catch::Contains("inconsistent") && Catch::Contains("'dx'") &&
                                     Catch::Contains("interval " + std::to_string(bad.worstInterval)));
  CHECK_THAT(bad.json(), Catch::Contains("\"status\":\"inconsistent\"") && Catch::Contains("\"worst_state\":\"dx\""));
  CHECK(good.status.code == trellis::ConsistencyCode::kOk);
  CHECK(trellis::ConsistencyResult{}.status.code == trellis::ConsistencyCode::kNotChecked);
  // Intervals away from the corrupted knot stay clean.
  CHECK(bad.intervalDefects(0) < 1e-8);
  CHECK(bad.intervalDefects(9) < 1e-8);
}

TEST_CASE("consistency: dynamics that fail at a knot are the verdict, not an exception",
          "[consistency][status]") {
  // A joint that moves no mass: M is singular at every state, so no knot has a q''.
  trellis::ModelBuilder b("massless");
  b.addFrame("cart", "world", trellis::Transform::tx("x"), trellis::Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addFrame("spinner", "cart", trellis::Transform::rz("phi"));
  b.addConfigForce("x", "push");
  const trellis::Model model = std::move(b).finalize();
  const trellis::Trajectory still(model.configNames(), model.inputNames(),
                                  (Eigen::VectorXd(3) << 0.0, 0.5, 1.0).finished(), MatrixXd::Zero(4, 3),
                                  MatrixXd::Zero(1, 3));
  trellis::ConsistencyResult r;
  REQUIRE_NOTHROW(r = trellis::checkConsistency(model, still));
  CHECK_FALSE(r.ok());
  CHECK_FALSE(r.checked());
  CHECK(r.status.code == trellis::ConsistencyCode::kDynamicsFailure);
  CHECK(r.status.index == 0);
  CHECK(r.status.t == 0.0);
  CHECK_THAT(r.describe(), Catch::StartsWith("dynamics_failure at t = 0 (index 0): not checked: the dynamics fail at knot 0"));
  CHECK_THAT(r.json(), Catch::Contains("\"max_defect\":null"));
  // Names that do not match stay bad input.
  const trellis::Trajectory other({"y", "phi"}, model.inputNames(), (Eigen::VectorXd(2) << 0.0, 1.0).finished(),
                                  MatrixXd::Zero(4, 2), MatrixXd::Zero(1, 2));
  CHECK_THROWS_AS(trellis::checkConsistency(model, other), trellis::TrajectoryError);
}

TEST_CASE("consistency: Radau, BDF and Adams agree on a stiff model; Radau in far fewer steps",
          "[consistency][methods]") {
  // A pushed block carrying a light, heavily damped slider: m ÿ + c ẏ + k y = −m ẍ with m = 0.01,
  // c = 60, k = 100 has the eigenvalues −1.67 and −5 998 s⁻¹ (a fast mode like the hand's finger
  // modes). The trajectory is the plant's own response (BDF at rtol 1e-12) to an input that is
  // linear between the knots — the rule checkConsistency reads — so every method must find the
  // same small defects, and a corrupted knot the same defect in the same place.
  trellis::ModelBuilder b("stiff_slider");
  b.addFrame("block", "world", trellis::Transform::tx("x"), trellis::Mass{1.0});
  b.addFrame("slider", "block", trellis::Transform::tx("y"), trellis::Mass{0.01});
  b.addConfigSpring("y", 100.0, 0.0);
  b.addDamping(0.0, {{"y", 60.0}});
  b.addConfigForce("x", "push");
  const trellis::Model model = std::move(b).finalize();
  const int N = 41;
  const VectorXd times = VectorXd::LinSpaced(N, 0.0, 2.0);
  VectorXd uk(N);
  for (int k = 0; k < N; ++k) uk(k) = std::sin(3.0 * times(k));  // 0 at t = 0: the start is at rest
  const trellis::Policy linear = [&](double t, const VectorXd&, VectorXd& u) {
    const int k = std::min(N - 2, static_cast<int>(std::floor(t / 0.05)));
    const double s = std::clamp((t - times(k)) / (times(k + 1) - times(k)), 0.0, 1.0);
    u.resize(1);
    u(0) = (1.0 - s) * uk(k) + s * uk(k + 1);
  };
  trellis::SimulationOptions so;
  so.method = trellis::IntegrationMethod::kBDF;
  so.rtol = 1e-12;
  so.atol = 1e-14;
  so.outputStep = 0.05;
  so.breakpoints.assign(times.data() + 1, times.data() + N - 1);
  const trellis::SimulationResult run = trellis::simulate(model, VectorXd::Zero(4), 0.0, 2.0, linear, so);
  INFO(run.describe());
  REQUIRE(run.ok());
  REQUIRE(run.trajectory.size() == N);
  const MatrixXd U = uk.transpose();
  const trellis::Trajectory plant(model.configNames(), model.inputNames(), times, run.trajectory.states(), U);
  MatrixXd Xbad = run.trajectory.states();
  Xbad(3, 20) += 1e-3;  // the slider's velocity at t = 1
  const trellis::Trajectory corrupted(model.configNames(), model.inputNames(), times, Xbad, U);

  trellis::ConsistencyResult good[3], bad[3];
  const trellis::IntegrationMethod methods[3] = {trellis::IntegrationMethod::kRadau, trellis::IntegrationMethod::kBDF,
                                                 trellis::IntegrationMethod::kAdams};
  for (int m = 0; m < 3; ++m) {
    trellis::ConsistencyOptions o;
    o.method = methods[m];
    good[m] = trellis::checkConsistency(model, plant, o);
    bad[m] = trellis::checkConsistency(model, corrupted, o);
    CAPTURE(m, good[m].describe(), bad[m].describe(), good[m].steps, good[m].rhsEvaluations);
    // What remains is not integration error: the cubic Hermite spline between the knots misses the
    // slider's fast response to the input's kinks (4.6e-4 of dy's small range, at the first
    // midpoint) — the same figure for every method.
    CHECK(good[m].ok());
    CHECK(good[m].maxDefect == Approx(good[0].maxDefect).epsilon(1e-6));
    CHECK(bad[m].status.code == trellis::ConsistencyCode::kInconsistent);
    CHECK(bad[m].worstStateName == "dy");
    CHECK((bad[m].worstInterval == 19 || bad[m].worstInterval == 20));
    CHECK(bad[m].maxDefect == Approx(bad[0].maxDefect).epsilon(1e-6));
    CHECK(bad[m].maxDefect > 1.0);  // 1e-3 against dy's range of ~1e-3
  }
  CHECK(good[0].jacobianEvaluations > 0);
  CHECK(good[2].jacobianEvaluations == 0);
  // Adams is held below its stability limit by the fast mode (|λ|h ≲ 1) and restarts at order 1
  // at every knot; Radau is neither.
  CHECK(good[0].steps * 10 < good[2].steps);
  CHECK_THAT(good[0].json(), Catch::Contains("\"jacobian_evaluations\":"));

  trellis::ConsistencyOptions wrong;
  wrong.method = static_cast<trellis::IntegrationMethod>(17);
  CHECK_THROWS_WITH(trellis::checkConsistency(model, plant, wrong), Catch::Contains("ConsistencyOptions.method = 17"));
}
