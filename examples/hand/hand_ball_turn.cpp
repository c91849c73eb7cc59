// examples/hand/hand_ball_turn.cpp — the hand turns a free ball (issue 26, step 2): optimizes the
// turn of ball_turn.hpp on a free-ball hand scene and checks the contacts along the result.
//
//   hand_ball_turn [--scene NAME] [--angle DEG] [--horizon S] [--knots N] [--facets F] [--print-level L]
//                  [--equilibrium-only] [--lbfgs]
//
// First a grasp equilibrium is searched (findGraspEquilibrium; --equilibrium-only stops there, exit
// 0 only when found); when its contacts hold, the turn starts from it, else from the stored grasp.
// --lbfgs: Ipopt's limited-memory Hessian instead of the exact one.
// NAME: a scene of examples/scenes written by make_hand_scene.py --free-ball (default hand_ball;
// hand_ball_pinch is the thumb-and-index reduction), read with examples/hand/NAME_limits.json. Prints the
// optimizer's one-line result, its time split, and the contact margins at every collocation point:
// the smallest normal force and the largest ‖λ_t‖ / (μ λ_n). Exit status 0 only when the
// optimizer reports solved (its a-posteriori consistency check included), the ball turned by the
// angle, and every point keeps λ_n ≥ the margin and ‖λ_t‖ ≤ μ λ_n; 1 otherwise; 2 on bad arguments.
#include "ball_turn.hpp"

#include <trellis/core.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <numbers>
#include <string>

using namespace trellis;

int main(int argc, char** argv) {
  std::string scene = "hand_ball";
  hand::BallTurnOptions options;
  int printLevel = 0;
  bool equilibriumOnly = false;
  bool lbfgs = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "hand_ball_turn: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    try {
      if (a == "--scene") scene = value();
      else if (a == "--angle") options.angle = std::stod(value()) * std::numbers::pi / 180.0;
      else if (a == "--horizon") options.horizon = std::stod(value());
      else if (a == "--knots") options.knots = std::stoi(value());
      else if (a == "--facets") options.facets = std::stoi(value());
      else if (a == "--print-level") printLevel = std::stoi(value());
      else if (a == "--equilibrium-only") equilibriumOnly = true;
      else if (a == "--lbfgs") lbfgs = true;
      else if (a == "--help") {
        std::cout << "usage: hand_ball_turn [--scene NAME] [--angle DEG] [--horizon S] [--knots N] "
                     "[--facets F] [--print-level L] [--equilibrium-only] [--lbfgs]\n";
        return 0;
      } else {
        std::cerr << "hand_ball_turn: unknown option '" << a << "' (--help lists them)\n";
        return 2;
      }
    } catch (const std::exception&) {
      std::cerr << "hand_ball_turn: " << a << ": '" << argv[i] << "' is not a number\n";
      return 2;
    }
  }
  const std::string dir = TRELLIS_EXAMPLE_SCENES_DIR;
  const auto t0 = std::chrono::steady_clock::now();
  Scene s;
  hand::BallLimits limits;
  OptimalControlProblem problem;
  try {
    s = loadScene(dir + "/" + scene + ".json");
    auto model = std::make_shared<const Model>(s.model);
    limits = hand::loadBallLimits(std::string(TRELLIS_HAND_DIR) + "/" + scene + "_limits.json", *model);
    problem = hand::makeBallTurnProblem(model, s.q, limits, options);
  } catch (const std::exception& e) {
    std::cerr << "hand_ball_turn: " << e.what() << "\n";
    return 2;
  }
  std::printf("scene %s: %d coordinates, %d tendons, %d contact rows; turn %.2f deg in %.2f s, %d knots, "
              "%d-facet pyramid, mu = %.2f, normal >= %.3f N\n",
              scene.c_str(), s.model.nq(), s.model.nu(), s.model.nc(), options.angle * 180.0 / std::numbers::pi,
              options.horizon, options.knots, options.facets, limits.friction, limits.normalMin);
  // What the start costs: the closest static hold of the stored grasp under 0 ≤ u (ball_turn.hpp).
  const hand::StaticHold hold = hand::closestStaticHold(s.model, s.q);
  const hand::ContactMargins holdMargins = hand::contactMargins(hold.lambda, limits);
  std::printf("stored grasp: closest static hold with u >= 0 leaves %.3g of the static load unbalanced "
              "(0: an equilibrium); its contacts: min normal %.4f N (%s), worst friction ratio %.3f (%s)\n",
              hold.relativeResidual, holdMargins.minNormal, limits.digits[holdMargins.minNormalContact].c_str(),
              holdMargins.worstFrictionRatio, limits.digits[holdMargins.worstFrictionContact].c_str());
  const hand::GraspEquilibrium ge = hand::findGraspEquilibrium(s.model, s.q, limits, options.facets);
  std::printf("grasp equilibrium: %s after %d iterations: |qdd| %.3g, |h| %.3g m, min normal %.4f N, "
              "worst friction ratio %.4f, max tension %.2f N%s%s\n",
              ge.ok ? "found" : "NOT found", ge.iterations, ge.accelerationResidual, ge.constraintResidual,
              ge.margins.minNormal, ge.margins.worstFrictionRatio, ge.u.size() ? ge.u.maxCoeff() : 0.0,
              ge.message.empty() ? "" : ": ", ge.message.c_str());
  if (equilibriumOnly) return ge.ok ? 0 : 1;
  // Start from the equilibrium search's point when its contacts hold (even if its static residual
  // is not yet at tolerance): the stored grasp is no equilibrium under u ≥ 0.
  if (ge.q.size() == s.model.nq() && ge.lambda.size() == s.model.nc() &&
      ge.margins.minNormal >= limits.normalMin && ge.margins.worstFrictionRatio <= 1.0) {
    options.guessTensions = ge.u;
    problem = hand::makeBallTurnProblem(problem.model, ge.q, limits, options);
    std::printf("starting from the equilibrium search's grasp\n");
  }
  OptimizerOptions oo;
  oo.printLevel = printLevel;
  oo.maxIterations = 500;
  if (lbfgs) oo.hessian = HessianMode::kLimitedMemory;
  const OptimizationResult r = optimizeTrajectory(problem, oo);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("optimizer: %s\n", r.describe().c_str());
  std::printf("evaluations: %ld dynamics, %ld linearizations, %ld second-order; solve %.3f s wall, %.3f s CPU\n",
              r.dynamicsEvaluations, r.linearizationEvaluations, r.secondOrderEvaluations, r.solveTime,
              r.solveCpuTime);
  bool ok = r.ok();
  if (!r.trajectory.size()) {
    std::printf("no trajectory\n");
    return 1;
  }
  // Contacts at the knots (the collocation points the bounds hold at, evaluated again here).
  Data data(s.model);
  const Trajectory& tr = r.trajectory;
  const int n = s.model.nq();
  double minNormal = 1e300, worstRatio = 0.0;
  for (int k = 0; k < tr.size(); ++k) {
    const Eigen::VectorXd x = tr.states().col(k);
    if (!computeDynamics(s.model, data, x.head(n), x.tail(n), tr.inputs().col(k)).ok()) {
      std::printf("dynamics failed at knot %d\n", k);
      return 1;
    }
    const hand::ContactMargins c = hand::contactMargins(data.lambda, limits);
    minNormal = std::min(minNormal, c.minNormal);
    worstRatio = std::max(worstRatio, c.worstFrictionRatio);
  }
  const double yawEnd = tr.states()(s.model.configIndex("ball_yaw"), tr.size() - 1);
  std::printf("ball rotation: %.3f deg\n", yawEnd * 180.0 / std::numbers::pi);
  std::printf("min normal force: %.4f N (margin %.3f N)\n", minNormal, limits.normalMin);
  std::printf("worst friction ratio: %.4f (cone: 1)\n", worstRatio);
  std::printf("whole job: %.3f s\n", seconds);
  // Tolerances: Ipopt's constraint tolerance is absolute (1e-8 N on the force rows).
  ok = ok && minNormal >= limits.normalMin - 1e-6 && worstRatio <= 1.0 + 1e-6;
  std::printf("%s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
