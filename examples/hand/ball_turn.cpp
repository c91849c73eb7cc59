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
