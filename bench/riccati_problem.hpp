// bench/riccati_problem.hpp — the Riccati benchmark's problem (see riccati_bench.cpp), shared by
// the benchmark and the profiling loop (riccati_profile.cpp).
#pragma once

#include "models.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/linearization.hpp"

#include <trellis/control.hpp>

#include <cmath>
#include <map>
#include <stdexcept>
#include <utility>

namespace trellis::bench {

constexpr double kRiccatiHorizon = 2.0;

struct ChainSystem {
  Eigen::MatrixXd Aa, Ab, Ba, Bb;
};

/// Exact linearizations of the n-link planar chain at two random non-equilibrium states.
inline const ChainSystem& chainSystem(int n) {
  static std::map<int, ChainSystem> cache;
  auto it = cache.find(n);
  if (it != cache.end()) return it->second;
  ModelSpec spec;
  spec.kind = ModelKind::kPlanarChain;
  spec.links = n;
  ChainSystem sys;
  for (std::uint32_t seed : {20100503u, 7u}) {
    const auto bm = makeBenchModel(spec, seed);
    trellis::Data data(bm.model);
    const auto status = trellis::computeLinearization(bm.model, data, bm.q, bm.dq, bm.u);
    if (!status.ok()) throw std::runtime_error("riccati bench: linearization failed: " + status.message);
    (seed == 7u ? sys.Ab : sys.Aa) = data.A;
    (seed == 7u ? sys.Bb : sys.Ba) = data.B;
  }
  return cache.emplace(n, std::move(sys)).first->second;
}

/// A(t) = (1 − s) A_a + s A_b, s(t) = ½(1 − cos(π t / T)), the same for B.
inline trellis::LinearizationCallback blendedChain(int n) {
  const ChainSystem& sys = chainSystem(n);
  return [&sys](double t, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
    const double s = 0.5 * (1.0 - std::cos(3.14159265358979323846 * t / kRiccatiHorizon));
    A = (1.0 - s) * sys.Aa + s * sys.Ab;
    B = (1.0 - s) * sys.Ba + s * sys.Bb;
    return trellis::ReferenceStatus{};
  };
}

/// Q = I, R = I, Qf = I.
inline trellis::LqrWeights unitRiccatiWeights(int nx, int nu) {
  trellis::LqrWeights w;
  w.Q = Eigen::MatrixXd::Identity(nx, nx);
  w.R = Eigen::MatrixXd::Identity(nu, nu);
  w.Qf = Eigen::MatrixXd::Identity(nx, nx);
  return w;
}

}  // namespace trellis::bench
