// cli/optimize.cpp — `trellis optimize PROBLEM.json --out TRAJ.csv`: trajectory optimization.
#include "cli_options.hpp"
#include "command.hpp"
#include "json_output.hpp"

#include "trellis/optimization.hpp"

#include <cmath>
#include <cstdio>
#include <iostream>

#include <unistd.h>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis optimize PROBLEM.json [--out TRAJ.csv] [options]

Reads an optimal control problem file (optimization/README.md: a scene file, the horizon, knots,
boundary states, bounds and cost weights), transcribes it by direct collocation (Hermite-Simpson,
trapezoidal or Radau IIA) with the exact first and second derivatives of the dynamics, and solves it with
Ipopt (MUMPS, exact Lagrangian Hessian by default). The solution is then checked a posteriori: the exact
dynamics are integrated (CVODES, rtol 1e-10) over every interval from every knot under the input
as every trellis tool reads the CSV (linear between knots), and the worst miss of the next knot
or of the Hermite reference at the interval's midpoint, relative to each state's range, must be
below --consistency-tol (closed chains: the slack's share too). Otherwise the mesh is refined
where the defect is large (intervals above the tolerance cut by the defect's order, their 3
neighbours on each side halved, every interval halved while the worst defect exceeds 5 % of a
state's range; warm start) and the problem solved again, up to --max-refinements rounds.

While solving, one progress line per Ipopt iteration goes to standard error:
  iter  cost  constraint-violation  dual-infeasibility  step
At the end a summary goes to standard output (key: value lines): status, ipopt_status,
iterations (all rounds), cost, constraint_violation, bound_violation, max_slack, horizon, knots
(of the returned solution), method, derivatives, hessian, consistency_defect (worst relative defect),
consistency_where (state, interval, time), slack_defect (closed chains), refinement_rounds, one
'round_K: knots N, iterations I, defect D' line per solve, solve_time_ms (wall clock, all
rounds), solve_cpu_time_ms, evaluation_time_ms, hessian_time_ms (of the evaluations, the
Hessian's), check_time_ms (the a-posteriori checks; the rest is Ipopt with MUMPS), and trajectory (the CSV written, if any).

The trajectory CSV (the knots; trellis::Trajectory layout) has one row per knot:
  t, <configs...>, d<configs...>, <inputs...>
and means what it says: the input is linear between knots (the Hermite-Simpson midpoint input is
constrained to the knot average), the state the cubic Hermite spline of the knots.

options:
  --out FILE            write the optimized trajectory (the last iterate if the solve failed)
  --knots N             override the problem's number of knots (N >= 2)
  --method NAME         override the method: hermite_simpson, trapezoidal or radau
  --max-iter N          Ipopt's max_iter (default 1000)
  --tol X               Ipopt's tol (default 1e-8)
  --print-level N       Ipopt's own log at print_level N (0-12) on standard output, in place of
                        the progress lines (5 is Ipopt's usual iteration log)
  --consistency-tol X   tolerance of the a-posteriori check (default 1e-3 of each state's range)
  --max-refinements N   rounds of mesh refinement (default 6; 0: check only)
  --hessian NAME        the Lagrangian Hessian: exact (the transcription's exact second
                        derivatives; the default unless the problem file says "hessian": "lbfgs")
                        or lbfgs (Ipopt's limited-memory quasi-Newton approximation)
  --cold-refinement     start each refinement round from the previous solution's primal point
                        only (no multipliers, no Ipopt warm start; for comparison)
  --finite-difference   build the constraint Jacobian from central differences of the dynamics
                        instead of the exact linearization (for comparison)
  --quiet               no progress lines
  --json                print the result's report as one JSON object (one line: the keys above
                        and "ok", "message", "t", "index" of the status; "rounds" a list,
                        "consistency_where" an object)
  -h, --help            show this help

Exit status: 0 when Ipopt converges (Solve_Succeeded or Solved_To_Acceptable_Level) AND the
solution passes the consistency check; 3 when Ipopt does not converge (infeasible, iteration
limit, failure); 4 when it converges but the solution is not consistent after the allowed
refinements (status: inconsistent; the message names the state, interval and time). With 3 and 4
the summary and the CSV of the last iterate are still written, and one line 'trellis: optimize:
...' on standard error says why; 1 for a bad problem or scene file (the message names the field,
e.g. a fixed boundary state off the constraint manifold); 2 on a usage error.
)";

int runOptimize(std::span<const std::string> args, std::ostream& out) {
  OptionSpec spec;
  spec.valued = {"--out", "--knots", "--method", "--max-iter", "--tol", "--print-level",
                 "--consistency-tol", "--max-refinements", "--hessian"};
  spec.flags = {"--finite-difference", "--quiet", "--json", "--cold-refinement"};
  const ParsedOptions options("optimize", args, spec);
  const std::string path = options.singlePositional("the problem file");

  if (auto out = options.value("--out")) checkOutputIsNotInput("optimize", *out, {{"problem", path}});
  OptimalControlProblem problem = loadProblem(path);
  if (auto v = options.value("--knots")) {
    problem.knots = options.integer<int>("--knots", *v, 2, 100000);
  }
  if (auto v = options.value("--method")) {
    if (*v == "hermite_simpson") {
      problem.method = CollocationMethod::kHermiteSimpson;
    } else if (*v == "trapezoidal") {
      problem.method = CollocationMethod::kTrapezoidal;
    } else if (*v == "radau") {
      problem.method = CollocationMethod::kRadau;
    } else {
      throw UsageError("optimize: --method: '" + *v + "' (expected hermite_simpson, trapezoidal or radau)");
    }
  }
  OptimizerOptions solver;
  if (auto v = options.value("--max-iter")) solver.maxIterations = options.integer<int>("--max-iter", *v, 0);
  if (auto v = options.value("--tol")) solver.tolerance = options.positiveNumber("--tol", *v);
  if (auto v = options.value("--print-level")) {
    solver.printLevel = options.integer<int>("--print-level", *v, 0, 12);
  }
  if (auto v = options.value("--consistency-tol")) {
    solver.consistencyTolerance = options.numberInRange(
        "--consistency-tol", *v, 1e-12, 0.5, "a defect relative to each state's range: above, any trajectory passes");
  }
  if (auto v = options.value("--max-refinements")) {
    solver.maxRefinements = options.integer<int>("--max-refinements", *v, 0, 50);
  }
  if (options.flag("--finite-difference")) solver.derivatives = DerivativeMode::kFiniteDifference;
  if (auto v = options.value("--hessian")) {
    try {
      solver.hessian = parseEnum<HessianMode>(*v, "optimize: --hessian");
    } catch (const std::invalid_argument& e) {
      throw UsageError(e.what());
    }
  }
  if (options.flag("--cold-refinement")) solver.warmStart = false;
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

  // Ipopt's own log (--print-level > 0) is written to the process's standard output by Ipopt;
  // standard output carries the summary or the JSON object, so the log goes to standard error:
  // descriptor 1 points at descriptor 2 for the solve, then back.
  struct StdoutToStderr {
    int saved = -1;
    explicit StdoutToStderr(bool active) {
      std::fflush(stdout);
      if (active && (saved = ::dup(STDOUT_FILENO)) >= 0) ::dup2(STDERR_FILENO, STDOUT_FILENO);
    }
    ~StdoutToStderr() {
      if (saved < 0) return;
      std::fflush(stdout);
      ::dup2(saved, STDOUT_FILENO);
      ::close(saved);
    }
  };
  const OptimizationResult result = [&] {
    const StdoutToStderr redirect(solver.printLevel > 0);
    return optimizeTrajectory(problem, solver);
  }();
  const auto outPath = options.value("--out");
  if (outPath) result.trajectory.writeCsvFile(*outPath);

  const char* methodName =
      problem.method == CollocationMethod::kHermiteSimpson ? "hermite_simpson"
      : problem.method == CollocationMethod::kRadau        ? "radau"
                                                           : "trapezoidal";
  const char* derivativesName =
      solver.derivatives == DerivativeMode::kExact ? "exact" : "finite_difference";
  if (options.flag("--json")) {
    // The result's own report (OptimizationResult::json) with what only the command knows.
    OutputJson j = OutputJson::parse(result.json());
    j["method"] = methodName;
    j["derivatives"] = derivativesName;
    j["trajectory"] = outPath ? OutputJson(*outPath) : OutputJson(nullptr);
    writeJson(out, j, true);
    if (!result.ok()) {
      std::cerr << "trellis: optimize: " << result.status.describe() << '\n';
      return result.status.code == OptimizationCode::kInconsistent ? 4 : 3;
    }
    return 0;
  }
  out << "status: " << result.status.name() << '\n'
      << "ipopt_status: " << result.ipoptStatus << '\n'
      << "iterations: " << result.iterations << '\n'
      << "cost: " << formatNumber(result.cost, 10) << '\n'
      << "constraint_violation: " << formatNumber(result.constraintViolation, 3) << '\n'
      << "bound_violation: " << formatNumber(result.boundViolation, 3) << '\n'
      << "max_slack: " << formatNumber(result.maxSlack, 3) << '\n'
      << "horizon: " << formatNumber(result.horizon, 10) << '\n'
      << "knots: " << result.trajectory.size() << '\n'
      << "method: " << methodName << '\n'
      << "derivatives: " << derivativesName << '\n'
      << "hessian: " << toString(result.hessian) << '\n'
      << "consistency_defect: "
      << (result.consistency.checked() ? formatNumber(result.consistency.maxDefect, 3)
                                        : std::string("not checked (the solve or the integration failed first)"))
      << '\n';
  if (result.consistency.worstInterval >= 0 && result.consistency.checked()) {
    out << "consistency_where: " << result.consistency.worstStateName << " on interval "
        << result.consistency.worstInterval << " at t = " << formatNumber(result.consistency.worstTime, 6)
        << '\n';
  }
  if (problem.model->nc() > 0) out << "slack_defect: " << formatNumber(result.maxSlackDefect, 3) << '\n';
  out << "refinement_rounds: " << (result.rounds.empty() ? 0 : result.rounds.size() - 1) << '\n';
  for (std::size_t k = 0; k < result.rounds.size(); ++k) {
    const RefinementRound& r = result.rounds[k];
    out << "round_" << k << ": knots " << r.knots << ", iterations " << r.iterations << ", defect "
        << formatNumber(r.maxDefect, 3) << '\n';
  }
  out << "solve_time_ms: " << formatNumber(1e3 * result.solveTime, 4) << '\n'
      << "solve_cpu_time_ms: " << formatNumber(1e3 * result.solveCpuTime, 4) << '\n'
      << "evaluation_time_ms: " << formatNumber(1e3 * result.evaluationTime, 4) << '\n'
      << "hessian_time_ms: " << formatNumber(1e3 * result.hessianTime, 4) << '\n'
      << "check_time_ms: " << formatNumber(1e3 * result.checkTime, 4) << '\n';
  if (outPath) out << "trajectory: " << *outPath << '\n';
  if (!result.hessianNote.empty()) out << "hessian_note: " << result.hessianNote << '\n';
  if (!result.ok()) {
    std::cerr << "trellis: optimize: " << result.status.describe() << '\n';
    return result.status.code == OptimizationCode::kInconsistent ? 4 : 3;
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
