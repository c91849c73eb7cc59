// bench/second_order_bench.cpp — the exact second derivatives (issue 30) against the number of
// bodies: time of the contraction Σ wᵢ ∇²q̈ᵢ (w = 1), of the full tensors, of one exact
// linearization (the unit of the cost target), and of the baseline, central differences of the
// exact Jacobians (2N linearizations, N = 2n + m); beside each time the error of the exact
// tensors against those differences.
//
// Benchmarks: <Method>/<model>/N:<n>/nc:<c>, Method ∈ {Linearization, Contraction, Tensors,
// FdJacobians}; models: planar chains N = 2 … 64, 3D chains N = 8, 40, the 20-joint hand tree
// without and with its fingertip point constraint, and the hand scene (examples/scenes/hand.json
// at its stored state).
// Counters: nq, nu, nc, pairs (hyper-dual residual passes of the tensors per call), and
//   err         max |H − D| / max(1, ‖D column‖∞) over every output and entry, D the central
//               differences of the exact Jacobians at h = ε^(1/3)·max(1, |z|) (Tensors: each
//               ∇²q̈ᵢ; Contraction: Σᵢ ∇²q̈ᵢ)
//   err_fd4     Tensors: the same against fourth-order differences (h = ε^(1/5)·max(1, |z|));
//               on ill-conditioned models (long light chains, the light hand tree) the central
//               differences' rounding error ε·κ/h dominates `err`, and this one is smaller
//   vs_tensors  Contraction: max |H − Σᵢ ∇²q̈ᵢ| / max(1, max |Σ|), the two exact paths against
//               each other
//
//   trellis_bench_second_order --benchmark_format=json > second_order.json
#include "fixture_cache.hpp"
#include "models.hpp"

#include "trellis/core/linearization.hpp"
#include "trellis/core/scene.hpp"
#include "trellis/core/second_order.hpp"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using trellis::bench::BenchModel;
using trellis::bench::ModelKind;
using trellis::bench::ModelSpec;

struct Fixture {
  BenchModel bm;
  std::unique_ptr<trellis::Data> data;
  std::unique_ptr<trellis::SecondOrderWorkspace> ws;
  Eigen::VectorXd w, rho, z, zz, qv, dqv, uv;
  Eigen::MatrixXd H;
  double tensorError = 0.0, contractionError = 0.0, tensorError4 = 0.0, agreement = 0.0;
  int pairs = 0;
  std::string error;

  explicit Fixture(BenchModel model) : bm(std::move(model)) {
    const int n = bm.model.nq(), m = bm.model.nu(), N = 2 * n + m;
    data = std::make_unique<trellis::Data>(bm.model);
    ws = std::make_unique<trellis::SecondOrderWorkspace>(bm.model);
    w = Eigen::VectorXd::Ones(n);
    rho = Eigen::VectorXd::Zero(bm.model.nc());
    z.resize(N);
    z << bm.q, bm.dq, bm.u;
    zz = z;
    qv = bm.q;
    dqv = bm.dq;
    uv = bm.u;
    H = Eigen::MatrixXd::Zero(N, N);
    pairs = N * (N + 1) / 2 - m * (m + 1) / 2;
    const trellis::DynamicsStatus st = trellis::computeSecondOrderTensors(bm.model, *data, *ws, bm.q, bm.dq, bm.u);
    if (!st.ok()) {
      error = "second order: " + st.message;
      return;
    }
    trellis::computeSecondOrderContraction(bm.model, *data, *ws, bm.q, bm.dq, bm.u, w, rho, H);
    // Central differences of the exact Jacobians, column a of every output's Hessian.
    Eigen::MatrixXd Jp(n, N), Jm(n, N), Hsum = Eigen::MatrixXd::Zero(N, N), Dsum = Eigen::MatrixXd::Zero(N, N);
    std::vector<Eigen::MatrixXd> D(n, Eigen::MatrixXd::Zero(N, N));
    for (int a = 0; a < N; ++a) {
      const double h = std::cbrt(std::numeric_limits<double>::epsilon()) * std::max(1.0, std::abs(z[a]));
      for (int sgn = 0; sgn < 2; ++sgn) {
        linearizeAt(a, sgn == 0 ? h : -h);
        (sgn == 0 ? Jp : Jm) << data->dqdd_dq, data->dqdd_ddq, data->dqdd_du;
      }
      const double step = (z[a] + h) - (z[a] - h);
      for (int i = 0; i < n; ++i) D[i].col(a) = (Jp.row(i) - Jm.row(i)).transpose() / step;
    }
    for (int i = 0; i < n; ++i) {
      tensorError = std::max(tensorError, columnError(D[i], ws->qddHessian[i]));
      Dsum += D[i];
      Hsum += ws->qddHessian[i];
    }
    contractionError = columnError(Dsum, H);
    // The two exact paths (hyper-dual tensors, forward-over-reverse contraction) against each other.
    agreement = (H - Hsum).cwiseAbs().maxCoeff() / std::max(1.0, Hsum.cwiseAbs().maxCoeff());
    // Fourth-order central differences (h = ε^(1/5)·max(1, |z|), truncation O(h⁴)): where they
    // agree better than the central ones, the error above is the reference's, not the tensors'.
    Eigen::MatrixXd J2p(n, N), J2m(n, N);
    for (int a = 0; a < N; ++a) {
      const double h = std::pow(std::numeric_limits<double>::epsilon(), 0.2) * std::max(1.0, std::abs(z[a]));
      const double hs[4] = {2 * h, h, -h, -2 * h};
      Eigen::MatrixXd* Js[4] = {&J2p, &Jp, &Jm, &J2m};
      for (int k = 0; k < 4; ++k) {
        linearizeAt(a, hs[k]);
        *Js[k] << data->dqdd_dq, data->dqdd_ddq, data->dqdd_du;
      }
      for (int i = 0; i < n; ++i)
        D[i].col(a) = (-J2p.row(i) + 8.0 * Jp.row(i) - 8.0 * Jm.row(i) + J2m.row(i)).transpose() / (12.0 * h);
    }
    for (int i = 0; i < n; ++i) tensorError4 = std::max(tensorError4, columnError(D[i], ws->qddHessian[i]));
  }
  void linearizeAt(int a, double h) {
    const int n = bm.model.nq();
    zz = z;
    zz[a] += h;
    qv = zz.head(n);
    dqv = zz.segment(n, n);
    uv = zz.tail(zz.size() - 2 * n);
    trellis::computeLinearization(bm.model, *data, qv, dqv, uv);
  }
  static double columnError(const Eigen::MatrixXd& ref, const Eigen::MatrixXd& got) {
    double e = 0.0;
    for (Eigen::Index j = 0; j < ref.cols(); ++j)
      e = std::max(e, (got.col(j) - ref.col(j)).cwiseAbs().maxCoeff() / std::max(1.0, ref.col(j).cwiseAbs().maxCoeff()));
    return e;
  }
};

std::map<std::string, std::unique_ptr<Fixture>>& fixtures() {
  static std::map<std::string, std::unique_ptr<Fixture>> f;
  return f;
}

/// spec.links < 0: the hand scene.
Fixture* fixtureFor(const ModelSpec& spec, bool scene, benchmark::State& state) {
  const std::string key = scene ? std::string("hand_scene") : trellis::bench::caseName(spec);
  auto& f = fixtures()[key];
  if (!f) {
    try {
      if (scene) {
        trellis::Scene s = trellis::loadScene(std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/hand.json");
        f = std::make_unique<Fixture>(BenchModel{std::move(s.model), s.q, s.dq, s.u, "hand_scene"});
      } else {
        f = std::make_unique<Fixture>(trellis::bench::makeBenchModel(spec));
      }
    } catch (const std::exception& e) {
      state.SkipWithError(e.what());
      return nullptr;
    }
  }
  if (!f->error.empty()) {
    state.SkipWithError(f->error.c_str());
    return nullptr;
  }
  state.counters["nq"] = f->bm.model.nq();
  state.counters["nu"] = f->bm.model.nu();
  state.counters["nc"] = f->bm.model.nc();
  state.counters["pairs"] = f->pairs;
  return f.get();
}

enum class Method { kLinearization, kContraction, kTensors, kFdJacobians };

void run(benchmark::State& state, Method method, ModelSpec spec, bool scene) {
  Fixture* f = fixtureFor(spec, scene, state);
  if (!f) return;
  const auto& bm = f->bm;
  const int N = static_cast<int>(f->z.size());
  for (auto _ : state) {
    switch (method) {
      case Method::kLinearization:
        trellis::computeLinearization(bm.model, *f->data, bm.q, bm.dq, bm.u);
        benchmark::ClobberMemory();
        break;
      case Method::kContraction:
        trellis::computeSecondOrderContraction(bm.model, *f->data, *f->ws, bm.q, bm.dq, bm.u, f->w, f->rho, f->H);
        benchmark::ClobberMemory();
        break;
      case Method::kTensors:
        trellis::computeSecondOrderTensors(bm.model, *f->data, *f->ws, bm.q, bm.dq, bm.u);
        benchmark::ClobberMemory();
        break;
      case Method::kFdJacobians:
        for (int a = 0; a < N; ++a) {
          const double h = std::cbrt(std::numeric_limits<double>::epsilon()) * std::max(1.0, std::abs(f->z[a]));
          f->linearizeAt(a, h);
          f->linearizeAt(a, -h);
        }
        benchmark::ClobberMemory();
        break;
    }
  }
  if (method == Method::kTensors) {
    state.counters["err"] = f->tensorError;
    state.counters["err_fd4"] = f->tensorError4;
  }
  if (method == Method::kContraction) {
    state.counters["err"] = f->contractionError;
    state.counters["vs_tensors"] = f->agreement;
  }
}

void registerAll() {
  struct Case {
    ModelSpec spec;
    bool scene;
  };
  std::vector<Case> cases;
  for (int links : {2, 4, 8, 10, 16, 32, 64}) cases.push_back({{ModelKind::kPlanarChain, links, false}, false});
  for (int links : {8, 40}) cases.push_back({{ModelKind::kSpatialChain, links, false}, false});
  cases.push_back({{ModelKind::kHandTree, 20, false}, false});
  cases.push_back({{ModelKind::kHandTree, 20, true}, false});
  cases.push_back({{ModelKind::kHandTree, 20, false}, true});
  const std::pair<const char*, Method> methods[] = {{"Linearization", Method::kLinearization},
                                                    {"Contraction", Method::kContraction},
                                                    {"Tensors", Method::kTensors},
                                                    {"FdJacobians", Method::kFdJacobians}};
  for (const auto& [label, method] : methods)
    for (const Case& c : cases) {
      const std::string name = std::string(label) + "/" + (c.scene ? std::string("hand_scene") : trellis::bench::caseName(c.spec));
      benchmark::RegisterBenchmark(name.c_str(), [method = method, c](benchmark::State& s) { run(s, method, c.spec, c.scene); })
          ->Unit(benchmark::kMicrosecond);
    }
}

const int kRegistered = (registerAll(), 0);

}  // namespace

BENCHMARK_MAIN();
