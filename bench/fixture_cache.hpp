// fixture_cache.hpp — the benchmark programs' lazily built fixtures, one per model case, so that a
// --benchmark_filter run builds only the models it times.
#pragma once

#include "models.hpp"

#include <benchmark/benchmark.h>

#include <exception>
#include <map>
#include <memory>
#include <string>

namespace trellis::bench {

/// "kind/N:n/nc:k" — the hand tree always has 20 joints (3 constraint rows when constrained),
/// the chains `links` joints (1, 2 or 3 rows: TipRows); the planar chain's redundant z row is
/// named "nc:3z".
inline std::string caseName(const ModelSpec& spec) {
  const bool hand = spec.kind == ModelKind::kHandTree;
  const int n = hand ? 20 : spec.links;
  const bool redundant = spec.constrained && !hand && spec.tip == TipRows::kRedundant;
  return std::string(kindName(spec.kind)) + "/N:" + std::to_string(n) + "/nc:" +
         std::to_string(constraintRows(spec)) + (redundant ? "z" : "");
}

/// The Fixture for spec (constructed from it on first use; it has members `error`, a string set
/// when the fixture is unusable, and `bm.model`). Skips the benchmark with the reason and returns
/// nullptr when it cannot be built; otherwise records the sizes nq, nc, nu as counters.
template <class Fixture>
Fixture* fixtureFor(const ModelSpec& spec, benchmark::State& state) {
  static std::map<std::string, std::unique_ptr<Fixture>> fixtures;
  const std::string key = caseName(spec);
  auto it = fixtures.find(key);
  if (it == fixtures.end()) {
    try {
      it = fixtures.emplace(key, std::make_unique<Fixture>(spec)).first;
    } catch (const std::exception& e) {
      state.SkipWithError(("building " + key + ": " + e.what()).c_str());
      return nullptr;
    }
  }
  Fixture* f = it->second.get();
  if (!f->error.empty()) {
    state.SkipWithError(f->error.c_str());
    return nullptr;
  }
  state.counters["nq"] = f->bm.model.nq();
  state.counters["nc"] = f->bm.model.nc();
  state.counters["nu"] = f->bm.model.nu();
  return f;
}

}  // namespace trellis::bench
