// tests/support/random_state.cpp
#include "support/random_state.hpp"

#include <Eigen/Geometry>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace trellis::test {

double uniform(std::mt19937& rng, double lo, double hi) {
  // 53 random bits from two draws, mapped to [0, 1].
  const std::uint64_t a = rng() >> 5, b = rng() >> 6;                           // 27 and 26 bits
  const double unit = static_cast<double>((a << 26) | b) / 9007199254740991.0;  // 2^53 − 1
  return lo + (hi - lo) * unit;
}

Eigen::VectorXd uniformVector(std::mt19937& rng, Eigen::Index n, double lo, double hi) {
  Eigen::VectorXd v(n);
  for (Eigen::Index i = 0; i < n; ++i) v[i] = uniform(rng, lo, hi);
  return v;
}

Eigen::Matrix3d randomRotation(std::mt19937& rng) {
  Eigen::Vector4d c;
  do {
    c = uniformVector(rng, 4, -1.0, 1.0);
  } while (c.norm() < 0.1 || c.norm() > 1.0);  // rejection: uniform in the ball, then normalize
  Eigen::Quaterniond quat(c[0], c[1], c[2], c[3]);
  quat.normalize();
  return quat.toRotationMatrix();
}

Eigen::Matrix3d randomInertia(std::mt19937& rng, double lo, double hi) {
  Eigen::Vector3d d;
  do {
    d = uniformVector(rng, 3, lo, hi);
  } while (d[0] > d[1] + d[2] || d[1] > d[0] + d[2] || d[2] > d[0] + d[1]);
  const Eigen::Matrix3d R = randomRotation(rng);
  Eigen::Matrix3d I = R * d.asDiagonal() * R.transpose();
  return 0.5 * (I + I.transpose());  // exactly symmetric for the builder's check
}

Eigen::Matrix4d randomSE3(std::mt19937& rng, double t) {
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  g.topLeftCorner<3, 3>() = randomRotation(rng);
  g.topRightCorner<3, 1>() = uniformVector(rng, 3, -t, t);
  return g;
}

State randomState(const Model& model, std::mt19937& rng, double qRange, double dqRange,
                  double uRange) {
  State s;
  s.q = uniformVector(rng, model.nq(), -qRange, qRange);
  s.dq = uniformVector(rng, model.nq(), -dqRange, dqRange);
  s.u = uniformVector(rng, model.nu(), -uRange, uRange);
  return s;
}

bool projectToConstraints(const Model& model, Eigen::VectorXd& q, Eigen::VectorXd& dq) {
  const int n = model.nq(), nc = model.nc();
  if (nc == 0) return true;
  Data data(model);
  std::vector<int> holonomicRows;
  for (int i = 0; i < nc; ++i)
    if (model.constraints()[static_cast<std::size_t>(i)].holonomic()) holonomicRows.push_back(i);
  const int nh = static_cast<int>(holonomicRows.size());
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd h(nh);
  Eigen::MatrixXd Ah(nh, n);
  bool converged = nh == 0;
  for (int iter = 0; iter < 100 && !converged; ++iter) {
    computeConstraints(model, data, q, zero);
    for (int r = 0; r < nh; ++r) {
      h[r] = data.constraintValue[holonomicRows[static_cast<std::size_t>(r)]];
      Ah.row(r) = data.constraintJacobian.row(holonomicRows[static_cast<std::size_t>(r)]);
    }
    if (h.cwiseAbs().maxCoeff() <= 1e-14) {
      converged = true;
      break;
    }
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(Ah, Eigen::ComputeThinU | Eigen::ComputeThinV);
    svd.setThreshold(1e-10);
    q -= svd.solve(h);
  }
  computeConstraints(model, data, q, zero);
  for (int r = 0; r < nh; ++r)
    h[r] = data.constraintValue[holonomicRows[static_cast<std::size_t>(r)]];
  if (nh > 0 && h.cwiseAbs().maxCoeff() > 1e-13) return false;
  // q̇ ← (I − A⁺A) q̇: the orthogonal projection onto the null space of A (all rows).
  const Eigen::MatrixXd A = data.constraintJacobian;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
  svd.setThreshold(1e-10);
  dq -= svd.solve(A * dq);
  dq -= svd.solve(A * dq);  // a second pass removes what rounding left of the first
  return (A * dq).cwiseAbs().maxCoeff() <= 1e-13 * std::max(1.0, dq.cwiseAbs().maxCoeff());
}

State randomConsistentState(const Model& model, std::mt19937& rng, double qRange, double dqRange,
                            double uRange) {
  for (int attempt = 0; attempt < 20; ++attempt) {
    State s = randomState(model, rng, qRange, dqRange, uRange);
    if (projectToConstraints(model, s.q, s.dq)) return s;
  }
  throw std::runtime_error("randomConsistentState: projection did not converge in 20 tries");
}

}  // namespace trellis::test
