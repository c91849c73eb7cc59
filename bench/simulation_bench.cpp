// simulation_bench — the hand's closed loop as the main job runs it (examples/main_job): the
// designed reference (301 knots over 3 s), manifold TV-LQR gains (Q = diag(100 I, I), R = I,
// kProjected transport), BDF at rtol 1e-7 / atol 1e-9, tensions clipped at 0, constraints
// projected, starts perturbed by 0.05 along seeded tangent directions.
//   BM_HandClosedLoop/exact:1/saturation:1  one 3 s run as in the main job, exact Jacobian A − B S K;
//     exact:0 difference quotients; saturation:0 without the tension limits (what switching costs)
//   BM_HandClosedLoopBatch/threads:T  the main job's 20 runs through simulateBatch on T threads
// Counters: steps, restarts, projections, Jacobians and difference-quotient right-hand sides per
// run, and the final tracking error (the speed is worth nothing if the run is wrong).
#include "reference_motion.hpp"

#include <trellis/control.hpp>
#include <trellis/core/scene.hpp>

#include <benchmark/benchmark.h>

#include <Eigen/Core>

#include <cmath>
#include <memory>
#include <random>
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
    const trellis::Model& model = scene.model;
    const int n = model.nq(), m = model.nu(), nx = 2 * n;
    const trellis::hand::ReferenceMotion motion = trellis::hand::makeReferenceMotion(model, scene.q);
    if (!motion.ok) throw std::runtime_error("reference motion: " + motion.message);
    reference = motion.trajectory;
    trellis::LqrWeights w;
    w.Q = Eigen::MatrixXd::Identity(nx, nx);
    w.Q.topLeftCorner(n, n) *= 100.0;
    w.R = Eigen::MatrixXd::Identity(m, m);
    w.Qf = w.Q;
    trellis::RiccatiOptions ro;
    ro.rtol = 1e-6;
    ro.atol = 1e-8;
    trellis::TangentTransportOptions transport;
    transport.method = trellis::TangentTransport::kProjected;
    transport.substeps = 2;
    const trellis::ManifoldRiccatiSolution lqr =
        trellis::solveManifoldRiccati(model, reference, w, ro, transport);
    if (!lqr.ok()) throw std::runtime_error("manifold Riccati: " + lqr.message());
    gains = trellis::GainSchedule::sample([&](double t) { return lqr.K(t); }, reference.times());
    options.method = trellis::IntegrationMethod::kBDF;
    options.rtol = 1e-7;
    options.atol = 1e-9;
    options.inputLower = Eigen::VectorXd::Zero(m);
    options.inputUpper = Eigen::VectorXd::Constant(m, INFINITY);
    std::mt19937 rng(1);
    std::normal_distribution<double> normal(0.0, 1.0);
    const Eigen::MatrixXd T0 = lqr.basis.basis(reference.startTime());
    const Eigen::VectorXd x0 = reference.states().col(0);
    for (int r = 0; r < 20; ++r) {
      Eigen::VectorXd z(T0.cols());
      for (int i = 0; i < z.size(); ++i) z(i) = normal(rng);
      z *= 0.05 / z.norm();
      starts.push_back(x0 + T0 * z);
    }
  }
};

HandLoop& hand() {
  static const std::unique_ptr<HandLoop> loop = std::make_unique<HandLoop>();
  return *loop;
}

void setCounters(benchmark::State& state, const std::vector<trellis::SimulationResult>& results) {
  double steps = 0, restarts = 0, projections = 0, jacobians = 0, quotient = 0, error = 0;
  for (const trellis::SimulationResult& r : results) {
    if (!r.ok()) state.SkipWithError(r.message.c_str());
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
