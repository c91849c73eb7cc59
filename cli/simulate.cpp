// cli/simulate.cpp — `trellis simulate SCENE.json --trajectory TRAJ.csv --gains GAINS.csv
// --out CLOSED.csv`: the nonlinear closed loop u = u_ref − K(t)(x − x_ref) from a perturbed start.
#include "cli_options.hpp"
#include "command.hpp"
#include "model_questions.hpp"

#include "trellis/core/gain_schedule.hpp"
#include "trellis/analysis/simulation.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/control/tvlqr.hpp"
#include "trellis/core/scene.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <algorithm>
#include <cstdint>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis simulate SCENE.json --trajectory TRAJ.csv --gains GAINS.csv --out CLOSED.csv
                        [--perturb NAME=VALUE,...] [--perturb-random SIGMA [--seed N]] [options]
       trellis simulate SCENE.json --hold T [--state STATE.json] --gains GAINS.csv --out CLOSED.csv
                        [--perturb ...] [options]

Simulates the NONLINEAR scene (SCENE_FORMAT.md) under the time-varying feedback

  u = sat( u_ref(t) - K(t) (x - x_ref(t)) ),   x = [q; q'],

along the reference trajectory (x_ref: cubic Hermite through its knots; u_ref linear between
knots, or cubic Hermite when the file has rate_<input> columns; K linear between gain times, or
cubic with interpolation=cubic in its metadata line), from x(t0) = x_ref(t0) + dx0, over the reference's time span,
with SUNDIALS CVODES. GAINS.csv is a gain schedule as `trellis gains` writes it (header
t,K[<input>|<state>],... or the older t,K_<input>_<state>,..., checked against the scene's names;
K is m x 2n and must cover the reference's time span). sat clips u to [--umin, --umax].

Sampled gains: a file from `trellis gains --rate HZ` holds zero-order-hold gains for a controller
sampling at HZ; it is applied only with the same --rate. What the sampled controller applies: at
each sample t_k = t0 + k/HZ it measures x(t_k) and holds, until t_{k+1},
  u_k = sat( uff_k - K_k (x(t_k) - x_ref(t_k)) ),
uff_k the file's feed-forward column uff[<input>] (the held input that carries the reference from
t_k to t_{k+1} through the exact dynamics, see `trellis gains --help`); a file without those
columns (older files, or gains --feedforward reference) gives uff_k = u_ref(t_k), the reference's
input sampled at t_k, which lets even an unperturbed loop drift from the reference by
O(h^2 |u_ref'|) per sample. Running sampled gains continuously or at another rate is refused.
Continuous gains with --rate are sampled, with uff_k = u_ref(t_k) (a warning on standard error
says so: they were not designed for that rate). The summary names the feed-forward used.

Balancing a pose (--hold T instead of --trajectory): the reference is the held pose that
`trellis gains --hold T` builds -- the pose q of the scene's stored state (or of --state) at
rest over [0, T] with the inputs that hold it (on the constraints, for a scene with them) -- so
  trellis gains SCENE --hold 10 --rate 100 --infinite-horizon --out G.csv
  trellis simulate SCENE --hold 10 --rate 100 --gains G.csv --perturb q1=0.1 --out C.csv
balances the pose at 100 Hz from the command line alone. The gains must cover [0, T].

Perturbation dx0 (the sum of both; default none):
  --perturb NAME=VALUE[,NAME=VALUE...]   add VALUE to the state NAME, a column name of the
                                         trajectory (a configuration or d<configuration>);
                                         may be repeated
  --perturb-random SIGMA                 add independent normal deviates of standard deviation
                                         SIGMA to every state, from --seed N (default 1;
                                         Mersenne Twister 64 and Box-Muller: the same seed gives
                                         the same perturbation on every platform)
For a scene with constraints the perturbed start is projected onto the constraints h(q) = 0,
A(q) q' = 0 (least mass-weighted change), and so is the state at every integration segment end
(knots, gain times, samples), unless --no-project.

Output (--out): the closed-loop trajectory in the trajectory layout (t, <configs>,
d<configs>, <inputs>; the inputs are the applied, saturated u), at the reference's knots or every
--output-step. Then a summary on standard output: the perturbation, the tracking error
|x - x_ref| (2-norm over the full state) at the start, at the end and its maximum, the constraint
drift max(|h|, |A q'|) (before projection), the saturation (control evaluations with a clipped
input), and the integrator's work; with --json one JSON object instead.

options:
  --trajectory FILE      the reference trajectory (CSV; required unless --hold)
  --hold T               instead of --trajectory: the held pose over [0, T] (see above)
  --state FILE           with --hold: the pose (a state object, see `trellis linearize --help`)
  --gains FILE           the gain schedule (CSV; required)
  --out FILE             where to write the closed-loop trajectory (CSV; required)
  --perturb ...          see above
  --perturb-random SIGMA see above (SIGMA >= 0)
  --seed N               seed of --perturb-random (default 1)
  --rate HZ              sampled feedback: u computed at t0 + k/HZ and held (default:
                         continuous feedback); must equal the rate of sampled gains
  --json                 print the summary as one JSON object
  --umin U, --umax U     input bounds: one number for every input or a comma list of m
                         (default: unbounded)
  --no-project           do not project onto the constraints (the drift is still reported)
  --output-step DT       output every DT (default: at the reference's knots)
  --rtol X, --atol X     CVODES tolerances (defaults 1e-8, 1e-10)
  --method M             adams (default; non-stiff), bdf (stiff: stiff springs, high gains) or
                         radau (Radau IIA, stiff too; keeps its step across the samples of --rate)
  --max-steps N          limit on the integrator's internal steps (default 500000)
  -h, --help             show this help

Exit status: 0 on success; 1 if a file cannot be read or does not match the scene (trajectory
names, gain size or time span) or the simulation fails (the message gives the time and the
cause; the trajectory up to the failure is still written to --out); 2 on a usage error (unknown
option or state name, malformed number, missing file argument). Errors are one line on standard
error and nothing on standard output.
)";

/// Standard normal deviates by Box–Muller from a 64-bit Mersenne Twister, whose output sequence
/// the C++ standard fixes (std::normal_distribution's algorithm is implementation-defined).
class PortableNormal {
 public:
  explicit PortableNormal(std::uint64_t seed) : engine_(seed) {}
  double operator()() {
    if (haveSpare_) {
      haveSpare_ = false;
      return spare_;
    }
    // u1 in (0, 1] (log is finite), u2 in [0, 1): 53 random bits each.
    const double u1 = (static_cast<double>(engine_() >> 11) + 1.0) * 0x1.0p-53;
    const double u2 = static_cast<double>(engine_() >> 11) * 0x1.0p-53;
    const double radius = std::sqrt(-2.0 * std::log(u1));
    spare_ = radius * std::sin(2.0 * std::numbers::pi * u2);
    haveSpare_ = true;
    return radius * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  std::mt19937_64 engine_;
  double spare_ = 0.0;
  bool haveSpare_ = false;
};

/// δx0 from the --perturb items (names from the trajectory's header: configs, d<configs>).
Eigen::VectorXd namedPerturbation(const ParsedOptions& options, const Trajectory& reference) {
  std::vector<std::string> names = reference.configNames();
  for (const std::string& c : reference.configNames()) names.push_back("d" + c);
  Eigen::VectorXd delta = Eigen::VectorXd::Zero(reference.nx());
  std::vector<bool> seen(names.size(), false);
  for (const std::string& list : options.values("--perturb")) {
    std::size_t start = 0;
    while (true) {
      const std::size_t comma = list.find(',', start);
      const std::string item = list.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      const std::size_t equals = item.find('=');
      if (equals == std::string::npos || equals == 0) {
        throw UsageError("simulate: --perturb: '" + item + "' is not NAME=VALUE");
      }
      const std::string name = item.substr(0, equals);
      const auto it = std::find(names.begin(), names.end(), name);
      if (it == names.end()) {
        throw UsageError("simulate: --perturb: unknown state '" + name + "' (the states are " +
                         joinNames(names) + ")");
      }
      const auto index = static_cast<std::size_t>(it - names.begin());
      if (seen[index]) throw UsageError("simulate: --perturb: state '" + name + "' given more than once");
      seen[index] = true;
      delta(static_cast<Eigen::Index>(index)) = options.number("--perturb " + name, item.substr(equals + 1));
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
  }
  return delta;
}

int runSimulate(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options(
      "simulate", args,
      {.valued = {"--trajectory", "--gains", "--out", "--perturb", "--perturb-random", "--seed", "--rate",
                  "--umin", "--umax", "--output-step", "--rtol", "--atol", "--method", "--max-steps", "--hold",
                  "--state"},
       .flags = {"--no-project", "--json"},
       .repeatable = {"--perturb"}});
  const std::string scenePath = options.singlePositional("scene file");
  if (options.has("--hold") && options.has("--trajectory")) {
    throw UsageError("simulate: --hold and --trajectory exclude each other (--hold makes the reference)");
  }
  if (options.has("--state") && !options.has("--hold")) {
    throw UsageError("simulate: --state applies to --hold only (the reference comes from --trajectory)");
  }
  const bool hold = options.has("--hold");
  const double holdSpan = hold ? options.positiveNumber("--hold", *options.value("--hold")) : 0.0;
  const std::string trajectoryPath =
      hold ? std::string("the held pose") : options.required("--trajectory", "(the reference trajectory CSV, or --hold T)");
  const std::string gainsPath = options.required("--gains", "(the gain schedule CSV from 'trellis gains')");
  const std::string outPath = options.required("--out", "(the closed-loop trajectory CSV to write)");
  {
    std::vector<std::pair<std::string, std::string>> inputs{{"scene", scenePath}, {"--gains", gainsPath}};
    if (!hold) inputs.emplace_back("--trajectory", trajectoryPath);
    if (auto v = options.value("--state")) inputs.emplace_back("--state", *v);
    checkOutputIsNotInput("simulate", outPath, inputs);
  }

  SimulationOptions simulation;
  if (auto v = options.value("--rtol")) simulation.rtol = options.relativeTolerance("--rtol", *v);
  if (auto v = options.value("--atol")) simulation.atol = options.absoluteTolerance("--atol", *v);
  if (auto v = options.value("--rate")) simulation.sampleRate = options.positiveNumber("--rate", *v);
  if (auto v = options.value("--output-step")) simulation.outputStep = options.positiveNumber("--output-step", *v);
  if (auto v = options.value("--max-steps")) simulation.maxSteps = options.integer<long>("--max-steps", *v, 1);
  if (auto v = options.value("--method")) {
    try {
      simulation.method = parseEnum<IntegrationMethod>(*v, "--method");
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("simulate: ") + e.what());
    }
  }
  if (options.flag("--no-project")) simulation.constraints = ConstraintHandling::kNone;
  double sigma = 0.0;
  if (auto v = options.value("--perturb-random")) sigma = options.positiveNumber("--perturb-random", *v, true);
  std::uint64_t seed = 1;
  if (auto v = options.value("--seed")) {
    if (!options.has("--perturb-random")) throw UsageError("simulate: --seed needs --perturb-random");
    seed = options.integer<std::uint64_t>("--seed", *v);
  }

  const LoadedScene loaded = loadSceneArgument(scenePath);
  const Model& model = loaded.scene.model;
  const int n = model.nq(), m = model.nu(), nx = 2 * n;
  const Trajectory reference = hold ? heldPoseReference(loaded, options.value("--state"), holdSpan, "simulate --hold")
                                    : loadReference(model, scenePath, trajectoryPath);
  const double span = reference.endTime() - reference.startTime();
  if (simulation.outputStep > 0.0) options.gridPoints("--output-step", simulation.outputStep, span, kMaxOutputRows, "output rows");
  if (simulation.sampleRate > 0.0) options.gridPoints("--rate", 1.0 / simulation.sampleRate, span, kMaxFeedbackSamples, "feedback samples");
  const GainSchedule gains = GainSchedule::readCsvFile(gainsPath);
  // The library's applicability check (core/gain_schedule.hpp): names, rate, alignment, span.
  const std::string note =
      checkGainScheduleApplies(gains, model, reference, simulation.sampleRate, gainsPath + " (for the scene " + scenePath + ")");
  if (!note.empty()) {
    std::cerr << "simulate: warning: " << note << "; trellis gains --rate " << formatNumber(simulation.sampleRate)
              << " computes gains for it\n";
  }

  if (options.has("--umin") || options.has("--umax")) {
    const double inf = std::numeric_limits<double>::infinity();
    simulation.inputLower = options.value("--umin")
                                ? options.broadcastList("--umin", *options.value("--umin"), m, "inputs")
                                : Eigen::VectorXd::Constant(m, -inf);
    simulation.inputUpper = options.value("--umax")
                                ? options.broadcastList("--umax", *options.value("--umax"), m, "inputs")
                                : Eigen::VectorXd::Constant(m, inf);
    for (int i = 0; i < m; ++i) {
      if (!(simulation.inputLower(i) <= simulation.inputUpper(i))) {
        throw UsageError("simulate: input '" + model.inputNames()[static_cast<std::size_t>(i)] + "': --umin " +
                         formatNumber(simulation.inputLower(i), 17) + " > --umax " +
                         formatNumber(simulation.inputUpper(i), 17));
      }
    }
  }

  Eigen::VectorXd delta = namedPerturbation(options, reference);
  if (sigma > 0.0) {
    PortableNormal normal(seed);
    for (int i = 0; i < nx; ++i) delta(i) += sigma * normal();
  }
  const Eigen::VectorXd x0 = reference.state(reference.startTime()) + delta;
  if (!x0.allFinite()) throw UsageError("simulate: the perturbed start x_ref(t0) + dx0 is not finite (--perturb, --perturb-random)");

  const SimulationResult result = simulateClosedLoop(model, reference, gains, x0, simulation);
  if (result.trajectory.size() > 0) result.trajectory.writeCsvFile(outPath);
  if (!result.ok()) {
    throw std::runtime_error("simulate: the closed loop failed (" + std::string(result.status.name()) +
                             ") at t = " + formatNumber(result.status.t) + ": " + result.status.message +
                             (result.trajectory.size() > 0 ? " (the trajectory up to t = " +
                                                                 formatNumber(result.trajectory.endTime()) +
                                                                 " is in " + outPath + ")"
                                                           : ""));
  }

  // The summary, after the file is written.
  if (options.flag("--json")) {
    // The library's report, and what only the command knows, with the JSON library.
    nlohmann::ordered_json report = nlohmann::ordered_json::parse(result.json());
    const auto number = [](double v) { return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(); };
    report["out"] = outPath;
    report["sample_rate_hz"] = number(simulation.sampleRate);
    report["gains_sample_rate_hz"] = number(gains.sampleRate());
    report["feedforward"] = simulation.sampleRate > 0.0 ? (gains.hasFeedforward() ? "gain_file" : "reference_sampled") : "reference";
    report["perturbation_norm"] = number(delta.norm());
    out << report.dump() << "\n";
    return 0;
  }
  const Eigen::VectorXd& error = result.trackingError;
  Eigen::Index worst = 0;
  error.maxCoeff(&worst);
  out << "wrote " << outPath << ": " << result.trajectory.size() << " rows on ["
      << formatNumber(result.trajectory.startTime()) << ", " << formatNumber(result.trajectory.endTime())
      << "], feedback "
      << (simulation.sampleRate > 0.0 ? "sampled at " + formatNumber(simulation.sampleRate) + " Hz" : "continuous")
      << (simulation.sampleRate > 0.0 ? (gains.hasFeedforward() ? ", feed-forward uff_k from the gain file"
                                                                  : ", feed-forward u_ref(t_k) (the gain file has none)")
                                      : std::string())
      << "\n";
  out << "perturbation: |dx0| = " << formatNumber(delta.stableNorm()) << "\n";  // no overflow of the squares
  out << "tracking error |x - x_ref|: initial " << formatNumber(error(0)) << ", final "
      << formatNumber(error(error.size() - 1)) << ", max " << formatNumber(error(worst)) << " (at t = "
      << formatNumber(result.trajectory.times()(worst)) << ")\n";
  if (model.nc() > 0) {
    // The drift at t0 is that of the perturbed start itself; after it, that of the integration.
    const Eigen::VectorXd& drift = result.constraintDrift;
    const double later = drift.size() > 1 ? drift.tail(drift.size() - 1).maxCoeff() : 0.0;
    out << "constraint drift max(|h|, |A dq|): at the start " << formatNumber(drift(0), 3)
        << ", max at later output times " << formatNumber(later, 3) << ", max overall "
        << formatNumber(result.maxConstraintDrift, 3)
        << (simulation.constraints == ConstraintHandling::kProject
                ? " (before projection; " + std::to_string(result.projections) + " projections)"
                : " (not projected)")
        << "\n";
  } else {
    out << "constraint drift: none (the scene has no constraints)\n";
  }
  out << "saturation: " << result.saturatedSamples << " of " << result.controlSamples
      << " control evaluations clipped (" << formatNumber(100.0 * result.saturatedFraction, 3) << "%)"
      << (simulation.inputLower.size() == 0 ? ", no bounds" : "") << "\n";
  out << "integrator: " << result.steps << " steps, " << result.rhsEvaluations << " right-hand-side evaluations, "
      << result.restarts << " restarts\n";
  return 0;
}

}  // namespace

const Command kSimulateCommand{
    "simulate",
    "the nonlinear closed loop of a gain schedule about a reference, from a perturbed start",
    kHelp,
    &runSimulate,
};

const CommandRegistration kRegisterSimulate{kSimulateCommand};

}  // namespace trellis::cli
