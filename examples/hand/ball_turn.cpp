// examples/hand/ball_turn.cpp — the ball-turning problem and the contact margins (ball_turn.hpp).
#include "ball_turn.hpp"
#include "grasp.hpp"

#include <trellis/core.hpp>

#include <Eigen/Dense>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace trellis::hand {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw std::runtime_error(path + ": " + what);
}

}  // namespace

BallLimits loadBallLimits(const std::string& path, const Model& model) {
  std::ifstream in(path);
  if (!in) fail(path, "cannot be read");
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception& e) {
    fail(path, std::string("is not JSON: ") + e.what());
  }
  BallLimits l;
  for (const char* key : {"friction_coefficient", "normal_force_min", "contacts", "joint_range", "tension_max"})
    if (!j.contains(key)) fail(path, std::string("missing field '") + key + "'");
  l.friction = j["friction_coefficient"].get<double>();
  l.normalMin = j["normal_force_min"].get<double>();
  if (!(l.friction > 0.0) || !std::isfinite(l.friction))
    fail(path, "friction_coefficient = " + std::to_string(l.friction) + " must be > 0 and finite");
  if (!(l.normalMin >= 0.0) || !std::isfinite(l.normalMin))
    fail(path, "normal_force_min = " + std::to_string(l.normalMin) + " must be >= 0 and finite");
  // JSON objects are unordered: the contacts are put in row order, and must tile the rows by 3.
  std::vector<std::pair<int, std::string>> byRow;
  for (auto it = j["contacts"].begin(); it != j["contacts"].end(); ++it)
    byRow.emplace_back(it.value()["rows"].at(0).get<int>(), it.key());
  std::sort(byRow.begin(), byRow.end());
  for (const auto& [first, name] : byRow) {
    const int d = static_cast<int>(l.digits.size());
    const auto rows = j["contacts"][name]["rows"].get<std::vector<int>>();
    if (rows != std::vector<int>{3 * d, 3 * d + 1, 3 * d + 2})
      fail(path, "contacts." + name + ".rows must be [" + std::to_string(3 * d) + ", " +
                     std::to_string(3 * d + 1) + ", " + std::to_string(3 * d + 2) + "]");
    l.digits.push_back(name);
  }
  if (3 * static_cast<int>(l.digits.size()) != model.nc())
    fail(path, std::to_string(l.digits.size()) + " contacts for " + std::to_string(model.nc()) +
                   " constraint rows (3 per contact expected)");
  l.qLower = Eigen::VectorXd::Constant(model.nq(), -kInf);
  l.qUpper = Eigen::VectorXd::Constant(model.nq(), kInf);
  for (auto it = j["joint_range"].begin(); it != j["joint_range"].end(); ++it) {
    int i = -1;
    try {
      i = model.configIndex(it.key());
    } catch (const std::exception&) {
      fail(path, "joint_range." + it.key() + ": no such coordinate in the model");
    }
    l.qLower(i) = it.value()[0].get<double>();
    l.qUpper(i) = it.value()[1].get<double>();
  }
  l.uMax = Eigen::VectorXd::Constant(model.nu(), kInf);
  for (int k = 0; k < model.nu(); ++k) {
    const std::string& name = model.inputNames()[k];
    if (!j["tension_max"].contains(name)) fail(path, "tension_max." + name + " is missing");
    l.uMax(k) = j["tension_max"][name].get<double>();
    if (!(l.uMax(k) > 0.0) || !std::isfinite(l.uMax(k)))
      fail(path, "tension_max." + name + " = " + std::to_string(l.uMax(k)) + " must be > 0 and finite");
  }
  return l;
}

OptimizerOptions ballTurnOptimizerOptions(int threads) {
  OptimizerOptions oo;
  oo.initialBarrier = 1e-4;
  oo.initialBoundPush = 1e-2;
  oo.maxRefinements = 0;
  oo.maxIterations = 500;
  oo.ordering = MumpsOrdering::kQamd;
  oo.threads = threads;
  return oo;
}

OptimalControlProblem makeBallTurnProblem(std::shared_ptr<const Model> model, const Eigen::VectorXd& q0,
                                          const BallLimits& limits, const BallTurnOptions& options) {
  if (options.facets < 3) throw std::invalid_argument("BallTurnOptions::facets = " + std::to_string(options.facets) + " must be >= 3");
  if (options.knots < 2) throw std::invalid_argument("BallTurnOptions::knots = " + std::to_string(options.knots) + " must be >= 2");
  if (!(options.horizon > 0.0)) throw std::invalid_argument("BallTurnOptions::horizon must be > 0");
  const Model& m = *model;
  const int n = m.nq(), nc = m.nc();
  OptimalControlProblem p(model);
  p.method = CollocationMethod::kHermiteSimpson;
  p.knots = options.knots;
  p.setFixedHorizon(options.horizon);
  p.initialState = Eigen::VectorXd::Zero(2 * n);
  p.initialState.head(n) = q0;
  p.finalState = p.initialState;
  const int yaw = m.configIndex("ball_yaw");
  p.finalState(yaw) = options.angle;
  // Rest at the ends without redundant rows. The transcription imposes h(q_k) = 0 and A q̇_k = 0
  // at every knot; fixing all of q̇_k (or q_k) as well leaves those rows with a zero Jacobian in the
  // free variables — a rank-deficient NLP that Ipopt regularizes (slow, ill-conditioned steps).
  // So only the independent coordinates I are fixed (the n − nc columns a column-pivoted QR of
  // A(q0) without the yaw column leaves last, and the yaw): q̇_I = 0 and A q̇ = 0 give q̇ = 0 (A_D
  // invertible), and likewise q_I and h(q) = 0 give the grasp's q locally.
  std::vector<bool> independent(n, true);
  {
    Data data(m);
    computeConstraints(m, data, q0, Eigen::VectorXd::Zero(n));
    Eigen::MatrixXd A = data.constraintJacobian;
    A.col(yaw).setZero();
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
    if (qr.rank() != nc)
      throw std::runtime_error("makeBallTurnProblem: the contact rows have rank " + std::to_string(qr.rank()) +
                               " of " + std::to_string(nc) + " at q0 (without the yaw column)");
    for (int i = 0; i < nc; ++i) independent[qr.colsPermutation().indices()(i)] = false;
  }
  p.finalFixed.assign(2 * n, false);
  p.initialFixed.assign(2 * n, false);
  for (int i = 0; i < n; ++i) {
    p.finalFixed[n + i] = p.initialFixed[n + i] = independent[i];
    p.initialFixed[i] = independent[i] && !options.freeInitialConfiguration;
  }
  p.finalFixed[yaw] = p.initialFixed[yaw] = true;
  p.stateLower.head(n) = limits.qLower;
  p.stateUpper.head(n) = limits.qUpper;
  // The ball stays in the hand: its centre within 2 cm of the grasp centre, pitch and roll within
  // ±0.5 rad (far from the Z-Y-X singularity at ±π/2), the yaw within 0.5 rad of [0, angle].
  // Without them Ipopt's first steps (‖d‖ ~ 10² in the variables) throw the ball away.
  for (const char* c : {"ball_x", "ball_y", "ball_z"}) {
    p.stateLower(m.configIndex(c)) = -0.02;
    p.stateUpper(m.configIndex(c)) = 0.02;
  }
  for (const char* c : {"ball_pitch", "ball_roll"}) {
    p.stateLower(m.configIndex(c)) = -0.5;
    p.stateUpper(m.configIndex(c)) = 0.5;
  }
  p.stateLower(yaw) = std::min(0.0, options.angle) - 0.5;
  p.stateUpper(yaw) = std::max(0.0, options.angle) + 0.5;
  p.inputLower = Eigen::VectorXd::Zero(m.nu());
  p.inputUpper = limits.uMax;
  p.R = options.effortScale * Eigen::MatrixXd::Identity(m.nu(), m.nu());
  p.Q = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  p.Q.bottomRightCorner(n, n).diagonal().setConstant(options.effortScale * options.velocityWeight);
  p.goalState = Eigen::VectorXd::Zero(2 * n);
  if (options.implicitForm) {
    p.dynamics = DynamicsForm::kImplicit;
    // "Starting and ending at rest in a grasp equilibrium": q̈_I = 0 at both end knots too (the
    // independent coordinates, as for the rates: A q̈ + Ȧ q̇ = 0 then fixes the others).
    p.initialAccelerationFixed.assign(n, false);
    p.finalAccelerationFixed.assign(n, false);
    for (int i = 0; i < n; ++i) p.initialAccelerationFixed[i] = p.finalAccelerationFixed[i] = independent[i];
    p.initialAccelerationFixed[yaw] = p.finalAccelerationFixed[yaw] = true;
    if (options.accelerationWeight > 0.0)
      p.accelerationWeights = Eigen::VectorXd::Constant(n, options.effortScale * options.accelerationWeight);
  }
  const double facet = limits.friction * std::cos(std::numbers::pi / options.facets);
  for (std::size_t d = 0; d < limits.digits.size(); ++d) {
    const int r = 3 * static_cast<int>(d);
    p.forceLower(r) = limits.normalMin;
    for (int k = 0; k < options.facets; ++k) {
      const double th = 2.0 * std::numbers::pi * k / options.facets;
      OptimalControlProblem::ForceCombination c;
      c.name = limits.digits[d] + " friction facet " + std::to_string(k);
      c.coefficients = Eigen::VectorXd::Zero(nc);
      c.coefficients(r) = -facet;
      c.coefficients(r + 1) = std::cos(th);
      c.coefficients(r + 2) = std::sin(th);
      c.upper = 0.0;
      p.forceCombinations.push_back(c);
    }
  }
  p.initialGuess = quasiStaticTurn(m, q0, limits, options);
  p.validate();
  return p;
}

Trajectory quasiStaticTurn(const Model& model, const Eigen::VectorXd& q0, const BallLimits& limits,
                           const BallTurnOptions& options) {
  const int n = model.nq(), N = options.knots, yaw = model.configIndex("ball_yaw");
  Data data(model);
  Eigen::VectorXd times(N);
  Eigen::MatrixXd states = Eigen::MatrixXd::Zero(2 * n, N), inputs(model.nu(), N);
  Eigen::VectorXd q = q0;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  for (int k = 0; k < N; ++k) {
    const double s = static_cast<double>(k) / (N - 1);
    times(k) = options.horizon * s;
    q(yaw) = options.angle * (3.0 * s * s - 2.0 * s * s * s);
    const double yawRate = options.angle * 6.0 * s * (1.0 - s) / options.horizon;
    // Gauss–Newton on h(q) = 0 over the coordinates other than the yaw, minimum-norm steps.
    Eigen::MatrixXd Ao;
    double residual = 0.0;
    for (int it = 0; it < 30; ++it) {
      computeConstraints(model, data, q, zero);
      Ao = data.constraintJacobian;
      Ao.col(yaw).setZero();
      residual = data.constraintValue.cwiseAbs().maxCoeff();
      if (residual < 1e-14) break;
      q -= Ao.transpose() * (Ao * Ao.transpose()).ldlt().solve(data.constraintValue);
    }
    if (!(residual < 1e-12))
      throw std::runtime_error("quasiStaticTurn: knot " + std::to_string(k) + " (yaw " + std::to_string(q(yaw)) +
                               " rad): the pads cannot follow the ball, |h| = " + std::to_string(residual) + " m");
    Eigen::VectorXd dq = Eigen::VectorXd::Zero(n);
    dq(yaw) = yawRate;
    const Eigen::VectorXd rhs = data.constraintJacobian.col(yaw) * yawRate;
    dq -= Ao.transpose() * (Ao * Ao.transpose()).ldlt().solve(rhs);
    // Tensions: the hold of this pose with the contacts inside the pyramid (grasp.hpp), twice the
    // normal-force margin and 90 % of the facets' friction, small tensions preferred.
    states.col(k) << q, dq;
    const PyramidHold hold = pyramidHold(model, q, 2.0 * limits.normalMin,
                                         0.9 * limits.friction * std::cos(std::numbers::pi / options.facets),
                                         options.facets, 1e-6);
    if (!hold.ok) throw std::runtime_error("quasiStaticTurn: knot " + std::to_string(k) + ": the dynamics failed");
    inputs.col(k) = hold.tension;
  }
  return Trajectory(model.configNames(), model.inputNames(), times, states, inputs);
}

RestHold solveRestHold(const Model& model, const BallLimits& limits, const Eigen::VectorXd& qPrev,
                       const Eigen::VectorXd& uPrev, double yawValue, const RestHoldOptions& options,
                       const Eigen::VectorXd& velocity) {
  const int n = model.nq(), m = model.nu(), nc = model.nc(), F = options.facets;
  const int nd = static_cast<int>(limits.digits.size());
  if (F < 3) throw std::invalid_argument("RestHoldOptions::facets = " + std::to_string(F) + " must be >= 3");
  if (qPrev.size() != n || uPrev.size() != m)
    throw std::invalid_argument("solveRestHold: qPrev has " + std::to_string(qPrev.size()) + " entries, uPrev " +
                                std::to_string(uPrev.size()) + " (model: " + std::to_string(n) + ", " + std::to_string(m) + ")");
  const int yaw = model.configIndex("ball_yaw");
  // The independent accelerations: the coordinates a column-pivoted QR of A(qPrev) leaves last.
  auto data = std::make_shared<Data>(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  if (velocity.size() != 0 && velocity.size() != n)
    throw std::invalid_argument("solveRestHold: velocity has " + std::to_string(velocity.size()) + " entries, not " +
                                std::to_string(n));
  const Eigen::VectorXd dq = velocity.size() == n ? velocity : zero;
  computeConstraints(model, *data, qPrev, zero);
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(data->constraintJacobian);
  if (qr.rank() != nc)
    throw std::runtime_error("solveRestHold: the contact rows have rank " + std::to_string(qr.rank()) + " of " +
                             std::to_string(nc) + " at the start");
  std::vector<int> independent;
  for (int i = nc; i < n; ++i) independent.push_back(qr.colsPermutation().indices()(i));
  const int ni = static_cast<int>(independent.size());
  // Row scales: q̈_i times M_ii(qPrev), a generalized force — a light phalanx's q̈ is ~10⁴ times its
  // force imbalance, and unscaled those rows would dominate Ipopt's steps and its tolerance.
  if (!computeDynamics(model, *data, qPrev, dq, uPrev).ok())
    throw std::runtime_error("solveRestHold: the dynamics fail at the start");
  Eigen::VectorXd scale(ni);
  for (int i = 0; i < ni; ++i) scale(i) = data->M(independent[i], independent[i]);
  const double mu = limits.friction * std::cos(std::numbers::pi / F) * options.frictionUse;
  const double ell = 0.02;
  // x = [q; u; s]; rows [h (nc); q̈_I (ni); λ_n − s (nd); facets (nd F)].
  const int nx = n + m + 1, ng = nc + ni + nd + nd * F;
  NlpProblem p;
  p.lower.resize(nx);
  p.upper.resize(nx);
  p.lower << limits.qLower, Eigen::VectorXd::Zero(m), -kInf;
  p.upper << limits.qUpper, limits.uMax, options.marginCap;
  p.lower(yaw) = p.upper(yaw) = yawValue;
  // With a velocity the configuration is the path's (fixed): q̈ and λ are then affine in u, and the
  // program is a convex one in (u, s).
  if (velocity.size() == n) p.lower.head(n) = p.upper.head(n) = qPrev;
  p.constraintLower = Eigen::VectorXd::Zero(ng);
  p.constraintUpper = Eigen::VectorXd::Zero(ng);
  p.constraintUpper.tail(nd + nd * F).setConstant(kInf);
  p.start.resize(nx);
  // s starts at half the start's smallest normal force (a hold's margin, strictly inside its
  // rows): from 0 Ipopt spent ~10³ iterations raising it.
  double s0 = 0.0;
  if (data->lambda.size() == nc) {
    s0 = kInf;
    for (int d = 0; d < nd; ++d) s0 = std::min(s0, data->lambda(3 * d));
    s0 = std::clamp(0.5 * s0, 0.0, options.marginCap);  // inside λ_n − s ≥ 0
  }
  p.start << qPrev, uPrev, s0;
  p.start(yaw) = yawValue;
  const Eigen::VectorXd uMax = limits.uMax;
  p.objective = [=](const Eigen::VectorXd& x, double& f, Eigen::VectorXd& g) {
    const Eigen::VectorXd du = x.segment(n, m).cwiseQuotient(uMax), dq = (x.head(n) - qPrev) / ell;
    f = -x(n + m) + options.tensionWeight * du.squaredNorm() + options.stayWeight * dq.squaredNorm();
    g.setZero();
    g.head(n) = 2.0 * options.stayWeight * dq / ell;
    g.segment(n, m) = 2.0 * options.tensionWeight * du.cwiseQuotient(uMax);
    g(n + m) = -1.0;
    return true;
  };
  std::vector<double> cosK(F), sinK(F);
  for (int k = 0; k < F; ++k) {
    cosK[k] = std::cos(2.0 * std::numbers::pi * k / F);
    sinK[k] = std::sin(2.0 * std::numbers::pi * k / F);
  }
  p.constraints = [=, &model](const Eigen::VectorXd& x, Eigen::VectorXd& g, Eigen::MatrixXd& J) {
    const Eigen::VectorXd q = x.head(n), u = x.segment(n, m);
    computeConstraints(model, *data, q, zero);
    const Eigen::VectorXd h = data->constraintValue;
    const Eigen::MatrixXd A = data->constraintJacobian;
    if (!computeLinearization(model, *data, q, dq, u).ok()) return false;
    J.setZero();
    g.head(nc) = h;
    J.block(0, 0, nc, n) = A;
    for (int i = 0; i < ni; ++i) {
      g(nc + i) = scale(i) * data->qdd(independent[i]);
      J.block(nc + i, 0, 1, n) = scale(i) * data->dqdd_dq.row(independent[i]);
      J.block(nc + i, n, 1, m) = scale(i) * data->dqdd_du.row(independent[i]);
    }
    // λ rows: ∂λ/∂q and ∂λ/∂u are columns [0, n) and [2n, 2n + m) of dlambda_dx.
    const auto row = [&](int r, const Eigen::VectorXd& c, double sCoeff) {
      g(r) = c.dot(data->lambda) + sCoeff * x(n + m);
      J.block(r, 0, 1, n) = c.transpose() * data->dlambda_dx.leftCols(n);
      J.block(r, n, 1, m) = c.transpose() * data->dlambda_dx.middleCols(2 * n, m);
      J(r, n + m) = sCoeff;
    };
    Eigen::VectorXd c = Eigen::VectorXd::Zero(nc);
    for (int d = 0; d < nd; ++d) {
      c.setZero();
      c(3 * d) = 1.0;
      row(nc + ni + d, c, -1.0);
      for (int k = 0; k < F; ++k) {
        c.setZero();
        c(3 * d) = mu;
        c(3 * d + 1) = -cosK[k];
        c(3 * d + 2) = -sinK[k];
        row(nc + ni + nd + d * F + k, c, 0.0);
      }
    }
    return true;
  };
  RestHold r;
  r.nlp = solveNlp(p, options.ipopt);
  r.q = r.nlp.x.head(n);
  r.u = r.nlp.x.segment(n, m);
  r.margin = r.nlp.x(n + m);
  if (computeDynamics(model, *data, r.q, dq, r.u).ok()) r.lambda = data->lambda;
  // A hold is a feasible point: Ipopt's optimum, or its last iterate at the iteration limit when
  // every row and bound holds there (solveNlp evaluates them again at x). The margin is then the
  // contacts' own smallest normal force, not the variable s.
  r.certified = r.nlp.ok();
  const bool feasible = r.nlp.constraintViolation <= options.ipopt.constraintTolerance &&
                        r.nlp.boundViolation <= options.ipopt.constraintTolerance;
  if (r.lambda.size() == nc) {
    double smallest = kInf;
    for (int d = 0; d < nd; ++d) smallest = std::min(smallest, r.lambda(3 * d));
    r.margin = std::min(r.margin, smallest);
  }
  r.ok = (r.certified || (r.nlp.status.code == OptimizationCode::kIterationLimit && feasible)) &&
         r.margin >= limits.normalMin && r.lambda.size() == nc;
  if (!r.ok)
    r.message = !(r.certified || r.nlp.status.code == OptimizationCode::kIterationLimit) || !feasible
                    ? r.nlp.status.message
                    : "the smallest normal force " + std::to_string(r.margin) + " N is below the margin " +
                          std::to_string(limits.normalMin) + " N";
  return r;
}

HoldPath quasiStaticHolds(const Model& model, const Eigen::VectorXd& q0, const Eigen::VectorXd& u0,
                          const BallLimits& limits, const BallTurnOptions& options, const RestHoldOptions& holdOptions) {
  const int n = model.nq(), N = options.knots, yaw = model.configIndex("ball_yaw");
  HoldPath path;
  Eigen::VectorXd q = q0, u = u0;
  double psi = q0(yaw);
  std::vector<double> times;
  for (int k = 0; k < N; ++k) {
    const double s = static_cast<double>(k) / (N - 1);
    const double target = options.angle * (3.0 * s * s - 2.0 * s * s * s);
    // Continuation from psi to target: halve the step on failure, take the rest once a step holds.
    double step = target - psi;
    int halvings = 0;
    RestHold hold;
    while (true) {
      const double next = (k == 0 || std::abs(target - psi) <= std::abs(step)) ? target : psi + step;
      hold = solveRestHold(model, limits, q, u, next, holdOptions);
      ++path.solves;
      if (hold.ok) {
        q = hold.q;
        u = hold.u;
        psi = next;
        path.reached = psi;
        if (next == target) break;
        continue;
      }
      if (++halvings > 6 || k == 0) {
        path.message = "no hold at yaw " + std::to_string(next * 180.0 / std::numbers::pi) + " deg (knot " +
                       std::to_string(k) + "): " + hold.message + "; the largest yaw held is " +
                       std::to_string(path.reached * 180.0 / std::numbers::pi) + " deg";
        return path;
      }
      step *= 0.5;
    }
    path.holds.push_back(hold);
    times.push_back(options.horizon * s);
  }
  Eigen::MatrixXd states = Eigen::MatrixXd::Zero(2 * n, N), inputs(model.nu(), N);
  Data data(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  for (int k = 0; k < N; ++k) {
    states.col(k).head(n) = path.holds[k].q;
    inputs.col(k) = path.holds[k].u;
    if (k == 0 || k == N - 1) continue;
    Eigen::VectorXd dq = (path.holds[k + 1].q - path.holds[k - 1].q) / (times[k + 1] - times[k - 1]);
    computeConstraints(model, data, path.holds[k].q, zero);
    const Eigen::MatrixXd& A = data.constraintJacobian;
    dq -= A.transpose() * (A * A.transpose()).ldlt().solve(A * dq);
    // The joints' dampers resist that velocity (a phalanx's q̈ ~ 10² rad/s² per 0.1 rad/s at rest
    // tensions): the tensions that keep q̈ ≈ 0 while moving are solved again with q̇ given.
    const RestHold moving = solveRestHold(model, limits, path.holds[k].q, path.holds[k].u,
                                          path.holds[k].q(yaw), holdOptions, dq);
    ++path.solves;
    if (!moving.ok) {
      path.message = "no steady hold at knot " + std::to_string(k) + " with the path's velocity: " + moving.message;
      return path;
    }
    path.holds[k] = moving;
    states.col(k).head(n) = moving.q;
    inputs.col(k) = moving.u;
    states.col(k).tail(n) = dq;
  }
  path.guess = Trajectory(model.configNames(), model.inputNames(), Eigen::Map<const Eigen::VectorXd>(times.data(), N),
                          states, inputs);
  path.complete = true;
  return path;
}

KinematicReach kinematicReach(const Model& model, const BallLimits& limits, const Eigen::VectorXd& q0,
                              double maxYaw, double step, double resolution) {
  const int n = model.nq(), nc = model.nc(), yaw = model.configIndex("ball_yaw");
  if (q0.size() != n) throw std::invalid_argument("kinematicReach: q0 has " + std::to_string(q0.size()) + " entries, not " + std::to_string(n));
  if (!(step > 0.0) || !(resolution > 0.0)) throw std::invalid_argument("kinematicReach: step and resolution must be > 0");
  if (!(maxYaw > q0(yaw)))
    throw std::invalid_argument("kinematicReach: maxYaw = " + std::to_string(maxYaw) + " rad must exceed the start's yaw " +
                                std::to_string(q0(yaw)) + " rad (the search turns the ball in the positive sense)");
  KinematicReach r;
  r.q = q0;
  r.reached = q0(yaw);
  auto data = std::make_shared<Data>(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  NlpOptions o;
  o.constraintTolerance = 1e-10;
  o.maxIterations = 500;
  while (r.reached < maxYaw && step >= resolution) {
    const double psi = std::min(maxYaw, r.reached + step);
    const Eigen::VectorXd prev = r.q;
    NlpProblem p;
    p.lower = limits.qLower;
    p.upper = limits.qUpper;
    p.lower(yaw) = p.upper(yaw) = psi;
    p.constraintLower = p.constraintUpper = Eigen::VectorXd::Zero(nc);
    p.start = prev;
    p.start(yaw) = psi;
    p.objective = [prev](const Eigen::VectorXd& x, double& f, Eigen::VectorXd& g) {
      f = (x - prev).squaredNorm();
      g = 2.0 * (x - prev);
      return true;
    };
    p.constraints = [&model, data, zero](const Eigen::VectorXd& x, Eigen::VectorXd& g, Eigen::MatrixXd& J) {
      computeConstraints(model, *data, x, zero);
      g = data->constraintValue;
      J = data->constraintJacobian;
      return true;
    };
    const NlpResult s = solveNlp(p, o);
    ++r.solves;
    if (s.ok()) {
      r.reached = psi;
      r.q = s.x;
    } else {
      r.limit = psi;
      r.stop = s.ipoptStatus;
      step *= 0.5;
    }
  }
  for (int i = 0; i < n; ++i)
    if (std::min(r.q(i) - limits.qLower(i), limits.qUpper(i) - r.q(i)) < 1e-4) r.atRangeEnds.push_back(model.configNames()[i]);
  return r;
}

ContactMargins contactMargins(const Eigen::VectorXd& lambda, const BallLimits& limits) {
  ContactMargins c;
  c.minNormal = kInf;
  for (std::size_t d = 0; d < limits.digits.size(); ++d) {
    const double ln = lambda(3 * d), lt = std::hypot(lambda(3 * d + 1), lambda(3 * d + 2));
    const double ratio = ln > 0.0 ? lt / (limits.friction * ln) : kInf;
    if (ln < c.minNormal || c.minNormalContact < 0) {
      c.minNormal = ln;
      c.minNormalContact = static_cast<int>(d);
    }
    if (ratio > c.worstFrictionRatio || c.worstFrictionContact < 0) {
      c.worstFrictionRatio = ratio;
      c.worstFrictionContact = static_cast<int>(d);
    }
  }
  return c;
}

}  // namespace trellis::hand
