// examples/hand/hand_feedback.cpp — see hand_feedback.hpp.
#include "hand_feedback.hpp"

#include <trellis/core/model.hpp>

#include <algorithm>
#include <cmath>
#include <random>

namespace trellis::hand {

LqrWeights feedbackWeights(const Model& model) {
  const int n = model.nq(), m = model.nu(), nx = 2 * n;
  LqrWeights w;
  w.Q = Eigen::MatrixXd::Identity(nx, nx);
  w.Q.topLeftCorner(n, n) *= 100.0;
  w.R = Eigen::MatrixXd::Identity(m, m);
  w.Qf = w.Q;
  return w;
}

TangentTransportOptions feedbackTransport() {
  TangentTransportOptions t;
  t.method = TangentTransport::kProjected;
  t.substeps = 2;
  return t;
}

RiccatiOptions feedbackRiccatiOptions() {
  RiccatiOptions o;
  o.rtol = 1e-6;
  o.atol = 1e-8;
  return o;
}

GainSchedule feedbackGains(const ManifoldRiccatiSolution& lqr, const Trajectory& reference) {
  const Eigen::VectorXd& knots = reference.times();
  std::vector<double> times(knots.data(), knots.data() + knots.size());
  const std::vector<double> steps = lqr.reduced.stepTimes();
  times.insert(times.end(), steps.begin(), steps.end());
  std::sort(times.begin(), times.end());
  // Rows closer than 1e-9 of the horizon are one row (a step ending on a knot).
  const double merge = 1e-9 * std::max(1.0, reference.endTime() - reference.startTime());
  std::vector<double> rows;
  for (double t : times) {
    if (t < reference.startTime() || t > reference.endTime()) continue;
    if (rows.empty() || t - rows.back() > merge) rows.push_back(t);
  }
  rows.front() = reference.startTime();
  rows.back() = reference.endTime();
  GainSchedule gains = GainSchedule::sample(
      [&](double t) { return lqr.K(t); },
      Eigen::Map<const Eigen::VectorXd>(rows.data(), static_cast<Eigen::Index>(rows.size())));
  gains.setInterpolation(GainInterpolation::kCubic);
  return gains;
}

SimulationOptions closedLoopOptions(int m) {
  SimulationOptions o;
  o.method = IntegrationMethod::kBDF;
  o.rtol = 1e-7;
  o.atol = 5e-10;
  o.inputLower = Eigen::VectorXd::Zero(m);
  o.inputUpper = Eigen::VectorXd::Constant(m, INFINITY);
  return o;
}

std::vector<Eigen::VectorXd> perturbedStarts(const Eigen::MatrixXd& T0, const Eigen::VectorXd& x0,
                                             int runs, unsigned seed, double size) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<Eigen::VectorXd> starts;
  for (int r = 0; r < runs; ++r) {
    Eigen::VectorXd z(T0.cols());
    for (int i = 0; i < z.size(); ++i) z(i) = normal(rng);
    z *= size / z.norm();
    starts.push_back(x0 + T0 * z);
  }
  return starts;
}

}  // namespace trellis::hand
