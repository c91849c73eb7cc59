// sampled_bench — sampled-data (zero-order-hold) TV-LQR gains along the hand's reference motion
// (examples/scenes/hand.json + examples/hand's reference, as in examples/main_job) at 100 Hz and
// 1 kHz against the continuous solve: the time of each solve (solveTvlqr, wall clock, best of
// --repeat), and the closed-loop tracking error of a controller sampling at that rate from the
// same seeded perturbed start with (a) the continuous gains sampled at the rate and (b) the ZOH
// gains for that rate.
//
// Weights as the main job: Q = diag(100·I_n, I_n), R = I, Qf = Q; the tangent basis by discrete
// transport on the knots (kProjected, 2 substeps); continuous Riccati and interval discretization
// rtol 1e-6, atol 1e-8.
// Closed loop: examples/hand/hand_feedback.hpp's options (BDF, rtol 1e-7, atol 5e-10, tensions clipped at 0), perturbation of norm --perturbation
// along a seeded random tangent direction at t0.
//
// --feedforward reference|average|consistent: the held feed-forward of the ZOH gains (TvlqrOptions::
// feedforward). Default reference (none: u_ref(t_k) held), so that the solve times stay those of
// the discretization and recursion measured before issue 27; consistent adds one plant run per
// interval and Gauss-Newton step (its cost is printed in the solve's line as plant runs).
//   trellis_bench_sampled [--duration 3] [--knots 301] [--rates 100,1000] [--perturbation 0.01]
//                         [--seed 1] [--repeat 1] [--no-simulate] [--feedforward reference]
// One line per solve and per closed loop; a JSON line (prefix "json: ") per row for scripts.
#include "hand_feedback.hpp"
#include "reference_motion.hpp"

#include <trellis/control.hpp>
#include <trellis/core/scene.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

namespace {

struct Args {
  double duration = 3.0;
  int knots = 301;
  std::vector<double> rates = {100.0, 1000.0};
  double perturbation = 0.01;
  unsigned seed = 1;
  int repeat = 1;
  bool simulate = true;
  trellis::SampledFeedforward feedforward = trellis::SampledFeedforward::kReference;
};

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error(k + " needs a value");
      return argv[++i];
    };
    if (k == "--duration") a.duration = std::stod(next());
    else if (k == "--knots") a.knots = std::stoi(next());
    else if (k == "--perturbation") a.perturbation = std::stod(next());
    else if (k == "--seed") a.seed = static_cast<unsigned>(std::stoul(next()));
    else if (k == "--repeat") a.repeat = std::stoi(next());
    else if (k == "--no-simulate") a.simulate = false;
    else if (k == "--feedforward") a.feedforward = trellis::parseEnum<trellis::SampledFeedforward>(next(), "--feedforward");
    else if (k == "--rates") {
      a.rates.clear();
      std::stringstream ss(next());
      std::string item;
      while (std::getline(ss, item, ',')) a.rates.push_back(std::stod(item));
    } else {
      throw std::runtime_error("unknown option " + k);
    }
  }
  return a;
}

}  // namespace

int main(int argc, char** argv) try {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // line by line, also into a pipe
  const Args args = parse(argc, argv);
  const trellis::Scene scene = trellis::loadScene(std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/hand.json");
  const trellis::Model& model = scene.model;
  const int n = model.nq(), m = model.nu();
  trellis::hand::ReferenceMotionOptions ro;
  ro.duration = args.duration;
  ro.knots = args.knots;
  const trellis::hand::ReferenceMotion reference = trellis::hand::makeReferenceMotion(model, scene.q, ro);
  if (!reference.ok) throw std::runtime_error("reference motion: " + reference.message);
  const trellis::Trajectory& trajectory = reference.trajectory;
  std::printf("hand: n = %d, m = %d, nc = %d; reference %d knots over %.3g s\n", n, m, model.nc(),
              trajectory.size(), trajectory.endTime() - trajectory.startTime());

  const trellis::LqrWeights weights = trellis::hand::feedbackWeights(model);
  trellis::TvlqrOptions base;
  base.transport = trellis::hand::feedbackTransport();
  base.riccati = trellis::hand::feedbackRiccatiOptions();
  base.sampled.rtol = base.riccati.rtol;  // the same tolerances for the interval discretization
  base.sampled.atol = base.riccati.atol;

  auto timed = [&](const trellis::TvlqrOptions& o, double& best) {
    trellis::TvlqrSolution sol;
    best = INFINITY;
    for (int r = 0; r < std::max(1, args.repeat); ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      sol = trellis::solveTvlqr(model, trajectory, weights, o);
      best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    if (!sol.ok()) throw std::runtime_error("solveTvlqr: " + sol.status.describe());
    return sol;
  };

  double tCont = 0.0;
  const trellis::TvlqrSolution cont = timed(base, tCont);
  std::printf("continuous: %.3f s, %ld steps, %ld rhs\n", tCont, cont.steps, cont.rhsEvaluations);
  std::printf("json: {\"solve\": \"continuous\", \"seconds\": %.6g, \"steps\": %ld, \"rhs\": %ld}\n", tCont,
              cont.steps, cont.rhsEvaluations);
  // Continuous gains on a fine grid for the sampled view (the knots: every 10 ms on the default motion).
  const trellis::GainSchedule& contGains = cont.gains;

  // Seeded tangent perturbation at t0.
  const trellis::TangentBasisTrajectory basis = trellis::transportTangentBasis(model, trajectory, base.transport);
  const Eigen::VectorXd x0 = trellis::hand::perturbedStarts(basis.basis(trajectory.startTime()),
                                                            trajectory.states().col(0), 1, args.seed,
                                                            args.perturbation)[0];
  trellis::SimulationOptions sim = trellis::hand::closedLoopOptions(m);

  for (double rate : args.rates) {
    trellis::TvlqrOptions o = base;
    o.sampleRate = rate;
    o.feedforward = args.feedforward;
    double tSamp = 0.0;
    const trellis::TvlqrSolution samp = timed(o, tSamp);
    std::printf("sampled %g Hz: %.3f s (%.2fx the continuous solve), %ld steps, %ld rhs, %ld linearizations, "
                "feed-forward %s (%ld plant runs, defect %.3g against %.3g for u_ref(t_k), predicted deviation %.3g)\n",
                rate, tSamp, tSamp / tCont, samp.steps, samp.rhsEvaluations, samp.linearizations,
                std::string(trellis::toString(args.feedforward)).c_str(), samp.feedforwardSimulations,
                samp.feedforwardDefect, samp.referenceDefect, samp.predictedDeviation);
    std::printf("json: {\"solve\": \"sampled\", \"rate_hz\": %g, \"seconds\": %.6g, \"ratio_to_continuous\": %.4g, "
                "\"steps\": %ld, \"rhs\": %ld, \"linearizations\": %ld}\n",
                rate, tSamp, tSamp / tCont, samp.steps, samp.rhsEvaluations, samp.linearizations);
    if (!args.simulate) continue;
    sim.sampleRate = rate;
    for (int which = 0; which < 2; ++which) {
      const trellis::GainSchedule& g = which == 0 ? contGains : samp.gains;
      const trellis::SimulationResult r = trellis::simulateClosedLoop(model, trajectory, g, x0, sim);
      const char* label = which == 0 ? "continuous gains sampled" : "ZOH gains";
      if (!r.ok()) {
        std::printf("  closed loop at %g Hz, %s: FAILED (%s)\n", rate, label, r.status.message.c_str());
        std::printf("json: {\"closed_loop\": \"%s\", \"rate_hz\": %g, \"ok\": false}\n", label, rate);
        continue;
      }
      const double e0 = r.trackingError(0), eT = r.trackingError(r.trackingError.size() - 1);
      const double emax = r.trackingError.maxCoeff();
      std::printf("  closed loop at %g Hz, %s: error initial %.3g, final %.3g, max %.3g\n", rate, label, e0, eT,
                  emax);
      std::printf("json: {\"closed_loop\": \"%s\", \"rate_hz\": %g, \"ok\": true, \"initial\": %.6g, "
                  "\"final\": %.6g, \"max\": %.6g}\n",
                  label, rate, e0, eT, emax);
    }
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "sampled_bench: %s\n", e.what());
  return 1;
}
