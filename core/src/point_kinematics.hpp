// Internal: kinematics of points and directions fixed on bodies, the constraint functions built on
// them, and the forces of point-based elements — each with its directional derivative (tangent).
//
// A tangent is the derivative along one state direction (∂/∂q_k or ∂/∂q̇_k) with q̈ and λ fixed.
// Body tangents: δθ (the twist by which the body moves, δp = δθ_v + δθ_ω × p), δv, δa.
#pragma once

#include "internal.hpp"

namespace trellis::detail {

using namespace spatial;

struct PointKin {  ///< world position, velocity, acceleration of a body point
  Vector3d p = Vector3d::Zero(), v = Vector3d::Zero(), a = Vector3d::Zero();
};

inline Vector3d pointPosition(const Data& data, const BodyPoint& bp) {
  auto& ws = detail::workspace(data);
  if (bp.joint == kWorld) return bp.local;
  return ws.jointP[bp.joint] + ws.jointR[bp.joint] * bp.local;
}

/// ṗ = v + ω × p, p̈ = a_v + α × p + ω × ṗ (a: spatial acceleration).
inline PointKin pointKin(const Data& data, const BodyPoint& bp) {
  auto& ws = detail::workspace(data);
  PointKin k;
  k.p = pointPosition(data, bp);
  if (bp.joint == kWorld) return k;
  const Vector6d& v = ws.v[bp.joint];
  const Vector6d& a = ws.a[bp.joint];
  k.v = pointVelocity(v, k.p);
  k.a = lin(a) + ang(a).cross(k.p) + ang(v).cross(k.v);
  return k;
}

/// A unit-free direction n = R d fixed on a body: n, ṅ = ω × n, n̈ = α × n + ω × ṅ.
inline PointKin directionKin(const Data& data, int joint, const Vector3d& local) {
  auto& ws = detail::workspace(data);
  PointKin k;
  if (joint == kWorld) {
    k.p = local;
    return k;
  }
  k.p = ws.jointR[joint] * local;
  const Vector3d w = ang(ws.v[joint]);
  k.v = w.cross(k.p);
  k.a = ang(ws.a[joint]).cross(k.p) + w.cross(k.v);
  return k;
}

/// The derivative of a body's motion along one state direction: δθ (the twist by which the body
/// is displaced, δp = δθ_v + δθ_ω × p), δv and δa. Zero for bodies the direction does not move.
struct BodyTangent {
  Vector6d theta = Vector6d::Zero(), v = Vector6d::Zero(), a = Vector6d::Zero();
};

/// One state direction, ∂/∂q_k or ∂/∂q̇_k. It moves the subtree [k, end) of joint k only.
struct Direction {
  int k = 0, end = 0;
  bool velocity = false;
  Vector6d Sk, vP, aP;  ///< S_k and the parent's velocity and acceleration
  Vector6d w;           ///< S_k × v_parent
  bool moves(int joint) const { return joint >= k && joint < end; }
};

inline Direction makeDirection(const Model& model, const Data& data, int k, bool velocity) {
  auto& ws = detail::workspace(data);
  Direction d;
  d.k = k;
  d.end = model.joints()[k].subtreeEnd;
  d.velocity = velocity;
  d.Sk = ws.S[k];
  const int p = model.joints()[k].parent;
  d.vP = p == kWorld ? Vector6d::Zero() : ws.v[p];
  d.aP = p == kWorld ? Vector6d::Zero() : ws.a[p];
  d.w = crossMotion(d.Sk, d.vP);
  return d;
}

/// Closed forms of the body tangents on the subtree of k (parent p = λ(k), w = S_k × v_p):
///  ∂/∂q_k:  δθ = S_k, δv = S_k × v − w, δa = S_k × (a − a_p) − w × (v − v_p);
///  ∂/∂q̇_k:  δθ = 0,   δv = S_k,         δa = S_k × v − 2 w.
inline BodyTangent bodyTangent(const Data& data, const Direction& d, int joint) {
  auto& ws = detail::workspace(data);
  BodyTangent t;
  if (!d.moves(joint)) return t;
  const Vector6d& v = ws.v[joint];
  if (!d.velocity) {
    t.theta = d.Sk;
    t.v = crossMotion(d.Sk, v) - d.w;
    t.a = crossMotion(d.Sk, ws.a[joint] - d.aP) - crossMotion(d.w, v - d.vP);
  } else {
    t.v = d.Sk;
    t.a = crossMotion(d.Sk, v) - 2.0 * d.w;
  }
  return t;
}

/// Tangent of pointKin, given the body's tangent t (bodyTangent; the body moves).
inline __attribute__((always_inline)) PointKin pointTangentOf(const Data& data, int joint, const BodyTangent& t, const PointKin& k) {
  auto& ws = detail::workspace(data);
  PointKin d;
  const Vector3d w = ang(ws.v[joint]), al = ang(ws.a[joint]);
  d.p = lin(t.theta) + ang(t.theta).cross(k.p);
  d.v = lin(t.v) + ang(t.v).cross(k.p) + w.cross(d.p);
  d.a = lin(t.a) + ang(t.a).cross(k.p) + al.cross(d.p) + ang(t.v).cross(k.v) + w.cross(d.v);
  return d;
}

/// Tangent of pointKin. Out of line, as GCC chose before pointTangentOf was split off: inlined,
/// its callers (PointKind::differenceTangent) grew out of the tangent pass (+0.6 %, hand.json).
inline __attribute__((noinline)) PointKin pointTangent(const Data& data, const Direction& dir, int joint, const PointKin& k) {
  if (!dir.moves(joint)) return PointKin{};
  return pointTangentOf(data, joint, bodyTangent(data, dir, joint), k);
}

/// Displacement δp of a body point under direction dir (zero for q̇ directions).
inline Vector3d pointDisplacement(const Direction& dir, int joint, const Vector3d& p) {
  if (dir.velocity || !dir.moves(joint)) return Vector3d::Zero();
  return lin(dir.Sk) + ang(dir.Sk).cross(p);
}

/// Tangent of directionKin, given the body's tangent t (bodyTangent; the body moves).
inline __attribute__((always_inline)) PointKin directionTangentOf(const Data& data, int joint, const BodyTangent& t, const PointKin& k) {
  auto& ws = detail::workspace(data);
  PointKin d;
  const Vector3d w = ang(ws.v[joint]), al = ang(ws.a[joint]);
  d.p = ang(t.theta).cross(k.p);
  d.v = ang(t.v).cross(k.p) + w.cross(d.p);
  d.a = ang(t.a).cross(k.p) + al.cross(d.p) + ang(t.v).cross(k.v) + w.cross(d.v);
  return d;
}

/// Tangent of directionKin.
inline PointKin directionTangent(const Data& data, const Direction& dir, int joint, const PointKin& k) {
  if (!dir.moves(joint)) return PointKin{};
  return directionTangentOf(data, joint, bodyTangent(data, dir, joint), k);
}

/// Tension per unit length τ(L) of a linear spring: the force on a is τ (p_b − p_a).
inline double springTensionPerLength(const LinearSpring& s, double L) { return s.k * (1.0 - s.x0 / L); }
inline double springTensionPerLengthDerivative(const LinearSpring& s, double L) { return s.k * s.x0 / (L * L); }

/// World wrench of a body wrench w = [f; τ] given in the frame's axes at its origin.
inline Vector6d bodyWrenchWorld(const Data& data, const BodyWrench& bw, const Vector6d& w) {
  auto& ws = detail::workspace(data);
  const Eigen::Matrix3d R = ws.jointR[bw.joint] * bw.R;
  const Vector3d p = ws.jointP[bw.joint] + ws.jointR[bw.joint] * bw.p;
  const Vector3d f = R * w.head<3>();
  return make(f, p.cross(f) + R * w.tail<3>());
}

/// row(j) += g · ∂p/∂q_j for the joints j that move the body point at world position p; with a
/// `bound` row, also bound(j) += gScale ‖∂p/∂q_j‖, the largest |row(j)| a gradient of the
/// natural size gScale could give (see constraint_kinds.hpp).
template <class Row>
inline void addPointGradient(const Model& model, const Data& data, int joint, const Vector3d& p,
                             const Vector3d& g, Row&& row, Eigen::VectorXd* bound = nullptr, double gScale = 0.0) {
  auto& ws = detail::workspace(data);
  for (int j = joint; j != kWorld; j = model.joints()[j].parent) {
    const Vector3d dp = lin(ws.S[j]) + ang(ws.S[j]).cross(p);
    row(j) += g.dot(dp);
    if (bound) (*bound)[j] += gScale * dp.norm();
  }
}

inline void addBodyWrench(DataWorkspace& ws, int joint, const Vector6d& w) {
  if (joint != kWorld) ws.fext[joint] += w;
}

/// Tangent of a force f applied at a moving point p: [δf; δp × f + p × δf].
inline Vector6d forceAtTangent(const Vector3d& p, const Vector3d& dp, const Vector3d& f, const Vector3d& df) {
  return make(df, dp.cross(f) + p.cross(df));
}

}  // namespace trellis::detail
