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
  o.atol = 5e-10;
  return o;
}

GainSchedule feedbackGains(const ManifoldRiccatiSolution& lqr, const Trajectory& reference) {
  // Rows: the knots, each interval bisected while K at its midpoint differs from the chord through
  // its ends by more than kTolerance of the local gain size (max |K_ij| at the two ends). The chord
  // test is conservative for the cubic rule used between rows (its error is O(h⁴) where the
  // chord's is O(h²)); it puts rows into the end-time boundary layer and nowhere else.
  constexpr double kTolerance = 1e-3;
  const double span = reference.endTime() - reference.startTime();
  const double shortest = 1e-7 * std::max(1.0, span);
  const Eigen::VectorXd& knots = reference.times();
  std::vector<double> rows;
  std::vector<Eigen::MatrixXd> values;
  rows.push_back(knots(0));
  values.push_back(lqr.K(knots(0)));
  struct Interval {
    double a, b;
    Eigen::MatrixXd Kb;
  };
  std::vector<Interval> pending;  // right halves still to test (a stack: rows stay in order)
  for (Eigen::Index k = 1; k < knots.size(); ++k) {
    pending.push_back({rows.back(), knots(k), lqr.K(knots(k))});
    while (!pending.empty()) {
      Interval iv = std::move(pending.back());
      pending.pop_back();
      const Eigen::MatrixXd& Ka = values.back();
      const double mid = 0.5 * (iv.a + iv.b);
      Eigen::MatrixXd Km = lqr.K(mid);
      const double scale = std::max(Ka.cwiseAbs().maxCoeff(), iv.Kb.cwiseAbs().maxCoeff());
      const double chordError = (Km - 0.5 * (Ka + iv.Kb)).cwiseAbs().maxCoeff();
      if (chordError > kTolerance * scale && iv.b - iv.a > 2.0 * shortest) {
        pending.push_back({mid, iv.b, std::move(iv.Kb)});  // tested after the left half
        pending.push_back({iv.a, mid, std::move(Km)});
        continue;
      }
      rows.push_back(iv.b);
      values.push_back(std::move(iv.Kb));
    }
  }
  GainSchedule gains(Eigen::Map<const Eigen::VectorXd>(rows.data(), static_cast<Eigen::Index>(rows.size())),
                     std::move(values));
  gains.setInterpolation(GainInterpolation::kCubic);
  return gains;
}

SimulationOptions closedLoopOptions(int m) {
  SimulationOptions o;
  o.method = IntegrationMethod::kBDF;
  o.rtol = 1e-7;
  o.atol = 5e-10;
  o.driftTolerance = 3e-11;  // see the header
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
