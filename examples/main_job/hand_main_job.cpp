// hand_main_job — the human hand turns a free ball (issue 26): an optimized motion with unilateral
// contacts and friction, sampled TV-LQR gains for a 200 Hz controller, and contact-checked
// closed loops. The project's main job; the former one (the hand holding a fixed ball, issue 5)
// is examples/hand/hand_hold_job.
//
// Stages (each prints a progress line and its time):
//   1. load examples/scenes/hand_ball.json (26 coordinates: 20 joints and the ball's 6; 23 tendons;
//      15 sticking-contact rows) and examples/hand/hand_ball_limits.json (μ, normal-force margin,
//      joint ranges, tendon maxima; sources in make_hand_scene.py);
//   2. the turn optimized (ball_turn.hpp): the ball's yaw 0 → 20° in 2 s, rest to rest from the
//      stored grasp, 0 ≤ u ≤ u_max, joint ranges, λ_n ≥ 0.05 N and the 8-facet pyramid inscribed
//      in the cone at every collocation point; implicit dynamics, Hermite–Simpson on 11 knots,
//      Ipopt with the exact Hessian;
//   3. the reference (ball_reference.hpp): the optimized motion kept, its tensions and contact
//      forces redistributed by inverse dynamics on 201 knots so that the plant follows it between
//      knots, and checked as the optimizer checks (checkConsistency, tolerance 1e-3);
//   4. sampled TV-LQR gains (200 Hz, exact zero-order hold) on the constraint manifold and the
//      seeded perturbed closed loops, tensions clipped to [0, u_max], every contact checked at every
//      integrator step (ball_feedback.hpp);
//   5. files in the output folder (default output/hand/): reference.csv and closed_loop_<k>.csv
//      (the trajectory layout plus lambda_<digit>_n, _t1, _t2: each contact's force in its frame),
//      tracking_error.csv, gains.csv, summary.txt, hand.html (3D view), and the plots of
//      scripts/plot_ball_turn.py: ball_orientation.png, tensions.png, contacts.png,
//      tracking_error.png.
// Exit status 0 only when the optimizer converged, the reference is consistent and keeps its
// contacts, every closed loop kept every contact and converged, and the files and plots were
// written; else 1.
//
// usage: hand_main_job [--out DIR] [--runs N] [--seed S] [--perturbation SIZE] [--threads N] [--no-plots]
#include "ball_feedback.hpp"
#include "job_options.hpp"
#include "job_progress.hpp"
#include "ball_reference.hpp"
#include "ball_turn.hpp"

#include "trellis/analysis/consistency.hpp"
#include "trellis/core.hpp"
#include "trellis/optimization.hpp"
#include "trellis/viewer/view.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <memory>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace {

using Clock = trellis::hand::JobClock;
using trellis::hand::format;
using trellis::hand::Progress;
using trellis::hand::secondsSince;
using namespace trellis;


constexpr const char* kHelp = R"(usage: hand_main_job [--out DIR] [--runs N] [--seed S] [--perturbation SIZE] [--threads N] [--no-plots]

The human hand turns a free ball (examples/scenes/hand_ball.json: 20 joints, the ball's 6
coordinates, 23 tendons, 5 sticking contacts): the turn by 20 degrees about the palm's normal in
2 s optimized with unilateral contacts inside the friction cone, made a reference the plant
follows (inverse dynamics on 201 knots), sampled TV-LQR gains for a 200 Hz controller, and
closed loops from perturbed starts whose contacts are checked at every integrator step.

options:
  --out DIR             output folder (default output/hand)
  --runs N              closed loops, 1..1000 (default 20); the first 100 are written as
                        closed_loop_<k>.csv and drawn in the plots
  --seed S              seed of the perturbed starts (default 1; same seed, same starts)
  --perturbation SIZE   norm of each start's deviation, tangent to the constraint manifold, in
                        [rad, m, rad/s, m/s] (default 0.01; > 0)
  --threads N           threads for the closed loops, the gains' plant runs and the optimizer's
                        Hessian blocks, 1..64 (default: the machine's cores)
  --no-plots            skip the PNG plots (they need python3-matplotlib)
  -h, --help            show this help

Files in DIR: reference.csv, closed_loop_<k>.csv (t, coordinates, rates, tensions, and each
contact's force lambda_<digit>_n/_t1/_t2 in its contact frame [N]), tracking_error.csv,
gains.csv, summary.txt, hand.html (3D view), ball_orientation.png, tensions.png, contacts.png,
tracking_error.png. Exit status 0 only when every closed loop kept every contact and converged
(final tracking error at most half the initial) and everything was written; else 1.
)";

constexpr int kMaxClosedLoopFiles = 100;

struct Options {
  std::string out = "output/hand";
  int runs = 20;
  unsigned seed = 1;
  double perturbation = 0.01;
  int threads = 0;  // 0: the machine's cores
  bool plots = true;
};

Options parseOptions(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out") o.out = hand::optionValue(argc, argv, i);
    else if (a == "--runs") o.runs = static_cast<int>(hand::integerOption(a, hand::optionValue(argc, argv, i), 1, 1000));
    else if (a == "--seed") o.seed = static_cast<unsigned>(hand::integerOption(a, hand::optionValue(argc, argv, i), 0, 4294967295L));
    else if (a == "--perturbation") o.perturbation = hand::positiveOption(a, hand::optionValue(argc, argv, i));
    else if (a == "--threads") o.threads = static_cast<int>(hand::integerOption(a, hand::optionValue(argc, argv, i), 1, 64));
    else if (a == "--no-plots") o.plots = false;
    else if (a == "-h" || a == "--help") {
      std::printf("%s", kHelp);
      std::exit(0);
    } else {
      throw std::invalid_argument("unknown option '" + a + "' (--help lists them)");
    }
  }
  return o;
}


/// The plot script started at the job's beginning (scripts/plot_ball_turn.py --arguments-on-stdin):
/// its Python and matplotlib imports, ~0.4 s, run on the core the optimizer's serial MUMPS phases
/// leave idle, and it draws as soon as the CSV files exist, while the gains' CSV and the 3D view
/// are written. A job that fails before the plots closes the pipe with nothing sent: the script
/// then exits (status 3) drawing nothing.
class Plotter {
 public:
  /// Starts `python script --arguments-on-stdin`; started() is false when it could not be.
  Plotter(const char* python, const std::string& script) {
    int fds[2];
    if (pipe2(fds, O_CLOEXEC) != 0) return;
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[0], STDIN_FILENO);  // dup2 clears CLOEXEC
    std::string exe = python, path = script, flag = "--arguments-on-stdin";
    char* argv[] = {exe.data(), path.data(), flag.data(), nullptr};
    const int spawned = posix_spawnp(&pid_, python, &actions, nullptr, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    close(fds[0]);
    if (spawned != 0) {
      pid_ = -1;
      close(fds[1]);
      return;
    }
    fd_ = fds[1];
  }
  Plotter(const Plotter&) = delete;
  Plotter& operator=(const Plotter&) = delete;
  /// An unfinished plotter (the job failed before the plots) gets EOF and is reaped.
  ~Plotter() {
    if (fd_ >= 0) close(fd_);
    if (pid_ > 0) waitpid(pid_, nullptr, 0);
  }
  bool started() const { return pid_ > 0; }

  /// Sends the arguments (each ended by NUL) and closes the pipe; false when the script is gone.
  bool send(const std::vector<std::string>& args) {
    if (fd_ < 0) return false;
    std::string data;
    for (const std::string& a : args) data += a + '\0';
    bool ok = true;
    for (std::size_t done = 0; ok && done < data.size();) {
      const ssize_t n = write(fd_, data.data() + done, data.size() - done);  // EPIPE: SIGPIPE is ignored
      if (n > 0) done += static_cast<std::size_t>(n);
      else ok = n < 0 && errno == EINTR;
    }
    close(fd_);
    fd_ = -1;
    return ok;
  }
  /// Waits for the script: true when it exited with status 0.
  bool wait() {
    if (pid_ <= 0) return false;
    int status = 0;
    pid_t r;
    do r = waitpid(pid_, &status, 0);
    while (r < 0 && errno == EINTR);
    pid_ = -1;
    return r > 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0;
  }

 private:
  pid_t pid_ = -1;
  int fd_ = -1;
};

/// A trajectory's CSV with its contact forces: Trajectory's columns (t, coordinates, d<coordinate>,
/// inputs; no input rates) and lambda_<digit>_n/_t1/_t2, written whole or not at all.
void writeWithContacts(const std::string& path, const Model& model, const hand::BallLimits& limits,
                       const Trajectory& trajectory) {
  const hand::ContactForces f = hand::contactForces(model, limits, trajectory);
  std::ostringstream csv;
  csv.precision(17);
  csv << 't';
  for (const std::string& name : trajectory.configNames()) csv << ',' << name;
  for (const std::string& name : trajectory.configNames()) csv << ",d" << name;
  for (const std::string& name : trajectory.inputNames()) csv << ',' << name;
  for (const std::string& name : f.names) csv << ',' << name;
  csv << '\n';
  for (int k = 0; k < trajectory.size(); ++k) {
    csv << trajectory.times()(k);
    for (int i = 0; i < trajectory.nx(); ++i) csv << ',' << trajectory.states()(i, k);
    for (int i = 0; i < trajectory.nu(); ++i) csv << ',' << trajectory.inputs()(i, k);
    for (int i = 0; i < f.lambda.rows(); ++i) csv << ',' << f.lambda(i, k);
    csv << '\n';
  }
  writeFileAtomically(path, csv.str());
}

}  // namespace

int main(int argc, char** argv) try {
  std::signal(SIGXFSZ, SIG_IGN);  // beyond a file-size limit a write fails (EFBIG) and is reported
  std::signal(SIGPIPE, SIG_IGN);  // a plot script that died early is a failed write (EPIPE), reported
  const Options options = parseOptions(argc, argv);
  const auto jobStart = Clock::now();
  std::unique_ptr<Plotter> plotter;
  if (options.plots) {
    std::fflush(stdout);
    const char* python = std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
    plotter = std::make_unique<Plotter>(python, std::string(TRELLIS_SOURCE_DIR) + "/scripts/plot_ball_turn.py");
  }
  Progress progress(6);
  std::filesystem::create_directories(options.out);

  // 1. Scene and limits -------------------------------------------------------------------------
  progress.begin("scene and limits");
  const std::string scenePath = std::string(TRELLIS_EXAMPLE_SCENES_DIR) + "/hand_ball.json";
  const std::string limitsPath = std::string(TRELLIS_HAND_DIR) + "/hand_ball_limits.json";
  const Scene scene = loadScene(scenePath);
  const Model& model = scene.model;
  const hand::BallLimits limits = hand::loadBallLimits(limitsPath, model);
  progress.end(format("%.0f coordinates, %.0f tendons, %.0f contact rows; mu = %.2f", model.nq(), model.nu(), model.nc(),
                      limits.friction) +
               format(", normal force >= %.3f N", limits.normalMin));

  // Closed loops, the gains' plant runs and the optimizer's Hessian blocks use this many threads.
  const int threads = options.threads > 0 ? options.threads : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));

  // 2. The turn, optimized ----------------------------------------------------------------------
  progress.begin("the turn optimized (Ipopt, exact Hessian)");
  hand::BallTurnOptions turn;
  turn.angle = 20.0 * std::numbers::pi / 180.0;
  turn.horizon = 2.0;
  turn.knots = 11;
  turn.implicitForm = true;
  const auto shared = std::make_shared<const Model>(model);
  const OptimalControlProblem problem = hand::makeBallTurnProblem(shared, scene.q, limits, turn);
  const OptimizerOptions oo = hand::ballTurnOptimizerOptions(threads);  // ball_turn.hpp
  const OptimizationResult opt = optimizeTrajectory(problem, oo);
  const bool converged = (opt.ipoptStatus == "Solve_Succeeded" || opt.ipoptStatus == "Solved_To_Acceptable_Level") &&
                         opt.trajectory.size() == turn.knots;
  progress.end(format("Ipopt %.0f iterations, cost %.4g, constraint violation %.1e", opt.iterations, opt.cost,
                      opt.constraintViolation) +
               " (" + opt.ipoptStatus + "); on its 11 knots the coarse mesh's own check: " +
               format("defect %.2g", opt.consistency.maxDefect));
  if (!converged) throw std::runtime_error("the optimizer did not converge: " + opt.describe());

  // 3. The reference the plant follows ------------------------------------------------------------
  progress.begin("the reference by inverse dynamics, checked");
  hand::InverseReferenceOptions ro;
  ro.knots = 201;
  const hand::InverseReference inv = hand::inverseDynamicsReference(model, limits, opt.trajectory, ro);
  if (!inv.ok) throw std::runtime_error("the redistribution failed: " + inv.message);
  const Trajectory& reference = inv.trajectory;
  const ConsistencyResult consistency = checkConsistency(model, reference);
  progress.end(format("relative residual %.1e, tensions >= %.2f N, normal forces >= %.4f N, friction ratio <= %.4f",
                      inv.maxRelativeResidual, inv.minTension, inv.minNormal, inv.worstFrictionRatio) +
               "; consistency: " + consistency.status.describe());
  if (!consistency.ok()) throw std::runtime_error("the reference is not consistent: " + consistency.status.describe());

  // 4. Gains and closed loops -------------------------------------------------------------------
  progress.begin("gains (200 Hz) and closed loops");
  hand::BallFeedbackOptions fo;
  fo.runs = options.runs;
  fo.seed = options.seed;
  fo.perturbation = options.perturbation;
  // The held feed-forward: the interval average of u_ref (tvlqr.hpp). On this turn it leaves the
  // same predicted deviation as the default "consistent" one (6.62e-3 against 6.57e-3) at a third
  // of the gains' time (7.9 s against 21 s: the consistent one runs the plant ~8 times per interval).
  fo.feedforward = SampledFeedforward::kAverage;
  fo.threads = threads;
  const hand::BallFeedbackResult fb = hand::runBallFeedback(model, limits, reference, fo);
  if (!fb.lqr.ok()) throw std::runtime_error("the gains failed: " + fb.lqr.describe());
  for (std::size_t r = 0; r < fb.runs.size(); ++r)
    if (!fb.runs[r].ok()) std::printf("      run %zu: %s\n", r, fb.runs[r].describe().c_str());
  progress.end(format("gains %.2f s, closed loops %.2f s; %.0f of %.0f runs failed", fb.gainSeconds, fb.closedLoopSeconds,
                      fb.failed, fb.runs.size()));

  // 5. Files and the 3D view ----------------------------------------------------------------------
  progress.begin("files, 3D view, plots");
  // The plots' CSV files first, then the plot script draws while the gains and the view are written.
  writeWithContacts(options.out + "/reference.csv", model, limits, reference);
  const int files = std::min(options.runs, kMaxClosedLoopFiles);
  std::vector<ViewTrajectory> shown{{"reference", reference, false}};
  {
    std::ostringstream csv;  // ‖x − x_ref‖₂ of every run at the reference's knots
    csv.precision(10);
    csv << 't';
    for (int r = 0; r < files; ++r) csv << ",run_" << r;
    csv << '\n';
    for (int k = 0; k < reference.size(); ++k) {
      csv << reference.times()(k);
      for (int r = 0; r < files; ++r) {
        const Eigen::VectorXd& e = fb.runs[r].simulation.trackingError;
        csv << ',';
        if (k < e.size()) csv << e(k);
      }
      csv << '\n';
    }
    writeFileAtomically(options.out + "/tracking_error.csv", csv.str());
  }
  for (int r = 0; r < files; ++r) {
    const Trajectory& t = fb.runs[r].simulation.trajectory;
    if (t.size() == 0) continue;
    writeWithContacts(options.out + "/closed_loop_" + std::to_string(r) + ".csv", model, limits, t);
    shown.push_back({"closed loop " + std::to_string(r), t, true});
  }
  bool plotsOk = true;
  if (plotter) {
    // --name=value: a path that begins with '-' stays a value.
    std::vector<std::string> args{"--out=" + options.out, "--limits=" + limitsPath, "--reference=" + options.out + "/reference.csv",
                                  "--tracking=" + options.out + "/tracking_error.csv"};
    for (int r = 0; r < files; ++r)
      if (fb.runs[r].simulation.trajectory.size() > 0) args.push_back("--closed=" + options.out + "/closed_loop_" + std::to_string(r) + ".csv");
    plotsOk = plotter->started() && plotter->send(args);
  }
  fb.lqr.gains.writeCsvFile(options.out + "/gains.csv");
  ViewOptions viewOptions;
  viewOptions.title = "human hand turning a ball: reference and closed loops";
  const ViewReport view = writeView(options.out + "/hand.html", scene, scene.q, shown, viewOptions);
  if (plotter) {
    plotsOk = plotter->wait() && plotsOk;
    if (!plotsOk) std::fprintf(stderr, "hand_main_job: error: the plots failed (scripts/plot_ball_turn.py; python3-matplotlib missing?)\n");
  }
  progress.end(format("hand.html %.2f MB, %.0f closed-loop files", static_cast<double>(view.bytes) / 1e6, files) +
               (options.plots ? (plotsOk ? ", plots written" : ", plots FAILED") : ", no plots"));

  // 6. Summary ------------------------------------------------------------------------------------
  progress.begin("summary");
  progress.end();
  const int yaw = model.configIndex("ball_yaw");
  const double turned = (reference.states()(yaw, reference.size() - 1) - reference.states()(yaw, 0)) * 180.0 / std::numbers::pi;
  double minNormal = std::min(inv.minNormal, fb.referenceMinNormal), worstFriction = std::max(inv.worstFrictionRatio, fb.referenceWorstFrictionRatio);
  for (const hand::BallRun& run : fb.runs) {
    minNormal = std::min(minNormal, run.minNormal);
    worstFriction = std::max(worstFriction, run.worstFrictionRatio);
  }
  // After the perturbation has decayed the error is the 200 Hz hold's own deviation from the
  // continuous reference (the gains' prediction, tvlqr.hpp): reported beside the final error.
  double plateau = 0.0;
  for (const hand::BallRun& run : fb.runs)
    for (int k = 0; k < run.simulation.trackingError.size() && k < reference.size(); ++k)
      if (reference.times()(k) >= 0.5) plateau = std::max(plateau, run.simulation.trackingError(k));
  std::ostringstream summary;
  summary << "\nhand main job (the hand turns a ball) — summary\n";
  const double whole = secondsSince(jobStart);
  progress.table(summary, whole);
  summary << "\n";
  summary << format("ball rotation: %.3f deg (target 20)\n", turned);
  summary << format("min normal force: %.4f N (margin %.3f N; over the reference's knots and every closed loop's checked points)\n",
                    minNormal, limits.normalMin);
  summary << format("worst friction ratio: %.4f (|lambda_t| / (mu lambda_n); the cone is 1)\n", worstFriction);
  summary << format("worst final/initial: %.3g (tracking error at 2 s over at t = 0; worst final error %.3g, worst ball orientation error %.3g deg)\n",
                    fb.worstErrorRatio, fb.worstFinalError, fb.worstOrientationError * 180.0 / std::numbers::pi);
  summary << format("tracking error from t = 0.5 s on: at most %.3g (the 200 Hz hold's own deviation from the reference; predicted %.3g)\n",
                    plateau, fb.lqr.predictedDeviation);
  summary << format("N failed: %.0f of %.0f closed loops (%.0f broke a contact)\n", fb.failed, fb.runs.size(), fb.contactFailures);
  summary << format("optimizer: %.0f Ipopt iterations on %.0f knots, %.2f s: ", opt.iterations, turn.knots, opt.solveTime) +
                 format("evaluations %.2f s (the Hessian %.2f s; %.0f linearizations, ", opt.evaluationTime, opt.hessianTime,
                        opt.linearizationEvaluations) +
                 format("%.0f second-order), the a-posteriori check %.2f s, Ipopt with MUMPS %.2f s\n", opt.secondOrderEvaluations,
                        opt.checkTime, opt.solveTime - opt.evaluationTime - opt.checkTime);
  summary << format("reference: %.0f knots, consistency defect %.2g (tolerance 1e-3), gains: %.0f rows of K at 200 Hz\n",
                    reference.size(), consistency.maxDefect, fb.lqr.gains.size());
  summary << format("whole job: %.2f s\n", whole);
  summary << "files: " << std::filesystem::absolute(options.out).string() << "/\n";
  const bool ok = plotsOk && fb.ok() && minNormal >= limits.normalMin && worstFriction <= 1.0;
  summary << (ok ? "ok\n" : "FAILED\n");
  std::printf("%s", summary.str().c_str());
  writeFileAtomically(options.out + "/summary.txt", summary.str());
  return ok ? 0 : 1;
} catch (const std::exception& e) {
  std::fprintf(stderr, "hand_main_job: error: %s\n", e.what());
  return 1;
}
