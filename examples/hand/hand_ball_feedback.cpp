// examples/hand/hand_ball_feedback.cpp — sampled TV-LQR gains and contact-checked closed loops of
// the hand holding or turning a free ball (issue 26; ball_feedback.hpp).
//
//   hand_ball_feedback [--reference CSV] [--scene NAME] [--runs N] [--seed S] [--perturbation Z]
//                      [--rate HZ] [--horizon T] [--threads N] [--max-ratio R] [--gains CSV]
//                      [--rtol R] [--atol A] [--drift D] [--method bdf|radau] [--transport-substeps S]
//                      [--quasi-static DEG [--knots N]] [--pulse NAME:A] [--write-reference CSV]
//                      [--feedforward reference|average|consistent]
//                      [--optimize DEG [--optimize-knots N]] [--redistribute N [--tension-floor F]]
//
// --reference: a trajectory CSV of the scene (Trajectory::writeCsv; e.g. the optimized turn);
// without it the provisional reference: the scene's stored hold (q = s.q, q̇ = 0, u = s.u, a
// certified static equilibrium) held for T (default 2 s), knots every 0.1 s; with --quasi-static
// DEG the quasi-static turn of ball_turn.hpp by DEG degrees in T on N knots (default 21): a motion
// whose tensions hold each pose at rest, NOT a solution of the dynamics (the optimizer's warm
// start) — a stand-in that moves until the optimized turn exists; --write-reference writes the
// reference used; --pulse NAME:A the plant's own motion from the hold under a tension pulse
// s.u + A sin²(πt/T) on tendon NAME (pulseReference below: moves, and satisfies the dynamics). NAME: a free-ball
// scene of examples/scenes (default hand_ball) with examples/hand/NAME_limits.json. --gains writes
// the gain schedule (with its feed-forward); --rtol, --atol, --drift: the closed loops' integrator
// tolerances and projection threshold, --method their integrator, --transport-substeps the tangent basis's steps per knot
// interval (BallFeedbackOptions). Prints the gains' solve and time, one line per run,
// the aggregate; exit 0 only when the gains are solved and every closed loop kept every contact
// at every integrator step and converged (final / initial tracking error ≤ R, default 0.5);
// 1 otherwise; 2 on bad arguments or files.
// --redistribute N: the reference's motion kept and its tensions and contact forces redistributed
// on N uniform knots (ball_reference.hpp: inverse dynamics, tensions in (F, u_max) with
// --tension-floor F, default 0.3 N, contacts with λ_n ≥ margin + 0.05 N inside 90 % of the cone),
// then checked as the optimizer checks its results (checkConsistency; an inconsistent one fails).
// --optimize DEG: the reference is the turn by DEG degrees in T optimized first (ball_turn.hpp,
// implicit Hermite–Simpson on --optimize-knots knots, default 11), then redistributed (201 knots
// unless --redistribute says otherwise); the summary lines and each stage's time follow.
#include "ball_feedback.hpp"
#include "ball_reference.hpp"
#include "ball_turn.hpp"
#include "hand_feedback.hpp"
#include "job_options.hpp"

#include <trellis/analysis/consistency.hpp>

#include <trellis/analysis/simulation.hpp>
#include <trellis/control/tvlqr.hpp>
#include <trellis/core.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <numbers>
#include <string>

using namespace trellis;

namespace {

/// --pulse NAME:A: the plant's own motion from the stored hold at rest under
///   u(t) = s.u + A sin²(π t / T) e_NAME − K∞ (x − x_hold),
/// clipped to [0, u_max], one tendon's tension raised (lowered for A < 0) and returned, with the
/// stationary manifold LQR
/// gain of the hold (the hold is unstable open loop: under constant tensions the hand leaves it
/// within 0.3 s, measured), simulated (BDF, rtol 1e-10, atol 1e-12, projected) with outputs every
/// 10 ms: a reference that moves and satisfies the dynamics to the integration's accuracy (between
/// knots to the linear interpolation of u, O(h²)). Its contacts are whatever the pulse makes them
/// (printed by the summary).
Trajectory pulseReference(const Scene& s, const hand::BallLimits& limits, const std::string& spec, double horizon) {
  const auto colon = spec.find(':');
  if (colon == std::string::npos) throw std::invalid_argument("--pulse '" + spec + "': expected NAME:AMPLITUDE");
  const std::string name = spec.substr(0, colon);
  const int i = s.model.inputIndex(name);
  if (i < 0) throw std::invalid_argument("--pulse '" + spec + "': no tendon named '" + name + "'");
  const double amplitude = std::stod(spec.substr(colon + 1));
  const int n = s.model.nq();
  Eigen::VectorXd x0(2 * n);
  x0 << s.q, Eigen::VectorXd::Zero(n);
  TvlqrOptions stationary;
  stationary.infiniteHorizon = true;
  stationary.transport = hand::feedbackTransport();
  stationary.riccati = hand::feedbackRiccatiOptions();
  const TvlqrSolution hold =
      solveTvlqr(s.model, hand::holdReference(s.model, s.q, s.u, horizon, horizon), hand::feedbackWeights(s.model), stationary);
  if (!hold.ok()) throw std::runtime_error("--pulse: the hold's stationary gain failed: " + hold.status.describe());
  const Eigen::MatrixXd K = hold.gains.gains()[0];
  const Eigen::VectorXd u0 = s.u;
  const Policy policy = [u0, i, amplitude, horizon, K, x0](double t, const Eigen::VectorXd& x, Eigen::VectorXd& u) {
    const double w = std::sin(std::numbers::pi * t / horizon);
    u = u0 - K * (x - x0);
    u(i) += amplitude * w * w;
  };
  SimulationOptions o;
  o.method = IntegrationMethod::kBDF;
  o.rtol = 1e-10;
  o.atol = 1e-12;
  o.outputStep = 0.01;
  o.inputLower = Eigen::VectorXd::Zero(s.model.nu());
  o.inputUpper = limits.uMax;
  const SimulationResult r = simulate(s.model, x0, 0.0, horizon, policy, o);
  if (!r.ok()) throw std::runtime_error("--pulse: the plant's simulation failed: " + r.status.describe());
  return r.trajectory;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene = "hand_ball", referencePath, gainsPath, writeReference;
  hand::BallFeedbackOptions options;
  double horizon = 2.0, quasiStaticDegrees = 0.0;
  std::string pulse;
  int quasiStaticKnots = 21, redistributeKnots = 0, optimizeKnots = 11;
  double optimizeDegrees = 0.0;
  double tensionFloor = 0.3;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "hand_ball_feedback: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    // A name parser's message with the option in front ("--method: integration method 'x' is not one of …").
    const auto named = [&a](auto parse) {
      try {
        return parse();
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(a + ": " + e.what());
      }
    };
    try {
      if (a == "--reference") referencePath = value();
      else if (a == "--scene") scene = value();
      else if (a == "--gains") gainsPath = value();
      else if (a == "--write-reference") writeReference = value();
      else if (a == "--runs") options.runs = static_cast<int>(hand::integerOption(a, value(), 0, 1000));
      else if (a == "--seed") options.seed = static_cast<unsigned>(hand::integerOption(a, value(), 0, 4294967295L));
      else if (a == "--perturbation") options.perturbation = hand::numberOption(a, value());
      else if (a == "--rate") options.sampleRate = hand::numberOption(a, value());
      else if (a == "--horizon") horizon = hand::numberOption(a, value());
      else if (a == "--threads") options.threads = static_cast<int>(hand::integerOption(a, value(), 1, 64));
      else if (a == "--max-ratio") options.maxErrorRatio = hand::numberOption(a, value());
      else if (a == "--quasi-static") quasiStaticDegrees = hand::numberOption(a, value());
      else if (a == "--pulse") pulse = value();
      else if (a == "--knots") quasiStaticKnots = static_cast<int>(hand::integerOption(a, value(), 2, 100000));
      else if (a == "--redistribute") redistributeKnots = static_cast<int>(hand::integerOption(a, value(), 0, 100000));
      else if (a == "--optimize") optimizeDegrees = hand::numberOption(a, value());
      else if (a == "--optimize-knots") optimizeKnots = static_cast<int>(hand::integerOption(a, value(), 2, 10000));
      else if (a == "--tension-floor") tensionFloor = hand::numberOption(a, value());
      else if (a == "--feedforward") options.feedforward = named([&] { return parseEnum<SampledFeedforward>(value(), "feed-forward"); });
      else if (a == "--transport-substeps") options.transportSubsteps = static_cast<int>(hand::integerOption(a, value(), 1, 1000));
      else if (a == "--rtol") options.rtol = hand::numberOption(a, value());
      else if (a == "--atol") options.atol = hand::numberOption(a, value());
      else if (a == "--drift") options.driftTolerance = hand::numberOption(a, value());
      else if (a == "--method") options.method = named([&] { return parseIntegrationMethod(value()); });
      else if (a == "--help") {
        std::cout << "usage: hand_ball_feedback [--reference CSV] [--scene NAME] [--runs N] [--seed S] "
                     "[--perturbation Z] [--rate HZ] [--horizon T] [--threads N] [--max-ratio R] [--gains CSV] "
                     "[--rtol R] [--atol A] [--drift D] [--method bdf|radau] [--transport-substeps S] [--quasi-static DEG [--knots N]] "
                     "[--pulse NAME:A] [--write-reference CSV] [--feedforward reference|average|consistent] "
                     "[--optimize DEG [--optimize-knots N]] [--redistribute N [--tension-floor F]]\n";
        return 0;
      } else {
        std::cerr << "hand_ball_feedback: unknown option '" << a << "' (--help lists them)\n";
        return 2;
      }
    } catch (const std::exception& e) {  // the parsers name the option, the text and the rule
      std::cerr << "hand_ball_feedback: error: " << e.what() << "\n";
      return 2;
    }
  }
  Scene s;
  hand::BallLimits limits;
  Trajectory reference;
  const auto jobStart = std::chrono::steady_clock::now();
  double stageSeconds[3] = {0.0, 0.0, 0.0};  // optimization, redistribution, consistency check
  try {
    s = loadScene(std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/" + scene + ".json");
    limits = hand::loadBallLimits(std::string(TRELLIS_HAND_DIR) + "/" + scene + "_limits.json", s.model);
    if (optimizeDegrees != 0.0) {
      // The turn optimized (ball_turn.hpp; the implicit form, Hermite–Simpson on a coarse mesh,
      // from the quasi-static warm start): Ipopt must converge; its own check on the coarse mesh
      // is reported, and the reference the gains use is the redistribution below.
      if (redistributeKnots <= 0) redistributeKnots = 201;
      hand::BallTurnOptions turn;
      turn.angle = optimizeDegrees * std::numbers::pi / 180.0;
      turn.horizon = horizon;
      turn.knots = optimizeKnots;
      turn.implicitForm = true;
      const auto model = std::make_shared<const Model>(s.model);
      const OptimalControlProblem problem = hand::makeBallTurnProblem(model, s.q, limits, turn);
      const OptimizerOptions oo = hand::ballTurnOptimizerOptions(options.threads);  // ball_turn.hpp
      const auto a = std::chrono::steady_clock::now();
      const OptimizationResult opt = optimizeTrajectory(problem, oo);
      stageSeconds[0] = std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count();
      std::printf("optimized the turn (%g deg in %g s, %d knots, implicit Hermite-Simpson): %s\n", optimizeDegrees, horizon,
                  optimizeKnots, opt.describe().c_str());
      std::fflush(stdout);
      const bool converged = opt.ipoptStatus == "Solve_Succeeded" || opt.ipoptStatus == "Solved_To_Acceptable_Level";
      if (!converged || opt.trajectory.size() != optimizeKnots) {
        std::printf("the optimizer did not converge\nFAILED\n");
        return 1;
      }
      reference = opt.trajectory;
    } else if (!referencePath.empty()) {
      reference = Trajectory::readCsvFile(referencePath);
    } else if (quasiStaticDegrees != 0.0) {
      hand::BallTurnOptions turn;
      turn.angle = quasiStaticDegrees * std::numbers::pi / 180.0;
      turn.horizon = horizon;
      turn.knots = quasiStaticKnots;
      reference = hand::quasiStaticTurn(s.model, s.q, limits, turn);
    } else if (!pulse.empty()) {
      reference = pulseReference(s, limits, pulse, horizon);
    } else {
      reference = hand::holdReference(s.model, s.q, s.u, horizon, 0.1);
    }
    reference.checkCompatible(s.model);
    if (redistributeKnots > 0) {
      // The motion kept, the tensions and contact forces redistributed on a dense grid so that
      // the plant follows it (ball_reference.hpp); its consistency checked as the optimizer's is.
      hand::InverseReferenceOptions ro;
      ro.knots = redistributeKnots;
      ro.tensionFloor = tensionFloor;
      const auto a = std::chrono::steady_clock::now();
      const hand::InverseReference inv = hand::inverseDynamicsReference(s.model, limits, reference, ro);
      const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count();
      stageSeconds[1] = sec;
      std::printf("redistributed on %d knots: %s (%.3f s, %d Newton iterations; |h| %.2g m, relative residual %.2g, "
                  "min normal %.4f N, worst friction ratio %.4f, min tension margin %.3g N)\n",
                  redistributeKnots, inv.ok ? "ok" : inv.message.c_str(), sec, inv.iterations, inv.maxConstraintResidual,
                  inv.maxRelativeResidual, inv.minNormal, inv.worstFrictionRatio, inv.minTensionMargin);
      if (!inv.ok) {
        std::fflush(stdout);
        return 1;
      }
      reference = inv.trajectory;
      const auto b = std::chrono::steady_clock::now();
      const ConsistencyResult c = checkConsistency(s.model, reference);
      stageSeconds[2] = std::chrono::duration<double>(std::chrono::steady_clock::now() - b).count();
      if (!c.ok()) {
        std::printf("its consistency: %s\nFAILED\n", c.status.describe().c_str());
        return 1;
      }
      std::printf("its consistency: %s (worst %.3g, median interval %.3g)\n", c.status.describe().c_str(), c.maxDefect,
                  [&] {
                    Eigen::VectorXd d = c.intervalDefects;
                    std::sort(d.data(), d.data() + d.size());
                    return d.size() ? d(d.size() / 2) : 0.0;
                  }());
      std::fflush(stdout);
    }
    options.validate();
    if (!writeReference.empty()) reference.writeCsvFile(writeReference);
  } catch (const std::exception& e) {
    std::cerr << "hand_ball_feedback: " << e.what() << "\n";
    return 2;
  }
  std::printf("scene %s: %d coordinates, %d tendons, %d contact rows; reference %s: %d knots on [%g, %g] s\n",
              scene.c_str(), s.model.nq(), s.model.nu(), s.model.nc(),
              optimizeDegrees != 0.0 ? "the optimized turn, redistributed (ball_reference.hpp)"
              : !referencePath.empty() ? referencePath.c_str()
              : quasiStaticDegrees != 0.0 ? "the quasi-static turn (ball_turn.hpp, not a solution of the dynamics)"
              : !pulse.empty()            ? "the plant's motion under a tension pulse"
                                          : "the stored hold",
              reference.size(),
              reference.startTime(), reference.endTime());
  std::printf("controller %g Hz, %d runs (seed %u, tangent perturbation %g), contacts: lambda_n >= %g N, "
              "|lambda_t| <= %g lambda_n (smooth cone) at every integrator step\n",
              options.sampleRate, options.runs, options.seed, options.perturbation, limits.normalMin, limits.friction);
  std::fflush(stdout);
  hand::BallFeedbackResult r;
  try {
    r = hand::runBallFeedback(s.model, limits, reference, options);
  } catch (const std::exception& e) {
    std::cerr << "hand_ball_feedback: " << e.what() << "\n";
    return 2;
  }
  std::printf("gains: %s\n", r.lqr.describe().c_str());
  std::printf("gains: %.3f s wall (%ld linearizations, %ld steps, %ld feed-forward simulations; feed-forward "
              "defect %.3g, predicted deviation %.3g)\n",
              r.gainSeconds, r.lqr.linearizations, r.lqr.steps, r.lqr.feedforwardSimulations, r.lqr.feedforwardDefect,
              r.lqr.predictedDeviation);
  if (!gainsPath.empty() && r.lqr.ok()) r.lqr.gains.writeCsvFile(gainsPath);
  for (std::size_t k = 0; k < r.runs.size(); ++k) std::printf("run %zu: %s\n", k, r.runs[k].describe().c_str());
  std::printf("%s", r.summary().c_str());
  {  // The job's figures in the words (over the reference's knots and every closed loop).
    const int yaw = s.model.configIndex("ball_yaw");
    const double turned = (reference.states()(yaw, reference.size() - 1) - reference.states()(yaw, 0)) * 180.0 / std::numbers::pi;
    const hand::ContactForces f = hand::contactForces(s.model, limits, reference);
    int failed = 0;
    double worstRatio = 0.0, minNormal = 1e300, worstFriction = 0.0;
    for (const hand::BallRun& run : r.runs) {
      failed += run.ok() ? 0 : 1;
      worstRatio = std::max(worstRatio, run.errorRatio);
      minNormal = std::min(minNormal, run.minNormal);
      worstFriction = std::max(worstFriction, run.worstFrictionRatio);
    }
    for (int k = 0; k < f.lambda.cols(); ++k) {
      const hand::ContactMargins c = hand::contactMargins(f.lambda.col(k), limits);
      minNormal = std::min(minNormal, c.minNormal);
      worstFriction = std::max(worstFriction, c.worstFrictionRatio);
    }
    const double whole = std::chrono::duration<double>(std::chrono::steady_clock::now() - jobStart).count();
    std::printf("ball rotation: %.3f deg\n", turned);
    std::printf("min normal force: %.4f N (margin %.3f N; reference and all closed loops)\n", minNormal, limits.normalMin);
    std::printf("worst friction ratio: %.4f (cone: 1)\n", worstFriction);
    std::printf("worst final/initial: %.3g\n", worstRatio);
    std::printf("N failed: %d of %zu\n", failed, r.runs.size());
    std::printf("stages: optimization %.2f s, redistribution %.2f s, consistency check %.2f s, gains %.2f s, closed loops %.2f s\n",
                stageSeconds[0], stageSeconds[1], stageSeconds[2], r.gainSeconds, r.closedLoopSeconds);
    std::printf("whole job: %.2f s\n", whole);
  }
  std::printf("%s\n", r.ok() ? "ok" : "FAILED");
  return r.ok() ? 0 : 1;
}
