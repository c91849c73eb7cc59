// are_bench — algebraic Riccati solvers (solveCare, solveDare) against n, beside the cost of the
// stabilizability screen (Google Benchmark).
//
// Problem (seeded): A with N(0, 1/n) entries (spectral radius ≈ 1, about half the eigenvalues in
// the right half plane), B n×m with m = max(1, n/10), Q = I, R = I. DARE: Ad = A/ρ(A)·1.2 (unstable
// modes outside the unit circle).
// Benchmarks (argument n = 10 … 400):
//   CARE, DARE         the full solve (balancing, sign function / doubling, Newton steps, residual,
//                      closed-loop eigenvalues); counters residual (scale-invariant), ok
//   Screen             checkStabilizability: one complex Schur form + a left eigenvector per unstable
//                      mode, O(n³) (the solvers run it only after a failed solve)
//   ScreenPBH          the former screen: one complex SVD of [A − λI, B] per unstable eigenvalue,
//                      O(n⁴); run to n = 100 only
//
//   trellis_bench_are --benchmark_min_time=0.01 [--benchmark_format=json]
#include <trellis/control.hpp>

#include <benchmark/benchmark.h>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <complex>
#include <map>
#include <random>

namespace {

using Eigen::MatrixXd;

struct Problem {
  MatrixXd A, Ad, B, Q, R;
};

const Problem& problem(int n) {
  static std::map<int, Problem> cache;
  auto it = cache.find(n);
  if (it != cache.end()) return it->second;
  std::mt19937 rng(1000 + n);
  std::normal_distribution<double> nd(0.0, 1.0 / std::sqrt(static_cast<double>(n)));
  const int m = std::max(1, n / 10);
  Problem p;
  p.A = MatrixXd::NullaryExpr(n, n, [&] { return nd(rng); });
  p.B = MatrixXd::NullaryExpr(n, m, [&] { return nd(rng); });
  const double rho = Eigen::EigenSolver<MatrixXd>(p.A, false).eigenvalues().cwiseAbs().maxCoeff();
  p.Ad = p.A * (1.2 / rho);
  p.Q = MatrixXd::Identity(n, n);
  p.R = MatrixXd::Identity(m, m);
  return cache.emplace(n, std::move(p)).first->second;
}

void report(benchmark::State& state, const trellis::LqrResult& r) {
  state.counters["residual"] = r.residual;
  state.counters["ok"] = r.ok() ? 1 : 0;
  state.counters["iterations"] = r.iterations;
}

void BM_Care(benchmark::State& state) {
  const Problem& p = problem(static_cast<int>(state.range(0)));
  trellis::LqrResult r;
  for (auto _ : state) {
    r = trellis::solveCare(p.A, p.B, p.Q, p.R);
    benchmark::DoNotOptimize(r.S.data());
  }
  report(state, r);
}

void BM_Dare(benchmark::State& state) {
  const Problem& p = problem(static_cast<int>(state.range(0)));
  trellis::LqrResult r;
  for (auto _ : state) {
    r = trellis::solveDare(p.Ad, p.B, p.Q, p.R);
    benchmark::DoNotOptimize(r.S.data());
  }
  report(state, r);
}

void BM_Screen(benchmark::State& state) {
  const Problem& p = problem(static_cast<int>(state.range(0)));
  trellis::StabilizabilityCheck c;
  for (auto _ : state) {
    c = trellis::checkStabilizability(p.A, p.B, false);
    benchmark::DoNotOptimize(c.margin);
  }
  state.counters["stabilizable"] = c.stabilizable ? 1 : 0;
}

/// The former screen, kept here only as the baseline: PBH by one complex SVD per unstable λ.
void BM_ScreenPBH(benchmark::State& state) {
  const Problem& p = problem(static_cast<int>(state.range(0)));
  const Eigen::Index n = p.A.rows(), m = p.B.cols();
  double worst = 1.0;
  for (auto _ : state) {
    const Eigen::VectorXcd ev = Eigen::EigenSolver<MatrixXd>(p.A, false).eigenvalues();
    Eigen::MatrixXcd M(n, n + m);
    for (Eigen::Index i = 0; i < n; ++i) {
      if (ev(i).real() < 0.0) continue;
      M.leftCols(n) = p.A.cast<std::complex<double>>();
      M.leftCols(n).diagonal().array() -= ev(i);
      M.rightCols(m) = p.B.cast<std::complex<double>>();
      worst = std::min(worst, Eigen::JacobiSVD<Eigen::MatrixXcd>(M).singularValues()(n - 1));
    }
    benchmark::DoNotOptimize(worst);
  }
  state.counters["sigma_min"] = worst;
}

}  // namespace

BENCHMARK(BM_Care)->Arg(10)->Arg(25)->Arg(50)->Arg(100)->Arg(200)->Arg(400)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Dare)->Arg(10)->Arg(25)->Arg(50)->Arg(100)->Arg(200)->Arg(400)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Screen)->Arg(10)->Arg(25)->Arg(50)->Arg(100)->Arg(200)->Arg(400)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ScreenPBH)->Arg(10)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
