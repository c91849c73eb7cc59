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
  if (bp.joint == kWorld) return bp.local;
  return data.jointP[bp.joint] + data.jointR[bp.joint] * bp.local;
}

/// ṗ = v + ω × p, p̈ = a_v + α × p + ω × ṗ (a: spatial acceleration).
inline PointKin pointKin(const Data& data, const BodyPoint& bp) {
  PointKin k;
  k.p = pointPosition(data, bp);
  if (bp.joint == kWorld) return k;
  const Vector6d& v = data.v[bp.joint];
  const Vector6d& a = data.a[bp.joint];
  k.v = pointVelocity(v, k.p);
  k.a = lin(a) + ang(a).cross(k.p) + ang(v).cross(k.v);
  return k;
}

/// A unit-free direction n = R d fixed on a body: n, ṅ = ω × n, n̈ = α × n + ω × ṅ.
inline PointKin directionKin(const Data& data, int joint, const Vector3d& local) {
  PointKin k;
  if (joint == kWorld) {
    k.p = local;
    return k;
  }
  k.p = data.jointR[joint] * local;
  const Vector3d w = ang(data.v[joint]);
  k.v = w.cross(k.p);
  k.a = ang(data.a[joint]).cross(k.p) + w.cross(k.v);
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
  Direction d;
  d.k = k;
  d.end = model.joints()[k].subtreeEnd;
  d.velocity = velocity;
  d.Sk = data.S[k];
  const int p = model.joints()[k].parent;
  d.vP = p == kWorld ? Vector6d::Zero() : data.v[p];
  d.aP = p == kWorld ? Vector6d::Zero() : data.a[p];
  d.w = crossMotion(d.Sk, d.vP);
  return d;
}

/// Closed forms of the body tangents on the subtree of k (parent p = λ(k), w = S_k × v_p):
///  ∂/∂q_k:  δθ = S_k, δv = S_k × v − w, δa = S_k × (a − a_p) − w × (v − v_p);
///  ∂/∂q̇_k:  δθ = 0,   δv = S_k,         δa = S_k × v − 2 w.
inline BodyTangent bodyTangent(const Data& data, const Direction& d, int joint) {
  BodyTangent t;
  if (!d.moves(joint)) return t;
  const Vector6d& v = data.v[joint];
  if (!d.velocity) {
    t.theta = d.Sk;
    t.v = crossMotion(d.Sk, v) - d.w;
    t.a = crossMotion(d.Sk, data.a[joint] - d.aP) - crossMotion(d.w, v - d.vP);
  } else {
    t.v = d.Sk;
    t.a = crossMotion(d.Sk, v) - 2.0 * d.w;
  }
  return t;
}

/// Tangent of pointKin.
inline PointKin pointTangent(const Data& data, const Direction& dir, int joint, const PointKin& k) {
  PointKin d;
  if (!dir.moves(joint)) return d;
  const BodyTangent t = bodyTangent(data, dir, joint);
  const Vector3d w = ang(data.v[joint]), al = ang(data.a[joint]);
  d.p = lin(t.theta) + ang(t.theta).cross(k.p);
  d.v = lin(t.v) + ang(t.v).cross(k.p) + w.cross(d.p);
  d.a = lin(t.a) + ang(t.a).cross(k.p) + al.cross(d.p) + ang(t.v).cross(k.v) + w.cross(d.v);
  return d;
}

/// Displacement δp of a body point under direction dir (zero for q̇ directions).
inline Vector3d pointDisplacement(const Direction& dir, int joint, const Vector3d& p) {
  if (dir.velocity || !dir.moves(joint)) return Vector3d::Zero();
  return lin(dir.Sk) + ang(dir.Sk).cross(p);
}

/// Tangent of directionKin.
inline PointKin directionTangent(const Data& data, const Direction& dir, int joint, const PointKin& k) {
  PointKin d;
  if (!dir.moves(joint)) return d;
  const BodyTangent t = bodyTangent(data, dir, joint);
  const Vector3d w = ang(data.v[joint]), al = ang(data.a[joint]);
  d.p = ang(t.theta).cross(k.p);
  d.v = ang(t.v).cross(k.p) + w.cross(d.p);
  d.a = ang(t.a).cross(k.p) + al.cross(d.p) + ang(t.v).cross(k.v) + w.cross(d.v);
  return d;
}

/// Tension per unit length τ(L) of a linear spring: the force on a is τ (p_b − p_a).
inline double springTensionPerLength(const LinearSpring& s, double L) { return s.k * (1.0 - s.x0 / L); }
inline double springTensionPerLengthDerivative(const LinearSpring& s, double L) { return s.k * s.x0 / (L * L); }

/// World wrench of a body wrench w = [f; τ] given in the frame's axes at its origin.
inline Vector6d bodyWrenchWorld(const Data& data, const BodyWrench& bw, const Vector6d& w) {
  const Eigen::Matrix3d R = data.jointR[bw.joint] * bw.R;
  const Vector3d p = data.jointP[bw.joint] + data.jointR[bw.joint] * bw.p;
  const Vector3d f = R * w.head<3>();
  return make(f, p.cross(f) + R * w.tail<3>());
}

struct ConstraintEval {
  double h = 0.0;     ///< h(q) (0 for nonholonomic)
  double hdot = 0.0;  ///< A q̇
  double c = 0.0;     ///< A q̈ + Ȧ q̇ at the current accelerations
};

inline Vector3d constraintAxis(const Constraint& c) { return Vector3d::Unit(c.axis); }

/// h, A q̇ and d/dt(A q̇) from the kinematics of the constraint's points (and direction).
inline ConstraintEval evaluateConstraint(const Data& data, const Constraint& c) {
  ConstraintEval e;
  const PointKin a = pointKin(data, c.a);
  switch (c.type) {
    case ConstraintType::kDistance: {
      const PointKin b = pointKin(data, c.b);
      const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
      e.h = d.squaredNorm() - c.distance * c.distance;
      e.hdot = 2.0 * d.dot(dd);
      e.c = 2.0 * dd.squaredNorm() + 2.0 * d.dot(ddd);
      break;
    }
    case ConstraintType::kPoint: {
      const PointKin b = pointKin(data, c.b);
      const Vector3d ax = constraintAxis(c);
      e.h = ax.dot(a.p - b.p);
      e.hdot = ax.dot(a.v - b.v);
      e.c = ax.dot(a.a - b.a);
      break;
    }
    case ConstraintType::kPointOnPlane: {
      const PointKin b = pointKin(data, c.b);
      const PointKin n = directionKin(data, c.a.joint, c.direction);
      const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
      e.h = n.p.dot(d);
      e.hdot = n.v.dot(d) + n.p.dot(dd);
      e.c = n.a.dot(d) + 2.0 * n.v.dot(dd) + n.p.dot(ddd);
      break;
    }
    case ConstraintType::kKnifeEdge: {
      const PointKin n = directionKin(data, c.a.joint, c.direction);
      e.hdot = n.p.dot(a.v);
      e.c = n.v.dot(a.v) + n.p.dot(a.a);
      break;
    }
  }
  return e;
}

/// Directional derivative of evaluateConstraint (uses the body tangents in data).
inline ConstraintEval constraintTangent(const Data& data, const Direction& dir, const Constraint& c) {
  ConstraintEval e;
  const PointKin a = pointKin(data, c.a);
  const PointKin ta = pointTangent(data, dir, c.a.joint, a);
  switch (c.type) {
    case ConstraintType::kDistance: {
      const PointKin b = pointKin(data, c.b);
      const PointKin tb = pointTangent(data, dir, c.b.joint, b);
      const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
      const Vector3d td = ta.p - tb.p, tdd = ta.v - tb.v, tddd = ta.a - tb.a;
      e.h = 2.0 * d.dot(td);
      e.hdot = 2.0 * (td.dot(dd) + d.dot(tdd));
      e.c = 4.0 * dd.dot(tdd) + 2.0 * (td.dot(ddd) + d.dot(tddd));
      break;
    }
    case ConstraintType::kPoint: {
      const PointKin b = pointKin(data, c.b);
      const PointKin tb = pointTangent(data, dir, c.b.joint, b);
      const Vector3d ax = constraintAxis(c);
      e.h = ax.dot(ta.p - tb.p);
      e.hdot = ax.dot(ta.v - tb.v);
      e.c = ax.dot(ta.a - tb.a);
      break;
    }
    case ConstraintType::kPointOnPlane: {
      const PointKin b = pointKin(data, c.b);
      const PointKin tb = pointTangent(data, dir, c.b.joint, b);
      const PointKin n = directionKin(data, c.a.joint, c.direction);
      const PointKin tn = directionTangent(data, dir, c.a.joint, n);
      const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
      const Vector3d td = ta.p - tb.p, tdd = ta.v - tb.v, tddd = ta.a - tb.a;
      e.h = tn.p.dot(d) + n.p.dot(td);
      e.hdot = tn.v.dot(d) + n.v.dot(td) + tn.p.dot(dd) + n.p.dot(tdd);
      e.c = tn.a.dot(d) + n.a.dot(td) + 2.0 * (tn.v.dot(dd) + n.v.dot(tdd)) + tn.p.dot(ddd) + n.p.dot(tddd);
      break;
    }
    case ConstraintType::kKnifeEdge: {
      const PointKin n = directionKin(data, c.a.joint, c.direction);
      const PointKin tn = directionTangent(data, dir, c.a.joint, n);
      e.hdot = tn.p.dot(a.v) + n.p.dot(ta.v);
      e.c = tn.v.dot(a.v) + n.v.dot(ta.v) + tn.p.dot(a.a) + n.p.dot(ta.a);
      break;
    }
  }
  return e;
}

/// row(j) += g · ∂p/∂q_j for the joints j that move the body point at world position p; with a
/// `bound` row, also bound(j) += |g| ‖∂p/∂q_j‖, the largest |row(j)| the point could give.
template <class Row>
inline void addPointGradient(const Model& model, const Data& data, int joint, const Vector3d& p,
                             const Vector3d& g, Row&& row, Eigen::VectorXd* bound = nullptr) {
  const double gn = bound ? g.norm() : 0.0;
  for (int j = joint; j != kWorld; j = model.joints()[j].parent) {
    const Vector3d dp = lin(data.S[j]) + ang(data.S[j]).cross(p);
    row(j) += g.dot(dp);
    if (bound) (*bound)[j] += gn * dp.norm();
  }
}

/// The constraint's row of A = ∂(A q̇)/∂q̇ (for holonomic rows, ∂h/∂q), and optionally the
/// entry-wise bound of addPointGradient (used to measure how close the row is to singular).
template <class Row>
inline void addConstraintJacobianRow(const Model& model, const Data& data, const Constraint& c, Row&& row,
                                     Eigen::VectorXd* bound = nullptr) {
  const Vector3d pa = pointPosition(data, c.a);
  switch (c.type) {
    case ConstraintType::kDistance: {
      const Vector3d d = pa - pointPosition(data, c.b);
      addPointGradient(model, data, c.a.joint, pa, 2.0 * d, row, bound);
      addPointGradient(model, data, c.b.joint, pointPosition(data, c.b), -2.0 * d, row, bound);
      break;
    }
    case ConstraintType::kPoint: {
      const Vector3d ax = constraintAxis(c);
      addPointGradient(model, data, c.a.joint, pa, ax, row, bound);
      addPointGradient(model, data, c.b.joint, pointPosition(data, c.b), -ax, row, bound);
      break;
    }
    case ConstraintType::kPointOnPlane: {
      // The normal turns with the plane body: the plane body sees the force n at the point p_b.
      const Vector3d pb = pointPosition(data, c.b);
      const Vector3d n = directionKin(data, c.a.joint, c.direction).p;
      addPointGradient(model, data, c.a.joint, pb, n, row, bound);
      addPointGradient(model, data, c.b.joint, pb, -n, row, bound);
      break;
    }
    case ConstraintType::kKnifeEdge: {
      const Vector3d n = directionKin(data, c.a.joint, c.direction).p;
      addPointGradient(model, data, c.a.joint, pa, n, row, bound);
      break;
    }
  }
}

inline void addBodyWrench(Data& data, int joint, const Vector6d& w) {
  if (joint != kWorld) data.fext[joint] += w;
}
/// Constraint forces Aᵀλ of one row as wrenches on the bodies (data.fext).
inline void addConstraintWrenches(Data& data, const Constraint& c, double lambda) {
  const Vector3d pa = pointPosition(data, c.a);
  switch (c.type) {
    case ConstraintType::kDistance: {
      const Vector3d pb = pointPosition(data, c.b);
      const Vector3d f = 2.0 * lambda * (pa - pb);
      addBodyWrench(data, c.a.joint, forceAt(pa, f));
      addBodyWrench(data, c.b.joint, forceAt(pb, -f));
      break;
    }
    case ConstraintType::kPoint: {
      const Vector3d f = lambda * constraintAxis(c);
      addBodyWrench(data, c.a.joint, forceAt(pa, f));
      addBodyWrench(data, c.b.joint, forceAt(pointPosition(data, c.b), -f));
      break;
    }
    case ConstraintType::kPointOnPlane: {
      const Vector3d pb = pointPosition(data, c.b);
      const Vector3d f = lambda * directionKin(data, c.a.joint, c.direction).p;
      addBodyWrench(data, c.a.joint, forceAt(pb, f));
      addBodyWrench(data, c.b.joint, forceAt(pb, -f));
      break;
    }
    case ConstraintType::kKnifeEdge: {
      const Vector3d f = lambda * directionKin(data, c.a.joint, c.direction).p;
      addBodyWrench(data, c.a.joint, forceAt(pa, f));
      break;
    }
  }
}

/// Tangent of a force f applied at a moving point p: [δf; δp × f + p × δf].
inline Vector6d forceAtTangent(const Vector3d& p, const Vector3d& dp, const Vector3d& f, const Vector3d& df) {
  return make(df, dp.cross(f) + p.cross(df));
}

/// Tangent of addConstraintWrenches at fixed λ along a configuration direction; each body wrench
/// tangent is handed to emit(joint, δW).
template <class Emit>
inline void constraintWrenchTangents(const Data& data, const Direction& dir, const Constraint& c, double lambda,
                                     Emit&& emit) {
  const BodyPoint& A = c.a;
  const Vector3d pa = pointPosition(data, A), dpa = pointDisplacement(dir, A.joint, pa);
  switch (c.type) {
    case ConstraintType::kDistance: {
      const Vector3d pb = pointPosition(data, c.b), dpb = pointDisplacement(dir, c.b.joint, pb);
      const Vector3d f = 2.0 * lambda * (pa - pb), df = 2.0 * lambda * (dpa - dpb);
      emit(A.joint, forceAtTangent(pa, dpa, f, df));
      emit(c.b.joint, forceAtTangent(pb, dpb, -f, -df));
      break;
    }
    case ConstraintType::kPoint: {
      const Vector3d pb = pointPosition(data, c.b), dpb = pointDisplacement(dir, c.b.joint, pb);
      const Vector3d f = lambda * constraintAxis(c);
      emit(A.joint, forceAtTangent(pa, dpa, f, Vector3d::Zero()));
      emit(c.b.joint, forceAtTangent(pb, dpb, -f, Vector3d::Zero()));
      break;
    }
    case ConstraintType::kPointOnPlane: {
      const Vector3d pb = pointPosition(data, c.b), dpb = pointDisplacement(dir, c.b.joint, pb);
      const Vector3d n = directionKin(data, A.joint, c.direction).p;
      const Vector3d dn = dir.moves(A.joint) ? Vector3d(ang(dir.Sk).cross(n)) : Vector3d::Zero().eval();
      const Vector3d f = lambda * n, df = lambda * dn;
      emit(A.joint, forceAtTangent(pb, dpb, f, df));
      emit(c.b.joint, forceAtTangent(pb, dpb, -f, -df));
      break;
    }
    case ConstraintType::kKnifeEdge: {
      const Vector3d n = directionKin(data, A.joint, c.direction).p;
      const Vector3d dn = dir.moves(A.joint) ? Vector3d(ang(dir.Sk).cross(n)) : Vector3d::Zero().eval();
      emit(A.joint, forceAtTangent(pa, dpa, lambda * n, lambda * dn));
      break;
    }
  }
}

}  // namespace trellis::detail
