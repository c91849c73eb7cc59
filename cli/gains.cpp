// cli/gains.cpp — `trellis gains SCENE.json --trajectory TRAJ.csv --out GAINS.csv`: the TV-LQR
// feedback gain K(t) along a reference trajectory, as a CSV gain schedule (a thin layer over
// trellis::solveTvlqr: continuous, or sampled with --rate).
#include "cli_options.hpp"
#include "command.hpp"
#include "json_output.hpp"
#include "model_questions.hpp"
#include "weights.hpp"

#include "trellis/analysis/cost_to_go.hpp"
#include "trellis/control/controllability.hpp"
#include "trellis/core/gain_schedule.hpp"
#include "trellis/control/manifold_lqr.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/control/tvlqr.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/equilibrium.hpp"
#include "trellis/core/scene.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <stdexcept>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis gains SCENE.json --trajectory TRAJ.csv --out GAINS.csv [options]
       trellis gains SCENE.json --hold T [--state STATE.json] [--infinite-horizon]
                     [--write-reference REF.csv] --out GAINS.csv [options]

Time-varying LQR along a reference trajectory x_ref(t), u_ref(t) of the scene (SCENE_FORMAT.md):
with the exact linearization dx' = A(t) dx + B(t) du at the reference, x = [q; q'] (2n states,
m inputs), the feedback du = -K(t) dx minimizes

  J = integral_{t0}^{T} dx^T Q dx + du^T R du dt + dx(T)^T Qf dx(T),

K = R^-1 B^T S with S the solution of the Riccati equation
  -S' = A^T S + S A - S B R^-1 B^T S + Q,   S(T) = Qf,
integrated backward with SUNDIALS CVODES. For a scene WITH constraints the directions that leave
the constraint manifold cannot be steered, so the problem is solved on its tangent space: with
an orthonormal basis T(t) (2n x d) transported along the reference, Ar = T^T A T, Br = T^T B,
Qr = T^T Q T, and K = Kr T^T (the gain ignores off-manifold deviations).

The trajectory file has one row per knot: t, <configs>, d<configs>, <inputs> (the layout
`trellis simulate --out` writes); its names must equal the scene's, in order. Optional columns
rate_<input> after the inputs (one per input) give du/dt at the knots: u_ref(t) is then the cubic
Hermite spline through them instead of linear between knots.

Holding a pose (--hold T, no trajectory file; a URDF works as it is): the reference is the pose q
of the scene's stored state (or of --state; its velocities are ignored) at rest over [0, T], with
the inputs that hold it still (as `trellis equilibrium --hold`: B_u u + A^T lambda = b(q), least
squares of minimum norm; the command fails if no inputs hold the pose exactly), 101 knots. On a
scene with constraints the pose must satisfy them (`trellis project` moves a state onto them).
--write-reference REF.csv writes the reference used (the held pose, or the trajectory read) in
the trajectory layout, for `trellis simulate --trajectory` (or use `simulate --hold T`, which
builds the same pose).

Balancing (--hold with --infinite-horizon): the finite-horizon gain ends in a terminal layer
(K(T) = R^-1 B^T Qf for continuous gains) that can destabilize a loop run up to T. With
--infinite-horizon the terminal cost Qf is the stationary cost-to-go S_inf at the pose: the
solution of the CARE (continuous gains) or, with --rate, of the DARE of the exact sampled-data
discretization (with its cross term) -- on the tangent space of the constraint manifold when the
scene has constraints. The Riccati equation (recursion) then starts at its fixed point: K(t) =
K_inf at every row, no terminal layer (the summary gives max |K_k - K_inf| / |K_inf|). --Qf
does not apply. A pose that cannot be stabilized (no stabilizing CARE/DARE solution) fails.

Weights W (for --Q, --Qf: 2n x 2n, positive semidefinite; for --R: m x m, positive definite):
  a number            that multiple of the identity            --Q 10
  a comma list        the diagonal (2n or m numbers)           --Q 10,10,1,1
  a JSON file         the full matrix as a list of rows         --Q q.json
                      (a file named like a number: ./NAME)
Q and Qf are in the full state [q; q'] (order of the trajectory's columns).

Sampled controller (--rate HZ): for a controller that samples x at t_k = t0 + k/HZ and holds u
until the next sample, the gains are computed for that controller, not sampled from K(t): over
each sample interval the linearization is discretized exactly (transition matrix and input
integral from the variational equation on the exact A(t), B(t); where the reference is at rest,
as with --hold, by the exact matrix exponential instead), the cost J above is integrated
over the interval with the input held (which gives per-sample weights with a cross term), and the
discrete Riccati recursion gives K_k at the sample times. The file's metadata line says
"sample_rate_hz=HZ": `trellis simulate` applies such gains only with the same --rate.

What the sampled controller applies: at t_k it measures x(t_k) and holds
  u_k = uff_k - K_k (x(t_k) - x_ref(t_k))   until t_{k+1}.
K_k is exact for the hold; so is the feed-forward uff_k (--feedforward consistent, the default):
the held input that carries x_ref(t_k) to x_ref(t_{k+1}) through the exact nonlinear dynamics
as closely as one held input can, in the metric of the cost-to-go S_{k+1} (Gauss-Newton from
the interval average of u_ref, with the hold's exact input matrix as the Jacobian; on the
constraint manifold when there are constraints). u_ref(t_k) held instead lets the unperturbed
loop leave the reference by O(h^2 |u_ref'|) per interval, which the feedback then chases (at
100 Hz up to 10x the tracking error of continuous feedback). The summary gives the largest defect
left at the next sample, sqrt(d^T S_{k+1} d), beside that of u_ref(t_k) held: what remains is
what one held input cannot do (m < 2n), including the reference's own collocation error.
Written as columns uff[<input>] after the gains. --feedforward average writes the interval
average of u_ref; --feedforward reference writes none (the controller then applies u_ref(t_k),
as files from before this option do).

Output (--out): a CSV whose first line is metadata ("# trellis gain schedule: m=.. nx=.. " then
"continuous" or "sample_rate_hz=HZ"), then the header t,K[<input>|<state>],...[,uff[<input>],...]
(K row-major: the inputs in order, each with the states [q; dq] in order, e.g. K[push|x],
K[push|dtheta]; a column splits at its first '|', which input names may not contain; files with
the older K_<input>_<state> columns are still read), one row per output time: the trajectory's
knots, or with --dt a uniform grid from t0 (T included), or with --rate the sample times (T
included, repeating the last sample's gain and feed-forward).
`trellis simulate --gains` reads it and checks the names against the scene. Then a summary on standard output: the rows written, the
Riccati solve (steps, right-hand-side evaluations, time taken), the smallest and largest
eigenvalue of S over the solver's steps (of Sr on the tangent space for a constrained scene),
the controllability of the linearization at the first knot (rank of the Krylov matrix) and the
reachability Gramian over the whole trajectory (largest eigenvalue, and the smallest when it is
resolved, above 1e-10 x the largest; below that the line says it was not computed and why). With --json the
summary is one JSON object instead.

options:
  --trajectory FILE   the reference trajectory (CSV; required unless --hold)
  --hold T            instead of --trajectory: hold the stored (or --state) pose still for T s
  --state FILE        with --hold: the pose (a state object, see `trellis linearize --help`)
  --out FILE          where to write the gains (CSV; required)
  --Q W               state weight (default 1)
  --R W               input weight (default 1)
  --Qf W              terminal weight (default: the value of --Q)
  --dt DT             continuous gains written on a uniform grid of step DT (default: at the
                      trajectory's knots). This only SAMPLES the continuous K(t): it does not
                      make gains for a controller running at 1/DT; use --rate for that
  --rate HZ           zero-order-hold gains for a controller sampling at HZ (see above)
  --feedforward F     with --rate: consistent (default), average or reference (see above)
  --infinite-horizon  with --hold: Qf = S_inf of the CARE (DARE with --rate), see Balancing
  --write-reference F write the reference used (the held pose, or the trajectory) to F (CSV)
  --cost-to-go FILE   also write the Riccati solution S(t) at the gains' times (CSV, the upper
                      triangle; `trellis funnel` measures its level sets V = dx^T S dx)
  --json              print the summary as one JSON object
  --rtol X, --atol X  CVODES tolerances on S (defaults 1e-8, 1e-10); with --rate, the tolerances
                      of each sample interval's integration instead (defaults: rtol 1e-6 for the
                      Radau integration along a moving reference, whose error estimate is
                      conservative; atol 1e-12)
  --method M          bdf (default), adams (non-stiff problems only) or factored (Cholesky
                      factor of S; needs Qf positive definite); continuous gains only
  --max-steps N       limit on the integrator's internal steps (default 100000)
  -h, --help          show this help

Exit status: 0 on success; 1 if a file cannot be read or is invalid (trajectory not matching the
scene, bad weight file) or the solve fails (the message gives the time and the cause); 2 on a
usage error (unknown option, missing file argument, malformed number or weight list). Errors are
one line on standard error, nothing on standard output, and no output file.
)";

/// W ≻ 0 is controllability. A λ_min below 1e-10 λ_max (GramianReport::controllable) is not
/// resolved by an integration at the summary's tolerance: its sign and size are then rounding, not
/// information. An unstable reference makes λ_max grow like e^{2σT} and pushes λ_min there although
/// the pair is controllable, so the verdict says the Gramian cannot decide instead of "not
/// controllable" (the rank at t0 above still can).
std::string gramianVerdict(const GramianReport& gramian) {
  if (gramian.controllable()) return " (controllable)";
  return std::string(" (undecided: min eigenvalue not resolved below 1e-10 x max") +
         (gramian.maxEigenvalue > 1e8 ? ", max grows as an unstable reference does" : "") + "; see the rank at t0)";
}

int runGains(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options(
      "gains", args,
      {.valued = {"--trajectory", "--hold", "--state", "--out", "--Q", "--R", "--Qf", "--dt", "--rate", "--rtol", "--atol", "--method",
                  "--max-steps", "--feedforward", "--write-reference", "--cost-to-go"},
       .flags = {"--json", "--infinite-horizon"},
       .repeatable = {}});
  const std::string scenePath = options.singlePositional("scene file");
  if (options.has("--hold") && options.has("--trajectory")) {
    throw UsageError("gains: --hold and --trajectory exclude each other (--hold makes the reference)");
  }
  if (options.has("--state") && !options.has("--hold")) {
    throw UsageError("gains: --state applies to --hold only (the reference comes from --trajectory)");
  }
  // A plain flag and value rather than std::optional<double>: GCC 12 warns, wrongly, that the
  // optional's payload may be read uninitialized in the branch below (-Wmaybe-uninitialized).
  const bool hold = options.has("--hold");
  const double holdSpan = hold ? options.positiveNumber("--hold", *options.value("--hold")) : 0.0;
  const std::string trajectoryPath =
      hold ? std::string("the held pose") : options.required("--trajectory", "(the reference trajectory CSV, or --hold T)");
  const std::string outPath = options.required("--out", "(the gains CSV to write)");
  const bool infiniteHorizon = options.flag("--infinite-horizon");
  if (infiniteHorizon && !hold) {
    throw UsageError("gains: --infinite-horizon applies to a held pose only (--hold T): along a moving "
                     "reference there is no stationary cost-to-go");
  }
  if (infiniteHorizon && options.has("--Qf")) {
    throw UsageError("gains: --infinite-horizon and --Qf exclude each other (the terminal cost is S_inf)");
  }
  const std::optional<std::string> referenceOut = options.value("--write-reference");
  {
    std::vector<std::pair<std::string, std::string>> inputs{{"scene", scenePath}};
    if (!hold) inputs.emplace_back("--trajectory", trajectoryPath);
    for (const char* option : {"--state", "--Q", "--R", "--Qf"})
      if (auto v = options.value(option)) inputs.emplace_back(option, *v);
    checkOutputIsNotInput("gains", outPath, inputs);
    // The other outputs may not overwrite an input nor each other.
    inputs.emplace_back("--out", outPath);
    if (referenceOut) {
      checkOutputIsNotInput("gains", *referenceOut, inputs);
      inputs.emplace_back("--write-reference", *referenceOut);
    }
    if (auto v = options.value("--cost-to-go")) checkOutputIsNotInput("gains", *v, inputs);
  }

  TvlqrOptions tvlqr;
  RiccatiOptions& riccati = tvlqr.riccati;
  if (auto v = options.value("--method")) {
    try {
      riccati.method = parseEnum<RiccatiMethod>(*v, "--method");
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("gains: ") + e.what());
    }
  }
  if (auto v = options.value("--rtol")) riccati.rtol = options.relativeTolerance("--rtol", *v);
  if (auto v = options.value("--atol")) riccati.atol = options.absoluteTolerance("--atol", *v);
  if (auto v = options.value("--max-steps")) {
    riccati.maxSteps = options.integer<long>("--max-steps", *v, 1);
    tvlqr.sampled.maxSteps = riccati.maxSteps;
  }
  if (auto v = options.value("--dt")) tvlqr.outputStep = options.positiveNumber("--dt", *v);
  if (auto v = options.value("--rate")) tvlqr.sampleRate = options.positiveNumber("--rate", *v);
  if (options.has("--rate") && options.has("--dt")) {
    throw UsageError("gains: --rate and --dt exclude each other (--rate writes the gains at the sample times)");
  }
  if (options.has("--rate") && options.has("--method")) {
    throw UsageError("gains: --method applies to continuous gains only (--rate uses the exact discretization)");
  }
  if (auto v = options.value("--feedforward")) {
    if (!options.has("--rate")) throw UsageError("gains: --feedforward applies to sampled gains only (--rate)");
    try {
      tvlqr.feedforward = parseEnum<SampledFeedforward>(*v, "--feedforward");
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("gains: ") + e.what());
    }
  }
  if (options.has("--rate")) {
    if (auto v = options.value("--rtol")) tvlqr.sampled.rtol = options.relativeTolerance("--rtol", *v);
    if (auto v = options.value("--atol")) tvlqr.sampled.atol = options.absoluteTolerance("--atol", *v);
  }

  const LoadedScene loaded = loadSceneArgument(scenePath);
  const Model& model = loaded.scene.model;
  const int n = model.nq(), m = model.nu(), nx = 2 * n;
  if (m == 0) throw std::runtime_error(scenePath + ": the scene has no inputs: there is nothing to control");

  const Trajectory trajectory = hold ? heldPoseReference(loaded, options.value("--state"), holdSpan, "gains --hold")
                                         : loadReference(model, scenePath, trajectoryPath);
  if (tvlqr.outputStep > 0.0) options.gridPoints("--dt", tvlqr.outputStep, trajectory.endTime() - trajectory.startTime(), kMaxOutputRows, "output rows");
  if (tvlqr.sampleRate > 0.0) {
    const double span = trajectory.endTime() - trajectory.startTime();
    // Sampled gains need two sample times inside the reference: a period longer than its span
    // leaves one (the discretization would fail with a message about its internals).
    if (!(1.0 / tvlqr.sampleRate <= span)) {
      throw UsageError("gains: --rate: " + formatNumber(tvlqr.sampleRate) + " Hz samples every " +
                       formatNumber(1.0 / tvlqr.sampleRate) + " s, longer than the reference's " + formatNumber(span) +
                       " s; at least 2 samples are needed (a rate of at least " + formatNumber(1.0 / span) + " Hz)");
    }
    options.gridPoints("--rate", 1.0 / tvlqr.sampleRate, span, kMaxOutputRows, "output rows");
  }
  Data data(model);

  const std::string states = "2n = " + std::to_string(nx) + " states";
  const std::string inputs = "m = " + std::to_string(m) + " inputs";
  const std::string qText = options.value("--Q").value_or("1");
  LqrWeights weights;
  weights.Q = parseWeight("gains", "--Q", qText, nx, states, WeightKind::kSemidefinite);
  weights.R = parseWeight("gains", "--R", options.value("--R").value_or("1"), m, inputs, WeightKind::kDefinite);
  weights.Qf = options.value("--Qf")
                   ? parseWeight("gains", "--Qf", *options.value("--Qf"), nx, states, WeightKind::kSemidefinite)
                   : weights.Q;

  // The solve (on the tangent space of the constraint manifold for a constrained scene).
  tvlqr.infiniteHorizon = infiniteHorizon;
  const TvlqrSolution solution = solveTvlqr(model, trajectory, weights, tvlqr);
  if (!solution.ok()) throw std::runtime_error("gains: " + solution.status.describe());
  solution.gains.writeCsvFile(outPath);
  if (auto v = options.value("--cost-to-go")) {
    CostToGo costToGo(solution.gains.times(), solution.S);
    costToGo.setStateNames(GainSchedule::stateNames(model.configNames()));
    costToGo.writeCsvFile(*v);
  }
  if (referenceOut) trajectory.writeCsvFile(*referenceOut);

  // The summary, after the file is written.
  const bool json = options.flag("--json");
  if (!json) {
    out << "wrote " << outPath << ": " << solution.summary();
    if (referenceOut) out << "wrote " << *referenceOut << ": the reference used (" << trajectory.size() << " knots)\n";
  }
  const ControllabilityReport pointwise = computeControllabilityAt(
      model, data, trajectory.states().col(0).head(n), trajectory.states().col(0).tail(n),
      trajectory.inputs().col(0));
  const GramianOptions gramianOptions;  // summary accuracy (controllability.hpp)
  const GramianReport gramian = computeControllabilityGramian(model, trajectory, trajectory.startTime(),
                                                              trajectory.endTime(), gramianOptions);
  if (json) {
    // The library's report, then the file and the controllability checks (their own reports).
    OutputJson body = OutputJson::parse(solution.json());
    body["out"] = outPath;
    body["reference_out"] = referenceOut ? OutputJson(*referenceOut) : OutputJson(nullptr);
    body["controllable_at_t0"] = pointwise.controllable();
    body["rank_at_t0"] = pointwise.rank;
    body["gramian_ok"] = gramian.ok();
    body["gramian_resolved"] = gramian.controllable();
    const OutputJson gramianReport = OutputJson::parse(gramian.json());
    // null when not resolved (below 1e-10 x max: rounding, see the text summary).
    body["gramian_min_eigenvalue"] = gramian.controllable() ? gramianReport["min_eigenvalue"] : OutputJson(nullptr);
    body["gramian_max_eigenvalue"] = gramianReport["max_eigenvalue"];
    body["controllability_at_t0"] = OutputJson::parse(pointwise.json());
    body["gramian"] = gramianReport;
    writeJson(out, body, true);
    return 0;
  }
  out << "controllability at t = " << formatNumber(trajectory.startTime()) << ": rank " << pointwise.rank
      << " of " << pointwise.dimension << (pointwise.controllable() ? " (controllable)" : " (NOT controllable)")
      << ", smallest singular value " << formatNumber(pointwise.smallestSingularValue, 3) << "\n";
  if (gramian.ok() && gramian.controllable()) {
    out << "gramian on [" << formatNumber(trajectory.startTime()) << ", "
        << formatNumber(trajectory.endTime()) << "]: min eigenvalue " << formatNumber(gramian.minEigenvalue, 3)
        << ", max eigenvalue " << formatNumber(gramian.maxEigenvalue, 3)
        << gramianVerdict(gramian) << "\n";
  } else if (gramian.ok()) {
    // Below 1e-10 x max the integration's rounding decides the smallest eigenvalue's sign and
    // size: printing it (even a negative one, of a PSD matrix) would pass rounding off as a result.
    out << "gramian on [" << formatNumber(trajectory.startTime()) << ", " << formatNumber(trajectory.endTime())
        << "]: max eigenvalue " << formatNumber(gramian.maxEigenvalue, 3)
        << "; min eigenvalue not computed: it lies below 1e-10 x max, where the integration's rounding "
           "decides its sign and size"
        << (gramian.maxEigenvalue > 1e8 ? " (an unstable reference makes the Gramian grow like exp(2 sigma T))" : "")
        << "; controllability is decided by the rank at t = " << formatNumber(trajectory.startTime()) << " above\n";
  } else {
    out << "gramian: not available (" << gramian.status.describe() << ")\n";
  }
  return 0;
}

}  // namespace

const Command kGainsCommand{
    "gains",
    "TV-LQR feedback gains along a reference trajectory, as a CSV gain schedule",
    kHelp,
    &runGains,
};

const CommandRegistration kRegisterGains{kGainsCommand};

}  // namespace trellis::cli
