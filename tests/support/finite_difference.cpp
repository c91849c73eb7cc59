// tests/support/finite_difference.cpp — see the header for the step and error model.
#include "support/finite_difference.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis::test {

// The step rules and stencils are the core's (trellis/core/numdiff.hpp); these wrappers keep
// the tests' vocabulary.
namespace {
DifferenceScheme schemeOf(Stencil stencil) {
  return stencil == Stencil::kSecondOrder ? DifferenceScheme::kCentral
                                          : DifferenceScheme::kCentralFourthOrder;
}
}  // namespace

double fdRelativeStep() { return defaultRelativeStep(DifferenceScheme::kCentral); }

double fdStep(double x) { return fdRelativeStep() * std::max(1.0, std::abs(x)); }

double fdBaseStep(Stencil stencil) { return defaultRelativeStep(schemeOf(stencil)); }

Eigen::MatrixXd centralDifferenceJacobian(const VectorFunction& f, const Eigen::VectorXd& x,
                                          double stepScale, Stencil stencil) {
  NumDiffOptions options;
  options.scheme = schemeOf(stencil);
  options.relativeStep = stepScale * fdBaseStep(stencil);
  return differenceJacobian([&](const Eigen::VectorXd& xx, Eigen::VectorXd& out) { out = f(xx); }, x,
                            options);
}

Eigen::VectorXd centralDifferenceDirectional(const VectorFunction& f, const Eigen::VectorXd& x,
                                             const Eigen::VectorXd& v) {
  const double scale = v.size() > 0 ? v.cwiseAbs().maxCoeff() : 0.0;
  if (scale == 0.0) return Eigen::VectorXd::Zero(f(x).size());
  const Eigen::VectorXd w = v / scale;
  const double h = fdRelativeStep() * std::max(1.0, x.size() > 0 ? x.cwiseAbs().maxCoeff() : 0.0);
  const Eigen::VectorXd fp = f(x + h * w);
  const Eigen::VectorXd fm = f(x - h * w);
  return scale * (fp - fm) / (2.0 * h);
}

DynamicsFiniteDifference finiteDifferenceDynamics(const Model& model, const Eigen::VectorXd& q,
                                                  const Eigen::VectorXd& dq,
                                                  const Eigen::VectorXd& u, double stepScale,
                                                  Stencil stencil) {
  const int n = model.nq(), m = model.nu(), nc = model.nc();
  Data data(model);  // a workspace of its own: the caller's Data keeps the analytic results
  DynamicsFiniteDifference out;
  Eigen::VectorXd z(2 * n + m);
  z << q, dq, u;
  const VectorFunction f = [&](const Eigen::VectorXd& zz) {
    const DynamicsStatus status =
        computeDynamics(model, data, zz.head(n), zz.segment(n, n), zz.tail(m));
    if (!status.ok() && out.ok) {
      out.ok = false;
      std::ostringstream os;
      os << "computeDynamics failed at a finite-difference point (|z - z0|inf = "
         << (zz - z).cwiseAbs().maxCoeff() << "): " << status.message;
      out.failure = os.str();
    }
    Eigen::VectorXd result(n + nc);
    result << data.qdd, data.lambda;
    return result;
  };
  const Eigen::MatrixXd J = centralDifferenceJacobian(f, z, stepScale, stencil);
  out.dqdd = J.topRows(n);
  out.dlambda = J.bottomRows(nc);
  return out;
}

Vector6d finiteDifferenceBodyVelocity(const Model& model, const Eigen::VectorXd& q,
                                      const Eigen::VectorXd& dq, int frame) {
  Data data(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq());
  // Pose as a 12-vector [p; vec(R)] so the generic directional difference applies.
  const VectorFunction pose = [&](const Eigen::VectorXd& qq) {
    computeKinematics(model, data, qq, zero);
    const Eigen::Isometry3d& g = data.framePose[static_cast<std::size_t>(frame)];
    Eigen::VectorXd out(12);
    out.head<3>() = g.translation();
    const Eigen::Matrix3d R = g.linear();  // a contiguous copy: linear() is a strided block
    out.tail<9>() = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(R.data());
    return out;
  };
  const Eigen::VectorXd d = centralDifferenceDirectional(pose, q, dq);
  computeKinematics(model, data, q, zero);
  const Eigen::Matrix3d R = data.framePose[static_cast<std::size_t>(frame)].linear();
  const Eigen::Vector3d pdot = d.head<3>();
  const Eigen::Matrix3d Rdot = Eigen::Map<const Eigen::Matrix3d>(d.tail<9>().data());
  // Rᵀ Ṙ is skew-symmetric exactly; its FD estimate only up to the FD error, so take the skew part.
  const Eigen::Matrix3d W = R.transpose() * Rdot;
  const Eigen::Matrix3d Wskew = 0.5 * (W - W.transpose());
  Vector6d vb;
  vb.head<3>() = R.transpose() * pdot;
  vb.tail<3>() = Eigen::Vector3d(Wskew(2, 1), Wskew(0, 2), Wskew(1, 0));
  return vb;
}

}  // namespace trellis::test
