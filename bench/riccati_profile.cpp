// bench/riccati_profile.cpp — solveRiccati on the Riccati benchmark's problem in a plain loop, for
// profilers (valgrind --tool=callgrind, perf) and for the integrator's statistics per solve.
//
//   trellis_bench_riccati_profile <links n> [iterations=1] [tol exponent e=6] [solver]
//   (nx = 2n states; rtol = 10^-e, atol = rtol·1e-2; solver: auto, dense, krylov, lyapunov)
#include "riccati_problem.hpp"

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <map>
#include <string>

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s <links> [iterations] [tol exponent] [solver]\n", argv[0]);
    return 2;
  }
  try {
    const int n = std::atoi(argv[1]);
    const long iterations = argc > 2 ? std::atol(argv[2]) : 1;
    const int e = argc > 3 ? std::atoi(argv[3]) : 6;
    trellis::RiccatiOptions o;
    o.rtol = std::pow(10.0, -e);
    o.atol = o.rtol * 1e-2;
    o.trackEigenvalues = false;
    if (argc > 4) o.linearSolver = trellis::parseRiccatiLinearSolver(argv[4]);
    const auto lin = trellis::bench::blendedChain(n);
    const auto w = trellis::bench::unitRiccatiWeights(2 * n, n);
    trellis::RiccatiSolution sol;
    for (long i = 0; i < iterations; ++i) {
      sol = trellis::solveRiccati(0.0, trellis::bench::kRiccatiHorizon, 2 * n, n, lin, w, o);
    }
    std::printf("status %s  steps %ld  rhs %ld  newton %ld  lyapunov solves %ld  setups %ld  "
                "schur %ld  error-test failures %ld  convergence failures %ld  linearizations %ld\n",
                sol.status.name(), sol.steps, sol.rhsEvaluations, sol.newtonIterations,
                sol.preconditionerSolves, sol.linearSolverSetups, sol.schurFactorizations,
                sol.errorTestFailures, sol.convergenceFailures, sol.linearizations);
    std::map<int, int> orders;
    for (int q : sol.stepOrders()) ++orders[q];
    std::printf("orders:");
    for (const auto& [q, c] : orders) std::printf("  %d: %d", q, c);
    const auto t = sol.stepTimes();
    std::printf("\nstep sizes (t descending, every 10th):");
    for (std::size_t k = t.size() - 1; k > 0; k -= std::min<std::size_t>(10, k)) {
      std::printf(" %.2g@%.3g", t[k] - t[k - 1], t[k]);
    }
    std::printf("\n");
    return sol.ok() ? 0 : 1;
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "error: %s\n", ex.what());
    return 1;
  }
}
