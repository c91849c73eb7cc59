// riccati_bench — Riccati solve time against accuracy (Google Benchmark).
//
// System: a chain of nq unit masses joined by springs whose stiffness varies in time,
// k(t) = 100 (1 + 0.3 sin 3t), light damping, one force input per mass — nx = 2 nq states
// (2, 10, 20, 40), horizon 2 s, Q = I, R = I, Qf = I. For each method (BDF / Adams) and tolerance
// rtol = atol·100 = 1e-3 … 1e-10 the counter max_rel_err is max |S − S_ref| / max |S_ref| over 21
// times, S_ref from BDF with rtol 1e-13 (computed once, outside the timed loop).
//
//   trellis_riccati_bench --benchmark_format=json > riccati.json
#include <trellis/control.hpp>

#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <utility>

namespace {

using Eigen::MatrixXd;

constexpr double kHorizon = 2.0;

trellis::LinearizationCallback chain(int nq) {
  return [nq](double t, MatrixXd& A, MatrixXd& B) {
    const double k = 100.0 * (1.0 + 0.3 * std::sin(3.0 * t));
    A.setZero();
    B.setZero();
    A.topRightCorner(nq, nq).setIdentity();
    for (int i = 0; i < nq; ++i) {
      A(nq + i, i) = -2 * k;
      if (i > 0) A(nq + i, i - 1) = k;
      if (i + 1 < nq) A(nq + i, i + 1) = k;
      A(nq + i, nq + i) = -0.1;
      B(nq + i, i) = 1.0;
    }
  };
}

trellis::LqrWeights weights(int nx, int nu) {
  trellis::LqrWeights w;
  w.Q = MatrixXd::Identity(nx, nx);
  w.R = MatrixXd::Identity(nu, nu);
  w.Qf = MatrixXd::Identity(nx, nx);
  return w;
}

const std::vector<MatrixXd>& reference(int nq) {
  static std::map<int, std::vector<MatrixXd>> cache;
  auto it = cache.find(nq);
  if (it != cache.end()) return it->second;
  trellis::RiccatiOptions o;
  o.rtol = 1e-13;
  o.atol = 1e-15;
  o.trackEigenvalues = false;
  const auto sol = trellis::solveRiccati(0.0, kHorizon, 2 * nq, nq, chain(nq), weights(2 * nq, nq), o);
  std::vector<MatrixXd> S;
  for (int i = 0; i <= 20; ++i) S.push_back(sol.S(kHorizon * i / 20.0));
  return cache.emplace(nq, std::move(S)).first->second;
}

void BM_Riccati(benchmark::State& state) {
  const int nq = static_cast<int>(state.range(0));
  const auto method = state.range(1) == 0 ? trellis::RiccatiMethod::kBDF : trellis::RiccatiMethod::kAdams;
  const double rtol = std::pow(10.0, -static_cast<double>(state.range(2)));
  const auto& ref = reference(nq);
  trellis::RiccatiOptions o;
  o.method = method;
  o.rtol = rtol;
  o.atol = rtol * 1e-2;
  o.trackEigenvalues = false;
  const auto lin = chain(nq);
  const auto w = weights(2 * nq, nq);
  trellis::RiccatiSolution sol;
  for (auto _ : state) {
    sol = trellis::solveRiccati(0.0, kHorizon, 2 * nq, nq, lin, w, o);
    benchmark::DoNotOptimize(sol);
  }
  double err = 0.0, scale = 0.0;
  if (sol.ok()) {
    for (int i = 0; i <= 20; ++i) {
      err = std::max(err, (sol.S(kHorizon * i / 20.0) - ref[i]).cwiseAbs().maxCoeff());
      scale = std::max(scale, ref[i].cwiseAbs().maxCoeff());
    }
  }
  state.counters["nx"] = 2 * nq;
  state.counters["rtol"] = rtol;
  state.counters["max_rel_err"] = sol.ok() ? err / scale : -1.0;
  state.counters["steps"] = static_cast<double>(sol.steps);
  state.counters["ok"] = sol.ok() ? 1 : 0;
  state.SetLabel(method == trellis::RiccatiMethod::kBDF ? "BDF" : "Adams");
}

void args(benchmark::internal::Benchmark* b) {
  for (int nq : {1, 5, 10, 20})
    for (int m : {0, 1})
      for (int e : {3, 4, 6, 8, 10}) b->Args({nq, m, e});
}

BENCHMARK(BM_Riccati)->Apply(args)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
