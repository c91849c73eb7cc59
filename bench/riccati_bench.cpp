// riccati_bench — Riccati solve time against accuracy (Google Benchmark).
//
// System: the planar chain of bench/models.hpp with n = 2, 10, 20, 40 links (nx = 2n = 4, 20, 40,
// 80 states), one torque per joint (m = n), gravity on. A(t), B(t) blend two exact
// linearizations at fixed non-equilibrium states a and b (makeBenchModel with two seeds: random
// q, q̇, u, not an equilibrium):
//   A(t) = (1 − s(t)) A_a + s(t) A_b,   s(t) = ½(1 − cos(π t / T)),   same for B,
// a smooth time-varying system with the magnitudes of a real chain linearization (not the
// linearization along one dynamic trajectory: that would put a simulation and a computeLinearization
// call inside every right-hand side and measure the core, not the Riccati solver).
// Horizon T = 2 s; Q = I, R = I, Qf = I.
//
// Methods (second argument):
//   0 BDF          kAuto: dense exact Jacobian for nx ≤ 10, the direct Lyapunov solve above
//                  (kLyapunov; so n = 2 uses the dense solver, n ≥ 10 the Lyapunov solve)
//   1 BDF-dense    dense exact Jacobian (N×N LU, N = nx(nx+1)/2)
//   2 BDF-GMRES    GMRES without preconditioner (the solver before the preconditioner existed)
//   3 Adams        functional iteration
//   4 factored     Cholesky factor, kAuto linear solver (dense DQ ≤ 10, GMRES + preconditioner above)
//   5 BDF-GMRES    GMRES with the Lyapunov preconditioner (kKrylov: the default above nx = 10
//                  before kLyapunov)
// Tolerance (third argument e): rtol = 10^−e, atol = rtol·1e-2.
// Counters (also newton, setups, schur, etf, ncf: see RiccatiSolution): rel_err_t0 = max|S(t0) − S_ref(t0)| / max|S_ref(t0)|, max_rel_err = the same over 21
// times, steps, rhs (evaluations), ok. S_ref: BDF with rtol 1e-13, atol 1e-15 (computed once,
// outside the timed loop; it agrees with the factored form at rtol 1e-12 to ≈1e-12).
//
//   trellis_bench_riccati --benchmark_min_time=0.05 [--benchmark_format=json]
#include "riccati_problem.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <stdexcept>
#include <utility>
#include <vector>

namespace {

using Eigen::MatrixXd;
using trellis::bench::kRiccatiHorizon;

constexpr double kHorizon = kRiccatiHorizon;

trellis::LinearizationCallback blended(int n) { return trellis::bench::blendedChain(n); }

trellis::LqrWeights weights(int nx, int nu) { return trellis::bench::unitRiccatiWeights(nx, nu); }

constexpr int kSamples = 20;

const std::vector<MatrixXd>& reference(int n) {
  static std::map<int, std::vector<MatrixXd>> cache;
  auto it = cache.find(n);
  if (it != cache.end()) return it->second;
  trellis::RiccatiOptions o;
  o.rtol = 1e-13;
  o.atol = 1e-15;
  o.trackEigenvalues = false;
  const auto sol = trellis::solveRiccati(0.0, kHorizon, 2 * n, n, blended(n), weights(2 * n, n), o);
  if (!sol.ok()) throw std::runtime_error("riccati_bench: reference failed: " + sol.status.message);
  std::vector<MatrixXd> S;
  for (int i = 0; i <= kSamples; ++i) S.push_back(sol.S(kHorizon * i / kSamples));
  return cache.emplace(n, std::move(S)).first->second;
}

const char* kMethodNames[] = {"BDF", "BDF-dense", "BDF-GMRES-noprec", "Adams", "factored",
                              "BDF-GMRES"};

trellis::RiccatiOptions optionsFor(int method, double rtol) {
  trellis::RiccatiOptions o;
  o.rtol = rtol;
  o.atol = rtol * 1e-2;
  o.trackEigenvalues = false;
  switch (method) {
    case 1: o.linearSolver = trellis::RiccatiLinearSolver::kDense; break;
    case 2:
      o.linearSolver = trellis::RiccatiLinearSolver::kKrylov;
      o.krylovPreconditioner = false;
      break;
    case 3: o.method = trellis::RiccatiMethod::kAdams; break;
    case 4: o.method = trellis::RiccatiMethod::kFactored; break;
    case 5: o.linearSolver = trellis::RiccatiLinearSolver::kKrylov; break;
    default: break;
  }
  return o;
}

void BM_Riccati(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const int method = static_cast<int>(state.range(1));
  const double rtol = std::pow(10.0, -static_cast<double>(state.range(2)));
  const auto& ref = reference(n);
  const auto o = optionsFor(method, rtol);
  const auto lin = blended(n);
  const auto w = weights(2 * n, n);
  trellis::RiccatiSolution sol;
  for (auto _ : state) {
    sol = trellis::solveRiccati(0.0, kHorizon, 2 * n, n, lin, w, o);
    benchmark::DoNotOptimize(sol);
  }
  double errMax = 0.0, err0 = 0.0;
  if (sol.ok()) {
    for (int i = 0; i <= kSamples; ++i) {
      const double e = (sol.S(kHorizon * i / kSamples) - ref[i]).cwiseAbs().maxCoeff() /
                       ref[i].cwiseAbs().maxCoeff();
      errMax = std::max(errMax, e);
      if (i == 0) err0 = e;
    }
  }
  state.counters["nx"] = 2 * n;
  state.counters["rtol"] = rtol;
  state.counters["rel_err_t0"] = sol.ok() ? err0 : -1.0;
  state.counters["max_rel_err"] = sol.ok() ? errMax : -1.0;
  state.counters["steps"] = static_cast<double>(sol.steps);
  state.counters["rhs"] = static_cast<double>(sol.rhsEvaluations);
  state.counters["ok"] = sol.ok() ? 1 : 0;
  state.counters["lin_iters"] = static_cast<double>(sol.linearIterations);
  state.counters["psolves"] = static_cast<double>(sol.preconditionerSolves);
  state.counters["jac"] = static_cast<double>(sol.jacobianEvaluations);
  state.counters["newton"] = static_cast<double>(sol.newtonIterations);
  state.counters["setups"] = static_cast<double>(sol.linearSolverSetups);
  state.counters["schur"] = static_cast<double>(sol.schurFactorizations);
  state.counters["etf"] = static_cast<double>(sol.errorTestFailures);
  state.counters["ncf"] = static_cast<double>(sol.convergenceFailures);
  state.SetLabel(kMethodNames[method]);
}

void args(benchmark::internal::Benchmark* b) {
  for (int n : {2, 10, 20, 40})
    for (int m : {0, 1, 2, 3, 4, 5})
      for (int e : {3, 4, 5, 6, 7, 8, 10}) {
        // Dense N×N LU (N = nx(nx+1)/2 = 820 at n = 20): three tolerances there, none at n = 40.
        if (m == 1 && (n > 20 || (n == 20 && e != 3 && e != 6 && e != 10))) continue;
        if (m == 5 && n == 2) continue;  // nx = 4: kAuto is the dense solver there
        b->Args({n, m, e});
      }
}

BENCHMARK(BM_Riccati)->Apply(args)->Unit(benchmark::kMillisecond)->ArgNames({"n", "method", "tol"});

}  // namespace

BENCHMARK_MAIN();
