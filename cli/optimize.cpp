// cli/optimize.cpp — `trellis optimize PROBLEM.json --out TRAJ.csv`: trajectory optimization.
#include "cli_options.hpp"
#include "command.hpp"

#include "trellis/optimization.hpp"

#include <cstdio>
#include <iostream>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis optimize PROBLEM.json [--out TRAJ.csv] [options]

Reads an optimal control problem file (optimization/README.md: a scene file, the horizon, knots,
boundary states, bounds and cost weights), transcribes it by direct collocation (Hermite-Simpson
or trapezoidal) with the exact derivatives of the dynamics, and solves it with Ipopt (MUMPS,
limited-memory quasi-Newton Hessian).

While solving, one progress line per Ipopt iteration goes to standard error:
  iter  cost  constraint-violation  dual-infeasibility  step
At the end a summary goes to standard output (key: value lines): status, ipopt_status,
iterations, cost, constraint_violation, bound_violation, max_slack, horizon, knots, method,
solve_time_ms (wall clock), solve_cpu_time_ms, and trajectory (the CSV written, if any).

The trajectory CSV (the knots; trellis::Trajectory layout) has one row per knot:
  t, <configs...>, d<configs...>, <inputs...>

options:
  --out FILE            write the optimized trajectory (the last iterate if the solve failed)
  --knots N             override the problem's number of knots (N >= 2)
  --method NAME         override the method: hermite_simpson or trapezoidal
  --max-iter N          Ipopt's max_iter (default 1000)
  --tol X               Ipopt's tol (default 1e-8)
  --print-level N       Ipopt's own log at print_level N (0-12) on standard output, in place of
                        the progress lines (5 is Ipopt's usual iteration log)
  --finite-difference   build the constraint Jacobian from central differences of the dynamics
                        instead of the exact linearization (for comparison)
  --quiet               no progress lines
  -h, --help            show this help

Exit status: 0 when Ipopt converges (Solve_Succeeded or Solved_To_Acceptable_Level); 3 when it
does not (infeasible, iteration limit, failure): the summary and the CSV of the last iterate are
still written, and one line 'trellis: optimize: ...' on standard error says why; 1 for a bad
problem or scene file (the message names the field); 2 on a usage error.
)";

int runOptimize(std::span<const std::string> args, std::ostream& out) {
  OptionSpec spec;
  spec.valued = {"--out", "--knots", "--method", "--max-iter", "--tol", "--print-level"};
  spec.flags = {"--finite-difference", "--quiet"};
  const ParsedOptions options("optimize", args, spec);
  const std::string path = options.singlePositional("the problem file");

  OptimalControlProblem problem = loadProblem(path);
  if (auto v = options.value("--knots")) {
    problem.knots = options.integer<int>("--knots", *v, 2, 100000);
  }
  if (auto v = options.value("--method")) {
    if (*v == "hermite_simpson") {
      problem.method = CollocationMethod::kHermiteSimpson;
    } else if (*v == "trapezoidal") {
      problem.method = CollocationMethod::kTrapezoidal;
    } else {
      throw UsageError("optimize: --method: '" + *v + "' (expected hermite_simpson or trapezoidal)");
    }
  }
  OptimizerOptions solver;
  if (auto v = options.value("--max-iter")) solver.maxIterations = options.integer<int>("--max-iter", *v, 0);
  if (auto v = options.value("--tol")) solver.tolerance = options.positiveNumber("--tol", *v);
  if (auto v = options.value("--print-level")) {
    solver.printLevel = options.integer<int>("--print-level", *v, 0, 12);
  }
  if (options.flag("--finite-difference")) solver.derivatives = DerivativeMode::kFiniteDifference;
  if (!options.flag("--quiet") && solver.printLevel == 0) {
    std::cerr << "iter        cost      constr_viol   dual_infeas     step\n";
    solver.onIteration = [](const IterationInfo& info) {
      char line[128];
      std::snprintf(line, sizeof line, "%4d%s %13.6e %12.4e %12.4e %9.3e\n", info.iteration,
                    info.restoration ? "r" : " ", info.cost, info.constraintViolation,
                    info.dualInfeasibility, info.stepSize);
      std::cerr << line;
      return true;
    };
  }

  const OptimizationResult result = optimizeTrajectory(problem, solver);
  const auto outPath = options.value("--out");
  if (outPath) result.trajectory.writeCsvFile(*outPath);

  out << "status: " << toString(result.status) << '\n'
      << "ipopt_status: " << result.ipoptStatus << '\n'
      << "iterations: " << result.iterations << '\n'
      << "cost: " << formatNumber(result.cost, 10) << '\n'
      << "constraint_violation: " << formatNumber(result.constraintViolation, 3) << '\n'
      << "bound_violation: " << formatNumber(result.boundViolation, 3) << '\n'
      << "max_slack: " << formatNumber(result.maxSlack, 3) << '\n'
      << "horizon: " << formatNumber(result.horizon, 10) << '\n'
      << "knots: " << problem.knots << '\n'
      << "method: "
      << (problem.method == CollocationMethod::kHermiteSimpson ? "hermite_simpson" : "trapezoidal") << '\n'
      << "derivatives: "
      << (solver.derivatives == DerivativeMode::kExact ? "exact" : "finite_difference") << '\n'
      << "solve_time_ms: " << formatNumber(1e3 * result.solveTime, 4) << '\n'
      << "solve_cpu_time_ms: " << formatNumber(1e3 * result.solveCpuTime, 4) << '\n';
  if (outPath) out << "trajectory: " << *outPath << '\n';
  if (!result.success()) {
    std::cerr << "trellis: optimize: " << result.message << '\n';
    return 3;
  }
  return 0;
}

}  // namespace

const Command kOptimizeCommand{
    "optimize",
    "trajectory optimization of a problem file (direct collocation, Ipopt); writes a CSV",
    kHelp,
    &runOptimize,
};

const CommandRegistration kRegisterOptimize{kOptimizeCommand};

}  // namespace trellis::cli
