// simulation_bench — the hand's closed loop as the main job runs it (examples/main_job): the
// designed reference (301 knots over 3 s, tensions with rates: cubic input rule), manifold TV-LQR
// gains as examples/hand/hand_feedback.hpp designs them (knots + Riccati steps, cubic gain rule),
// BDF at rtol 1e-7 / atol 5e-10 on the deviation from the reference, tensions clipped at 0,
// constraints projected, starts perturbed by 0.05 along seeded tangent directions.
//   BM_HandClosedLoop/exact:1/saturation:1  one 3 s run as in the main job, exact Jacobian A − B S K;
//     exact:0 difference quotients; saturation:0 without the tension limits (what switching costs)
//   BM_HandClosedLoopBatch/threads:T  the main job's 20 runs through simulateBatch on T threads
// Counters: steps, restarts, projections, Jacobians and difference-quotient right-hand sides per
// run, and the final tracking error (the speed is worth nothing if the run is wrong).
#include "hand_feedback.hpp"
#include "reference_motion.hpp"

#include <trellis/control.hpp>
#include <trellis/core/scene.hpp>

#include <benchmark/benchmark.h>

#include <Eigen/Core>

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

struct HandLoop {
  trellis::Scene scene;
  trellis::Trajectory reference;
  trellis::GainSchedule gains;
  std::vector<Eigen::VectorXd> starts;
  trellis::SimulationOptions options;

  HandLoop() : scene(trellis::loadScene(std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/hand.json")) {
    namespace hand = trellis::hand;
    const trellis::Model& model = scene.model;
    const hand::ReferenceMotion motion = hand::makeReferenceMotion(model, scene.q);
    if (!motion.ok) throw std::runtime_error("reference motion: " + motion.message);
    reference = motion.trajectory;
    const trellis::ManifoldRiccatiSolution lqr = trellis::solveManifoldRiccati(
        model, reference, hand::feedbackWeights(model), hand::feedbackRiccatiOptions(),
        hand::feedbackTransport());
    if (!lqr.ok()) throw std::runtime_error("manifold Riccati: " + lqr.status.message);
    gains = hand::feedbackGains(lqr, reference);
    options = hand::closedLoopOptions(model.nu());
    starts = hand::perturbedStarts(lqr.basis.basis(reference.startTime()),
                                   reference.states().col(0), 20, 1, 0.05);
  }
};

HandLoop& hand() {
  static const std::unique_ptr<HandLoop> loop = std::make_unique<HandLoop>();
  return *loop;
}

void setCounters(benchmark::State& state, const std::vector<trellis::SimulationResult>& results) {
  double steps = 0, restarts = 0, projections = 0, jacobians = 0, quotient = 0, error = 0;
  for (const trellis::SimulationResult& r : results) {
    if (!r.ok()) state.SkipWithError(r.status.message.c_str());
    steps += r.steps;
    restarts += r.restarts;
    projections += r.projections;
    jacobians += r.jacobianEvaluations;
    quotient += r.linearRhsEvaluations;
    if (r.trackingError.size() > 0)
      error = std::max(error, r.trackingError(r.trackingError.size() - 1));
  }
  const double k = static_cast<double>(results.size());
  state.counters["steps"] = steps / k;
  state.counters["restarts"] = restarts / k;
  state.counters["projections"] = projections / k;
  state.counters["jacobians"] = jacobians / k;
  state.counters["dq_rhs"] = quotient / k;
  state.counters["final_error"] = error;
}

void BM_HandClosedLoop(benchmark::State& state) {
  HandLoop& h = hand();
  trellis::SimulationOptions options = h.options;
  options.exactJacobian = state.range(0) != 0;
  if (state.range(1) == 0) options.inputLower.resize(0), options.inputUpper.resize(0);
  trellis::SimulationResult result;
  for (auto _ : state) {
    result = trellis::simulateClosedLoop(h.scene.model, h.reference, h.gains, h.starts[0], options);
    benchmark::DoNotOptimize(result.steps);
  }
  setCounters(state, {result});
}
BENCHMARK(BM_HandClosedLoop)->ArgNames({"exact", "saturation"})->Args({1, 1})->Args({0, 1})
    ->Args({1, 0})->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_HandClosedLoopBatch(benchmark::State& state) {
  HandLoop& h = hand();
  std::vector<trellis::SimulationResult> results;
  for (auto _ : state) {
    results = trellis::simulateBatch(h.scene.model, h.reference, h.gains, h.starts, h.options,
                                     static_cast<int>(state.range(0)));
    benchmark::DoNotOptimize(results.data());
  }
  setCounters(state, results);
}
BENCHMARK(BM_HandClosedLoopBatch)->ArgName("threads")->Arg(1)->Arg(2)
    ->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
