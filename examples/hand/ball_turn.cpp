// examples/hand/ball_turn.cpp — the ball-turning problem and the contact margins (ball_turn.hpp).
#include "ball_turn.hpp"
#include "reference_motion.hpp"

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

OptimalControlProblem makeBallTurnProblem(std::shared_ptr<const Model> model, const Eigen::VectorXd& q0,
                                          const BallLimits& limits, const BallTurnOptions& options) {
  if (options.facets < 3) throw std::invalid_argument("BallTurnOptions::facets = " + std::to_string(options.facets) + " must be >= 3");
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
  p.finalFixed.assign(2 * n, true);
  for (int i = 0; i < n; ++i) p.finalFixed[i] = (i == yaw);
  if (options.freeInitialConfiguration) {
    // The grasp the motion starts from is the optimizer's choice (at rest, yaw 0): the stored
    // one is not held by tensions u ≥ 0.
    p.initialFixed.assign(2 * n, true);
    for (int i = 0; i < n; ++i) p.initialFixed[i] = (i == yaw);
  }
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
  p.R = Eigen::MatrixXd::Identity(m.nu(), m.nu());
  p.Q = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  p.Q.bottomRightCorner(n, n).diagonal().setConstant(options.velocityWeight);
  p.goalState = Eigen::VectorXd::Zero(2 * n);
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
  p.initialGuess = quasiStaticTurn(m, q0, options);
  p.validate();
  return p;
}

StaticHold closestStaticHold(const Model& model, const Eigen::VectorXd& q) {
  Data data(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq());
  // q̈ = q̈(q, 0, 0) + (∂q̈/∂u) u: one linearization at u = 0 gives both terms exactly.
  if (!computeLinearization(model, data, q, zero, Eigen::VectorXd::Zero(model.nu())).ok())
    throw std::runtime_error("closestStaticHold: the dynamics failed at the pose: " + data.status.message);
  const Eigen::MatrixXd C = data.M * data.dqdd_du;
  const Eigen::VectorXd d = -(data.M * data.qdd);
  StaticHold h;
  h.tension = solveNonNegativeLeastSquares(C, d).x;
  h.relativeResidual = (C * h.tension - d).norm() / std::max(d.norm(), 1e-300);
  if (!computeDynamics(model, data, q, zero, h.tension).ok())
    throw std::runtime_error("closestStaticHold: the dynamics failed under the tensions: " + data.status.message);
  h.lambda = data.lambda;
  return h;
}

namespace {

/// The inequalities g(q, u) ≥ 0 of findGraspEquilibrium and their Jacobian (rows × (n + m)):
/// u ≥ 0, u_max − u ≥ 0, λ_n − normalMin ≥ 0, −(facet) ≥ 0 per contact.
struct GraspEval {
  Eigen::VectorXd r, g, lambda;
  Eigen::MatrixXd J, G;
  double phi = 0.0;
  bool ok = false;
};

constexpr double kAccelerationScale = 1e3;  // rad/s²: q̈ of the light phalanges off equilibrium
constexpr double kLengthScale = 1e-3;       // m: h

GraspEval evalGrasp(const Model& model, Data& data, const Eigen::VectorXd& y, const BallLimits& limits,
                    int facets, double mu, double effort, double shift) {
  const int n = model.nq(), m = model.nu(), nc = model.nc(), nd = nc / 3;
  GraspEval e;
  const Eigen::VectorXd q = y.head(n), u = y.tail(m), zero = Eigen::VectorXd::Zero(n);
  if (!computeLinearization(model, data, q, zero, u).ok()) return e;
  computeConstraints(model, data, q, zero);
  e.r.resize(n + nc);
  e.r << data.qdd / kAccelerationScale, data.constraintValue / kLengthScale;
  e.J = Eigen::MatrixXd::Zero(n + nc, n + m);
  e.J.topLeftCorner(n, n) = data.dqdd_dq / kAccelerationScale;
  e.J.topRightCorner(n, m) = data.dqdd_du / kAccelerationScale;
  e.J.bottomLeftCorner(nc, n) = data.constraintJacobian / kLengthScale;
  e.lambda = data.lambda;
  Eigen::MatrixXd dl(nc, n + m);
  dl << data.dlambda_dx.leftCols(n), data.dlambda_dx.rightCols(m);
  const int rows = 2 * m + nd * (1 + facets);
  e.g.resize(rows);
  e.G = Eigen::MatrixXd::Zero(rows, n + m);
  for (int j = 0; j < m; ++j) {
    e.g(j) = u(j);
    e.G(j, n + j) = 1.0;
    e.g(m + j) = limits.uMax(j) - u(j);
    e.G(m + j, n + j) = -1.0;
  }
  const double f = limits.friction * std::cos(std::numbers::pi / facets);
  for (int d = 0; d < nd; ++d) {
    const int row = 2 * m + d * (1 + facets), c = 3 * d;
    e.g(row) = e.lambda(c) - limits.normalMin;
    e.G.row(row) = dl.row(c);
    for (int k = 0; k < facets; ++k) {
      const double th = 2.0 * std::numbers::pi * k / facets;
      const Eigen::RowVectorXd a = -(std::cos(th) * dl.row(c + 1) + std::sin(th) * dl.row(c + 2) - f * dl.row(c));
      e.g(row + 1 + k) = -(std::cos(th) * e.lambda(c + 1) + std::sin(th) * e.lambda(c + 2) - f * e.lambda(c));
      e.G.row(row + 1 + k) = a;
    }
  }
  e.g.tail(rows - 2 * m).array() += shift;  // the contact rows relaxed by `shift` (phase 1)
  if (e.g.minCoeff() <= 0.0) return e;
  e.phi = 0.5 * e.r.squaredNorm() + 0.5 * effort * u.squaredNorm() - mu * e.g.array().log().sum();
  e.ok = std::isfinite(e.phi);
  return e;
}

}  // namespace

GraspEquilibrium findGraspEquilibrium(const Model& model, const Eigen::VectorXd& q0, const BallLimits& limits,
                                      int facets) {
  const int n = model.nq(), m = model.nu(), nc = model.nc();
  Data data(model);
  GraspEquilibrium out;
  // Start: tensions closest to a static hold with every contact pressing by 1 N and no tangential
  // force (stacked non-negative least squares; λ = λ(q, 0, 0) + (∂λ/∂u) u is affine in u).
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  if (!computeLinearization(model, data, q0, zero, Eigen::VectorXd::Zero(m)).ok()) {
    out.message = "the dynamics failed at the stored grasp";
    return out;
  }
  Eigen::MatrixXd C(n + nc, m);
  Eigen::VectorXd d(n + nc);
  C.topRows(n) = data.M * data.dqdd_du;
  d.head(n) = -(data.M * data.qdd);
  C.bottomRows(nc) = data.dlambda_dx.rightCols(m);
  for (int r = 0; r < nc; ++r) d(n + r) = (r % 3 == 0 ? 1.0 : 0.0) - data.lambda(r);
  Eigen::VectorXd y(n + m);
  y.head(n) = q0;
  y.tail(m) = solveNonNegativeLeastSquares(C, d).x.cwiseMax(0.05).cwiseMin(0.9 * limits.uMax);
  const double effort = 1e-6;
  double nu = 1e-3;
  int iterations = 0;
  // Phase 1: the contact rows are relaxed by `shift` so the start is strictly inside; each round
  // lowers the shift to what the iterate allows (a shifted barrier), down to 0 — then the barrier
  // parameter μ decreases.
  double shift = 0.0;
  {
    const GraspEval e0 = evalGrasp(model, data, y, limits, facets, 1.0, effort, 0.0);
    if (e0.g.size() > 0) shift = std::max(0.0, -e0.g.tail(e0.g.size() - 2 * m).minCoeff()) * 1.1 + 1e-3;
  }
  const auto rawContactMin = [&](const GraspEval& e) { return e.g.tail(e.g.size() - 2 * m).minCoeff() - shift; };
  for (double mu = 1e-2; mu >= 1e-10; mu *= (shift > 0.0 ? 1.0 : 0.1)) {
    GraspEval e = evalGrasp(model, data, y, limits, facets, mu, effort, shift);
    while (!e.ok && e.g.size() > 0 && shift > 0.0 && shift < 1e3) {  // widen the relaxation if needed
      shift = 2.0 * shift + 1e-3;
      e = evalGrasp(model, data, y, limits, facets, mu, effort, shift);
    }
    nu = 1e-3;
    if (!e.ok) {
      Eigen::Index worst = 0;
      const double gmin = e.g.size() ? e.g.minCoeff(&worst) : 0.0;
      out.message = "the start is not strictly inside the contact and tension bounds (barrier " +
                    std::to_string(mu) + "; inequality " + std::to_string(worst) + " = " + std::to_string(gmin) +
                    (e.g.size() ? "" : ", the dynamics failed") + ")";
      out.q = y.head(n);
      out.u = y.tail(m);
      return out;
    }
    for (int it = 0; it < 60; ++it, ++iterations) {
      const Eigen::VectorXd w = e.g.cwiseInverse();
      Eigen::MatrixXd H = e.J.transpose() * e.J + mu * e.G.transpose() * w.cwiseAbs2().asDiagonal() * e.G;
      H.bottomRightCorner(m, m).diagonal().array() += effort;
      Eigen::VectorXd grad = e.J.transpose() * e.r - mu * e.G.transpose() * w;
      grad.tail(m) += effort * y.tail(m);
      bool accepted = false;
      for (int tries = 0; tries < 20 && !accepted; ++tries) {
        Eigen::MatrixXd Hd = H;
        Hd.diagonal().array() += nu * (1.0 + H.diagonal().array());
        const Eigen::VectorXd step = -Hd.ldlt().solve(grad);
        const GraspEval trial = evalGrasp(model, data, y + step, limits, facets, mu, effort, shift);
        if (trial.ok && trial.phi < e.phi) {
          y += step;
          e = trial;
          nu = std::max(nu / 3.0, 1e-12);
          accepted = true;
        } else {
          nu *= 10.0;
        }
      }
      if (!accepted || grad.cwiseAbs().maxCoeff() < 1e-12) break;
    }
    if (shift > 0.0) {
      // Lower the relaxation to half of what the iterate still needs (0 once it is inside).
      const double need = -rawContactMin(e);
      const double next = need <= 0.0 ? 0.0 : std::min(0.999 * shift, 0.5 * shift + 0.5 * need * 1.1);
      if (!(next < shift) || iterations > 2000) {
        out.message = "phase 1 stalls: the contacts stay " + std::to_string(need) + " N outside their bounds";
        out.q = y.head(n);
        out.u = y.tail(m);
        out.iterations = iterations;
        return out;
      }
      shift = next < 1e-9 ? 0.0 : next;
    }
  }
  out.iterations = iterations;
  out.u = y.tail(m);
  // Polish q at the final tensions (Newton on [q̈; h] = 0, the core's equilibrium search).
  const EquilibriumResult eq = findEquilibrium(model, data, y.head(n), out.u);
  out.q = eq.q;
  if (!computeDynamics(model, data, out.q, zero, out.u).ok()) {
    out.message = "the dynamics failed at the polished equilibrium";
    return out;
  }
  computeConstraints(model, data, out.q, zero);
  out.lambda = data.lambda;
  out.accelerationResidual = eq.accelerationResidual;
  out.constraintResidual = eq.constraintResidual;
  out.margins = contactMargins(out.lambda, limits);
  const bool contacts = out.margins.minNormal >= limits.normalMin && out.margins.worstFrictionRatio <= 1.0;
  out.ok = eq.ok() && contacts;
  if (!eq.ok()) out.message = "the equilibrium polish did not converge: " + eq.describe();
  else if (!contacts) out.message = "a contact condition fails at the equilibrium";
  return out;
}

Trajectory quasiStaticTurn(const Model& model, const Eigen::VectorXd& q0, const BallTurnOptions& options) {
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
    // Tensions: the closest static hold (the stored grasp is not an exact equilibrium under
    // u ≥ 0; hand_ball_turn reports the residual).
    states.col(k) << q, dq;
    inputs.col(k) = options.guessTensions.size() == model.nu() ? options.guessTensions
                                                                : closestStaticHold(model, q).tension;
  }
  return Trajectory(model.configNames(), model.inputNames(), times, states, inputs);
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
