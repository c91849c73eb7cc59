// examples/hand/hand_ball_feedback.cpp — sampled TV-LQR gains and contact-checked closed loops of
// the hand holding or turning a free ball (issue 26; ball_feedback.hpp).
//
//   hand_ball_feedback [--reference CSV] [--scene NAME] [--runs N] [--seed S] [--perturbation Z]
//                      [--rate HZ] [--horizon T] [--threads N] [--max-ratio R] [--gains CSV]
//                      [--rtol R] [--atol A] [--drift D] [--transport-substeps S]
//                      [--quasi-static DEG [--knots N]] [--pulse NAME:A] [--write-reference CSV]
//                      [--feedforward reference|average|consistent]
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
// tolerances and projection threshold, --transport-substeps the tangent basis's steps per knot
// interval (BallFeedbackOptions). Prints the gains' solve and time, one line per run,
// the aggregate; exit 0 only when the gains are solved and every closed loop kept every contact
// at every integrator step and converged (final / initial tracking error ≤ R, default 0.5);
// 1 otherwise; 2 on bad arguments or files.
#include "ball_feedback.hpp"
#include "hand_feedback.hpp"

#include <trellis/analysis/simulation.hpp>
#include <trellis/control/tvlqr.hpp>
#include <trellis/core.hpp>

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
  int quasiStaticKnots = 21;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "hand_ball_feedback: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    try {
      if (a == "--reference") referencePath = value();
      else if (a == "--scene") scene = value();
      else if (a == "--gains") gainsPath = value();
      else if (a == "--write-reference") writeReference = value();
      else if (a == "--runs") options.runs = std::stoi(value());
      else if (a == "--seed") options.seed = static_cast<unsigned>(std::stoul(value()));
      else if (a == "--perturbation") options.perturbation = std::stod(value());
      else if (a == "--rate") options.sampleRate = std::stod(value());
      else if (a == "--horizon") horizon = std::stod(value());
      else if (a == "--threads") options.threads = std::stoi(value());
      else if (a == "--max-ratio") options.maxErrorRatio = std::stod(value());
      else if (a == "--quasi-static") quasiStaticDegrees = std::stod(value());
      else if (a == "--pulse") pulse = value();
      else if (a == "--knots") quasiStaticKnots = std::stoi(value());
      else if (a == "--feedforward") options.feedforward = parseEnum<SampledFeedforward>(value(), "feed-forward");
      else if (a == "--transport-substeps") options.transportSubsteps = std::stoi(value());
      else if (a == "--rtol") options.rtol = std::stod(value());
      else if (a == "--atol") options.atol = std::stod(value());
      else if (a == "--drift") options.driftTolerance = std::stod(value());
      else if (a == "--help") {
        std::cout << "usage: hand_ball_feedback [--reference CSV] [--scene NAME] [--runs N] [--seed S] "
                     "[--perturbation Z] [--rate HZ] [--horizon T] [--threads N] [--max-ratio R] [--gains CSV] "
                     "[--rtol R] [--atol A] [--drift D] [--transport-substeps S] [--quasi-static DEG [--knots N]] "
                     "[--pulse NAME:A] [--write-reference CSV] [--feedforward reference|average|consistent]\n";
        return 0;
      } else {
        std::cerr << "hand_ball_feedback: unknown option '" << a << "' (--help lists them)\n";
        return 2;
      }
    } catch (const std::exception&) {
      std::cerr << "hand_ball_feedback: " << a << ": '" << argv[i] << "' is not a number\n";
      return 2;
    }
  }
  Scene s;
  hand::BallLimits limits;
  Trajectory reference;
  try {
    s = loadScene(std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/" + scene + ".json");
    limits = hand::loadBallLimits(std::string(TRELLIS_HAND_DIR) + "/" + scene + "_limits.json", s.model);
    if (!referencePath.empty()) {
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
    options.validate();
    if (!writeReference.empty()) reference.writeCsvFile(writeReference);
  } catch (const std::exception& e) {
    std::cerr << "hand_ball_feedback: " << e.what() << "\n";
    return 2;
  }
  std::printf("scene %s: %d coordinates, %d tendons, %d contact rows; reference %s: %d knots on [%g, %g] s\n",
              scene.c_str(), s.model.nq(), s.model.nu(), s.model.nc(),
              !referencePath.empty() ? referencePath.c_str()
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
  std::printf("%s\n", r.ok() ? "ok" : "FAILED");
  return r.ok() ? 0 : 1;
}
