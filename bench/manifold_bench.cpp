// manifold_bench — the manifold TV-LQR along the hand's reference motion (examples/scenes/hand.json
// and examples/hand's reference, settings of examples/main_job: Q = diag(100·I_n, I_n), R = I,
// Qf = Q, transport kProjected with 2 substeps, Riccati rtol 1e-6, atol 1e-8), its parts (the
// transport, controllability at every knot, the reachability Gramian), and the Gramian of a
// 20-link planar chain hanging at rest (40 states, 2 s) beside that chain's Riccati solve.
// Counters: CVODES steps, dynamics evaluations (linearizations), difference-quotient rhs.
//
//   trellis_bench_manifold [--benchmark_filter=REGEX] [--benchmark_repetitions=3]
#include "models.hpp"
#include "reference_motion.hpp"

#include <trellis/control.hpp>
#include <trellis/control/controllability.hpp>
#include <trellis/control/manifold_lqr.hpp>
#include <trellis/core/data.hpp>
#include <trellis/core/scene.hpp>

#include <benchmark/benchmark.h>

#include <memory>
#include <stdexcept>
#include <string>

namespace {

struct Hand {
  trellis::Scene scene;
  trellis::Trajectory trajectory;
  trellis::LqrWeights weights;
  trellis::RiccatiOptions riccati;
  trellis::TangentTransportOptions transport;
};

const Hand& hand() {
  static const std::unique_ptr<Hand> h = [] {
    auto p = std::make_unique<Hand>();
    p->scene = trellis::loadScene(std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/hand.json");
    const trellis::Model& model = p->scene.model;
    const auto ref = trellis::hand::makeReferenceMotion(model, p->scene.q);
    if (!ref.ok) throw std::runtime_error("reference motion: " + ref.message);
    p->trajectory = ref.trajectory;
    const int n = model.nq(), m = model.nu(), nx = 2 * n;
    p->weights.Q = Eigen::MatrixXd::Identity(nx, nx);
    p->weights.Q.topLeftCorner(n, n) *= 100.0;
    p->weights.R = Eigen::MatrixXd::Identity(m, m);
    p->weights.Qf = p->weights.Q;
    p->riccati.rtol = 1e-6;
    p->riccati.atol = 1e-8;
    p->transport.method = trellis::TangentTransport::kProjected;
    p->transport.substeps = 2;
    return p;
  }();
  return *h;
}

void HandManifoldRiccati(benchmark::State& state) {
  const Hand& h = hand();
  trellis::ManifoldRiccatiSolution sol;
  for (auto _ : state) {
    sol = trellis::solveManifoldRiccati(h.scene.model, h.trajectory, h.weights, h.riccati, h.transport);
    if (!sol.ok()) {
      state.SkipWithError(sol.status.message.c_str());
      return;
    }
  }
  state.counters["steps"] = static_cast<double>(sol.reduced.steps);
  state.counters["rhs"] = static_cast<double>(sol.reduced.rhsEvaluations);
  state.counters["jacobians"] = static_cast<double>(sol.reduced.jacobianEvaluations);
  state.counters["linearizations"] = static_cast<double>(sol.linearizations);
  state.counters["d"] = sol.dimension();
}
BENCHMARK(HandManifoldRiccati)->Unit(benchmark::kMillisecond);

void HandTransport(benchmark::State& state) {
  const Hand& h = hand();
  trellis::TangentTransportOptions o = h.transport;
  if (state.range(0) == 1) o.method = trellis::TangentTransport::kIntegrated;
  trellis::TangentBasisTrajectory b;
  for (auto _ : state) {
    b = trellis::transportTangentBasis(h.scene.model, h.trajectory, o);
    if (!b.ok()) {
      state.SkipWithError(b.describe().c_str());
      return;
    }
  }
  state.SetLabel(state.range(0) == 1 ? "integrated" : "projected");
  state.counters["steps"] = static_cast<double>(b.steps());
  state.counters["dq_rhs"] = static_cast<double>(b.differenceQuotientEvaluations());
}
BENCHMARK(HandTransport)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void HandControllabilityAtKnots(benchmark::State& state) {
  const Hand& h = hand();
  for (auto _ : state) {
    benchmark::DoNotOptimize(trellis::controllabilityAtKnots(h.scene.model, h.trajectory));
  }
}
BENCHMARK(HandControllabilityAtKnots)->Unit(benchmark::kMillisecond);

void HandGramian(benchmark::State& state) {
  const Hand& h = hand();
  trellis::GramianOptions o;
  o.transport = h.transport;
  trellis::GramianReport r;
  for (auto _ : state) {
    r = trellis::computeControllabilityGramian(h.scene.model, h.trajectory, h.trajectory.startTime(),
                                               h.trajectory.endTime(), o);
    if (!r.ok()) {
      state.SkipWithError(r.status.message.c_str());
      return;
    }
  }
  state.counters["steps"] = static_cast<double>(r.steps);
  state.counters["linearizations"] = static_cast<double>(r.linearizations);
  state.counters["dq_rhs"] = static_cast<double>(r.differenceQuotientEvaluations);
  state.counters["lambda_min"] = r.minEigenvalue;
}
BENCHMARK(HandGramian)->Unit(benchmark::kMillisecond);

struct Chain {
  trellis::bench::BenchModel bm;
  trellis::Trajectory trajectory;
};

const Chain& chain() {
  static const std::unique_ptr<Chain> c = [] {
    auto p = std::unique_ptr<Chain>(new Chain{
        trellis::bench::makeBenchModel({trellis::bench::ModelKind::kPlanarChain, 20, false}), {}});
    const trellis::Model& model = p->bm.model;
    const int n = model.nq(), knots = 201;
    Eigen::VectorXd times = Eigen::VectorXd::LinSpaced(knots, 0.0, 2.0);
    const Eigen::MatrixXd X = Eigen::MatrixXd::Zero(2 * n, knots);  // hanging at rest
    const Eigen::MatrixXd U = Eigen::MatrixXd::Zero(model.nu(), knots);
    p->trajectory = trellis::Trajectory(model.configNames(), model.inputNames(), times, X, U);
    trellis::Data data(model);
    p->trajectory.computeStateDerivatives(model, data);
    return p;
  }();
  return *c;
}

void ChainGramian(benchmark::State& state) {
  const Chain& c = chain();
  trellis::GramianReport r;
  for (auto _ : state) {
    r = trellis::computeControllabilityGramian(c.bm.model, c.trajectory, 0.0, 2.0,
                                               trellis::GramianOptions{});
    if (!r.ok()) {
      state.SkipWithError(r.status.message.c_str());
      return;
    }
  }
  state.counters["steps"] = static_cast<double>(r.steps);
  state.counters["linearizations"] = static_cast<double>(r.linearizations);
  state.counters["dq_rhs"] = static_cast<double>(r.differenceQuotientEvaluations);
}
BENCHMARK(ChainGramian)->Unit(benchmark::kMillisecond);

void ChainRiccati(benchmark::State& state) {
  const Chain& c = chain();
  const int nx = 2 * c.bm.model.nq(), m = c.bm.model.nu();
  const trellis::LqrWeights w{10.0 * Eigen::MatrixXd::Identity(nx, nx), Eigen::MatrixXd::Identity(m, m),
                              10.0 * Eigen::MatrixXd::Identity(nx, nx), {}, {}};
  trellis::RiccatiOptions o;
  o.rtol = 1e-6;
  trellis::RiccatiSolution s;
  for (auto _ : state) {
    s = trellis::solveRiccati(c.bm.model, c.trajectory, w, o);
    if (!s.ok()) {
      state.SkipWithError(s.status.message.c_str());
      return;
    }
  }
  state.counters["steps"] = static_cast<double>(s.steps);
}
BENCHMARK(ChainRiccati)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
