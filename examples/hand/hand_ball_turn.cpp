// examples/hand/hand_ball_turn.cpp — the hand turns a free ball (issue 26, step 2): optimizes the
// turn of ball_turn.hpp on a free-ball hand scene and checks the contacts along the result.
//
//   hand_ball_turn [--scene NAME] [--angle DEG] [--horizon S] [--knots N] [--facets F] [--print-level L]
//                  [--lbfgs] [--holds] [--diagnose] [--max-iterations N] [--barrier MU] [--bound-push P]
//                  [--implicit] [--effort-scale C] [--fixed-start]
//
// The turn starts at rest near the scene's stored grasp (the start's configuration is free: the
// stored grasp is no hold with pushing pads; the program prints how far it is from one).
// --lbfgs: Ipopt's limited-memory Hessian instead of the exact one. --implicit: the transcription's
// implicit dynamics form (q̈ and λ as variables, the equations of motion as rows in force units;
// problem.hpp DynamicsForm). --acceleration-weight W: with --implicit, BallTurnOptions::
// accelerationWeight (10; 0: none). --effort-scale C: BallTurnOptions::effortScale (1e-3). --fixed-start:
// the turn starts at the stored grasp itself (BallTurnOptions::freeInitialConfiguration false).
// --holds: the warm start is the path of holds (quasiStaticHolds at every collocation point, the
// dampers' load included) and the motion starts at its first hold; Ipopt then starts there with
// μ_init 1e-2 and bound_push 1e-8 (--barrier, --bound-push override). --diagnose: the guess's
// worst rows, each point's |q̈|, and the rank of the equality rows over the variables inside their
// bounds there (reportActiveRank: where active bounds leave rows dependent, LICQ fails). --max-iterations: Ipopt's limit (500);
// --refinements R: rounds of mesh refinement after the first solve (OptimizerOptions::maxRefinements; 0: check only).
// --out CSV: the returned trajectory (written whatever the status; the line says whether it is a solution).
// --method hermite_simpson|trapezoidal|radau: the collocation rule (problem.hpp CollocationMethod). --friction-use F: the
// share of the pyramid the holds may use (0.8); --hold-margin N: their margin cap (1 N; above it
// they minimize effort). --reach: only the kinematic reach (kinematicReach).
// NAME: a scene of examples/scenes written by make_hand_scene.py --free-ball (default hand_ball;
// hand_ball_pinch is the thumb-and-index reduction), read with examples/hand/NAME_limits.json. Prints the
// optimizer's one-line result, its time split, and the contact margins at every collocation point:
// the smallest normal force and the largest ‖λ_t‖ / (μ λ_n). Exit status 0 only when the
// optimizer reports solved (its a-posteriori consistency check included), the ball turned by the
// angle, and every point keeps λ_n ≥ the margin and ‖λ_t‖ ≤ μ λ_n; 1 otherwise; 2 on bad arguments.
#include "ball_turn.hpp"
#include "grasp.hpp"

#include <trellis/core.hpp>
#include <Eigen/SVD>
#include <trellis/core/second_order.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>
#include <iostream>
#include <numbers>
#include <string>

using namespace trellis;

namespace {

/// --diagnose: the rank of the equality rows' Jacobian over the variables strictly inside their
/// bounds at z (bounds within 1e-6 of z count as active). A combination of rows that loses every
/// free variable with the active bounds makes the active constraints' gradients dependent (LICQ
/// fails at z), where an interior-point method's multipliers and steps grow without limit. Rows
/// are scaled to unit largest entry; singular values below 1e-10 of the largest count as zero;
/// for the first three null vectors the rows with the largest weights are named.
void reportActiveRank(Transcription& tr, const Eigen::VectorXd& z, const Model& model, double tol = 1e-6) {
  Eigen::VectorXd zl, zu, gl, gu, g(tr.numConstraints());
  tr.variableBounds(zl, zu);
  tr.constraintBounds(gl, gu);
  if (!tr.evalConstraints(z.data(), g.data())) return;
  std::vector<double> values(tr.jacobianRows().size());
  if (!tr.evalJacobian(z.data(), values.data())) {
    std::printf("active rank: the Jacobian failed: %s\n", tr.lastError().c_str());
    return;
  }
  std::vector<int> column(tr.numVariables(), -1), row(tr.numConstraints(), -1), rowOf;
  int free = 0, active = 0;
  for (int i = 0; i < tr.numVariables(); ++i) {
    if (!(zl(i) < zu(i))) continue;  // fixed by the problem
    if (z(i) - zl(i) > tol && zu(i) - z(i) > tol) column[i] = free++;
    else ++active;
  }
  int nearInequalities = 0;
  for (int i = 0; i < tr.numConstraints(); ++i)
    if (gl(i) == gu(i) || std::min(g(i) - gl(i), gu(i) - g(i)) <= tol) {
      nearInequalities += gl(i) == gu(i) ? 0 : 1;
      row[i] = static_cast<int>(rowOf.size());
      rowOf.push_back(i);
    }
  const int eq = static_cast<int>(rowOf.size());
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(eq, free);
  for (std::size_t e = 0; e < values.size(); ++e) {
    const int r = row[tr.jacobianRows()[e]], c = column[tr.jacobianCols()[e]];
    if (r >= 0 && c >= 0) J(r, c) += values[e];
  }
  for (int i = 0; i < eq; ++i) {
    const double largest = J.row(i).cwiseAbs().maxCoeff();
    if (largest > 0.0) J.row(i) /= largest;
  }
  const Eigen::BDCSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeThinU);
  const Eigen::VectorXd& sv = svd.singularValues();
  int zeros = 0;
  for (Eigen::Index i = 0; i < sv.size(); ++i) zeros += sv(i) < 1e-10 * sv(0) ? 1 : 0;
  zeros += std::max(0, eq - free);
  std::printf("active rank (tolerance %g): %d equality and %d active inequality rows over %d free variables (%d "
              "bounds active): %d dependent row combinations; smallest nonzero singular value %.3g of %.3g\n",
              tol, eq - nearInequalities, nearInequalities, free, active, zeros,
              sv(sv.size() - 1 - std::min<Eigen::Index>(zeros, sv.size() - 1)), sv(0));
  const int n = model.nq(), nc = model.nc(), P = tr.numPoints(), N = tr.numKnots();
  const int defectRows = tr.knotConstraintRow(0) >= 0 ? tr.knotConstraintRow(0) : tr.numConstraints();
  const int perInterval = defectRows / std::max(1, N - 1);
  const int dynRows = n + nc, dynStart = tr.problem().dynamics == DynamicsForm::kImplicit ? tr.numConstraints() - P * dynRows : tr.numConstraints();
  const auto& names = model.configNames();
  auto describe = [&](int r) {
    char b[160];
    if (r < defectRows) {
      const int o = r % perInterval;
      const int nx = 2 * n;
      std::snprintf(b, sizeof b, "interval %d %s %s", r / perInterval, o < nx ? "simpson" : o < 2 * nx ? "hermite" : "input-average",
                    o < 2 * nx ? (o % nx < n ? names[o % n].c_str() : ("d" + names[o % n]).c_str()) : std::to_string(o - 2 * nx).c_str());
    } else if (r < defectRows + N * 2 * nc) {
      const int o = (r - defectRows) % (2 * nc);
      std::snprintf(b, sizeof b, "knot %d %s row %d", (r - defectRows) / (2 * nc), o < nc ? "h" : "A q'", o % nc);
    } else if (r >= dynStart) {
      const int o = (r - dynStart) % dynRows;
      std::snprintf(b, sizeof b, "point %d %s %s", (r - dynStart) / dynRows, o < n ? "r" : "c",
                    o < n ? names[o].c_str() : std::to_string(o - n).c_str());
    } else {
      const int f0 = tr.forceRow(0), nF = tr.forceRowsPerPoint();
      if (f0 >= 0 && r >= f0 && nF > 0) {
        const int j = (r - f0) % nF, nBox = nF - static_cast<int>(tr.problem().forceCombinations.size());
        std::snprintf(b, sizeof b, "point %d %s", (r - f0) / nF,
                      j < nBox ? ("lambda bound " + std::to_string(j)).c_str()
                               : tr.problem().forceCombinations[j - nBox].name.c_str());
      } else {
        std::snprintf(b, sizeof b, "row %d", r);
      }
    }
    return std::string(b);
  };
  for (int j = 0; j < std::min<int>(3, zeros) && j < sv.size(); ++j) {
    const Eigen::VectorXd w = svd.matrixU().col(sv.size() - 1 - j);
    std::vector<int> order(eq);
    for (int i = 0; i < eq; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](int a, int b) { return std::abs(w(a)) > std::abs(w(b)); });
    std::printf("  dependent combination %d:", j + 1);
    for (int k = 0; k < std::min(6, eq); ++k) std::printf(" [%s %.2f]", describe(rowOf[order[k]]).c_str(), w(order[k]));
    std::printf("\n");
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene = "hand_ball";
  hand::BallTurnOptions options;
  int printLevel = 0;
  bool lbfgs = false, holds = false, diagnose = false, reach = false;
  hand::RestHoldOptions holdOptions;
  int maxIterations = 500;
  CollocationMethod method = CollocationMethod::kHermiteSimpson;  // --method
  std::string outFile;   // --out: the optimizer's trajectory as CSV (trajectory.hpp), whatever its status
  int refinements = -1;  // --refinements: OptimizerOptions::maxRefinements (-1: its default)
  double barrier = 0.0, boundPush = 0.0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "hand_ball_turn: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    try {
      if (a == "--scene") scene = value();
      else if (a == "--angle") options.angle = std::stod(value()) * std::numbers::pi / 180.0;
      else if (a == "--horizon") options.horizon = std::stod(value());
      else if (a == "--knots") options.knots = std::stoi(value());
      else if (a == "--facets") options.facets = std::stoi(value());
      else if (a == "--print-level") printLevel = std::stoi(value());
      else if (a == "--lbfgs") lbfgs = true;
      else if (a == "--implicit") options.implicitForm = true;
      else if (a == "--acceleration-weight") options.accelerationWeight = std::stod(value());
      else if (a == "--effort-scale") options.effortScale = std::stod(value());
      else if (a == "--fixed-start") options.freeInitialConfiguration = false;
      else if (a == "--holds") holds = true;
      else if (a == "--diagnose") diagnose = true;
      else if (a == "--reach") reach = true;
      else if (a == "--friction-use") holdOptions.frictionUse = std::stod(value());
      else if (a == "--hold-margin") holdOptions.marginCap = std::stod(value());
      else if (a == "--max-iterations") maxIterations = std::stoi(value());
      else if (a == "--refinements") refinements = std::stoi(value());
      else if (a == "--out") outFile = value();
      else if (a == "--method") {
        const std::string v = value();
        if (v == "hermite_simpson") method = CollocationMethod::kHermiteSimpson;
        else if (v == "trapezoidal") method = CollocationMethod::kTrapezoidal;
        else if (v == "radau") method = CollocationMethod::kRadau;
        else {
          std::cerr << "hand_ball_turn: --method: '" << v << "' (expected hermite_simpson, trapezoidal or radau)\n";
          return 2;
        }
      }
      else if (a == "--barrier") barrier = std::stod(value());
      else if (a == "--bound-push") boundPush = std::stod(value());
      else if (a == "--help") {
        std::cout << "usage: hand_ball_turn [--scene NAME] [--angle DEG] [--horizon S] [--knots N] "
                     "[--facets F] [--print-level L] [--lbfgs] [--holds] [--diagnose] [--max-iterations N] [--refinements R] [--out CSV] [--method M] "
                     "[--barrier MU] [--bound-push P] [--implicit] [--acceleration-weight W] [--effort-scale C] [--fixed-start] [--friction-use F] "
                     "[--hold-margin N] [--reach]\n";
        return 0;
      } else {
        std::cerr << "hand_ball_turn: unknown option '" << a << "' (--help lists them)\n";
        return 2;
      }
    } catch (const std::exception&) {
      std::cerr << "hand_ball_turn: " << a << ": '" << argv[i] << "' is not a number\n";
      return 2;
    }
  }
  const std::string dir = TRELLIS_EXAMPLE_SCENES_DIR;
  const auto t0 = std::chrono::steady_clock::now();
  Scene s;
  hand::BallLimits limits;
  OptimalControlProblem problem;
  try {
    s = loadScene(dir + "/" + scene + ".json");
    auto model = std::make_shared<const Model>(s.model);
    limits = hand::loadBallLimits(std::string(TRELLIS_HAND_DIR) + "/" + scene + "_limits.json", *model);
    if (reach) {
      const auto tk = std::chrono::steady_clock::now();
      const hand::KinematicReach k = hand::kinematicReach(s.model, limits, s.q, options.angle, 1.0 * std::numbers::pi / 180.0,
                                                          0.01 * std::numbers::pi / 180.0);
      std::printf("kinematic reach: yaw %.3f deg held with the pads on the ball and the joints in range; "
                  "%.3f deg: %s (%d solves, %.2f s); at range ends:",
                  k.reached * 180.0 / std::numbers::pi, k.limit * 180.0 / std::numbers::pi, k.stop.c_str(), k.solves,
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - tk).count());
      for (const auto& c : k.atRangeEnds) std::printf(" %s", c.c_str());
      std::printf("\n");
      return k.reached >= options.angle ? 0 : 1;
    }
    if (holds) options.freeInitialConfiguration = false;
    problem = hand::makeBallTurnProblem(model, s.q, limits, options);
    problem.method = method;
    if (holds) {
      const auto th = std::chrono::steady_clock::now();
      // Holds at every collocation point (knots and midpoints): the midpoints' dynamics then start
      // near rest too (a light phalanx's q̈ is ~10⁴ times its force imbalance).
      hand::BallTurnOptions points = options;
      points.knots = 2 * options.knots - 1;
      const hand::HoldPath path = hand::quasiStaticHolds(*model, s.q, s.u, limits, points, holdOptions);
      std::printf("holds: %s, %d solves, largest yaw held %.3f deg, %.3f s\n", path.complete ? "complete" : path.message.c_str(),
                  path.solves, path.reached * 180.0 / std::numbers::pi,
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - th).count());
      for (const auto& h : path.holds)
        std::printf("  hold: margin %.4f N, %d iterations, max u %.2f N\n", h.margin, h.nlp.iterations, h.u.maxCoeff());
      if (!path.holds.empty()) {
        // Where the last hold meets the joint ranges (what limits the turn).
        const Eigen::VectorXd& q = path.holds.back().q;
        std::printf("  last hold at its range ends:");
        for (int i = 0; i < model->nq(); ++i)
          if (std::min(q(i) - limits.qLower(i), limits.qUpper(i) - q(i)) < 1e-4)
            std::printf(" %s", model->configNames()[i].c_str());
        std::printf("\n");
      }
      if (!path.complete) return 1;
      if (diagnose) {
        Data dd(*model);
        const int n = model->nq();
        for (int k = 0; k < path.guess.size(); ++k) {
          const Eigen::VectorXd x = path.guess.states().col(k);
          computeDynamics(*model, dd, x.head(n), Eigen::VectorXd::Zero(n), path.guess.inputs().col(k));
          const double a0 = dd.qdd.cwiseAbs().maxCoeff();
          computeDynamics(*model, dd, x.head(n), x.tail(n), path.guess.inputs().col(k));
          std::printf("point %d: |qdd| at rest %.3g, with the guess velocity %.3g, |qd| %.3g\n", k, a0,
                      dd.qdd.cwiseAbs().maxCoeff(), x.tail(n).cwiseAbs().maxCoeff());
        }
      }
      problem.initialGuess = path.guess;
      problem.initialState.head(model->nq()) = path.holds.front().q;
    }
  } catch (const std::exception& e) {
    std::cerr << "hand_ball_turn: " << e.what() << "\n";
    return 2;
  }
  std::printf("scene %s: %d coordinates, %d tendons, %d contact rows; turn %.2f deg in %.2f s, %d knots, "
              "%d-facet pyramid, mu = %.2f, normal >= %.3f N\n",
              scene.c_str(), s.model.nq(), s.model.nu(), s.model.nc(), options.angle * 180.0 / std::numbers::pi,
              options.horizon, options.knots, options.facets, limits.friction, limits.normalMin);
  // The start: how far the stored grasp is from a hold inside the pyramid (grasp.hpp; 0 = a hold).
  {
    const hand::PyramidHold h = hand::pyramidHold(s.model, s.q, limits.normalMin,
                                                  limits.friction * std::cos(std::numbers::pi / options.facets),
                                                  options.facets);
    Eigen::Index worst = 0;
    if (h.ok) h.residual.cwiseAbs().maxCoeff(&worst);
    std::printf("stored grasp: the best hold with u >= 0 and the contacts inside the pyramid leaves %.3g of the "
                "static load unbalanced (0: an equilibrium), most on %s\n",
                h.ok ? h.relativeResidual : NAN, s.model.configNames()[worst].c_str());
  }
  if (diagnose) {
    Transcription tr(problem);
    Eigen::VectorXd z = tr.initialGuess(), g(tr.numConstraints()), lo, hi;
    tr.constraintBounds(lo, hi);
    tr.evalConstraints(z.data(), g.data());
    const Eigen::VectorXd v = (lo - g).cwiseMax(g - hi).cwiseMax(0.0);
    std::vector<int> idx(v.size());
    for (int i = 0; i < v.size(); ++i) idx[i] = i;
    std::sort(idx.begin(), idx.end(), [&](int a, int b) { return v(a) > v(b); });
    const int n = s.model.nq(), m = s.model.nu();
    reportActiveRank(tr, z, s.model);
    const int perInterval = 4 * n + m;
    for (int k = 0; k < 15; ++k) {
      const int r = idx[k];
      std::printf("row %d: violation %.3g (interval %d, offset %d of %d)\n", r, v(r), r / perInterval, r % perInterval, perInterval);
    }
  }
  OptimizerOptions oo;
  oo.printLevel = printLevel;
  if (lbfgs) oo.hessian = HessianMode::kLimitedMemory;
  if (holds) {
    // The path of holds is nearly a solution: start there (tensions at 0 stay near 0).
    oo.initialBarrier = 1e-2;
    oo.initialBoundPush = 1e-8;
  }
  if (barrier > 0.0) oo.initialBarrier = barrier;
  if (boundPush > 0.0) oo.initialBoundPush = boundPush;
  oo.maxIterations = maxIterations;
  if (refinements >= 0) oo.maxRefinements = refinements;
  const OptimizationResult r = optimizeTrajectory(problem, oo);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("optimizer: %s\n", r.describe().c_str());
  if (diagnose && !r.ok() && r.variables.size() > 0) {
    // Where the solve stopped: the same rank report at the returned iterate (its own mesh).
    OptimalControlProblem last = problem;
    last.knots = r.trajectory.size();
    last.mesh = r.trajectory.size() > 1 ? Eigen::VectorXd(r.trajectory.times() / r.trajectory.times()(r.trajectory.size() - 1)) : Eigen::VectorXd();
    Transcription tr(last);
    if (tr.numVariables() == r.variables.size()) {
      for (const double tol : {1e-6, 1e-3, 1e-2}) {
        std::printf("at the returned iterate: ");
        reportActiveRank(tr, r.variables, s.model, tol);
      }
    }
  }
  std::printf("evaluations: %ld dynamics, %ld linearizations, %ld second-order; solve %.3f s wall, %.3f s CPU\n",
              r.dynamicsEvaluations, r.linearizationEvaluations, r.secondOrderEvaluations, r.solveTime,
              r.solveCpuTime);
  // The time split: each kind of evaluation timed alone at the grasp (200 calls, the fastest of 3
  // batches) times the count the solve made; the rest of the solve is Ipopt (MUMPS included), the
  // transcription's own assembly and the a-posteriori check.
  {
    const int n = s.model.nq();
    Data data(s.model);
    SecondOrderWorkspace ws(s.model);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n), w = Eigen::VectorXd::Ones(n),
                          rho = Eigen::VectorXd::Ones(s.model.nc());
    Eigen::MatrixXd H(2 * n + s.model.nu(), 2 * n + s.model.nu());
    const auto perCall = [&](const auto& call) {
      double best = 1e300;
      for (int batch = 0; batch < 3; ++batch) {
        const auto a = std::chrono::steady_clock::now();
        for (int k = 0; k < 200; ++k) call();
        best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count() / 200);
      }
      return best;
    };
    const double tDyn = perCall([&] { computeDynamics(s.model, data, s.q, zero, s.u); });
    const double tLin = perCall([&] { computeLinearization(s.model, data, s.q, zero, s.u); });
    const double tSec = perCall([&] { computeSecondOrderContraction(s.model, data, ws, s.q, zero, s.u, w, rho, H); });
    const double dyn = tDyn * r.dynamicsEvaluations, lin = tLin * r.linearizationEvaluations,
                 sec = tSec * r.secondOrderEvaluations;
    std::printf("time split (per-call cost x count, estimated): dynamics %.3f s (%.1f us each), derivatives %.3f s "
                "(%.1f us), second order %.3f s (%.1f us); the rest (Ipopt/MUMPS, assembly, check) %.3f s\n",
                dyn, 1e6 * tDyn, lin, 1e6 * tLin, sec, 1e6 * tSec, r.solveTime - dyn - lin - sec);
  }
  bool ok = r.ok();
  if (!r.trajectory.size()) {
    std::printf("no trajectory\n");
    return 1;
  }
  if (!outFile.empty()) {
    try {
      r.trajectory.writeCsvFile(outFile);
      std::printf("wrote %s (%s)\n", outFile.c_str(), r.ok() ? "ok" : "NOT a solution: see the optimizer line");
    } catch (const std::exception& e) {
      std::printf("%s\n", e.what());
      return 1;
    }
  }
  // Contacts at the knots (the collocation points the bounds hold at, evaluated again here).
  Data data(s.model);
  const Trajectory& tr = r.trajectory;
  const int n = s.model.nq();
  double minNormal = 1e300, worstRatio = 0.0;
  for (int k = 0; k < tr.size(); ++k) {
    const Eigen::VectorXd x = tr.states().col(k);
    if (!computeDynamics(s.model, data, x.head(n), x.tail(n), tr.inputs().col(k)).ok()) {
      std::printf("dynamics failed at knot %d\n", k);
      return 1;
    }
    const hand::ContactMargins c = hand::contactMargins(data.lambda, limits);
    minNormal = std::min(minNormal, c.minNormal);
    worstRatio = std::max(worstRatio, c.worstFrictionRatio);
  }
  const double yawEnd = tr.states()(s.model.configIndex("ball_yaw"), tr.size() - 1);
  std::printf("ball rotation: %.3f deg\n", yawEnd * 180.0 / std::numbers::pi);
  std::printf("min normal force: %.4f N (margin %.3f N)\n", minNormal, limits.normalMin);
  std::printf("worst friction ratio: %.4f (cone: 1)\n", worstRatio);
  std::printf("whole job: %.3f s\n", seconds);
  // Tolerances: Ipopt's constraint tolerance is absolute (1e-8 N on the force rows).
  ok = ok && minNormal >= limits.normalMin - 1e-6 && worstRatio <= 1.0 + 1e-6;
  std::printf("%s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
