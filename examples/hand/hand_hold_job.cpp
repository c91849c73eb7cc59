// hand_hold_job — feedback gains for the 20-DOF, 23-tendon human hand holding an object (issue 5):
// the project's main job until the hand turned a free ball (issue 26, examples/main_job).
//
// Steps (each prints a progress line and its time):
//   1. load examples/scenes/hand.json;
//   2. the reference motion (examples/hand: a designed motion on the constraint manifold with
//      strictly positive tensions from an interior-point inverse-dynamics tension distribution);
//   3. the exact linearization at every knot (and, for comparison, central finite differences of
//      the dynamics at the first knot: time and error);
//   4. controllability on the constraint manifold at every knot and over the whole trajectory
//      (the reduced reachability Gramian);
//   5. TV-LQR on the constraint manifold (CVODES), gains K(t) (23 × 40, full state) at the knots;
//   6. closed-loop simulations from seeded perturbed starts (tangent to the manifold), tensions
//      saturated at zero, constraints projected; tracking error, drift and saturation — one batch
//      (simulateBatch) over the machine's cores;
//   7. files in the output folder (default output/hand_hold/): reference.csv, gains.csv,
//      reference_accelerations.csv (q'' at the knots, for the plots' Hermite reference),
//      controllability.csv, closed_loop_<k>.csv (one per run, at most kMaxClosedLoopFiles), summary.txt, the PNG plots (scripts/plot_run.py)
//      and hand.html, the 3D view of the reference and every closed loop (docs/viewer.md).
// The plots are ONE Python process, started as soon as the gains are written: matplotlib's start-up
// and the gain and controllability plots overlap the closed loops; it is told "go" on its standard
// input once the closed-loop files exist. The summary (with each stage's time) is printed first;
// then the job waits for the plots, and a plot failure still fails the job.
//
// usage: hand_hold_job [--out DIR] [--runs N] [--seed S] [--perturbation SIZE] [--no-plots]
#include "hand_feedback.hpp"
#include "job_options.hpp"
#include "job_progress.hpp"
#include "reference_motion.hpp"

#include "trellis/control.hpp"
#include "trellis/core.hpp"
#include "trellis/core/numdiff.hpp"
#include "trellis/viewer/view.hpp"

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <sys/wait.h>

namespace {

using Clock = trellis::hand::JobClock;
using trellis::hand::format;
using trellis::hand::Progress;
using trellis::hand::secondsSince;


constexpr const char* kHelp = R"(usage: hand_hold_job [--out DIR] [--runs N] [--seed S] [--perturbation SIZE] [--no-plots]

Feedback gains for the 20-joint, 23-tendon human hand (examples/scenes/hand.json) holding an
object, end to end: a reference motion on the constraint manifold with positive tensions, the
exact linearization at every knot, controllability, TV-LQR on the manifold, and closed loops from
perturbed starts with tensions saturated at 0. States are joint angles [rad] and rates [rad/s];
inputs are tendon tensions [N]; the gains map them, K [N/rad] and [N s/rad].

options:
  --out DIR             output folder (default output/hand_hold)
  --runs N              closed-loop simulations, 1..1000 (default 20); the first 100 are
                        written as closed_loop_<k>.csv and drawn in the plots
  --seed S              seed of the perturbed starts (default 1; same seed, same starts)
  --perturbation SIZE   norm of each start's deviation from the reference, tangent to the
                        constraint manifold, in [rad, rad/s] (default 0.05; > 0)
  --no-plots            skip the PNG plots (they need python3-matplotlib)
  -h, --help            show this help

Files in DIR: reference.csv (t, angles, rates, tensions), reference_accelerations.csv (q'' at
the knots [rad/s^2]), gains.csv (K(t) per knot, row-major), controllability.csv (rank and
smallest singular value per knot), closed_loop_<k>.csv (the simulated runs, layout of
reference.csv), summary.txt, states.png, inputs.png, gains.png, tracking_error.png,
controllability.png (one panel row per digit) and hand.html (3D view).
Exit status 0 when every run converges (final error < half the initial), the hand is
controllable at every knot and over the trajectory, and the plots were written; else 1.
)";

/// The closed loops written as CSV files and drawn (each is a few MB of text; --runs may be larger).
constexpr int kMaxClosedLoopFiles = 100;

struct Options {
  std::string out = "output/hand_hold";
  int runs = 20;
  unsigned seed = 1;
  double perturbation = 0.05;  // norm of the initial tangent perturbation (rad, rad/s)
  bool plots = true;
};

Options parseOptions(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out") o.out = trellis::hand::optionValue(argc, argv, i);
    else if (a == "--runs") o.runs = static_cast<int>(trellis::hand::integerOption(a, trellis::hand::optionValue(argc, argv, i), 1, 1000));
    else if (a == "--seed") o.seed = static_cast<unsigned>(trellis::hand::integerOption(a, trellis::hand::optionValue(argc, argv, i), 0, 4294967295L));
    else if (a == "--perturbation") o.perturbation = trellis::hand::positiveOption(a, trellis::hand::optionValue(argc, argv, i));
    else if (a == "--no-plots") o.plots = false;
    else if (a == "-h" || a == "--help") {
      std::printf("%s", kHelp);
      std::exit(0);
    } else {
      throw std::invalid_argument("unknown option '" + a + "'");
    }
  }
  return o;
}


/// Central differences of ẋ = f(x, u) at x, u (the core's numdiff, step ε^(1/3)·max(1, |z|)):
/// the baseline that the exact method replaces. The q-rows are [0 I | 0] exactly.
void finiteDifferenceLinearization(const trellis::Model& model, trellis::Data& data,
                                   const Eigen::VectorXd& x, const Eigen::VectorXd& u,
                                   Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
  const int n = model.nq(), m = model.nu();
  trellis::NumDiffWorkspace workspace(model);
  Eigen::MatrixXd J;
  const trellis::DynamicsStatus status =
      trellis::differenceDynamics(model, data, x.head(n), x.tail(n), u, {}, workspace, J);
  if (!status.ok()) throw std::runtime_error("finite differences of the dynamics: " + status.message);
  A = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  A.topRightCorner(n, n).setIdentity();
  A.bottomRows(n) = J.leftCols(2 * n);
  B = Eigen::MatrixXd::Zero(2 * n, m);
  B.bottomRows(n) = J.rightCols(m);
}

}  // namespace

int main(int argc, char** argv) try {
  std::signal(SIGXFSZ, SIG_IGN);
  std::signal(SIGPIPE, SIG_IGN);  // a plot process that died early is reported by pclose, not fatal  // beyond a file-size limit a write fails (EFBIG) and is reported
  const Options options = parseOptions(argc, argv);
  const auto jobStart = Clock::now();
  Progress progress(7);
  std::filesystem::create_directories(options.out);

  // 1. Scene ------------------------------------------------------------------------------------
  progress.begin("loading the hand scene");
  const std::string scenePath = std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/hand.json";
  const trellis::Scene scene = trellis::loadScene(scenePath);
  const trellis::Model& model = scene.model;
  const int n = model.nq(), m = model.nu(), nx = 2 * n;
  progress.end(std::to_string(n) + " configurations, " + std::to_string(m) + " tendon inputs, " +
               std::to_string(model.nc()) + " constraint rows (" + scenePath + ")");

  // 2. Reference --------------------------------------------------------------------------------
  progress.begin("reference motion: designed on the constraint manifold, tensions > 0 by inverse dynamics");
  const trellis::hand::ReferenceMotion reference = trellis::hand::makeReferenceMotion(model, scene.q);
  if (!reference.ok) throw std::runtime_error("reference motion: " + reference.message);
  const trellis::Trajectory& trajectory = reference.trajectory;
  const int N = trajectory.size();
  progress.end(format("%.0f knots over %.2f s", N, trajectory.endTime() - trajectory.startTime()) +
               format(", inverse-dynamics residual ≤ %.1e, forward-dynamics error ≤ %.1e rad/s²",
                      reference.dynamicsResidual.maxCoeff(), reference.forwardDynamicsError.maxCoeff()) +
               format(", tensions %.3g … %.3g N", trajectory.inputs().minCoeff(), trajectory.inputs().maxCoeff()));
  trajectory.writeCsvFile(options.out + "/reference.csv");
  {  // q'' at the knots (the reference's state derivatives) for the plots' Hermite reference
    std::ostringstream csv;
    csv.precision(17);
    csv << 't';
    for (const std::string& name : trajectory.configNames()) csv << ',' << name;
    csv << '\n';
    for (int k = 0; k < N; ++k) {
      csv << trajectory.times()(k);
      for (int i = 0; i < n; ++i) csv << ',' << trajectory.stateDerivatives()(n + i, k);
      csv << '\n';
    }
    trellis::writeFileAtomically(options.out + "/reference_accelerations.csv", csv.str());
  }

  // 3. Linearization along the reference ---------------------------------------------------------
  progress.begin("exact linearization at every knot (and central differences at the first knot)");
  trellis::Data data(model);
  double maxConstraint = 0.0;
  const auto linStart = Clock::now();
  for (int k = 0; k < N; ++k) {
    const Eigen::VectorXd x = trajectory.states().col(k);
    const trellis::DynamicsStatus status = trellis::computeLinearization(
        model, data, x.head(n), x.tail(n), trajectory.inputs().col(k));
    if (!status.ok())
      throw std::runtime_error(format("linearization failed at knot t = %.4f s: ", trajectory.times()(k)) +
                               status.message);
    maxConstraint = std::max(maxConstraint, data.constraintValue.cwiseAbs().maxCoeff());
  }
  const double exactPerKnot = secondsSince(linStart) / N;
  const Eigen::VectorXd x0 = trajectory.states().col(0);
  const Eigen::VectorXd u0 = trajectory.inputs().col(0);
  trellis::computeLinearization(model, data, x0.head(n), x0.tail(n), u0);
  const Eigen::MatrixXd Aexact = data.A, Bexact = data.B;
  Eigen::MatrixXd Afd, Bfd;
  const auto fdStart = Clock::now();
  finiteDifferenceLinearization(model, data, x0, u0, Afd, Bfd);
  const double fdTime = secondsSince(fdStart);
  const double fdError = std::max((Afd - Aexact).cwiseAbs().maxCoeff(), (Bfd - Bexact).cwiseAbs().maxCoeff()) /
                         std::max(1.0, std::max(Aexact.cwiseAbs().maxCoeff(), Bexact.cwiseAbs().maxCoeff()));
  const double linTime = progress.end(
      format("exact %.1f µs per knot; central differences %.1f µs, relative difference %.1e", exactPerKnot * 1e6,
             fdTime * 1e6, fdError) +
      format(", max |h| at the knots %.1e", maxConstraint));
  (void)linTime;

  // 4. Controllability --------------------------------------------------------------------------
  progress.begin("controllability on the constraint manifold: every knot and the trajectory's Gramian");
  const std::vector<trellis::ControllabilityReport> knots = trellis::controllabilityAtKnots(model, trajectory);
  int minRank = nx, dimension = 0;
  double minSigma = INFINITY;
  {
    std::ostringstream csv;
    csv << "t,dimension,rank,smallest_singular_value\n";
    for (int k = 0; k < N; ++k) {
      const auto& r = knots[k];
      minRank = std::min(minRank, r.rank);
      dimension = r.dimension;
      minSigma = std::min(minSigma, r.smallestSingularValue);
      csv << trajectory.times()(k) << ',' << r.dimension << ',' << r.rank << ',' << r.smallestSingularValue << '\n';
    }
    trellis::writeFileAtomically(options.out + "/controllability.csv", csv.str());  // complete or absent
  }
  // The tensions come from a per-knot inverse-dynamics distribution and between knots they are
  // cubic in time: the reference satisfies the dynamics there only to the input rule's O(h⁴),
  // amplified by the fingertips' tiny inertias. The tangent basis is therefore carried by discrete transport on the
  // knots (manifold_lqr.hpp, kProjected), which does not rely on the dynamics between knots.
  const trellis::TangentTransportOptions transport = trellis::hand::feedbackTransport();
  const trellis::GramianReport gramian = trellis::computeControllabilityGramian(
      model, trajectory, trajectory.startTime(), trajectory.endTime(), transport);
  if (!gramian.ok()) throw std::runtime_error("controllability Gramian: " + gramian.status.describe());
  const bool pointwise = minRank == dimension;
  progress.end(format("tangent dimension %.0f, min rank over knots %.0f, min σ %.2e", dimension, minRank, minSigma) +
               format("; Gramian λ_min %.3e, λ_max %.3e", gramian.minEigenvalue, gramian.maxEigenvalue));

  // 5. TV-LQR on the manifold -------------------------------------------------------------------
  progress.begin("TV-LQR on the constraint manifold (CVODES, BDF)");
  // Q = diag(100 I, I) (angles matter more than rates), R = I, Qf = Q (hand_feedback.hpp). Tensions
  // in N: R = I. The hand is passively stable but very stiff (tangent eigenvalues down to −9e3 s⁻¹);
  // a much cheaper input (R = 1e-2 I) drives the closed loop to −1.3e5 s⁻¹ and the backward
  // Riccati integration with it (measured: S exceeded 1e15).
  const trellis::LqrWeights weights = trellis::hand::feedbackWeights(model);
  // S's eigenvalue range is not read here: its tracking (an eigenvalue solve per step) is off.
  trellis::RiccatiOptions riccatiOptions = trellis::hand::feedbackRiccatiOptions();
  riccatiOptions.trackEigenvalues = false;
  const trellis::ManifoldRiccatiSolution lqr =
      trellis::solveManifoldRiccati(model, trajectory, weights, riccatiOptions, transport);
  if (!lqr.ok()) throw std::runtime_error("manifold Riccati solve failed: " + lqr.status.describe());
  // K at the knots and the Riccati steps (its end-time boundary layer), cubic rule (hand_feedback.hpp).
  trellis::GainSchedule gains = trellis::hand::feedbackGains(lqr, trajectory);
  gains.setColumnNames(model.inputNames(), trellis::GainSchedule::stateNames(model.configNames()));
  gains.writeCsvFile(options.out + "/gains.csv");
  double maxGain = 0.0;
  for (const Eigen::MatrixXd& K : gains.gains()) maxGain = std::max(maxGain, K.norm());
  progress.end(format("%.0f Riccati steps on %.0f reduced states, max ‖K‖_F %.3g", lqr.reduced.steps,
                      lqr.basis.dimension(), maxGain));

  // The plots' one Python process starts now (see the file comment). popen's pipe is its stdin.
  FILE* plots = nullptr;
  const auto plotStart = Clock::now();
  if (options.plots) {
    std::ostringstream cmd;
    // Debian's interpreter has python3-matplotlib; a python3 earlier on PATH may not.
    const char* python = std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
    cmd << python << " \"" << TRELLIS_SOURCE_DIR << "/scripts/plot_run.py\" --closed-after-go --title 'human hand'"
        // The reference's knot accelerations (what simulate's Hermite reference uses): the tracking
        // error plotted as simulate measures it. (--scene would give the same from one `trellis
        // linearize` process per knot: 22 s for the 301 knots, measured.)
        << " --accelerations \"" << options.out << "/reference_accelerations.csv\""
        << " --reference \"" << options.out << "/reference.csv\" --gains \"" << options.out
        << "/gains.csv\" --controllability \"" << options.out << "/controllability.csv\" --out \""
        << options.out << "\""
        // Small multiples by digit: the thumb's own muscles have no digit word in their names.
        << " --group thumb=FPL,EPL,APL,ADP --config-unit rad --input-unit N --input-name 'tendon tension'";
    for (int r = 0; r < std::min(options.runs, kMaxClosedLoopFiles); ++r)
      cmd << " --closed \"" << options.out << "/closed_loop_" << r << ".csv\"";
    std::fflush(stdout);  // the child inherits the stream: no duplicated buffered output
    plots = popen(cmd.str().c_str(), "w");
    if (!plots) throw std::runtime_error("could not start the plot process: " + cmd.str());
  }

  // 6. Closed loop ------------------------------------------------------------------------------
  progress.begin("closed-loop simulations from seeded perturbed starts (tensions saturated at 0)");
  // The hand is stiff (eigenvalues to −9e3 s⁻¹ open loop, further with feedback): BDF, not Adams;
  // rtol 1e-7, atol 5e-10 on the deviation from the reference (hand_feedback.hpp).
  const trellis::SimulationOptions sim = trellis::hand::closedLoopOptions(m);
  struct Run {
    double initial, final, maxDrift, saturated;
    bool ok;
  };
  // Tangent to the manifold; the projection at t0 removes the O(‖z‖²) drift.
  const std::vector<Eigen::VectorXd> starts = trellis::hand::perturbedStarts(
      lqr.basis.basis(trajectory.startTime()), x0, options.runs, options.seed, options.perturbation);
  // One Data and one integrator per thread; model, reference and gains shared read-only.
  const std::vector<trellis::SimulationResult> results =
      trellis::simulateBatch(model, trajectory, gains, starts, sim, 0);
  std::vector<Run> runs;
  long steps = 0, restarts = 0, projections = 0, jacobians = 0, quotientRhs = 0;
  for (int r = 0; r < options.runs; ++r) {
    const trellis::SimulationResult& result = results[r];
    Run run{0, 0, result.maxConstraintDrift, result.saturatedFraction, result.ok()};
    if (result.trackingError.size() > 0) {
      run.initial = result.trackingError(0);
      run.final = result.trackingError(result.trackingError.size() - 1);
    }
    if (!result.ok()) std::printf("      run %d: %s\n", r, result.status.describe().c_str());
    if (r < kMaxClosedLoopFiles) result.trajectory.writeCsvFile(options.out + "/closed_loop_" + std::to_string(r) + ".csv");
    steps += result.steps;
    restarts += result.restarts;
    projections += result.projections;
    jacobians += result.jacobianEvaluations;
    quotientRhs += result.linearRhsEvaluations;
    runs.push_back(run);
  }
  if (plots) {  // the closed-loop files are complete: the plot process may read them
    std::fputs("go\n", plots);
    std::fflush(plots);
  }
  int converged = 0, failed = 0;
  double worstRatio = 0.0, worstDrift = 0.0, meanSaturated = 0.0, worstFinal = 0.0;
  for (const Run& run : runs) {
    if (!run.ok) {
      ++failed;
      continue;
    }
    const double ratio = run.final / run.initial;
    worstRatio = std::max(worstRatio, ratio);
    worstFinal = std::max(worstFinal, run.final);
    worstDrift = std::max(worstDrift, run.maxDrift);
    meanSaturated += run.saturated / runs.size();
    if (ratio < 0.5) ++converged;
  }
  progress.end(format("%.0f of %.0f runs end with less than half their initial error", converged, runs.size()) +
               format("; worst final/initial %.2e, worst final error %.2e", worstRatio, worstFinal) +
               format(", worst constraint drift %.1e", worstDrift) +
               format("; per run %.0f steps, %.1f restarts (= projections %.1f)", double(steps) / runs.size(),
                      double(restarts) / runs.size(), double(projections) / runs.size()) +
               format(", %.0f exact Jacobians, %.0f difference-quotient right-hand sides", double(jacobians) / runs.size(),
                      double(quotientRhs) / runs.size()));

  // The 3D view (docs/viewer.md): the reference and every closed loop, ghosted; poses from the
  // library's kinematics at every knot and 60 times per second.
  std::vector<trellis::ViewTrajectory> shown{{"reference", trajectory, false}};
  for (int r = 0; r < options.runs; ++r) {
    if (results[r].trajectory.size() > 0) {
      shown.push_back({"closed loop " + std::to_string(r), results[r].trajectory, true});
    }
  }
  trellis::ViewOptions viewOptions;
  viewOptions.title = "human hand: reference motion and closed loops";
  const trellis::ViewReport view = trellis::writeView(options.out + "/hand.html", scene, scene.q, shown, viewOptions);

  // 7. Summary; then the plots ----------------------------------------------------------------
  progress.begin("summary (the plots finish in parallel)");
  progress.end();
  std::ostringstream summary;
  summary << "\nhand hold job — summary\n";
  progress.table(summary, secondsSince(jobStart));
  summary << format("\n  linearization: exact %.1f µs per knot, central differences %.1f µs (relative difference %.1e)\n",
                    exactPerKnot * 1e6, fdTime * 1e6, fdError);
  summary << format("  controllability: manifold dimension %.0f, rank %.0f at every knot: ", dimension, minRank)
          << (pointwise ? "yes" : "NO") << format(" (min σ %.2e)\n", minSigma);
  summary << format("  Gramian over the trajectory: λ_min %.3e, λ_max %.3e → ", gramian.minEigenvalue,
                    gramian.maxEigenvalue)
          << (gramian.controllable() ? "controllable" : "NOT controllable") << '\n';
  summary << format("  closed loop: %.0f runs, %.0f failed, ", runs.size(), failed)
          << format("%.0f with final error < half the initial; worst final/initial %.2e, ", converged, worstRatio)
          << format("worst final error ‖x − x_ref‖ %.2e\n", worstFinal)
          << format("  constraint drift ≤ %.1e, tensions saturated at 0 in %.1f%% of the control evaluations\n",
                    worstDrift, 100 * meanSaturated);
  summary << format("  closed-loop integration per run: %.0f steps, %.1f restarts, %.1f projections, ",
                    double(steps) / runs.size(), double(restarts) / runs.size(), double(projections) / runs.size())
          << format("%.0f exact Jacobians, %.0f difference-quotient right-hand sides\n", double(jacobians) / runs.size(),
                    double(quotientRhs) / runs.size());
  summary << format("  3D view: hand.html, %.2f MB, %.0f trajectories, %.0f pose samples (open it in a browser)\n",
                    static_cast<double>(view.bytes) / 1e6, static_cast<double>(shown.size()),
                    static_cast<double>(view.samples));
  summary << format("  closed-loop files: closed_loop_0.csv … closed_loop_%.0f.csv (%.0f of ",
                    std::min(options.runs, kMaxClosedLoopFiles) - 1.0, std::min(options.runs, kMaxClosedLoopFiles))
          << format("%.0f runs), all drawn in the plots\n", options.runs);
  summary << "  files: " << std::filesystem::absolute(options.out).string() << "/\n";
  std::printf("%s", summary.str().c_str());
  std::fflush(stdout);
  trellis::writeFileAtomically(options.out + "/summary.txt", summary.str());

  bool plotsOk = true;
  if (plots) {
    const int status = pclose(plots);
    plotsOk = status != -1 && WIFEXITED(status) && WEXITSTATUS(status) == 0;
    const std::string line =
        plotsOk ? format("  plots: PNG files written by one Python process in %.3f s (started after the gains), "
                         "whole job with plots %.3f s\n", secondsSince(plotStart), secondsSince(jobStart))
                : format("  plots: FAILED (the plot process, scripts/plot_run.py, exited with status %.0f; "
                         "python3-matplotlib missing?)\n", WIFEXITED(status) ? WEXITSTATUS(status) : -1);
    std::printf("%s", line.c_str());
    trellis::writeFileAtomically(options.out + "/summary.txt", summary.str() + line);
    if (!plotsOk) std::fprintf(stderr, "hand_hold_job: error: the plots failed (see above)\n");
  }
  return (plotsOk && failed == 0 && pointwise && gramian.controllable() && converged == options.runs) ? 0 : 1;
} catch (const std::exception& e) {
  std::fprintf(stderr, "hand_hold_job: error: %s\n", e.what());
  return 1;
}
