// bench/linearization_sweep.cpp — the linearization benchmarks behind docs/performance.md:
// time against the number of bodies, and error against time, for the exact linearization and
// for central and forward finite differences of the same computeDynamics.
//
// J = ∂q̈/∂z, z = [q; q̇; u] (n × (2n+m)), the non-constant rows of [A B]. Methods:
//   exact    computeLinearization (the core's exact derivatives)
//   central  (q̈(z + h e_j) − q̈(z − h e_j)) / 2h      2(2n+m) dynamics evaluations, error O(h²) + O(ε/h)
//   forward  (q̈(z + h e_j) − q̈(z)) / h              2n+m+1 evaluations,       error O(h) + O(ε/h)
// with h_j = h·max(1, |z_j|) and the division by the representable step actually taken.
//
// Benchmarks:
//   Scaling/<method>/<model>/N:<n>/nc:<c>         default steps: central ε^(1/3), forward ε^(1/2)
//       models: planar chains N = 2, 4, 8, 16, 32, 64 without and with one constraint row,
//               3D chains N = 2 … 64, the 20-joint hand tree without and with a 3D point
//               constraint (see models.hpp)
//   Accuracy/<method>/<model>/N:<n>/nc:<c>/h:<k>  central and forward at h = 10^−k, k = 2 … 10
//       models: planar N = 16, the hand tree without and with the constraint
// Counters (every row): nq, nc, nu, evals (dynamics evaluations per call; 0 for exact),
//   err      max|J − J_ref| / max(1, max|J_ref|)
//   col_err  the same measure per column, worst column
// For the finite differences J_ref is the exact result. For the exact method J_ref is a
// high-order reference, two Richardson levels on central differences,
//   R = (64 D(h/4) − 20 D(h/2) + D(h)) / 45,   truncation O(h⁶), rounding O(ε/h),
// at h = ε^(1/7) (their balance, ≈ 5.8e-3 relative); ref_unc is that reference's own error,
// estimated as the difference between R at h and at 2h. `err` of the exact method is an upper
// bound on its error that is meaningful down to ref_unc — the error floor plotted in the report.
//
// Models, states, exact results and references are built once per process, outside the timed
// loops. (No double that is reported later goes through benchmark::DoNotOptimize: with Debian's
// benchmark 1.7 and GCC 12 at -O3 that was seen to corrupt the value.)
//
//   trellis_bench_linearization_sweep --benchmark_filter='Scaling/.*/hand' --benchmark_format=json
#include "finite_differences.hpp"
#include "fixture_cache.hpp"
#include "models.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using trellis::bench::ModelKind;
using trellis::bench::ModelSpec;

const double kEps = std::numeric_limits<double>::epsilon();
/// Central differences: O(h²) truncation against O(ε/h) rounding balance at h ≈ ε^(1/3).
const double kCentralStep = std::cbrt(kEps);
/// Forward differences: O(h) against O(ε/h) balance at h ≈ ε^(1/2).
const double kForwardStep = std::sqrt(kEps);
/// Two Richardson levels: O(h⁶) against O(ε/h) balance at h ≈ ε^(1/7).
const double kReferenceStep = std::pow(kEps, 1.0 / 7.0);

enum class Method { kExact, kCentral, kForward };

const char* methodName(Method m) {
  switch (m) {
    case Method::kExact: return "exact";
    case Method::kCentral: return "central";
    case Method::kForward: return "forward";
  }
  return "?";
}

/// Forward differences (trellis::differenceDynamics, DifferenceScheme::kForward), column j:
/// (q̈(z + h_j e_j) − q̈(z)) / (z_j⁺ − z_j), h_j = relStep·max(1, |z_j|). 2n+m+1 evaluations of
/// computeDynamics; qddBase receives q̈(z). Returns false if any evaluation failed.
bool forwardDifferences(const trellis::Model& model, trellis::Data& data, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& dq, const Eigen::VectorXd& u, double relStep,
                        trellis::bench::FdWorkspace& ws, Eigen::VectorXd& qddBase, Eigen::MatrixXd& J) {
  trellis::NumDiffOptions options;
  options.scheme = trellis::DifferenceScheme::kForward;
  options.relativeStep = relStep;
  const bool ok = trellis::differenceDynamics(model, data, q, dq, u, options, ws.numdiff, J).ok();
  qddBase = ws.numdiff.qddBase;
  return ok;
}

/// One model with its state, workspaces, exact result and high-order reference.
struct Fixture {
  explicit Fixture(const ModelSpec& spec)
      : bm(trellis::bench::makeBenchModel(spec)), data(bm.model), fd(bm.model) {
    const int n = bm.model.nq(), cols = 2 * n + bm.model.nu();
    exact.resize(n, cols);
    reference.resize(n, cols);
    work.resize(n, cols);
    qddBase.resize(n);
    const trellis::DynamicsStatus s = trellis::computeLinearization(bm.model, data, bm.q, bm.dq, bm.u);
    if (!s.ok()) {
      error = "computeLinearization failed: " + s.message;
      return;
    }
    gatherExact(exact);
    Eigen::MatrixXd other(n, cols);
    if (!richardson2(kReferenceStep, reference) || !richardson2(2.0 * kReferenceStep, other)) {
      error = "computeDynamics failed near the state: " + data.status.message;
      return;
    }
    referenceUncertainty = trellis::bench::maxRelativeError(other, reference);
  }

  /// Copies [dqdd_dq, dqdd_ddq, dqdd_du] out of data after computeLinearization.
  void gatherExact(Eigen::MatrixXd& J) const {
    const int n = bm.model.nq(), m = bm.model.nu();
    J.leftCols(n) = data.dqdd_dq;
    J.middleCols(n, n) = data.dqdd_ddq;
    J.rightCols(m) = data.dqdd_du;
  }

  /// R = (64 D(h/4) − 20 D(h/2) + D(h)) / 45: the Richardson table of central differences
  /// (D(h) = J + c₂h² + c₄h⁴ + O(h⁶)) taken two levels deep, which cancels c₂ and c₄.
  bool richardson2(double h, Eigen::MatrixXd& R) {
    Eigen::MatrixXd d1(R.rows(), R.cols()), d2(R.rows(), R.cols());
    bool ok = trellis::bench::centralDifferences(bm.model, data, bm.q, bm.dq, bm.u, h, fd, d1);
    ok = trellis::bench::centralDifferences(bm.model, data, bm.q, bm.dq, bm.u, 0.5 * h, fd, d2) && ok;
    ok = trellis::bench::centralDifferences(bm.model, data, bm.q, bm.dq, bm.u, 0.25 * h, fd, R) && ok;
    R = (64.0 * R - 20.0 * d2 + d1) / 45.0;
    return ok;
  }

  /// One call of the method; the result in `work` (FD) or data (exact).
  bool run(Method method, double step) {
    switch (method) {
      case Method::kExact:
        return trellis::computeLinearization(bm.model, data, bm.q, bm.dq, bm.u).ok();
      case Method::kCentral:
        return trellis::bench::centralDifferences(bm.model, data, bm.q, bm.dq, bm.u, step, fd, work);
      case Method::kForward:
        return forwardDifferences(bm.model, data, bm.q, bm.dq, bm.u, step, fd, qddBase, work);
    }
    return false;
  }

  trellis::bench::BenchModel bm;
  trellis::Data data;
  trellis::bench::FdWorkspace fd;
  Eigen::MatrixXd exact, reference, work;  ///< n × (2n+m)
  Eigen::VectorXd qddBase;                 ///< forward differences: q̈ at the unperturbed state
  double referenceUncertainty = 0.0;
  std::string error;  ///< non-empty: the model or its state is unusable
};

Fixture* fixtureFor(const ModelSpec& spec, benchmark::State& state) {
  return trellis::bench::fixtureFor<Fixture>(spec, state);
}

void runMethod(benchmark::State& state, ModelSpec spec, Method method, double step) {
  Fixture* f = fixtureFor(spec, state);
  if (f == nullptr) return;
  bool ok = true;
  for (auto _ : state) {
    ok = f->run(method, step) && ok;
    benchmark::DoNotOptimize(f->work.data());
    benchmark::DoNotOptimize(f->data.A.data());
    benchmark::ClobberMemory();
  }
  if (!ok) {
    state.SkipWithError((std::string(methodName(method)) + " failed: " + f->data.status.message).c_str());
    return;
  }
  const double cols = static_cast<double>(f->exact.cols());
  if (method == Method::kExact) {
    Eigen::MatrixXd J(f->exact.rows(), f->exact.cols());
    f->gatherExact(J);
    state.counters["err"] = trellis::bench::maxRelativeError(J, f->reference);
    state.counters["col_err"] = trellis::bench::maxColumnRelativeError(J, f->reference);
    state.counters["ref_unc"] = f->referenceUncertainty;
    state.counters["evals"] = 0;
  } else {
    state.counters["err"] = trellis::bench::maxRelativeError(f->work, f->exact);
    state.counters["col_err"] = trellis::bench::maxColumnRelativeError(f->work, f->exact);
    state.counters["evals"] = method == Method::kCentral ? 2.0 * cols : cols + 1.0;
  }
  state.counters["step"] = step;
}

std::vector<ModelSpec> scalingSweep() {
  std::vector<ModelSpec> specs;
  for (bool constrained : {false, true})
    for (int n : {2, 4, 8, 16, 32, 64}) specs.push_back({ModelKind::kPlanarChain, n, constrained});
  for (int n : {2, 4, 8, 16, 32, 64}) specs.push_back({ModelKind::kSpatialChain, n, false});
  specs.push_back({ModelKind::kHandTree, 20, false});
  specs.push_back({ModelKind::kHandTree, 20, true});
  return specs;
}

std::vector<ModelSpec> accuracySweep() {
  return {{ModelKind::kPlanarChain, 16, false}, {ModelKind::kHandTree, 20, false}, {ModelKind::kHandTree, 20, true}};
}

}  // namespace

int main(int argc, char** argv) {
  for (const ModelSpec& spec : scalingSweep()) {
    for (Method method : {Method::kExact, Method::kCentral, Method::kForward}) {
      const double step = method == Method::kCentral ? kCentralStep : method == Method::kForward ? kForwardStep : 0.0;
      const std::string name = std::string("Scaling/") + methodName(method) + "/" + caseName(spec);
      benchmark::RegisterBenchmark(name.c_str(), runMethod, spec, method, step)->Unit(benchmark::kMicrosecond);
    }
  }
  for (const ModelSpec& spec : accuracySweep()) {
    for (Method method : {Method::kCentral, Method::kForward}) {
      for (int k = 2; k <= 10; ++k) {
        const std::string name = std::string("Accuracy/") + methodName(method) + "/" + caseName(spec) +
                                 "/h:" + std::to_string(k);
        benchmark::RegisterBenchmark(name.c_str(), runMethod, spec, method, std::pow(10.0, -k))
            ->Unit(benchmark::kMicrosecond);
      }
    }
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
