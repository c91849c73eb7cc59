// sampled_gains_bench — sampled-data (zero-order-hold) TV-LQR gains against the continuous gains
// of the same problem (Google Benchmark; issue 31).
//
// Problems (built here, no files): the damped 6-link hanging chain of bench/chain_scene.py (12
// states, 6 torques; 0.1 kg point masses 0.1 m apart, damping 0.1 per joint) —
//  - `hold`: held hanging at rest for 5 s (as `trellis gains --hold 5`: ẋ = 0 at the knots, so the
//    reference is exactly constant and the sampled path uses the block exponential);
//  - `swing`: its free swing for 2 s from q_i = 0.3 rad (u = 0, simulated at rtol 1e-11, knots
//    every 20 ms): a time-varying reference, every interval integrated.
// Weights Q = I, R = I, Qf = I; the sampled rows time the gains alone (feed-forward reference
// without the held reference's plant runs); solveTvlqr with its default tolerances (continuous: Riccati rtol
// 1e-8, atol 1e-10; sampled: rtol kRadauRtol = 1e-6 for Radau, kRtol = 1e-10 for Magnus and BDF,
// atol 1e-12).
//
// Benchmarks: `Continuous/<problem>`; `RiccatiTracking/<problem>/track:<0|1>` (the continuous
// Riccati solve alone with S's per-step eigenvalue tracking off / on); and
// `Sampled/<problem>/rate:<Hz>/integrator:<i>/rtol:<E>` (i: 0 Magnus, 1 Radau — the default —, 2
// CVODES BDF; SampledIntegrator; rtol 10^−E, E = 0: the integrator's default; the swing's Magnus
// rows at E = 4, 6, 8 and Radau rows at E = 5, 7, 8 give time against error). Counter `max_rel_err`: max |K − K_ref| / max |K_ref|
// against every interval integrated by CVODES at rtol 1e-12, atol 1e-14 (exactConstantIntervals
// = false; computed once per problem and rate, outside the timing: ~15 s at 1000 Hz).
//   build/bench/trellis_bench_sampled_gains --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
#include <trellis/control.hpp>
#include <trellis/control/tvlqr.hpp>
#include <trellis/core/scene.hpp>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>
#include <vector>
#include <stdexcept>
#include <string>

namespace {

constexpr int kLinks = 6;

std::string chainJson(int n) {
  std::string frames;
  for (int i = n; i >= 1; --i) {
    const std::string child = frames.empty() ? "[]" : "[" + frames + "]";
    frames = R"({"name": "l)" + std::to_string(i) + R"(", "type": "rz", "config": "q)" + std::to_string(i) +
             R"(", "children": [{"name": "m)" + std::to_string(i) +
             R"(", "type": "ty", "value": -0.1, "mass": {"m": 0.1}, "children": )" + child + "}]}";
  }
  std::string forces;
  for (int i = 1; i <= n; ++i) {
    forces += R"({"type": "config_force", "config": "q)" + std::to_string(i) + R"(", "input": "u)" +
              std::to_string(i) + R"("}, )";
  }
  return R"({"name": "chain", "frames": [)" + frames +
         R"(], "potentials": [{"type": "gravity", "g": [0.0, -9.81, 0.0]}], "forces": [)" + forces +
         R"({"type": "damping", "default": 0.1}]})";
}

struct Problem {
  trellis::Scene scene;
  trellis::Trajectory hold, swing;
  trellis::LqrWeights weights;
};

const Problem& problem() {
  static const Problem p = [] {
    Problem r{trellis::parseScene(chainJson(kLinks), "6-link chain"), {}, {}, {}};
    const trellis::Model& model = r.scene.model;
    const int nx = 2 * model.nq(), m = model.nu();
    constexpr int kKnots = 101;
    r.hold = trellis::Trajectory(model.configNames(), model.inputNames(), Eigen::VectorXd::LinSpaced(kKnots, 0.0, 5.0),
                                 Eigen::MatrixXd::Zero(nx, kKnots), Eigen::MatrixXd::Zero(m, kKnots));
    r.hold.setStateDerivatives(Eigen::MatrixXd::Zero(nx, kKnots));  // at rest: the hanging equilibrium
    trellis::SimulationOptions so;
    so.rtol = 1e-11;
    so.atol = 1e-12;
    so.outputStep = 0.02;
    Eigen::VectorXd x0 = Eigen::VectorXd::Zero(nx);
    x0.head(model.nq()).setConstant(0.3);
    const trellis::Policy zero = [](double, const Eigen::VectorXd&, Eigen::VectorXd& u) { u.setZero(); };
    const trellis::SimulationResult s = trellis::simulate(model, x0, 0.0, 2.0, zero, so);
    if (!s.ok()) throw std::runtime_error("swing: " + s.status.message);
    r.swing = s.trajectory;
    r.weights.Q = Eigen::MatrixXd::Identity(nx, nx);
    r.weights.R = Eigen::MatrixXd::Identity(m, m);
    r.weights.Qf = r.weights.Q;
    return r;
  }();
  return p;
}

const trellis::Trajectory& reference(int which) { return which == 0 ? problem().hold : problem().swing; }

trellis::TvlqrSolution solve(int which, double rate, bool exact = true, bool tight = false,
                             trellis::SampledIntegrator integrator = trellis::SampledIntegrator::kMagnus,
                             double rtol = 0.0) {
  trellis::TvlqrOptions o;
  if (rtol > 0.0) o.sampled.rtol = rtol;
  o.sampleRate = rate;
  // The gains alone (discretization and recursion): no feed-forward and no plant run (the
  // held reference's runs give only the defect and the prediction; issue 27).
  o.feedforward = trellis::SampledFeedforward::kReference;
  o.measureHeldReference = false;
  o.sampled.integrator = integrator;
  o.sampled.exactConstantIntervals = exact;
  if (tight) {
    o.sampled.integrator = trellis::SampledIntegrator::kBdf;
    o.sampled.rtol = 1e-12;
    o.sampled.atol = 1e-14;
  }
  trellis::TvlqrSolution s = trellis::solveTvlqr(problem().scene.model, reference(which), problem().weights, o);
  if (!s.ok()) throw std::runtime_error("solveTvlqr: " + s.status.describe());
  return s;
}

double maxRelativeError(const std::vector<Eigen::MatrixXd>& ref, const std::vector<Eigen::MatrixXd>& got) {
  double scale = 0.0, diff = 0.0;
  for (std::size_t k = 0; k < ref.size(); ++k) {
    scale = std::max(scale, ref[k].cwiseAbs().maxCoeff());
    diff = std::max(diff, (got[k] - ref[k]).cwiseAbs().maxCoeff());
  }
  return diff / scale;
}

void BM_Continuous(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  trellis::TvlqrSolution last;
  for (auto _ : state) {
    last = solve(which, 0.0);
    benchmark::DoNotOptimize(last);
  }
  state.SetLabel(which == 0 ? "hold" : "swing");
  state.counters["steps"] = static_cast<double>(last.steps);
  state.counters["linearizations"] = static_cast<double>(last.linearizations);
}

// The continuous Riccati solve alone (solveTvlqr's default options), with S's per-step
// eigenvalue tracking on (1) or off (0): what solveTvlqr saves by taking the spectrum at its
// output grid instead.
void BM_RiccatiTracking(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  trellis::RiccatiOptions o;
  o.trackEigenvalues = state.range(1) != 0;
  for (auto _ : state) {
    const trellis::RiccatiSolution s = trellis::solveRiccati(problem().scene.model, reference(which), problem().weights, o);
    if (!s.ok()) throw std::runtime_error("solveRiccati: " + s.status.describe());
    benchmark::DoNotOptimize(s);
  }
  state.SetLabel(which == 0 ? "hold" : "swing");
}

void BM_Sampled(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const double rate = static_cast<double>(state.range(1));
  const auto integrator = static_cast<trellis::SampledIntegrator>(state.range(2));
  // rtol: 10^−range(3), or the default for 0.
  const double rtol = state.range(3) > 0 ? std::pow(10.0, -static_cast<double>(state.range(3))) : 0.0;
  trellis::TvlqrSolution last;
  for (auto _ : state) {
    last = solve(which, rate, true, false, integrator, rtol);
    benchmark::DoNotOptimize(last);
  }
  state.SetLabel(which == 0 ? "hold" : "swing");
  state.counters["steps"] = static_cast<double>(last.steps);
  state.counters["linearizations"] = static_cast<double>(last.linearizations);
  double err = -1.0;
  {
    static std::map<std::pair<int, double>, std::vector<Eigen::MatrixXd>> refs;  // once per problem and rate
    const auto key = std::make_pair(which, rate);
    auto it = refs.find(key);
    if (it == refs.end()) it = refs.emplace(key, solve(which, rate, false, true).gains.gains()).first;
    err = maxRelativeError(it->second, last.gains.gains());
  }
  state.counters["max_rel_err"] = err;
}

}  // namespace

BENCHMARK(BM_Continuous)->ArgNames({"problem"})->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RiccatiTracking)->ArgNames({"problem", "track"})->ArgsProduct({{0, 1}, {0, 1}})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Sampled)
    ->ArgNames({"problem", "rate", "integrator", "rtol"})
    ->Args({0, 10, 0, 0})
    ->Args({0, 100, 0, 0})
    ->Args({0, 1000, 0, 0})
    ->ArgsProduct({{1}, {10, 100, 1000}, {1, 0}, {0}})
    ->ArgsProduct({{1}, {100}, {0}, {4, 6, 8}})
    ->ArgsProduct({{1}, {100}, {1}, {5, 7, 8}})
    ->Args({1, 10, 2, 0})
    ->Args({1, 100, 2, 0})
    ->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
