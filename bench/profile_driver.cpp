// bench/profile_driver.cpp — a loop around one algorithm on one benchmark model, for profilers
// (valgrind --tool=callgrind, perf record) that want the hot path without Google Benchmark's
// calibration runs around it.
//
//   trellis_bench_profile <planar|spatial|hand> <N> <nc:0|1> <lin|dyn|fd> [iterations]
//   trellis_bench_profile scene <file.json> 0 <lin|dyn|fd> [iterations]   (the scene's stored state)
#include "finite_differences.hpp"
#include "models.hpp"

#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/scene.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <limits>
#include <string>

int main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr,
                 "usage: %s <planar|spatial|hand> <N> <constrained 0|1|2|3> <lin|dyn|fd> [iterations]\n",
                 argv[0]);
    return 2;
  }
  const std::string kind = argv[1], what = argv[4];
  trellis::bench::ModelSpec spec;
  if (!trellis::bench::parseProfileModel(argv[1], argv[2], argv[3], spec)) return 2;
  const long iterations = argc > 5 ? std::atol(argv[5]) : 1000;
  if (what != "lin" && what != "dyn" && what != "fd") {
    std::fprintf(stderr, "unknown algorithm '%s' (lin, dyn, fd)\n", what.c_str());
    return 2;
  }

  try {
    trellis::bench::BenchModel bm;
    if (kind == "scene") {
      trellis::Scene scene = trellis::loadScene(argv[2]);
      bm = trellis::bench::BenchModel{std::move(scene.model), scene.q, scene.dq, scene.u, "scene"};
    } else {
      bm = trellis::bench::makeBenchModel(spec);
    }
    trellis::Data data(bm.model);
    trellis::bench::FdWorkspace ws(bm.model);
    Eigen::MatrixXd J(bm.model.nq(), 2 * bm.model.nq() + bm.model.nu());
    const double step = std::cbrt(std::numeric_limits<double>::epsilon());
    double checksum = 0.0;
    for (long k = 0; k < iterations; ++k) {
      if (what == "lin") {
        trellis::computeLinearization(bm.model, data, bm.q, bm.dq, bm.u);
        checksum += data.A(data.A.rows() - 1, 0);
      } else if (what == "dyn") {
        trellis::computeDynamics(bm.model, data, bm.q, bm.dq, bm.u);
        checksum += data.qdd[0];
      } else {
        trellis::bench::centralDifferences(bm.model, data, bm.q, bm.dq, bm.u, step, ws, J);
        checksum += J(0, 0);
      }
    }
    std::printf("%s N=%d nq=%d nc=%d %s x%ld status=%s checksum=%.17g\n", kind.c_str(), spec.links,
                bm.model.nq(), bm.model.nc(), what.c_str(), iterations,
                data.status.ok() ? "ok" : data.status.message.c_str(), checksum);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
