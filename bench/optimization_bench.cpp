// optimization_bench.cpp — trajectory optimization: the cart-pole and acrobot swing-ups of
// examples/problems/ solved by Ipopt at 25, 50, 100, 200 knots (Hermite–Simpson), with the exact
// constraint Jacobian (the core's linearization) and with a finite-difference one (central
// differences of the forward dynamics at every collocation point; same NLP, same pattern).
//
// Time per solve (wall clock; the problem file is loaded outside the timed loop) and counters:
//   iterations   Ipopt iterations
//   success      1 when Ipopt converged (Solve_Succeeded / Solved_To_Acceptable_Level)
//   cost         final cost (speed against error: the two Jacobians should reach the same cost)
//   viol         max |defect| of the returned trajectory
//   cpu_ms       process CPU time of the solve (the machine may be shared: CPU time is the
//                steadier figure)
// (No DoNotOptimize on result.cost: with Debian's Google Benchmark 1.7 and GCC 12 at -O3 it
// corrupted the double it was given; the solve has side effects and cannot be elided.)
//
// The `solve` family measures one Ipopt solve (no refinement: maxRefinements = 0 and a tolerance
// that any result meets; the a-posteriori check still runs and its defect is a counter).
// The `refine` family measures "solved means consistent": the examples (two swing-ups and the
// closed-chain transfer) from their files' knots, Hermite–Simpson and trapezoidal, to a relative
// defect of 1e-3 and 1e-5, with refinement (up to 8 rounds) and without (one solve at the file's
// knots, usually reported inconsistent). Counters: knots (final), rounds, defect (final relative
// defect), slack (closed chains: the slack's share), success (1 = solved and consistent), cpu_ms.
//
// The `swingup` family measures issue 30's exact Hessian against L-BFGS (hessian = 0: exact, 1:
// lbfgs) with the default options (refinement up to 6 rounds, warm-started) on the example
// problems and the swing-ups of examples/problems/swingups (turntable arm, 4- and 5-link chains,
// turntable 4-link chain, two with joint speed limits; the paper pendulum with its constraint
// force bounded). Counters: iterations (all rounds),
// rounds, knots (final), success (1 = solved and consistent), inconsistent (1 when the refinement
// limit was reached first), iteration_limit (1 when a round hit Ipopt's limit), cost, defect,
// cpu_ms; the label lists the iterations per round. The `swingupStart` family runs the
// turntable arm (41–81 knots) and the 4-link chain (31–61) from other starting meshes with the
// default refinement rule and with the order-based cuts alone (rule = 0).
//
// Run: build/bench/trellis_bench_optimization --benchmark_out=opt.json --benchmark_out_format=json
#include <trellis/optimization.hpp>

#include <benchmark/benchmark.h>

#include <iterator>
#include <limits>
#include <string>

namespace {

const char* const kProblems[] = {"cart_pole_swingup", "acrobot_swingup"};

void solve(benchmark::State& state) {
  const std::string name = kProblems[state.range(0)];
  trellis::OptimalControlProblem problem = trellis::loadProblem(
      std::string(TRELLIS_SOURCE_DIR) + "/examples/problems/" + name + ".json");
  problem.knots = static_cast<int>(state.range(1));
  trellis::OptimizerOptions options;
  options.maxRefinements = 0;
  options.consistencyTolerance = 1e30;
  options.derivatives = state.range(2) == 0 ? trellis::DerivativeMode::kExact
                                            : trellis::DerivativeMode::kFiniteDifference;
  trellis::OptimizationResult result;
  double cpu = 0.0;
  for (auto _ : state) {
    result = trellis::optimizeTrajectory(problem, options);
    cpu += result.solveCpuTime;
  }
  state.SetLabel(name + (state.range(2) == 0 ? " exact" : " finite-difference"));
  state.counters["iterations"] = result.iterations;
  state.counters["success"] = result.ok() ? 1.0 : 0.0;
  state.counters["cost"] = result.cost;
  state.counters["viol"] = result.constraintViolation;
  state.counters["defect"] = result.consistency.maxDefect;
  state.counters["cpu_ms"] = 1e3 * cpu / static_cast<double>(state.iterations());
}

const char* const kRefineProblems[] = {"cart_pole_swingup", "acrobot_swingup", "paper_pendulum_transfer"};

void refine(benchmark::State& state) {
  const std::string name = kRefineProblems[state.range(0)];
  trellis::OptimalControlProblem problem = trellis::loadProblem(
      std::string(TRELLIS_SOURCE_DIR) + "/examples/problems/" + name + ".json");
  const bool hs = state.range(1) == 0;
  problem.method = hs ? trellis::CollocationMethod::kHermiteSimpson : trellis::CollocationMethod::kTrapezoidal;
  trellis::OptimizerOptions options;
  options.consistencyTolerance = state.range(2) == 3 ? 1e-3 : 1e-5;
  options.maxRefinements = state.range(3) == 0 ? 0 : 8;
  trellis::OptimizationResult result;
  double cpu = 0.0;
  for (auto _ : state) {
    result = trellis::optimizeTrajectory(problem, options);
    cpu += result.solveCpuTime;
  }
  state.SetLabel(name + (hs ? " hermite_simpson" : " trapezoidal") +
                 (state.range(3) == 0 ? " no refinement" : " refined"));
  state.counters["knots"] = result.trajectory.size();
  state.counters["rounds"] = static_cast<double>(result.rounds.size());
  state.counters["iterations"] = result.iterations;
  state.counters["defect"] = result.consistency.maxDefect;
  state.counters["slack"] = result.maxSlackDefect;
  state.counters["success"] = result.ok() ? 1.0 : 0.0;
  state.counters["cpu_ms"] = 1e3 * cpu / static_cast<double>(state.iterations());
}

const char* const kSwingups[] = {"cart_pole_swingup",
                                 "acrobot_swingup",
                                 "paper_pendulum_transfer",
                                 "swingups/turntable_arm_swingup",
                                 "swingups/turntable_arm_speed_limit_swingup",
                                 "swingups/chain4_swingup",
                                 "swingups/chain5_swingup",
                                 "swingups/chain5_speed_limit_swingup",
                                 "swingups/turntable_chain4_swingup",
                                 "swingups/paper_pendulum_force_bound_transfer"};

/// Runs the optimizer in the timed loop and reports the last run: label `what` + iterations per
/// round, and the counters both swing-up families share.
void runSwingup(benchmark::State& state, const trellis::OptimalControlProblem& problem,
                const trellis::OptimizerOptions& options, const std::string& what) {
  trellis::OptimizationResult result;
  double cpu = 0.0;
  for (auto _ : state) {
    result = trellis::optimizeTrajectory(problem, options);
    cpu += result.solveCpuTime;
  }
  std::string perRound;
  bool limit = false;
  for (const trellis::RefinementRound& r : result.rounds) {
    perRound += (perRound.empty() ? "" : "/") + std::to_string(r.iterations);
    limit = limit || r.ipoptStatus == "Maximum_Iterations_Exceeded";
  }
  state.SetLabel(what + " rounds " + perRound);
  state.counters["iterations"] = result.iterations;
  state.counters["rounds"] = static_cast<double>(result.rounds.size());
  state.counters["knots"] = result.trajectory.size();
  state.counters["success"] = result.ok() ? 1.0 : 0.0;
  state.counters["inconsistent"] = result.status.code == trellis::OptimizationCode::kInconsistent ? 1.0 : 0.0;
  state.counters["iteration_limit"] = limit ? 1.0 : 0.0;
  state.counters["cost"] = result.cost;
  state.counters["defect"] = result.consistency.maxDefect;
  state.counters["cpu_ms"] = 1e3 * cpu / static_cast<double>(state.iterations());
}

void swingup(benchmark::State& state) {
  const std::string name = kSwingups[state.range(0)];
  const trellis::OptimalControlProblem problem = trellis::loadProblem(
      std::string(TRELLIS_SOURCE_DIR) + "/examples/problems/" + name + ".json");
  trellis::OptimizerOptions options;
  options.hessian = state.range(1) == 0 ? trellis::HessianMode::kExact : trellis::HessianMode::kLimitedMemory;
  runSwingup(state, problem, options, name + (state.range(1) == 0 ? " exact" : " lbfgs"));
}

/// The refinement rule's robustness to the starting mesh (issue 30): the turntable arm and the
/// 4-link chain from other knot counts, exact Hessian, with the default rule (band = 3) and with
/// the order-based cuts alone (band = 0, no unresolved-motion rule).
void swingupStart(benchmark::State& state) {
  const std::string name = state.range(0) == 0 ? "swingups/turntable_arm_swingup" : "swingups/chain4_swingup";
  trellis::OptimalControlProblem problem = trellis::loadProblem(
      std::string(TRELLIS_SOURCE_DIR) + "/examples/problems/" + name + ".json");
  problem.knots = static_cast<int>(state.range(1));
  trellis::OptimizerOptions options;
  if (state.range(2) == 0) {
    options.refinementBand = 0;
    options.unresolvedDefect = std::numeric_limits<double>::infinity();
  }
  runSwingup(state, problem, options, name + (state.range(2) == 0 ? " cuts only" : " default rule"));
}

void swingupStartArguments(benchmark::internal::Benchmark* b) {
  for (int knots : {41, 51, 61, 71, 81})
    for (int rule = 0; rule < 2; ++rule) b->Args({0, knots, rule});
  for (int knots : {31, 41, 51, 61})
    for (int rule = 0; rule < 2; ++rule) b->Args({1, knots, rule});
}

void swingupArguments(benchmark::internal::Benchmark* b) {
  for (int problem = 0; problem < static_cast<int>(std::size(kSwingups)); ++problem)
    for (int hessian = 0; hessian < 2; ++hessian) b->Args({problem, hessian});
}

void refineArguments(benchmark::internal::Benchmark* b) {
  for (int problem = 0; problem < 3; ++problem)
    for (int method = 0; method < 2; ++method)
      for (int tolExponent : {3, 5})
        for (int refined = 0; refined < 2; ++refined) b->Args({problem, method, tolExponent, refined});
}

void arguments(benchmark::internal::Benchmark* b) {
  for (int problem = 0; problem < 2; ++problem)
    for (int knots : {25, 50, 100, 200})
      for (int mode = 0; mode < 2; ++mode) b->Args({problem, knots, mode});
}

BENCHMARK(solve)->Apply(arguments)->ArgNames({"problem", "knots", "fd"})->Unit(benchmark::kMillisecond)
    ->Iterations(3)->UseRealTime();
BENCHMARK(refine)->Apply(refineArguments)->ArgNames({"problem", "trap", "tol_exp", "refined"})
    ->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();
BENCHMARK(swingup)->Apply(swingupArguments)->ArgNames({"problem", "hessian"})
    ->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(swingupStart)->Apply(swingupStartArguments)->ArgNames({"problem", "knots", "rule"})
    ->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
