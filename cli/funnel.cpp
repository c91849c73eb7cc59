// cli/funnel.cpp — `trellis funnel SCENE --trajectory T.csv --gains G.csv --cost-to-go S.csv
// --levels ... --out FUNNEL.csv`: how far the feedback holds, estimated from many closed loops
// (a thin layer over trellis::FunnelProblem, analysis/funnel.hpp; on threads, or over MPI ranks
// with trellis-mpi).
#include "cli_options.hpp"
#include "command.hpp"
#include "funnel_command.hpp"
#include "json_output.hpp"
#include "model_questions.hpp"

#include "trellis/analysis/funnel.hpp"
#include "trellis/core/gain_schedule.hpp"
#include "trellis/core/io.hpp"
#include "trellis/core/model.hpp"
#include "trellis/core/trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace trellis::cli {

namespace {

const FunnelDistribution* gDistribution = nullptr;

constexpr std::string_view kHelp = R"(usage: trellis funnel SCENE.json --trajectory TRAJ.csv --gains GAINS.csv --cost-to-go S.csv
                      (--levels R1,R2,... | --level-range LO,HI,COUNT) --out FUNNEL.csv
                      [--samples N] [--seed S] [--threads T] [--start-knots K1,K2,...] [options]
       mpirun -n K trellis-mpi funnel ...   (the same command over K processes; docs/funnels.md)

How far does the feedback hold? Estimates a funnel (region of attraction along the reference) of
the closed loop u = sat(u_ref(t) - K(t)(x - x_ref(t))) by simulating many perturbed starts in the
NONLINEAR scene (as `trellis simulate` does), measured in the Lyapunov candidate

  V(t, dx) = dx^T S(t) dx,   S: the Riccati cost-to-go of the gains (`trellis gains --cost-to-go`)

(for a scene with constraints S lives on the tangent space of the constraint manifold).

For each start time t_s (the reference's start, or the knots of --start-knots) and each tested
level rho, N starts x0 = x_ref(t_s) + dx are drawn on the level set V(t_s, dx) = rho (a direction
uniform on the unit sphere of the S-metric), each simulated from t_s to the reference's end T with
the input clipped to [--umin, --umax] and the constraints projected. A start SUCCEEDS when the
simulation is ok and V(T, x(T) - x_ref(T)) <= --goal (default: the smallest tested level).

Sample g = (start·L + level)·N + i draws its direction from a generator keyed by (--seed, g) only:
the output is bit-identical for any --threads and any number of MPI ranks (rank r of K runs the
samples r, r + K, r + 2K, ...).

Output (--out), a CSV:
  # trellis funnel: samples=N seed=S goal_level=... confidence=0.95 failure_bound=... feedback=...
  # rho t=T_S rho=R                    (per start time; see below)
  # worst failing start t=... level=... index=... code=... final_level=... perturb=NAME=V,...
  t,level,samples,successes,failures,clean
one row per (start time, level); clean = 1 when no start failed at this level or any lower one.
rho(t_s) is the largest clean level (0 when the lowest fails). With N samples and no failure a
level's failing fraction (of its level set) is below failure_bound = 1 - (1 - c)^(1/N) with
confidence c (about 3/N at c = 0.95). The worst failing start (the lowest level's first failure)
at the reference's start is reproduced by the printed `trellis simulate ... --perturb ...`.
Then a summary on standard output (with --json one JSON object).

options:
  --trajectory FILE      the reference trajectory (CSV; required)
  --gains FILE           the gain schedule (CSV from `trellis gains`; required)
  --cost-to-go FILE      S(t) (CSV from `trellis gains --cost-to-go`; required)
  --out FILE             the funnel table (CSV; required)
  --levels LIST          tested levels rho (increasing, finite, > 0)
  --level-range LO,HI,C  C levels spaced geometrically from LO to HI
  --samples N            starts per start time and level (default 100)
  --seed S               key of the random streams (default 1)
  --threads T            worker threads (default 0: one per hardware thread)
  --start-knots LIST     knot indices of the reference to start from (default 0)
  --goal RHO_F           success needs V(T) <= RHO_F (default: the smallest level)
  --confidence C         of the stated bound (default 0.95)
  --rate HZ              sampled feedback (as `trellis simulate --rate`)
  --umin U, --umax U     input bounds: one number or a comma list of m (default unbounded)
  --no-project           do not project onto the constraints
  --drift-tolerance D    constraint drift tolerated before projecting, and after it (a start whose
                         drift stays above D fails); default 10 (atol + rtol)
  --rtol X, --atol X     CVODES tolerances (defaults 1e-8, 1e-10)
  --method M             adams (default), bdf or radau (as `trellis simulate --method`)
  --max-steps N          integrator steps per closed loop (default 500000)
  --samples-out FILE     every sample: index, t, level, success, code, final_level, dx0 (CSV)
  --plot FILE.svg        the funnel over time, projected on --plot-states (SVG)
  --plot-states LIST     state names for --plot (default: the configurations, at most 4)
  --json                 print the summary as one JSON object
  -h, --help             show this help

Exit status: 0 when every sample ran (failing starts are results); 1 if a file cannot be read or
does not match the scene (names, sizes, spans: a trajectory, gains and S of different scenes are
refused), a sample could not be run, or an MPI rank failed (nothing is written then); 2 on a
usage error (no levels, a level that is not finite, zero samples, more MPI ranks than samples).
)";

std::string num17(double v) { return formatNumber(v, 17); }

/// The --perturb argument of `trellis simulate` for δx.
std::string perturbArgument(const std::vector<std::string>& names, const Eigen::VectorXd& dx) {
  std::string text;
  for (Eigen::Index i = 0; i < dx.size(); ++i) {
    text += (i ? "," : "") + names[static_cast<std::size_t>(i)] + "=" + num17(dx(i));
  }
  return text;
}

std::string funnelTable(const FunnelResult& r, const FunnelOptions& options, const std::vector<std::string>& names) {
  std::ostringstream out;
  out << "# trellis funnel: samples=" << options.samples << " seed=" << options.seed
      << " goal_level=" << num17(r.goalLevel) << " confidence=" << num17(r.confidence)
      << " failure_bound=" << num17(r.failureBound) << " feedback="
      << (options.simulation.sampleRate > 0.0 ? "sampled_hz=" + num17(options.simulation.sampleRate) : std::string("continuous"))
      << "\n";
  for (std::size_t s = 0; s < r.startTimes.size(); ++s) {
    out << "# rho t=" << num17(r.startTimes[s]) << " rho=" << num17(r.rho(static_cast<Eigen::Index>(s))) << "\n";
  }
  for (std::size_t s = 0; s < r.startTimes.size(); ++s) {
    const long g = r.worstFailure[s];
    if (g < 0) continue;
    const FunnelSample& w = r.samples[static_cast<std::size_t>(g)];
    out << "# worst failing start t=" << num17(r.startTimes[s]) << " level=" << num17(r.levels[static_cast<std::size_t>(w.level)])
        << " index=" << w.index << " code=" << toString(w.code) << " final_level=" << num17(w.finalLevel)
        << " perturb=" << perturbArgument(names, w.dx0) << "\n";
  }
  out << "t,level,samples,successes,failures,clean\n";
  for (std::size_t s = 0; s < r.startTimes.size(); ++s) {
    bool clean = true;
    for (std::size_t j = 0; j < r.levels.size(); ++j) {
      const FunnelCell& c = r.cells[s * r.levels.size() + j];
      clean = clean && c.successes == c.samples;
      out << num17(c.t) << "," << num17(c.level) << "," << c.samples << "," << c.successes << ","
          << c.samples - c.successes << "," << (clean ? 1 : 0) << "\n";
    }
  }
  return out.str();
}

std::string samplesTable(const FunnelResult& r, const std::vector<std::string>& names) {
  std::ostringstream out;
  out << "index,t,level,success,code,final_level";
  for (const std::string& n : names) out << ",dx_" << n;
  out << "\n";
  for (const FunnelSample& s : r.samples) {
    out << s.index << "," << num17(r.startTimes[static_cast<std::size_t>(s.start)]) << ","
        << num17(r.levels[static_cast<std::size_t>(s.level)]) << "," << (s.success ? 1 : 0) << "," << toString(s.code)
        << "," << num17(s.finalLevel);
    for (Eigen::Index i = 0; i < s.dx0.size(); ++i) out << "," << num17(s.dx0(i));
    out << "\n";
  }
  return out.str();
}

/// The funnel over time, one panel per chosen state: the reference x_ref,i(t), the band
/// x_ref,i(t_s) ± the level set's extent at ρ(t_s) (a polygon through the start times, a bar for
/// one), and the sampled starts at their start time (green: succeeded, red: failed).
/// units[i]: state i's unit (rad or m, rad/s or m/s: the scene's lengths are metres).
std::string funnelSvg(const FunnelProblem& problem, const FunnelResult& r, const Trajectory& reference,
                      const std::vector<int>& states, const std::vector<std::string>& names,
                      const std::vector<std::string>& units) {
  const double width = 760, panel = 220, left = 130, right = 20, top = 30;
  const double t0 = reference.startTime(), T = reference.endTime();
  std::ostringstream out;
  out << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\""
      << top + panel * static_cast<double>(states.size()) + 10 << "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  out << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  out << "<text x=\"" << left << "\" y=\"18\">funnel: rho(t) with no failure in " << r.cells.front().samples
      << " samples per level (band), sampled starts (green ok, red failed)</text>\n";
  for (std::size_t p = 0; p < states.size(); ++p) {
    const int i = states[p];
    const double y0 = top + panel * static_cast<double>(p), h = panel - 40;
    // Value range: the reference, the band and the starts at the largest level.
    double lo = reference.states().row(i).minCoeff(), hi = reference.states().row(i).maxCoeff();
    std::vector<double> centre(r.startTimes.size()), half(r.startTimes.size()), reach(r.startTimes.size());
    for (std::size_t s = 0; s < r.startTimes.size(); ++s) {
      centre[s] = problem.reference(static_cast<int>(s)).states()(i, 0);
      const double rho = r.rho(static_cast<Eigen::Index>(s));
      half[s] = rho > 0.0 ? problem.extent(static_cast<int>(s), rho)(i) : 0.0;
      reach[s] = problem.extent(static_cast<int>(s), r.levels.back())(i);
      lo = std::min(lo, centre[s] - reach[s]);
      hi = std::max(hi, centre[s] + reach[s]);
    }
    if (!(hi > lo)) hi = lo + 1.0;
    const auto X = [&](double t) { return left + (width - left - right) * (T > t0 ? (t - t0) / (T - t0) : 0.0); };
    const auto Y = [&](double v) { return y0 + 10 + h * (1.0 - (v - lo) / (hi - lo)); };
    out << "<rect x=\"" << left << "\" y=\"" << y0 + 10 << "\" width=\"" << width - left - right << "\" height=\"" << h
        << "\" fill=\"none\" stroke=\"#888\"/>\n";
    out << "<text x=\"4\" y=\"" << y0 + 10 + h / 2 + 16 << "\">" << names[static_cast<std::size_t>(i)] << " ["
        << units[static_cast<std::size_t>(i)] << "]</text>\n";
    out << "<text x=\"" << left - 4 << "\" y=\"" << y0 + 20 << "\" text-anchor=\"end\">" << formatNumber(hi, 3) << "</text>\n";
    out << "<text x=\"" << left - 4 << "\" y=\"" << y0 + 10 + h << "\" text-anchor=\"end\">" << formatNumber(lo, 3) << "</text>\n";
    out << "<text x=\"" << left << "\" y=\"" << y0 + h + 26 << "\">t = " << formatNumber(t0, 4) << " s</text>\n";
    out << "<text x=\"" << width - right << "\" y=\"" << y0 + h + 26 << "\" text-anchor=\"end\">t = " << formatNumber(T, 4)
        << " s</text>\n";
    if (r.startTimes.size() > 1) {
      out << "<polygon fill=\"#9ecae1\" fill-opacity=\"0.6\" stroke=\"none\" points=\"";
      for (std::size_t s = 0; s < r.startTimes.size(); ++s) out << X(r.startTimes[s]) << "," << Y(centre[s] + half[s]) << " ";
      for (std::size_t s = r.startTimes.size(); s-- > 0;) out << X(r.startTimes[s]) << "," << Y(centre[s] - half[s]) << " ";
      out << "\"/>\n";
    }
    for (std::size_t s = 0; s < r.startTimes.size(); ++s) {
      out << "<line x1=\"" << X(r.startTimes[s]) << "\" x2=\"" << X(r.startTimes[s]) << "\" y1=\"" << Y(centre[s] + half[s])
          << "\" y2=\"" << Y(centre[s] - half[s]) << "\" stroke=\"#3182bd\" stroke-width=\"4\"/>\n";
    }
    out << "<polyline fill=\"none\" stroke=\"black\" points=\"";
    for (Eigen::Index k = 0; k < reference.size(); ++k) out << X(reference.times()(k)) << "," << Y(reference.states()(i, k)) << " ";
    out << "\"/>\n";
    // At most 2000 starts per panel (evenly by index) keep the file small.
    // Successes first, failures over them (the failures are what a reader looks for).
    const std::size_t stride = std::max<std::size_t>(1, r.samples.size() / 2000);
    for (int pass = 0; pass < 2; ++pass)
    for (std::size_t k = 0; k < r.samples.size(); k += stride) {
      const FunnelSample& s = r.samples[k];
      if (s.success != (pass == 0)) continue;
      out << "<circle cx=\"" << X(r.startTimes[static_cast<std::size_t>(s.start)]) + 6 << "\" cy=\""
          << Y(centre[static_cast<std::size_t>(s.start)] + s.dx0(i)) << "\" r=\"1.5\" fill=\"" << (s.success ? "#31a354" : "#de2d26")
          << "\"/>\n";
    }
  }
  out << "</svg>\n";
  return out.str();
}

std::vector<double> geometricLevels(const ParsedOptions& options, const std::string& text) {
  const std::vector<double> items = options.numberList("--level-range", text);
  if (items.size() != 3) throw UsageError("funnel: --level-range: expected LO,HI,COUNT, got '" + text + "'");
  const double lo = items[0], hi = items[1], count = items[2];
  if (!(lo > 0.0) || !(hi > lo) || !(count >= 2.0) || count != std::floor(count) || count > 1000.0) {
    throw UsageError("funnel: --level-range: " + text + " needs 0 < LO < HI and an integer COUNT in [2, 1000]");
  }
  std::vector<double> levels;
  const int n = static_cast<int>(count);
  for (int k = 0; k < n; ++k) levels.push_back(k == n - 1 ? hi : lo * std::pow(hi / lo, static_cast<double>(k) / (n - 1)));
  return levels;
}

int runFunnel(std::span<const std::string> args, std::ostream& out) {
  const FunnelDistribution* distribution = gDistribution;
  const int rank = distribution ? distribution->rank : 0;
  const int ranks = distribution ? distribution->size : 1;

  // Set-up (every process the same); under MPI the processes agree on its outcome before sampling.
  std::optional<ParsedOptions> parsed;
  std::optional<LoadedScene> loaded;
  std::optional<Trajectory> reference;
  std::optional<GainSchedule> gains;
  std::optional<CostToGo> costToGo;
  std::optional<FunnelProblem> problem;
  FunnelOptions funnel;
  std::string scenePath, trajectoryPath, gainsPath, outPath;
  std::vector<std::string> names, units;
  std::vector<int> plotStates;
  long total = 0;
  try {
    parsed.emplace("funnel", args,
                   OptionSpec{.valued = {"--trajectory", "--gains", "--cost-to-go", "--out", "--levels", "--level-range",
                                         "--samples", "--seed", "--threads", "--start-knots", "--goal", "--confidence",
                                         "--rate", "--umin", "--umax", "--rtol", "--atol", "--method", "--max-steps",
                                         "--samples-out", "--plot", "--plot-states", "--drift-tolerance"},
                              .flags = {"--no-project", "--json"},
                              .repeatable = {}});
    const ParsedOptions& options = *parsed;
    scenePath = options.singlePositional("scene file");
    trajectoryPath = options.required("--trajectory", "(the reference trajectory CSV)");
    gainsPath = options.required("--gains", "(the gain schedule CSV from 'trellis gains')");
    const std::string costPath = options.required("--cost-to-go", "(S(t) from 'trellis gains --cost-to-go')");
    outPath = options.required("--out", "(the funnel table CSV to write)");
    const std::vector<std::pair<std::string, std::string>> inputs{
        {"scene", scenePath}, {"--trajectory", trajectoryPath}, {"--gains", gainsPath}, {"--cost-to-go", costPath}};
    checkOutputIsNotInput("funnel", outPath, inputs);
    for (const char* extra : {"--samples-out", "--plot"})
      if (auto v = options.value(extra)) checkOutputIsNotInput("funnel", *v, inputs);

    if (options.has("--levels") == options.has("--level-range")) {
      throw UsageError("funnel: give the tested levels by exactly one of --levels R1,R2,... or --level-range LO,HI,COUNT");
    }
    if (auto v = options.value("--levels")) {
      funnel.levels = parseNumberList("funnel", "--levels", *v);  // refuses nan, inf and malformed items
    } else {
      funnel.levels = geometricLevels(options, *options.value("--level-range"));
    }
    for (std::size_t j = 0; j < funnel.levels.size(); ++j) {
      if (!(funnel.levels[j] > 0.0) || (j > 0 && !(funnel.levels[j] > funnel.levels[j - 1]))) {
        throw UsageError("funnel: --levels: level " + std::to_string(j + 1) + " = " + num17(funnel.levels[j]) +
                         " (the levels must be > 0 and increasing)");
      }
    }
    if (auto v = options.value("--samples")) funnel.samples = options.integer<long>("--samples", *v, 1, 1'000'000'000);
    if (auto v = options.value("--seed")) funnel.seed = options.integer<std::uint64_t>("--seed", *v);
    if (auto v = options.value("--threads")) funnel.threads = options.integer<int>("--threads", *v, 0, 1024);
    if (auto v = options.value("--goal")) funnel.goalLevel = options.positiveNumber("--goal", *v);
    if (auto v = options.value("--confidence")) {
      funnel.confidence = options.numberInRange("--confidence", *v, 1e-6, 1.0 - 1e-9, "a probability in (0, 1)");
    }
    SimulationOptions& simulation = funnel.simulation;
    if (auto v = options.value("--rtol")) simulation.rtol = options.relativeTolerance("--rtol", *v);
    if (auto v = options.value("--atol")) simulation.atol = options.absoluteTolerance("--atol", *v);
    if (auto v = options.value("--rate")) simulation.sampleRate = options.positiveNumber("--rate", *v);
    if (auto v = options.value("--max-steps")) simulation.maxSteps = options.integer<long>("--max-steps", *v, 1);
    if (auto v = options.value("--method")) {
      try {
        simulation.method = parseEnum<IntegrationMethod>(*v, "--method");
      } catch (const std::invalid_argument& e) {
        throw UsageError(std::string("funnel: ") + e.what());
      }
    }
    if (options.flag("--no-project")) simulation.constraints = ConstraintHandling::kNone;
    if (auto v = options.value("--drift-tolerance")) {
      simulation.driftTolerance = options.positiveNumber("--drift-tolerance", *v, true);
    }

    loaded.emplace(loadSceneArgument(scenePath));
    const Model& model = loaded->scene.model;
    const int m = model.nu();
    if (m == 0) throw std::runtime_error(scenePath + ": the scene has no inputs: there is no feedback to test");
    reference.emplace(loadReference(model, scenePath, trajectoryPath));
    const double span = reference->endTime() - reference->startTime();
    if (simulation.sampleRate > 0.0) {
      options.gridPoints("--rate", 1.0 / simulation.sampleRate, span, kMaxFeedbackSamples, "feedback samples");
    }
    gains.emplace(GainSchedule::readCsvFile(gainsPath));
    const std::string note = checkGainScheduleApplies(*gains, model, *reference, simulation.sampleRate,
                                                      gainsPath + " (for the scene " + scenePath + ")");
    if (!note.empty() && rank == 0) std::cerr << "funnel: warning: " << note << "\n";
    names = GainSchedule::stateNames(model.configNames());
    units.resize(names.size());
    for (int j = 0; j < model.nq(); ++j) {
      const bool revolute = model.joints()[static_cast<std::size_t>(j)].revolute;
      units[static_cast<std::size_t>(j)] = revolute ? "rad" : "m";
      units[static_cast<std::size_t>(model.nq() + j)] = revolute ? "rad/s" : "m/s";
    }
    costToGo.emplace(CostToGo::readCsvFile(costPath));
    costToGo->checkNames(names, costPath + " (for the scene " + scenePath + ")");

    if (options.has("--umin") || options.has("--umax")) {
      const double inf = std::numeric_limits<double>::infinity();
      simulation.inputLower = options.value("--umin") ? options.broadcastList("--umin", *options.value("--umin"), m, "inputs")
                                                      : Eigen::VectorXd::Constant(m, -inf);
      simulation.inputUpper = options.value("--umax") ? options.broadcastList("--umax", *options.value("--umax"), m, "inputs")
                                                      : Eigen::VectorXd::Constant(m, inf);
      for (int i = 0; i < m; ++i) {
        if (!(simulation.inputLower(i) <= simulation.inputUpper(i))) {
          throw UsageError("funnel: input '" + model.inputNames()[static_cast<std::size_t>(i)] + "': --umin " +
                           num17(simulation.inputLower(i)) + " > --umax " + num17(simulation.inputUpper(i)));
        }
      }
    }
    if (auto v = options.value("--start-knots")) {
      for (double k : parseNumberList("funnel", "--start-knots", *v)) {
        if (k != std::floor(k) || k < 0 || k >= reference->size() - 1) {
          throw UsageError("funnel: --start-knots: " + num17(k) + " is not a knot index in [0, " +
                           std::to_string(reference->size() - 2) + "] (the last knot is the end)");
        }
        funnel.startTimes.push_back(reference->times()(static_cast<Eigen::Index>(k)));
      }
    }
    if (auto v = options.value("--plot-states")) {
      std::string list = *v;
      std::size_t start = 0;
      while (true) {
        const std::size_t comma = list.find(',', start);
        const std::string name = list.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        const auto it = std::find(names.begin(), names.end(), name);
        if (it == names.end()) {
          throw UsageError("funnel: --plot-states: unknown state '" + name + "' (the states are " + joinNames(names) + ")");
        }
        plotStates.push_back(static_cast<int>(it - names.begin()));
        if (comma == std::string::npos) break;
        start = comma + 1;
      }
    } else {
      for (int i = 0; i < std::min(model.nq(), 4); ++i) plotStates.push_back(i);
    }

    try {
      funnel.validate();
    } catch (const std::invalid_argument& e) {
      throw UsageError(e.what());
    }
    problem.emplace(model, *reference, *gains, *costToGo, funnel);
    total = problem->sampleCount();
    if (total < ranks) {
      throw UsageError("funnel: " + std::to_string(ranks) + " MPI ranks for " + std::to_string(total) +
                       " samples: every rank needs at least one (use at most " + std::to_string(total) + " ranks)");
    }
  } catch (const std::exception& e) {
    if (distribution) distribution->agree(std::string(e.what()));
    throw;
  }
  if (distribution) {
    const std::string others = distribution->agree("");
    if (!others.empty()) throw std::runtime_error("funnel: the set-up failed on another process: " + others);
  }

  // Sampling: this process's block on its threads; under MPI rank 0 gathers every block.
  std::vector<FunnelSample> samples;
  if (distribution) {
    std::vector<FunnelSample> local;
    std::string error;
    try {
      // Rank r runs the samples r, r + K, r + 2K, ...: the costly high levels are shared out.
      local = problem->run(rank, total, ranks);
    } catch (const std::exception& e) {
      error = "samples " + std::to_string(rank) + ", " + std::to_string(rank + ranks) + ", ... (every " +
              std::to_string(ranks) + "th below " + std::to_string(total) + "): " + e.what();
    }
    samples = distribution->gather(std::move(local), error);
    if (rank != 0) return 0;  // rank 0 writes
  } else {
    samples = problem->run(0, problem->sampleCount());
  }
  const FunnelResult result = problem->summarize(std::move(samples));
  const FunnelOptions& used = problem->options();

  writeFileAtomically(outPath, funnelTable(result, used, names));
  if (auto v = parsed->value("--samples-out")) writeFileAtomically(*v, samplesTable(result, names));
  if (auto v = parsed->value("--plot")) {
    writeFileAtomically(*v, funnelSvg(*problem, result, *reference, plotStates, names, units));
  }

  // The command that reproduces the worst failing start at the reference's start.
  std::string reproduce;
  if (!result.worstFailure.empty() && result.worstFailure[0] >= 0 && used.startTimes[0] == reference->startTime()) {
    const FunnelSample& w = result.samples[static_cast<std::size_t>(result.worstFailure[0])];
    const SimulationOptions& sim = used.simulation;
    reproduce = "trellis simulate " + scenePath + " --trajectory " + trajectoryPath + " --gains " + gainsPath +
                " --out CLOSED.csv --perturb " + perturbArgument(names, w.dx0);
    if (sim.sampleRate > 0.0) reproduce += " --rate " + num17(sim.sampleRate);
    if (auto v = parsed->value("--umin")) reproduce += " --umin " + *v;
    if (auto v = parsed->value("--umax")) reproduce += " --umax " + *v;
    if (auto v = parsed->value("--method")) reproduce += " --method " + *v;
    if (auto v = parsed->value("--rtol")) reproduce += " --rtol " + *v;
    if (auto v = parsed->value("--atol")) reproduce += " --atol " + *v;
    if (auto v = parsed->value("--max-steps")) reproduce += " --max-steps " + *v;
    if (parsed->has("--drift-tolerance")) reproduce += " (simulate has no --drift-tolerance: its default applies)";
    if (parsed->flag("--no-project")) reproduce += " --no-project";
  }
  if (parsed->flag("--json")) {
    OutputJson body = OutputJson::parse(result.json());
    body["out"] = outPath;
    body["samples_per_level"] = used.samples;
    body["seed"] = used.seed;
    body["ranks"] = ranks;
    body["reproduce"] = reproduce;
    writeJson(out, body, true);
    return 0;
  }
  out << "wrote " << outPath << ": " << result.describe();
  if (!reproduce.empty()) out << "worst failing start at t0 (level " << num17(result.levels[static_cast<std::size_t>(result.samples[static_cast<std::size_t>(result.worstFailure[0])].level)]) << "): " << reproduce << "\n";
  return 0;
}

}  // namespace

void setFunnelDistribution(const FunnelDistribution* distribution) { gDistribution = distribution; }

const Command kFunnelCommand{
    "funnel",
    "how far the feedback holds: a funnel estimated from many perturbed closed loops (threads, MPI)",
    kHelp,
    &runFunnel,
};

const CommandRegistration kRegisterFunnel{kFunnelCommand};

}  // namespace trellis::cli
