// bench/closed_loop_bench.cpp — what a closing constraint costs, measured against the same model
// without it, interleaved in one process (issue 25).
//
//   trellis_bench_closed [rounds] [runs] [target_ms]
//
// Each pair is a free model and the same model with constraint rows added (bench/models.hpp:
// one tip row, the tip pinned, the planar tip pinned with its redundant z row, the hand's
// fingertip). In each round the free and the constrained computation are timed alternately,
// `runs` batches each (free, constrained, free, constrained, …; the batch size is calibrated once
// so that a free batch takes about target_ms), and the round's figure is the ratio of the two
// fastest batches: the minimum removes the batches another process interrupted, the alternation
// makes both sides see the same machine. Reported per pair and computation (dyn =
// computeDynamics, lin = computeLinearization): the median ratio over the rounds with its 10 %
// and 90 % quantiles, and the median per-call times. Times are wall-clock (steady_clock); run
// under `taskset -c K` to keep the process on one CPU. Exit status 1 if a model fails to build
// or a computation does not return ok.
#include "models.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

namespace {

using trellis::bench::ModelKind;
using trellis::bench::ModelSpec;
using trellis::bench::TipRows;

struct Case {
  explicit Case(const ModelSpec& spec) : bm(trellis::bench::makeBenchModel(spec)), data(bm.model) {}
  trellis::bench::BenchModel bm;
  trellis::Data data;
  /// One call; false when the status is not ok.
  bool call(bool lin) {
    const trellis::DynamicsStatus s = lin ? trellis::computeLinearization(bm.model, data, bm.q, bm.dq, bm.u)
                                          : trellis::computeDynamics(bm.model, data, bm.q, bm.dq, bm.u);
    return s.ok();
  }
  /// Seconds per call over a batch of `iterations` calls.
  double time(bool lin, long iterations) {
    const auto t0 = std::chrono::steady_clock::now();
    for (long k = 0; k < iterations; ++k) {
      call(lin);
      asm volatile("" : : "g"(data.A.data()), "g"(data.qdd.data()) : "memory");
    }
    const auto t1 = std::chrono::steady_clock::now();
    return std::chrono::duration<double>(t1 - t0).count() / static_cast<double>(iterations);
  }
};

double quantile(std::vector<double> x, double p) {
  std::sort(x.begin(), x.end());
  const double pos = p * static_cast<double>(x.size() - 1);
  const size_t i = static_cast<size_t>(pos);
  const double f = pos - static_cast<double>(i);
  return i + 1 < x.size() ? x[i] * (1.0 - f) + x[i + 1] * f : x[i];
}

std::string name(const ModelSpec& spec) {
  std::string s = std::string(trellis::bench::kindName(spec.kind)) + " " + std::to_string(spec.links);
  if (spec.kind == ModelKind::kHandTree) s = "hand 20";
  if (!spec.constrained) return s + " free";
  if (spec.kind == ModelKind::kHandTree) return s + " fingertip xyz";
  switch (spec.tip) {
    case TipRows::kOne: return s + (spec.kind == ModelKind::kPlanarChain ? " tip x" : " tip z");
    case TipRows::kPinned: return s + (spec.kind == ModelKind::kPlanarChain ? " tip xy" : " tip xyz");
    case TipRows::kRedundant: return s + " tip xyz (z redundant)";
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  const int rounds = argc > 1 ? std::atoi(argv[1]) : 41;
  const int runs = argc > 2 ? std::atoi(argv[2]) : 11;
  const double targetMs = argc > 3 ? std::atof(argv[3]) : 0.5;
  if (rounds < 1 || runs < 1 || !(targetMs > 0)) {
    std::fprintf(stderr, "usage: %s [rounds >= 1] [runs >= 1] [target_ms > 0]\n", argv[0]);
    return 2;
  }
  struct Pair {
    ModelSpec free, closed;
  };
  const auto chain = [](ModelKind k, int n, TipRows t) {
    return Pair{{k, n, false, TipRows::kOne}, {k, n, true, t}};
  };
  const std::vector<Pair> pairs = {
      chain(ModelKind::kSpatialChain, 20, TipRows::kPinned), chain(ModelKind::kSpatialChain, 40, TipRows::kPinned),
      chain(ModelKind::kSpatialChain, 5, TipRows::kPinned),  chain(ModelKind::kSpatialChain, 10, TipRows::kPinned),
      chain(ModelKind::kSpatialChain, 20, TipRows::kOne),    chain(ModelKind::kSpatialChain, 40, TipRows::kOne),
      chain(ModelKind::kPlanarChain, 40, TipRows::kPinned),  chain(ModelKind::kPlanarChain, 40, TipRows::kRedundant),
      chain(ModelKind::kPlanarChain, 20, TipRows::kPinned),  chain(ModelKind::kPlanarChain, 20, TipRows::kRedundant),
      {{ModelKind::kHandTree, 20, false}, {ModelKind::kHandTree, 20, true}},
  };
  std::printf("# trellis_bench_closed: %d rounds x %d runs per side, batches of ~%.2f ms\n", rounds, runs, targetMs);
  std::printf("%-36s %-4s %10s %10s %8s %8s %8s\n", "constrained model", "alg", "free us", "closed us", "ratio",
              "q10", "q90");
  int status = 0;
  for (const Pair& p : pairs) {
    try {
      Case fr(p.free), cl(p.closed);
      for (bool lin : {false, true}) {
        // The model with the redundant row reports it (kRedundantConstraints): not ok, but exact.
        if (!fr.call(lin) || (!cl.call(lin) && p.closed.tip != TipRows::kRedundant)) {
          std::fprintf(stderr, "%s: %s did not return ok: %s\n", name(p.closed).c_str(), lin ? "lin" : "dyn",
                       cl.data.status.message.c_str());
          status = 1;
          continue;
        }
        const double once = fr.time(lin, 50);
        const long iterations = std::max(1L, static_cast<long>(targetMs * 1e-3 / once));
        std::vector<double> ratio, tf, tc;
        for (int r = 0; r < rounds; ++r) {
          double bf = 1e300, bc = 1e300;
          for (int k = 0; k < runs; ++k) {
            // Alternate which side goes first, so that neither always follows the other.
            if ((r + k) % 2 == 0) {
              bf = std::min(bf, fr.time(lin, iterations));
              bc = std::min(bc, cl.time(lin, iterations));
            } else {
              bc = std::min(bc, cl.time(lin, iterations));
              bf = std::min(bf, fr.time(lin, iterations));
            }
          }
          ratio.push_back(bc / bf);
          tf.push_back(bf);
          tc.push_back(bc);
        }
        std::printf("%-36s %-4s %10.2f %10.2f %8.3f %8.3f %8.3f\n", name(p.closed).c_str(), lin ? "lin" : "dyn",
                    1e6 * quantile(tf, 0.5), 1e6 * quantile(tc, 0.5), quantile(ratio, 0.5), quantile(ratio, 0.1),
                    quantile(ratio, 0.9));
        std::fflush(stdout);
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "%s: %s\n", name(p.closed).c_str(), e.what());
      status = 1;
    }
  }
  return status;
}
