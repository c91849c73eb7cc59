// bench/core_bench.cpp — time of the dynamics and of the exact linearization against central
// finite differences of the same dynamics, with the error of each (speed against error).
//
// Benchmarks, for every model of the sweep (see README.md):
//   Dynamics/<model>/N:<n>/nc:<c>         computeDynamics                      (q̈, λ)
//   Linearization/<model>/N:<n>/nc:<c>    computeLinearization                 (A, B exact)
//   LinearizationFD/<model>/N:<n>/nc:<c>  central differences of computeDynamics (A, B approx.)
// Counters: nq, nc, nu on every row; on Linearization ref_err (exact vs a Richardson reference),
// ref_unc (that reference's own error, estimated from a second step size), ref_col_err,
// ref_col_unc and repeat_diff; max_rel_err (FD vs exact), col_rel_err and dyn_evals on LinearizationFD. Errors are
// max|J − ref| / max(1, max|ref|) over J = ∂q̈/∂[q; q̇; u], the non-trivial rows of [A B]; the
// col_ variants apply the same measure to each column and report the worst.
#include "finite_differences.hpp"
#include "fixture_cache.hpp"
#include "models.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <exception>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using trellis::bench::BenchModel;
using trellis::bench::ModelKind;
using trellis::bench::ModelSpec;

const double kEps = std::numeric_limits<double>::epsilon();
/// ε^(1/3): balances the O(h²) truncation and O(ε/h) rounding errors of central differences.
const double kCentralStep = std::cbrt(kEps);
/// ε^(1/5): the same balance for one Richardson step (O(h⁴) against O(ε/h)).
const double kRichardsonStep = std::pow(kEps, 0.2);

/// One model with its state, workspace and reference results, built once per process (never in
/// a timed loop) and shared by the three benchmarks of that model.
struct Fixture {
  explicit Fixture(const ModelSpec& spec)
      : bm(trellis::bench::makeBenchModel(spec)), data(bm.model), fd(bm.model) {
    const int n = bm.model.nq(), m = bm.model.nu();
    exact.resize(n, 2 * n + m);
    fdJ.resize(n, 2 * n + m);
    reference.resize(n, 2 * n + m);
  }
  BenchModel bm;
  trellis::Data data;
  trellis::bench::FdWorkspace fd;
  Eigen::MatrixXd exact, fdJ, reference;  ///< n × (2n+m): ∂q̈/∂[q; q̇; u]
  double referenceUncertainty = 0.0;        ///< estimated error of `reference`, same measure
  double referenceColumnUncertainty = 0.0;  ///< the same, column by column (worst column)
  bool haveExact = false, haveReference = false;
  std::string error;  ///< non-empty: the model or its state is unusable

  /// Copies [dqdd_dq, dqdd_ddq, dqdd_du] out of data after computeLinearization.
  void gatherExact(Eigen::MatrixXd& J) const {
    const int n = bm.model.nq(), m = bm.model.nu();
    J.leftCols(n) = data.dqdd_dq;
    J.middleCols(n, n) = data.dqdd_ddq;
    J.rightCols(m) = data.dqdd_du;
  }
  bool ensureExact() {
    if (!haveExact && error.empty()) {
      const trellis::DynamicsStatus s = trellis::computeLinearization(bm.model, data, bm.q, bm.dq, bm.u);
      if (!s.ok()) {
        error = "computeLinearization failed: " + s.message;
        return false;
      }
      gatherExact(exact);
      haveExact = true;
    }
    return error.empty();
  }
  bool ensureReference() {
    if (!haveReference && error.empty()) {
      // The reference at two steps: their disagreement estimates its own error, which grows
      // with the conditioning of the dynamics (rounding in q̈ divided by the step).
      Eigen::MatrixXd other(reference.rows(), reference.cols());
      if (!trellis::bench::richardsonDifferences(bm.model, data, bm.q, bm.dq, bm.u, kRichardsonStep,
                                                 fd, reference) ||
          !trellis::bench::richardsonDifferences(bm.model, data, bm.q, bm.dq, bm.u,
                                                 2.0 * kRichardsonStep, fd, other)) {
        error = "computeDynamics failed near the state: " + data.status.message;
        return false;
      }
      referenceUncertainty = trellis::bench::maxRelativeError(other, reference);
      referenceColumnUncertainty = trellis::bench::maxColumnRelativeError(other, reference);
      haveReference = true;
    }
    return error.empty();
  }
};

Fixture* fixtureFor(const ModelSpec& spec, benchmark::State& state) {
  return trellis::bench::fixtureFor<Fixture>(spec, state);
}

void runDynamics(benchmark::State& state, ModelSpec spec) {
  Fixture* f = fixtureFor(spec, state);
  if (f == nullptr) return;
  const trellis::DynamicsStatus s = trellis::computeDynamics(f->bm.model, f->data, f->bm.q, f->bm.dq, f->bm.u);
  if (!s.ok()) {
    state.SkipWithError(("computeDynamics: " + s.message).c_str());
    return;
  }
  for (auto _ : state) {
    trellis::computeDynamics(f->bm.model, f->data, f->bm.q, f->bm.dq, f->bm.u);
    benchmark::DoNotOptimize(f->data.qdd.data());
    benchmark::ClobberMemory();
  }
}

void runLinearization(benchmark::State& state, ModelSpec spec) {
  Fixture* f = fixtureFor(spec, state);
  if (f == nullptr) return;
  if (!f->ensureExact() || !f->ensureReference()) {
    state.SkipWithError(f->error.c_str());
    return;
  }
  for (auto _ : state) {
    trellis::computeLinearization(f->bm.model, f->data, f->bm.q, f->bm.dq, f->bm.u);
    benchmark::DoNotOptimize(f->data.A.data());
    benchmark::DoNotOptimize(f->data.B.data());
    benchmark::ClobberMemory();
  }
  // The timed loop recomputed the result: check that the last one is the one measured.
  Eigen::MatrixXd J(f->exact.rows(), f->exact.cols());
  f->gatherExact(J);
  state.counters["ref_err"] = trellis::bench::maxRelativeError(J, f->reference);
  state.counters["ref_unc"] = f->referenceUncertainty;
  state.counters["ref_col_err"] = trellis::bench::maxColumnRelativeError(J, f->reference);
  state.counters["ref_col_unc"] = f->referenceColumnUncertainty;
  state.counters["repeat_diff"] = (J - f->exact).cwiseAbs().maxCoeff();
}

void runLinearizationFD(benchmark::State& state, ModelSpec spec) {
  Fixture* f = fixtureFor(spec, state);
  if (f == nullptr) return;
  if (!f->ensureExact()) {
    state.SkipWithError(f->error.c_str());
    return;
  }
  bool ok = true;
  for (auto _ : state) {
    ok = trellis::bench::centralDifferences(f->bm.model, f->data, f->bm.q, f->bm.dq, f->bm.u,
                                            kCentralStep, f->fd, f->fdJ) && ok;
    benchmark::DoNotOptimize(f->fdJ.data());
    benchmark::ClobberMemory();
  }
  if (!ok) {
    state.SkipWithError(("computeDynamics failed near the state: " + f->data.status.message).c_str());
    return;
  }
  state.counters["max_rel_err"] = trellis::bench::maxRelativeError(f->fdJ, f->exact);
  state.counters["col_rel_err"] = trellis::bench::maxColumnRelativeError(f->fdJ, f->exact);
  state.counters["dyn_evals"] = 2.0 * static_cast<double>(f->fdJ.cols());
}

std::vector<ModelSpec> sweep() {
  std::vector<ModelSpec> specs;
  for (ModelKind kind : {ModelKind::kPlanarChain, ModelKind::kSpatialChain}) {
    for (bool constrained : {false, true}) {
      for (int n : {2, 5, 10, 20, 40, 64}) specs.push_back({kind, n, constrained});
    }
  }
  specs.push_back({ModelKind::kHandTree, 20, false});
  specs.push_back({ModelKind::kHandTree, 20, true});
  return specs;
}

}  // namespace

int main(int argc, char** argv) {
  for (const ModelSpec& spec : sweep()) {
    const std::string name = caseName(spec);
    benchmark::RegisterBenchmark(("Dynamics/" + name).c_str(), runDynamics, spec)
        ->Unit(benchmark::kMicrosecond);
    benchmark::RegisterBenchmark(("Linearization/" + name).c_str(), runLinearization, spec)
        ->Unit(benchmark::kMicrosecond);
    benchmark::RegisterBenchmark(("LinearizationFD/" + name).c_str(), runLinearizationFD, spec)
        ->Unit(benchmark::kMicrosecond);
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
