// examples/hand/ball_feedback.cpp — see ball_feedback.hpp.
#include "ball_feedback.hpp"

#include "hand_feedback.hpp"

#include <trellis/core/data.hpp>
#include <trellis/core/dynamics.hpp>
#include <trellis/core/linearization.hpp>
#include <trellis/core/model.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>
#include <thread>

namespace trellis::hand {

namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::string format(const char* fmt, double a, double b = 0.0, double c = 0.0, double d = 0.0) {
  char buffer[256];
  std::snprintf(buffer, sizeof buffer, fmt, a, b, c, d);
  return buffer;
}

Eigen::Matrix3d zyx(const Eigen::Vector3d& a) {
  return (Eigen::AngleAxisd(a(0), Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(a(1), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(a(2), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

}  // namespace

void BallFeedbackOptions::validate() const {
  const auto bad = [](const char* field, double value, const char* rule) {
    throw std::invalid_argument(std::string("BallFeedbackOptions.") + field + " = " + format("%.17g", value) +
                                ": must be " + rule);
  };
  if (!(sampleRate > 0.0) || !std::isfinite(sampleRate)) bad("sampleRate", sampleRate, "> 0 and finite");
  if (runs < 0) bad("runs", runs, ">= 0");
  if (!(perturbation > 0.0) || !std::isfinite(perturbation)) bad("perturbation", perturbation, "> 0 and finite");
  if (!(maxErrorRatio > 0.0) || !std::isfinite(maxErrorRatio)) bad("maxErrorRatio", maxErrorRatio, "> 0 and finite");
  if (threads < 1) bad("threads", threads, ">= 1");
  if (transportSubsteps < 1) bad("transportSubsteps", transportSubsteps, ">= 1");
  if (!(rtol > 0.0) || !std::isfinite(rtol)) bad("rtol", rtol, "> 0 and finite");
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol, "> 0 and finite");
  if (!(newtonTolerance >= 0.0 && newtonTolerance < 1.0)) bad("newtonTolerance", newtonTolerance, "0 or in (0, 1)");
  if (!(driftTolerance > 0.0) || !std::isfinite(driftTolerance)) bad("driftTolerance", driftTolerance, "> 0 and finite");
  if (std::string(toString(method)) == "unknown") bad("method", static_cast<double>(method), "adams, bdf or radau");
}

std::string ContactCheck::operator()(double t, const Eigen::VectorXd& lambda) {
  const BallLimits& l = *limits_;
  const ContactMargins c = contactMargins(lambda, l);
  if (c.minNormal < minNormal) {
    minNormal = c.minNormal;
    minNormalContact = c.minNormalContact;
  }
  if (c.worstFrictionRatio > worstFrictionRatio) {
    worstFrictionRatio = c.worstFrictionRatio;
    worstFrictionContact = c.worstFrictionContact;
  }
  // Unilateral first: without a positive normal force the cone means nothing.
  const bool normal = c.minNormal < l.normalMin;
  if (!normal && !(c.worstFrictionRatio > 1.0)) return {};
  const int d = normal ? c.minNormalContact : c.worstFrictionContact;
  violation = normal ? BallRunCode::kNormalForce : BallRunCode::kFrictionCone;
  violationContact = d;
  violationTime = t;
  const double ln = lambda(3 * d), lt1 = lambda(3 * d + 1), lt2 = lambda(3 * d + 2);
  const double lt = std::hypot(lt1, lt2);
  const std::string where = "contact " + l.digits[d] + " (rows " + std::to_string(3 * d) + ".." +
                            std::to_string(3 * d + 2) + ")";
  if (normal) {
    violationText = where + format(": normal force lambda_n = %.6g N below the margin %.6g N (lambda_t = (%.6g, %.6g) N)",
                                   ln, l.normalMin, lt1, lt2);
  } else {
    violationText = where + format(": outside the friction cone, |lambda_t| = %.6g N > mu lambda_n = %.6g N (ratio "
                                   "%.6g, lambda_n = %.6g N)",
                                   lt, l.friction * ln, c.worstFrictionRatio, ln);
  }
  return violationText;
}

ContactForces contactForces(const Model& model, const BallLimits& limits, const Trajectory& trajectory) {
  trajectory.checkCompatible(model);
  if (static_cast<int>(limits.digits.size()) * 3 != model.nc()) {
    throw std::invalid_argument("contactForces: " + std::to_string(limits.digits.size()) + " contacts in the limits, " +
                                std::to_string(model.nc()) + " constraint rows in the model");
  }
  ContactForces out;
  for (const std::string& d : limits.digits) {
    for (const char* axis : {"_n", "_t1", "_t2"}) out.names.push_back("lambda_" + d + axis);
  }
  const int n = model.nq();
  Data data(model);
  out.lambda.resize(model.nc(), trajectory.size());
  for (int k = 0; k < trajectory.size(); ++k) {
    const Eigen::VectorXd x = trajectory.states().col(k), u = trajectory.inputs().col(k);
    if (!computeDynamics(model, data, x.head(n), x.tail(n), u).ok()) {
      throw std::runtime_error("contactForces: the dynamics fail at row " + std::to_string(k) + " (t = " +
                               format("%.17g", trajectory.times()(k)) + "): " + data.status.message);
    }
    out.lambda.col(k) = data.lambda;
  }
  return out;
}

double ballOrientationError(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return Eigen::AngleAxisd(zyx(a).transpose() * zyx(b)).angle();
}

Trajectory holdReference(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& u, double horizon,
                         double spacing) {
  if (q.size() != model.nq()) throw std::invalid_argument("holdReference: q has size " + std::to_string(q.size()) +
                                                          ", the model has nq = " + std::to_string(model.nq()));
  if (u.size() != model.nu()) throw std::invalid_argument("holdReference: u has size " + std::to_string(u.size()) +
                                                          ", the model has nu = " + std::to_string(model.nu()));
  if (!(horizon > 0.0) || !std::isfinite(horizon)) throw std::invalid_argument("holdReference: horizon = " + format("%.17g", horizon) + ": must be > 0 and finite");
  if (!(spacing > 0.0) || !std::isfinite(spacing)) throw std::invalid_argument("holdReference: spacing = " + format("%.17g", spacing) + ": must be > 0 and finite");
  std::vector<double> t;
  for (long k = 0; k * spacing < horizon - 1e-9 * spacing; ++k) t.push_back(k * spacing);
  t.push_back(horizon);
  const auto N = static_cast<Eigen::Index>(t.size());
  Eigen::MatrixXd X(2 * model.nq(), N), U(model.nu(), N);
  for (Eigen::Index k = 0; k < N; ++k) {
    X.col(k) << q, Eigen::VectorXd::Zero(model.nq());
    U.col(k) = u;
  }
  return Trajectory(model.configNames(), model.inputNames(), Eigen::Map<const Eigen::VectorXd>(t.data(), N), X, U);
}

std::string BallRun::describe() const {
  std::string line = status.describe();
  line += format(" | min lambda_n %.4g N, worst friction ratio %.4g", minNormal, worstFrictionRatio);
  line += format(" | error %.3g -> %.3g (ratio %.3g), ball orientation %.3g deg", initialError, finalError, errorRatio,
                 orientationError * 180.0 / std::numbers::pi);
  line += format(" | %.3f s, %.0f steps, %.0f right-hand sides,", seconds, static_cast<double>(simulation.steps),
                 static_cast<double>(simulation.rhsEvaluations));
  line += format(" %.0f checks, %.0f Jacobians", static_cast<double>(simulation.checks),
                 static_cast<double>(simulation.jacobianEvaluations));
  return line;
}

std::string BallFeedbackResult::summary() const {
  std::string s = format("reference at its knots: min normal force %.4g N (knot %.0f), worst friction ratio %.4g "
                         "(knot %.0f)\n",
                         referenceMinNormal, referenceMinNormalKnot, referenceWorstFrictionRatio,
                         referenceWorstFrictionKnot);
  s += "gains: " + lqr.describe() + format(" (%.3f s)\n", gainSeconds);
  for (std::size_t r = 0; r < runs.size(); ++r) {
    if (!runs[r].ok()) s += "run " + std::to_string(r) + ": " + runs[r].describe() + "\n";
  }
  s += format("closed loops: %.0f runs, %.0f failed (%.0f broke a contact), %.3f s", static_cast<double>(runs.size()),
              failed, contactFailures, closedLoopSeconds);
  s += format("\nmin normal force %.4g N, worst friction ratio %.4g, worst final/initial %.3g, worst final error %.3g",
              minNormal, worstFrictionRatio, worstErrorRatio, worstFinalError);
  s += format(", worst ball orientation error %.3g deg\n", worstOrientationError * 180.0 / std::numbers::pi);
  return s;
}

BallFeedbackResult runBallFeedback(const Model& model, const BallLimits& limits, const Trajectory& given,
                                   const BallFeedbackOptions& options) {
  options.validate();
  given.checkCompatible(model);
  // The reference with its state derivatives (x_ref's Hermite spline needs them; computed once
  // here instead of by every solve and run).
  Data data(model);
  Trajectory withDerivatives;
  if (!given.hasStateDerivatives()) {
    withDerivatives = given;
    withDerivatives.computeStateDerivatives(model, data);
  }
  const Trajectory& reference = given.hasStateDerivatives() ? given : withDerivatives;
  const int n = model.nq(), m = model.nu();
  if (limits.uMax.size() != m || static_cast<int>(limits.digits.size()) * 3 != model.nc()) {
    throw std::invalid_argument("runBallFeedback: the limits (" + std::to_string(limits.uMax.size()) + " tensions, " +
                                std::to_string(limits.digits.size()) + " contacts) do not match the model (nu = " +
                                std::to_string(m) + ", nc = " + std::to_string(model.nc()) + ")");
  }
  // The tangent space keeps its dimension along the reference (the transport cannot follow a
  // change): checked at the knots, where the reference's own contact forces are measured too.
  BallFeedbackResult result;
  result.referenceMinNormal = INFINITY;
  {
    int d0 = -1;
    const Eigen::MatrixXd& X = reference.states();
    for (int k = 0; k < reference.size(); ++k) {
      const Eigen::VectorXd x = X.col(k), u = reference.inputs().col(k);
      if (!computeLinearization(model, data, x.head(n), x.tail(n), u).ok()) {
        throw std::invalid_argument("runBallFeedback: the dynamics fail at the reference's knot " + std::to_string(k) +
                                    " (t = " + format("%.17g", reference.times()(k)) + "): " + data.status.message);
      }
      const ContactMargins c = contactMargins(data.lambda, limits);
      if (c.minNormal < result.referenceMinNormal) {
        result.referenceMinNormal = c.minNormal;
        result.referenceMinNormalKnot = k;
      }
      if (c.worstFrictionRatio > result.referenceWorstFrictionRatio || result.referenceWorstFrictionKnot < 0) {
        result.referenceWorstFrictionRatio = c.worstFrictionRatio;
        result.referenceWorstFrictionKnot = k;
      }
      const int d = computeConstraintTangentBasis(model, data);
      if (d0 < 0) d0 = d;
      if (d != d0) {
        throw std::invalid_argument("runBallFeedback: the tangent space has dimension " + std::to_string(d) +
                                    " at the reference's knot " + std::to_string(k) + " (t = " +
                                    format("%.17g", reference.times()(k)) + "), " + std::to_string(d0) +
                                    " at its start");
      }
    }
  }
  // Gains.
  TvlqrOptions to;
  to.sampleRate = options.sampleRate;
  to.transport = feedbackTransport();
  to.transport.substeps = options.transportSubsteps;
  to.feedforward = options.feedforward;
  to.threads = options.threads;  // the feed-forward's plant runs (tvlqr.hpp)
  // The report reads the feed-forward's defect and the prediction, not the comparison with u_ref(t_k)
  // held: that run per interval (half of kAverage's plant runs) is left out.
  to.measureHeldReference = false;
  to.riccati = feedbackRiccatiOptions();
  const auto gainStart = std::chrono::steady_clock::now();
  result.lqr = solveTvlqr(model, reference, feedbackWeights(model), to);
  result.gainSeconds = secondsSince(gainStart);
  if (!result.lqr.ok()) return result;

  // Starts tangent to the manifold at the reference's start.
  Eigen::VectorXd x0(2 * n), u0(m);
  reference.evaluate(reference.startTime(), x0, u0);
  if (!computeLinearization(model, data, x0.head(n), x0.tail(n), u0).ok()) {
    throw std::invalid_argument("runBallFeedback: the dynamics fail at the reference's start: " + data.status.message);
  }
  computeConstraintTangentBasis(model, data);
  const std::vector<Eigen::VectorXd> starts =
      perturbedStarts(data.tangentBasis, x0, options.runs, options.seed, options.perturbation);
  const int yaw = model.configIndex("ball_yaw"), pitch = model.configIndex("ball_pitch"),
            roll = model.configIndex("ball_roll");
  if (yaw < 0 || pitch != yaw + 1 || roll != yaw + 2) {
    throw std::invalid_argument("runBallFeedback: the model needs the coordinates ball_yaw, ball_pitch, ball_roll in "
                                "this order");
  }

  SimulationOptions base = closedLoopOptions(m);
  base.sampleRate = options.sampleRate;
  base.inputUpper = limits.uMax;
  base.rtol = options.rtol;
  base.atol = options.atol;
  base.driftTolerance = options.driftTolerance;
  base.method = options.method;
  base.newtonTolerance = options.method == IntegrationMethod::kRadau ? options.newtonTolerance : 0.0;
  result.runs.resize(starts.size());
  const auto runOne = [&](std::size_t r) {
    const auto start = std::chrono::steady_clock::now();
    ContactCheck contacts(limits);
    SimulationOptions so = base;
    so.stepCheck = [&contacts](double t, const Eigen::VectorXd&, const Eigen::VectorXd&, const Eigen::VectorXd& lambda) {
      return contacts(t, lambda);
    };
    BallRun& run = result.runs[r];
    run.simulation = simulateClosedLoop(model, reference, result.lqr.gains, starts[r], so);
    const SimulationResult& sim = run.simulation;
    run.minNormal = contacts.minNormal;
    run.minNormalContact = contacts.minNormalContact;
    run.worstFrictionRatio = contacts.worstFrictionRatio;
    run.worstFrictionContact = contacts.worstFrictionContact;
    const Eigen::Index rows = sim.trackingError.size();
    run.initialError = run.finalError = run.errorRatio = run.orientationError = NAN;
    if (rows > 0) {
      run.initialError = sim.trackingError(0);
      run.finalError = sim.trackingError(rows - 1);
      run.errorRatio = run.finalError / run.initialError;
      const double tEnd = sim.trajectory.times()(rows - 1);
      Eigen::VectorXd xr(2 * n), ur(m);
      reference.evaluate(tEnd, xr, ur);
      run.orientationError =
          ballOrientationError(xr.segment<3>(yaw), sim.trajectory.states().col(rows - 1).segment<3>(yaw));
    }
    if (sim.status.code == SimulationCode::kCheckFailed && contacts.violation != BallRunCode::kOk) {
      run.status.set(contacts.violation, contacts.violationText, contacts.violationTime, contacts.violationContact);
    } else if (!sim.ok()) {
      run.status.set(BallRunCode::kSimulationFailure, sim.status.describe(), sim.status.t);
    } else if (!(run.errorRatio <= options.maxErrorRatio)) {
      run.status.set(BallRunCode::kNotConverged,
                     format("final / initial tracking error %.6g > %.6g (%.6g -> %.6g)", run.errorRatio,
                            options.maxErrorRatio, run.initialError, run.finalError),
                     sim.trajectory.endTime());
    }
    run.seconds = secondsSince(start);
  };
  // Runs on threads: the model, the reference and the gains are shared read-only (simulation.hpp);
  // each run owns its check, its options and its result slot.
  const auto loopStart = std::chrono::steady_clock::now();
  std::atomic<std::size_t> next{0};
  const auto worker = [&]() {
    for (std::size_t r = next++; r < starts.size(); r = next++) runOne(r);
  };
  const int threads = std::min<int>(options.threads, std::max<int>(1, static_cast<int>(starts.size())));
  std::vector<std::thread> pool;
  for (int k = 1; k < threads; ++k) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
  result.closedLoopSeconds = secondsSince(loopStart);

  result.minNormal = result.runs.empty() ? NAN : INFINITY;
  for (const BallRun& run : result.runs) {
    if (!run.ok()) ++result.failed;
    if (run.status.code == BallRunCode::kNormalForce || run.status.code == BallRunCode::kFrictionCone)
      ++result.contactFailures;
    result.minNormal = std::min(result.minNormal, run.minNormal);
    result.worstFrictionRatio = std::max(result.worstFrictionRatio, run.worstFrictionRatio);
    if (std::isnan(run.finalError)) continue;  // no output reached
    result.worstErrorRatio = std::max(result.worstErrorRatio, run.errorRatio);
    result.worstFinalError = std::max(result.worstFinalError, run.finalError);
    result.worstOrientationError = std::max(result.worstOrientationError, run.orientationError);
  }
  return result;
}

}  // namespace trellis::hand
