// cli/gains.cpp — `trellis gains SCENE.json --trajectory TRAJ.csv --out GAINS.csv`: the TV-LQR
// feedback gain K(t) along a reference trajectory, as a CSV gain schedule.
#include "cli_options.hpp"
#include "command.hpp"
#include "weights.hpp"

#include "trellis/control/controllability.hpp"
#include "trellis/control/gain_schedule.hpp"
#include "trellis/control/manifold_lqr.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/control/trajectory.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/scene.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis gains SCENE.json --trajectory TRAJ.csv --out GAINS.csv [options]

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
`trellis simulate --out` writes); its names must equal the scene's, in order.

Weights W (for --Q, --Qf: 2n x 2n, positive semidefinite; for --R: m x m, positive definite):
  a number            that multiple of the identity            --Q 10
  a comma list        the diagonal (2n or m numbers)           --Q 10,10,1,1
  a JSON file         the full matrix as a list of rows         --Q q.json
                      (a file named like a number: ./NAME)
Q and Qf are in the full state [q; q'] (order of the trajectory's columns).

Output (--out): a CSV with the header t,K_i_j,... (K row-major, i < m, j < 2n), one row per
output time: the trajectory's knots, or with --dt a uniform grid from t0 (T included).
`trellis simulate --gains` reads it. Then a summary on standard output: the rows written, the
Riccati solve (steps, right-hand-side evaluations, time taken), the smallest and largest
eigenvalue of S over the solver's steps (of Sr on the tangent space for a constrained scene),
the controllability of the linearization at the first knot (rank of the Krylov matrix) and the
reachability Gramian over the whole trajectory (smallest and largest eigenvalue).

options:
  --trajectory FILE   the reference trajectory (CSV; required)
  --out FILE          where to write the gains (CSV; required)
  --Q W               state weight (default 1)
  --R W               input weight (default 1)
  --Qf W              terminal weight (default: the value of --Q)
  --dt DT             output on a uniform grid of step DT (default: at the trajectory's knots)
  --rtol X, --atol X  CVODES tolerances on S (defaults 1e-8, 1e-10)
  --method M          bdf (default), adams (non-stiff problems only) or factored (Cholesky
                      factor of S; needs Qf positive definite)
  --max-steps N       limit on the integrator's internal steps (default 100000)
  -h, --help          show this help

Exit status: 0 on success; 1 if a file cannot be read or is invalid (trajectory not matching the
scene, bad weight file) or the solve fails (the message gives the time and the cause); 2 on a
usage error (unknown option, missing file argument, malformed number or weight list). Errors are
one line on standard error, nothing on standard output, and no output file.
)";

std::vector<double> outputTimes(const Trajectory& trajectory, std::optional<double> dt) {
  const Eigen::VectorXd& knots = trajectory.times();
  if (!dt) return {knots.data(), knots.data() + knots.size()};
  const double t0 = trajectory.startTime(), T = trajectory.endTime();
  std::vector<double> times;
  // k·dt from t0 (no accumulated round-off); T itself closes the grid unless a grid point is
  // already within a tiny fraction of a step of it.
  for (long k = 0;; ++k) {
    const double t = t0 + static_cast<double>(k) * *dt;
    if (t >= T - 1e-9 * *dt) break;
    times.push_back(t);
  }
  times.push_back(T);
  return times;
}

/// W ≻ 0 is controllability; a ratio λmin/λmax below 1e-10 (GramianReport::controllable) is
/// reported as ill-conditioned when λmin is still positive (typical of an unstable reference,
/// whose transition matrix grows the Gramian along the unstable directions).
std::string gramianVerdict(const GramianReport& gramian) {
  if (gramian.controllable()) return " (controllable)";
  if (gramian.minEigenvalue > 0.0) {
    return " (positive definite but ill-conditioned: min/max = " +
           formatNumber(gramian.minEigenvalue / gramian.maxEigenvalue, 3) + ")";
  }
  return " (NOT controllable)";
}

RiccatiMethod parseMethod(const ParsedOptions& options) {
  const std::string method = options.value("--method").value_or("bdf");
  if (method == "bdf") return RiccatiMethod::kBDF;
  if (method == "adams") return RiccatiMethod::kAdams;
  if (method == "factored") return RiccatiMethod::kFactored;
  throw UsageError("gains: --method: '" + method + "' is not one of bdf, adams, factored");
}

const char* methodName(RiccatiMethod method) {
  switch (method) {
    case RiccatiMethod::kBDF: return "bdf";
    case RiccatiMethod::kAdams: return "adams";
    case RiccatiMethod::kFactored: return "factored";
  }
  return "?";
}

int runGains(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options(
      "gains", args,
      {.valued = {"--trajectory", "--out", "--Q", "--R", "--Qf", "--dt", "--rtol", "--atol", "--method",
                  "--max-steps"},
       .flags = {},
       .repeatable = {}});
  const std::string scenePath = options.singlePositional("scene file");
  const std::string trajectoryPath = options.required("--trajectory", "(the reference trajectory CSV)");
  const std::string outPath = options.required("--out", "(the gains CSV to write)");

  RiccatiOptions riccati;
  riccati.method = parseMethod(options);
  if (auto v = options.value("--rtol")) riccati.rtol = options.relativeTolerance("--rtol", *v);
  if (auto v = options.value("--atol")) riccati.atol = options.absoluteTolerance("--atol", *v);
  if (auto v = options.value("--max-steps")) riccati.maxSteps = options.integer<long>("--max-steps", *v, 1);
  std::optional<double> dt;
  if (auto v = options.value("--dt")) dt = options.positiveNumber("--dt", *v);

  const Scene scene = loadScene(scenePath);
  const Model& model = scene.model;
  const int n = model.nq(), m = model.nu(), nx = 2 * n;
  if (m == 0) throw std::runtime_error(scenePath + ": the scene has no inputs: there is nothing to control");

  const Trajectory trajectory = loadReference(model, scenePath, trajectoryPath);
  if (dt) options.gridPoints("--dt", *dt, trajectory.endTime() - trajectory.startTime(), kMaxOutputRows, "output rows");
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

  // The solve; on a constrained scene on the tangent space of the constraint manifold.
  const bool constrained = model.nc() > 0;
  const auto start = std::chrono::steady_clock::now();
  std::optional<ManifoldRiccatiSolution> onManifold;
  std::optional<RiccatiSolution> fullState;
  if (constrained) {
    onManifold = solveManifoldRiccati(model, trajectory, weights, riccati);
    if (!onManifold->ok()) throw std::runtime_error("gains: the Riccati solve failed: " + onManifold->message());
  } else {
    fullState = solveRiccati(model, trajectory, weights, riccati);
    if (!fullState->ok()) throw std::runtime_error("gains: the Riccati solve failed: " + fullState->message);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const RiccatiSolution& solution = constrained ? onManifold->reduced : *fullState;
  checkSemidefinite("gains", constrained ? "Sr" : "S", solution.minEigenvalue, solution.maxEigenvalue);

  const std::vector<double> times = outputTimes(trajectory, dt);
  const GainSchedule schedule = GainSchedule::sample(
      [&](double t) { return constrained ? onManifold->K(t) : fullState->K(t); },
      Eigen::Map<const Eigen::VectorXd>(times.data(), static_cast<Eigen::Index>(times.size())));
  if (!std::all_of(schedule.gains().begin(), schedule.gains().end(),
                   [](const Eigen::MatrixXd& K) { return K.allFinite(); })) {
    throw std::runtime_error("gains: the gain K(t) is not finite");
  }
  schedule.writeCsvFile(outPath);

  // The summary, after the file is written.
  out << "wrote " << outPath << ": " << times.size() << " rows of K (" << m << " x " << nx
      << ") on [" << formatNumber(trajectory.startTime()) << ", " << formatNumber(trajectory.endTime())
      << "]\n";
  if (constrained) {
    out << "riccati: on the constraint manifold (tangent dimension " << onManifold->dimension() << " of "
        << nx << "; basis transport " << onManifold->basis.steps() << " steps, max correction "
        << formatNumber(onManifold->basis.maxCorrection(), 3) << ")\n";
  } else {
    out << "riccati: full state (no constraints)\n";
  }
  out << "riccati: " << methodName(riccati.method) << ", " << solution.steps << " steps, "
      << solution.rhsEvaluations << " right-hand-side evaluations, " << formatNumber(seconds, 3) << " s\n";
  out << "S" << (constrained ? "r" : "") << ": min eigenvalue " << formatNumber(solution.minEigenvalue)
      << ", max eigenvalue " << formatNumber(solution.maxEigenvalue) << "\n";

  const ControllabilityReport pointwise = computeControllabilityAt(
      model, data, trajectory.states().col(0).head(n), trajectory.states().col(0).tail(n),
      trajectory.inputs().col(0));
  out << "controllability at t = " << formatNumber(trajectory.startTime()) << ": rank " << pointwise.rank
      << " of " << pointwise.dimension << (pointwise.controllable() ? " (controllable)" : " (NOT controllable)")
      << ", smallest singular value " << formatNumber(pointwise.smallestSingularValue, 3) << "\n";
  const GramianReport gramian =
      computeControllabilityGramian(model, trajectory, trajectory.startTime(), trajectory.endTime());
  if (gramian.ok) {
    out << "gramian on [" << formatNumber(trajectory.startTime()) << ", "
        << formatNumber(trajectory.endTime()) << "]: min eigenvalue " << formatNumber(gramian.minEigenvalue, 3)
        << ", max eigenvalue " << formatNumber(gramian.maxEigenvalue, 3)
        << gramianVerdict(gramian) << "\n";
  } else {
    out << "gramian: not available (" << gramian.message << ")\n";
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
