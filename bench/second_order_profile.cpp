// bench/second_order_profile.cpp — a loop around one algorithm, for callgrind instruction counts
// of the second derivatives against one exact linearization (the figures of issue 30).
//
//   trellis_bench_second_order_profile <planar|spatial|hand> <N> <nc:0|1> <lin|contract|tensors|fdjac> [iterations]
//   trellis_bench_second_order_profile scene <file.json> 0 <…> [iterations]   (the scene's stored state)
//
// Per-call counts: run with two iteration counts and divide the difference of the totals
// (bench/second_order_callgrind.sh), which removes the set-up.
//   lin       computeLinearization
//   contract  computeSecondOrderContraction (w = 1, ρ = 1; includes its linearization)
//   contract_tape  the same on the recorded tape, also where the tree pass applies (the
//             comparison of second_order.hpp's cost figures)
//   tensors   computeSecondOrderTensors (includes its linearization)
//   fdjac     central differences of the exact Jacobians: 2N linearizations (the baseline)
#include "models.hpp"

#include "trellis/core/linearization.hpp"
#include "trellis/core/scene.hpp"
#include "trellis/core/second_order.hpp"

#include "second_order_tree.hpp"  // core/src: the switch to the tape

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <limits>
#include <string>

int main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr, "usage: %s <planar|spatial|hand|scene> <N|file> <nc 0|1> <lin|contract|tensors|fdjac> [iterations]\n",
                 argv[0]);
    return 2;
  }
  const std::string kind = argv[1], what = argv[4];
  trellis::bench::ModelSpec spec;
  if (!trellis::bench::parseProfileModel(argv[1], argv[2], argv[3], spec)) return 2;
  const long iterations = argc > 5 ? std::atol(argv[5]) : 10;
  if (what != "lin" && what != "contract" && what != "contract_tape" && what != "tensors" && what != "fdjac") {
    std::fprintf(stderr, "unknown algorithm '%s'\n", what.c_str());
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
    const int n = bm.model.nq(), N = 2 * n + bm.model.nu();
    trellis::Data data(bm.model);
    trellis::detail::secondOrderForceTape(what == "contract_tape");
    trellis::SecondOrderWorkspace ws(bm.model, what == "tensors");
    trellis::detail::secondOrderForceTape(false);
    const Eigen::VectorXd w = Eigen::VectorXd::Ones(n), rho = Eigen::VectorXd::Ones(bm.model.nc());
    Eigen::MatrixXd H(N, N), J(n, N);
    Eigen::VectorXd z(N), zz(N), qv(n), dqv(n), uv(N - 2 * n);
    z << bm.q, bm.dq, bm.u;
    double checksum = 0.0;
    for (long k = 0; k < iterations; ++k) {
      if (what == "lin") {
        trellis::computeLinearization(bm.model, data, bm.q, bm.dq, bm.u);
        checksum += data.A(data.A.rows() - 1, 0);
      } else if (what == "contract" || what == "contract_tape") {
        trellis::computeSecondOrderContraction(bm.model, data, ws, bm.q, bm.dq, bm.u, w, rho, H);
        checksum += H(0, 0);
      } else if (what == "tensors") {
        trellis::computeSecondOrderTensors(bm.model, data, ws, bm.q, bm.dq, bm.u);
        checksum += ws.qddHessian[0](0, 0);
      } else {
        for (int a = 0; a < N; ++a) {
          const double h = std::cbrt(std::numeric_limits<double>::epsilon()) * std::max(1.0, std::abs(z[a]));
          for (int sgn = -1; sgn <= 1; sgn += 2) {
            zz = z;
            zz[a] += sgn * h;
            qv = zz.head(n);
            dqv = zz.segment(n, n);
            uv = zz.tail(N - 2 * n);
            trellis::computeLinearization(bm.model, data, qv, dqv, uv);
            checksum += sgn * data.dqdd_dq(0, 0) / (2 * h);
          }
        }
      }
    }
    std::printf("%s N=%d nq=%d nu=%d nc=%d %s x%ld status=%s checksum=%.17g\n", kind.c_str(), spec.links, n,
                bm.model.nu(), bm.model.nc(), what.c_str(), iterations,
                data.status.ok() ? "ok" : data.status.message.c_str(), checksum);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
