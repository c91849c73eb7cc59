// Frame poses and velocities by recursion from the world (paper Sec. II-A), in spatial form.
#include "trellis/core/kinematics.hpp"

#include "internal.hpp"

#include <stdexcept>
#include <string>

namespace trellis {
namespace detail {

using namespace spatial;

void checkSize(const Eigen::VectorXd& v, int expected, const char* what) {
  if (v.size() != expected)
    throw std::invalid_argument(std::string(what) + ": expected " + std::to_string(expected) +
                                " entries, got " + std::to_string(v.size()));
}

void updateJoints(const Model& model, Data& data, const Eigen::VectorXd& q, const Eigen::VectorXd& dq) {
  auto& ws = detail::workspace(data);
  ws.q = q;  // same size: no allocation
  ws.dq = dq;
  const auto& joints = model.joints();
  const int n = model.nq();
  for (int i = 0; i < n; ++i) {
    const Joint& j = joints[i];
    Eigen::Matrix3d Rpre;
    Vector3d ppre;
    Vector6d vParent;
    if (j.parent == kWorld) {
      Rpre = j.R0;
      ppre = j.p0;
      vParent.setZero();
    } else {
      const Eigen::Matrix3d& Rp = ws.jointR[j.parent];
      Rpre.noalias() = Rp * j.R0;
      ppre = ws.jointP[j.parent] + Rp * j.p0;
      vParent = ws.v[j.parent];
    }
    const Vector3d e = Rpre.col(j.axis);
    if (j.revolute) {
      // R = Rpre · rot_axis(q): rotate the two columns orthogonal to the axis.
      const double c = std::cos(q[i]), s = std::sin(q[i]);
      const int a1 = (j.axis + 1) % 3, a2 = (j.axis + 2) % 3;
      Eigen::Matrix3d& R = ws.jointR[i];
      R.col(j.axis) = e;
      R.col(a1) = c * Rpre.col(a1) + s * Rpre.col(a2);
      R.col(a2) = -s * Rpre.col(a1) + c * Rpre.col(a2);
      ws.jointP[i] = ppre;
      ws.S[i] = make(ppre.cross(e), e);  // rotation about the axis through the joint origin
    } else {
      ws.jointR[i] = Rpre;
      ws.jointP[i] = ppre + q[i] * e;
      ws.S[i] = make(e, Vector3d::Zero());
    }
    ws.v[i] = vParent + ws.S[i] * dq[i];

    // World inertia: h = m p + R h_l; I_O = R I_l Rᵀ − m[p][p] − [p][R h_l] − [R h_l][p].
    const Eigen::Matrix3d& R = ws.jointR[i];
    const Vector3d& p = ws.jointP[i];
    const Vector3d hs = R * j.firstMoment;
    ws.wm[i] = j.mass;
    ws.wh[i] = j.mass * p + hs;
    Eigen::Matrix3d I = R * j.inertiaAtOrigin * R.transpose();
    const double pp = p.dot(p), ph = p.dot(hs);
    // −m[p][p] = m(|p|² E − p pᵀ); −[p][h] − [h][p] = 2(p·h) E − p hᵀ − h pᵀ.
    I.diagonal().array() += j.mass * pp + 2.0 * ph;
    I.noalias() -= j.mass * p * p.transpose();
    I.noalias() -= p * hs.transpose();
    I.noalias() -= hs * p.transpose();
    ws.wI[i] = I;
  }
}

}  // namespace detail

void computeKinematics(const Model& model, Data& data, const Eigen::VectorXd& q, const Eigen::VectorXd& dq) {
  auto& ws = detail::workspace(data);
  detail::checkSize(q, model.nq(), "computeKinematics: q");
  detail::checkSize(dq, model.nq(), "computeKinematics: dq");
  detail::updateJoints(model, data, q, dq);
  const auto& frames = model.frames();
  for (int k = 0; k < model.nframes(); ++k) {
    const FramePlacement& fp = frames[k];
    Eigen::Isometry3d& g = data.framePose[k];
    if (fp.joint == kWorld) {
      g.linear() = fp.R;
      g.translation() = fp.p;
      data.frameVelocity[k].setZero();
      continue;
    }
    const Eigen::Matrix3d& R = ws.jointR[fp.joint];
    g.linear().noalias() = R * fp.R;
    g.translation() = ws.jointP[fp.joint] + R * fp.p;
    const Vector6d& vj = ws.v[fp.joint];
    const Eigen::Matrix3d Rf = g.linear();
    const Eigen::Vector3d vPoint = spatial::pointVelocity(vj, g.translation());
    data.frameVelocity[k] << Rf.transpose() * vPoint, Rf.transpose() * spatial::ang(vj);
  }
}

}  // namespace trellis
