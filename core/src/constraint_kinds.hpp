// Internal: each constraint kind as one unit — its value, its row of A, its drift term, the
// forces its multiplier applies, and the derivatives of all of these — and the one dispatch on
// the kind. Adding a kind is one struct here and one line in withConstraintKind.
//
// A kind provides (Data holds the kinematics of the current state; see point_kinematics.hpp):
//   value(data, c)                 → {h, A q̇, A q̈ + Ȧ q̇} at the accelerations in data
//   tangent(data, dir, c)          → the derivative of value along one state direction
//   forces(data, c, emit)          → the row as point forces: A_r = Σ gᵀ ∂p/∂q over the calls
//                                    emit(joint, p, g, gScale), so that Aᵀλ is the force λ g at p
//                                    on `joint`'s body; gScale is the size ‖g‖ has in a regular
//                                    configuration (the row's natural scale, for conditioning)
//   forceTangents(data, dir, c, emit) → emit(joint, p, δp, g, δg): the derivative of forces
//                                    along a configuration direction
// Everything is fixed-size and inlined: no allocation, no virtual call.
#pragma once

#include "point_kinematics.hpp"

namespace trellis::detail {

struct ConstraintEval {
  double h = 0.0;     ///< h(q) (0 for nonholonomic)
  double hdot = 0.0;  ///< A q̇
  double c = 0.0;     ///< A q̈ + Ȧ q̇ at the current accelerations
};

/// h = ‖d‖² − ℓ², d = p_a − p_b: A q̇ = 2 d·ḋ, c = 2 ‖ḋ‖² + 2 d·d̈; the row is the force 2d on a,
/// −2d on b, of natural size 2ℓ (it vanishes when the points coincide: a degenerate row).
struct DistanceKind {
  static ConstraintEval value(const Data& data, const Constraint& c) {
    const PointKin a = pointKin(data, c.a), b = pointKin(data, c.b);
    const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
    return {d.squaredNorm() - c.distance * c.distance, 2.0 * d.dot(dd), 2.0 * dd.squaredNorm() + 2.0 * d.dot(ddd)};
  }
  static ConstraintEval tangent(const Data& data, const Direction& dir, const Constraint& c) {
    const PointKin a = pointKin(data, c.a), b = pointKin(data, c.b);
    const PointKin ta = pointTangent(data, dir, c.a.joint, a), tb = pointTangent(data, dir, c.b.joint, b);
    const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
    const Vector3d td = ta.p - tb.p, tdd = ta.v - tb.v, tddd = ta.a - tb.a;
    return {2.0 * d.dot(td), 2.0 * (td.dot(dd) + d.dot(tdd)), 4.0 * dd.dot(tdd) + 2.0 * (td.dot(ddd) + d.dot(tddd))};
  }
  template <class Emit>
  static void forces(const Data& data, const Constraint& c, Emit&& emit) {
    const Vector3d pa = pointPosition(data, c.a), pb = pointPosition(data, c.b);
    const Vector3d g = 2.0 * (pa - pb);
    emit(c.a.joint, pa, g, 2.0 * c.distance);
    emit(c.b.joint, pb, Vector3d(-g), 2.0 * c.distance);
  }
  template <class Emit>
  static void forceTangents(const Data& data, const Direction& dir, const Constraint& c, Emit&& emit) {
    const Vector3d pa = pointPosition(data, c.a), pb = pointPosition(data, c.b);
    const Vector3d dpa = pointDisplacement(dir, c.a.joint, pa), dpb = pointDisplacement(dir, c.b.joint, pb);
    const Vector3d g = 2.0 * (pa - pb), dg = 2.0 * (dpa - dpb);
    emit(c.a.joint, pa, dpa, g, dg);
    emit(c.b.joint, pb, dpb, Vector3d(-g), Vector3d(-dg));
  }
};

/// h = e·(p_a − p_b), e a fixed world axis: linear in the points; the row is the force e on a,
/// −e on b (natural size 1).
struct PointKind {
  static ConstraintEval value(const Data& data, const Constraint& c) {
    const PointKin a = pointKin(data, c.a), b = pointKin(data, c.b);
    const Vector3d e = Vector3d::Unit(c.axis);
    return {e.dot(a.p - b.p), e.dot(a.v - b.v), e.dot(a.a - b.a)};
  }
  static ConstraintEval tangent(const Data& data, const Direction& dir, const Constraint& c) {
    return fromDifferenceTangent(c, differenceTangent(data, dir, c));
  }
  /// The tangent of p_a − p_b (with its velocity and acceleration), shared by the rows of one
  /// point pair (constraintTangents computes it once for the x, y, z rows).
  static PointKin differenceTangent(const Data& data, const Direction& dir, const Constraint& c) {
    PointKin d;
    if (dir.moves(c.a.joint)) d = pointTangent(data, dir, c.a.joint, pointKin(data, c.a));
    if (dir.moves(c.b.joint)) {
      const PointKin tb = pointTangent(data, dir, c.b.joint, pointKin(data, c.b));
      d.p -= tb.p;
      d.v -= tb.v;
      d.a -= tb.a;
    }
    return d;
  }
  static ConstraintEval fromDifferenceTangent(const Constraint& c, const PointKin& d) {
    return {d.p[c.axis], d.v[c.axis], d.a[c.axis]};
  }
  /// The values of `count` consecutive rows on one point pair (rows[k] for k < count), from one
  /// evaluation of the two points: out(k, eval).
  template <class Out>
  static void pairValues(const Data& data, const Constraint* rows, int count, Out&& out) {
    const PointKin a = pointKin(data, rows[0].a), b = pointKin(data, rows[0].b);
    const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
    for (int k = 0; k < count; ++k) {
      const int axis = rows[k].axis;
      out(k, ConstraintEval{d[axis], dd[axis], ddd[axis]});
    }
  }
  /// Rows firstRow … firstRow + count − 1 of A for `count` consecutive rows on one point pair:
  /// A(r, j) = ±∂p/∂q_j along the row's axis, each ∂p/∂q_j formed once for all the rows, and
  /// bound(j) += ‖∂p/∂q_j‖ (the rows' common natural scale, addConstraintJacobianRow's).
  template <class Mat>
  static void addPairJacobianRows(const Model& model, const Data& data, const Constraint* rows, int count, int firstRow,
                                  Mat& A, Eigen::VectorXd& bound) {
    auto& ws = detail::workspace(data);
    for (int side = 0; side < 2; ++side) {
      const BodyPoint& bp = side == 0 ? rows[0].a : rows[0].b;
      const Vector3d p = pointPosition(data, bp);
      const double sign = side == 0 ? 1.0 : -1.0;
      for (int j = bp.joint; j != kWorld; j = model.joints()[j].parent) {
        const Vector3d dp = lin(ws.S[j]) + ang(ws.S[j]).cross(p);
        for (int k = 0; k < count; ++k) A(firstRow + k, j) += sign * dp[rows[k].axis];
        bound[j] += dp.norm();
      }
    }
  }
  static bool samePair(const Constraint& x, const Constraint& y) {
    return x.type == ConstraintType::kPoint && y.type == ConstraintType::kPoint && x.a.joint == y.a.joint &&
           x.b.joint == y.b.joint && x.a.local == y.a.local && x.b.local == y.b.local;
  }
  template <class Emit>
  static void forces(const Data& data, const Constraint& c, Emit&& emit) {
    const Vector3d e = Vector3d::Unit(c.axis);
    emit(c.a.joint, pointPosition(data, c.a), e, 1.0);
    emit(c.b.joint, pointPosition(data, c.b), Vector3d(-e), 1.0);
  }
  template <class Emit>
  static void forceTangents(const Data& data, const Direction& dir, const Constraint& c, Emit&& emit) {
    const Vector3d pa = pointPosition(data, c.a), pb = pointPosition(data, c.b);
    const Vector3d e = Vector3d::Unit(c.axis), zero = Vector3d::Zero();
    emit(c.a.joint, pa, pointDisplacement(dir, c.a.joint, pa), e, zero);
    emit(c.b.joint, pb, pointDisplacement(dir, c.b.joint, pb), Vector3d(-e), zero);
  }
  /// The wrench tangents of the rows of one point pair together, whose force is f = Σ λ_r e_r on
  /// a and −f on b (e_r fixed: δf = 0): emit(joint, [0; δp × f]) for each body that moves.
  template <class Emit>
  static inline __attribute__((always_inline)) void pairWrenchTangents(const Data& data, const Direction& dir, const Constraint& c, const Vector3d& f,
                                 Emit&& emit) {
    if (!dir.velocity && dir.moves(c.a.joint)) {
      const Vector3d dp = pointDisplacement(dir, c.a.joint, pointPosition(data, c.a));
      emit(c.a.joint, make(Vector3d::Zero(), dp.cross(f)));
    }
    if (!dir.velocity && dir.moves(c.b.joint)) {
      const Vector3d dp = pointDisplacement(dir, c.b.joint, pointPosition(data, c.b));
      emit(c.b.joint, make(Vector3d::Zero(), f.cross(dp)));
    }
  }
};

/// Normal n = R_a n_a of the plane body a, and its derivative along a configuration direction.
inline Vector3d bodyDirection(const Data& data, const Constraint& c) { return directionKin(data, c.a.joint, c.direction).p; }
inline Vector3d bodyDirectionDisplacement(const Direction& dir, const Constraint& c, const Vector3d& n) {
  return dir.moves(c.a.joint) ? Vector3d(ang(dir.Sk).cross(n)) : Vector3d::Zero().eval();
}

/// h = n·(p_a − p_b) with the normal n = R_a n_a turning with the plane body a. The row is the
/// force n on the plane body and −n on the point body, both at the point p_b (natural size ‖n_a‖).
struct PointOnPlaneKind {
  /// The rows of one contact on one pair of points (normal and two tangents) taken together.
  static constexpr int kContactRows = 3;
  static ConstraintEval value(const Data& data, const Constraint& c) {
    const PointKin a = pointKin(data, c.a), b = pointKin(data, c.b);
    const PointKin n = directionKin(data, c.a.joint, c.direction);
    const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
    return {n.p.dot(d), n.v.dot(d) + n.p.dot(dd), n.a.dot(d) + 2.0 * n.v.dot(dd) + n.p.dot(ddd)};
  }
  /// What the rows on one pair of points share along a direction: d = p_a − p_b with its
  /// velocity and acceleration (`kin`), and their tangents (`tan`). The three rows of a sticking
  /// contact (normal and two tangents, the same two points) differ only in their direction.
  /// The plane body's tangent too (`planeBody`, when `planeMoves`): it turns each row's normal.
  struct PairTangent {
    PointKin kin, tan;
    BodyTangent planeBody;
    bool planeMoves = false;
  };
  static PairTangent pairTangent(const Data& data, const Direction& dir, const Constraint& c) {
    const PointKin a = pointKin(data, c.a), b = pointKin(data, c.b);
    PairTangent pt;
    pt.planeMoves = dir.moves(c.a.joint);
    PointKin ta;
    if (pt.planeMoves) {
      pt.planeBody = bodyTangent(data, dir, c.a.joint);
      ta = pointTangentOf(data, c.a.joint, pt.planeBody, a);
    }
    const PointKin tb = pointTangent(data, dir, c.b.joint, b);
    pt.kin = {a.p - b.p, a.v - b.v, a.a - b.a};
    pt.tan = {ta.p - tb.p, ta.v - tb.v, ta.a - tb.a};
    return pt;
  }
  static ConstraintEval tangent(const Data& data, const Direction& dir, const Constraint& c) {
    return fromPairTangent(data, c, pairTangent(data, dir, c));
  }
  static ConstraintEval fromPairTangent(const Data& data, const Constraint& c, const PairTangent& pt) {
    const PointKin n = directionKin(data, c.a.joint, c.direction);
    const PointKin tn = pt.planeMoves ? directionTangentOf(data, c.a.joint, pt.planeBody, n) : PointKin{};
    const Vector3d &d = pt.kin.p, &dd = pt.kin.v, &ddd = pt.kin.a;
    const Vector3d &td = pt.tan.p, &tdd = pt.tan.v, &tddd = pt.tan.a;
    return {tn.p.dot(d) + n.p.dot(td), tn.v.dot(d) + n.v.dot(td) + tn.p.dot(dd) + n.p.dot(tdd),
            tn.a.dot(d) + n.a.dot(td) + 2.0 * (tn.v.dot(dd) + n.v.dot(tdd)) + tn.p.dot(ddd) + n.p.dot(tddd)};
  }
  /// The values of `count` consecutive rows on one pair (samePair), value's operations with the
  /// two points evaluated once.
  template <class Out>
  static void pairValues(const Data& data, const Constraint* rows, int count, Out&& out) {
    const PointKin a = pointKin(data, rows[0].a), b = pointKin(data, rows[0].b);
    const Vector3d d = a.p - b.p, dd = a.v - b.v, ddd = a.a - b.a;
    for (int k = 0; k < count; ++k) {
      const PointKin n = directionKin(data, rows[k].a.joint, rows[k].direction);
      out(k, ConstraintEval{n.p.dot(d), n.v.dot(d) + n.p.dot(dd), n.a.dot(d) + 2.0 * n.v.dot(dd) + n.p.dot(ddd)});
    }
  }
  /// Rows firstRow … firstRow + count − 1 of A for `count` ≤ kContactRows consecutive rows on one
  /// pair (samePair): each row's force n_k on the plane body and −n_k on the point body, both at
  /// p_b, with ∂p_b/∂q_j formed once for all the rows (addConstraintJacobianRow's sums otherwise);
  /// bound(j) += ‖∂p_b/∂q_j‖ per side, which row k's natural scale ‖n_a,k‖ multiplies.
  template <class Mat>
  static void addPairJacobianRows(const Model& model, const Data& data, const Constraint* rows, int count, int firstRow,
                                  Mat& A, Eigen::VectorXd& bound) {
    auto& ws = detail::workspace(data);
    const Vector3d pb = pointPosition(data, rows[0].b);
    Vector3d n[kContactRows];
    for (int k = 0; k < count; ++k) n[k] = bodyDirection(data, rows[k]);
    for (int side = 0; side < 2; ++side) {
      for (int j = side == 0 ? rows[0].a.joint : rows[0].b.joint; j != kWorld; j = model.joints()[j].parent) {
        const Vector3d dp = lin(ws.S[j]) + ang(ws.S[j]).cross(pb);
        for (int k = 0; k < count; ++k) {
          const double g = n[k].dot(dp);
          if (side == 0) A(firstRow + k, j) += g;
          else A(firstRow + k, j) -= g;  // (−n)·dp, exactly
        }
        bound[j] += dp.norm();
      }
    }
  }
  /// Whether rows x and y are point-on-plane rows on the same two body points (and plane body).
  static bool samePair(const Constraint& x, const Constraint& y) {
    return x.type == ConstraintType::kPointOnPlane && y.type == ConstraintType::kPointOnPlane && x.a.joint == y.a.joint &&
           x.b.joint == y.b.joint && x.a.local == y.a.local && x.b.local == y.b.local;
  }
  template <class Emit>
  static void forces(const Data& data, const Constraint& c, Emit&& emit) {
    const Vector3d pb = pointPosition(data, c.b), n = bodyDirection(data, c);
    const double s = c.direction.norm();
    emit(c.a.joint, pb, n, s);
    emit(c.b.joint, pb, Vector3d(-n), s);
  }
  template <class Emit>
  static void forceTangents(const Data& data, const Direction& dir, const Constraint& c, Emit&& emit) {
    const Vector3d pb = pointPosition(data, c.b), dpb = pointDisplacement(dir, c.b.joint, pb);
    const Vector3d n = bodyDirection(data, c), dn = bodyDirectionDisplacement(dir, c, n);
    emit(c.a.joint, pb, dpb, n, dn);
    emit(c.b.joint, pb, dpb, Vector3d(-n), Vector3d(-dn));
  }
  /// constraintTangents' work for one contact: the tangents ev[k] of the rows rows[0 … count − 1]
  /// that lie on rows[0]'s pair (samePair; at most kContactRows of the `available` rows), the
  /// pair's tangent once; returns count. Out of line, as contactWrenchTangents.
  static __attribute__((noinline)) int contactTangents(const Data& data, const Direction& dir, const Constraint* rows,
                                                      int available, ConstraintEval* ev) {
    const PairTangent pt = pairTangent(data, dir, rows[0]);
    int count = 0;
    do {
      ev[count] = fromPairTangent(data, rows[count], pt);
      ++count;
    } while (count < kContactRows && count < available && samePair(rows[0], rows[count]));
    return count;
  }
  /// Wrench tangents on the plane body (`a`) and on the point body (`b`).
  struct ContactWrenchTangents {
    Vector6d a, b;
  };
  /// The wrench tangents (configuration direction) of `count` consecutive rows on one pair
  /// (samePair) with multipliers lambda[k], together: one force f = Σ λ_k n_k at p_b on the plane
  /// body and −f on the point body, δf = Σ λ_k δn_k — two wrench tangents instead of two per row
  /// (forceAtTangent is linear in f, δf at one point). Out of line, as contactTangents: inlined
  /// into the tangent pass with it, code that free models never run cost their passes up to ~50
  /// instructions per direction (callgrind, planar 10-chain: +1.6 % of a linearization).
  static __attribute__((noinline)) ContactWrenchTangents contactWrenchTangents(const Data& data, const Direction& dir,
                                                                              const Constraint* rows,
                                                                              const double* lambda, int count) {
    const Constraint& c = rows[0];
    const Vector3d pb = pointPosition(data, c.b), dpb = pointDisplacement(dir, c.b.joint, pb);
    const bool turns = dir.moves(c.a.joint);  // bodyDirectionDisplacement's test, once
    Vector3d f = Vector3d::Zero(), df = Vector3d::Zero();
    for (int k = 0; k < count; ++k) {
      const Vector3d n = bodyDirection(data, rows[k]);
      f += lambda[k] * n;
      if (turns) df += lambda[k] * Vector3d(ang(dir.Sk).cross(n));
    }
    return {forceAtTangent(pb, dpb, f, df), forceAtTangent(pb, dpb, Vector3d(-f), Vector3d(-df))};
  }
};

/// Nonholonomic e·ṗ_a = 0 with e = R_a e_a fixed on the body (no h): A q̇ = e·ṗ_a,
/// c = ė·ṗ_a + e·p̈_a; the row is the force e at p_a (natural size ‖e_a‖).
struct KnifeEdgeKind {
  static ConstraintEval value(const Data& data, const Constraint& c) {
    const PointKin a = pointKin(data, c.a);
    const PointKin n = directionKin(data, c.a.joint, c.direction);
    return {0.0, n.p.dot(a.v), n.v.dot(a.v) + n.p.dot(a.a)};
  }
  static ConstraintEval tangent(const Data& data, const Direction& dir, const Constraint& c) {
    const PointKin a = pointKin(data, c.a), ta = pointTangent(data, dir, c.a.joint, a);
    const PointKin n = directionKin(data, c.a.joint, c.direction);
    const PointKin tn = directionTangent(data, dir, c.a.joint, n);
    return {0.0, tn.p.dot(a.v) + n.p.dot(ta.v), tn.v.dot(a.v) + n.v.dot(ta.v) + tn.p.dot(a.a) + n.p.dot(ta.a)};
  }
  template <class Emit>
  static void forces(const Data& data, const Constraint& c, Emit&& emit) {
    emit(c.a.joint, pointPosition(data, c.a), bodyDirection(data, c), c.direction.norm());
  }
  template <class Emit>
  static void forceTangents(const Data& data, const Direction& dir, const Constraint& c, Emit&& emit) {
    const Vector3d pa = pointPosition(data, c.a), n = bodyDirection(data, c);
    emit(c.a.joint, pa, pointDisplacement(dir, c.a.joint, pa), n, bodyDirectionDisplacement(dir, c, n));
  }
};

/// h = q_j − m q_i − o (j = a.joint, i = b.joint): a constant row A = e_j − m e_i, so A q̇ = q̇_j −
/// m q̇_i, c = q̈_j − m q̈_i (Ȧ = 0) and every tangent at fixed q̈ is the row itself (position
/// directions, on h; velocity directions, on A q̇). Its force Aᵀλ is a generalized force on two
/// coordinates, applied as wrenches so that every algorithm that sums body wrenches sees it: on a
/// revolute joint a unit couple about its axis a on the joint's body and the opposite couple on
/// its parent body — forces g = (a × u)/2 at o + u and −g at o − u (o on the axis, u ⟂ a unit;
/// (2u) × g = a); on a prismatic joint the force a at o and −a on the parent. In the row
/// Σ gᵀ ∂p/∂q the ancestors' columns cancel (equal and opposite forces at one point) and the
/// joint's own column is g·(a × u) + (−g)·(a × (−u)) = 1 (resp. a·a = 1). The points and forces
/// move rigidly with the joint's body, so their tangents are the body's: the couple's derivative
/// is δa = ω × a, exact whatever u is chosen.
struct CoordinateCouplingKind {
  static ConstraintEval value(const Data& data, const Constraint& c) {
    const auto& ws = detail::workspace(data);
    const int j = c.a.joint, i = c.b.joint;
    const double m = c.coupling.multiplier;
    return {ws.q[j] - m * ws.q[i] - c.coupling.offset, ws.dq[j] - m * ws.dq[i], ws.qddOfA[j] - m * ws.qddOfA[i]};
  }
  static ConstraintEval tangent(const Data&, const Direction& dir, const Constraint& c) {
    const double row = (dir.k == c.a.joint ? 1.0 : 0.0) - (dir.k == c.b.joint ? c.coupling.multiplier : 0.0);
    return dir.velocity ? ConstraintEval{0.0, row, 0.0} : ConstraintEval{row, 0.0, 0.0};
  }
  /// The generalized force `weight` on coordinate `joint` as emit(body, p, g, gScale) calls (with
  /// emitTangent: emit(body, p, δp, g, δg) along `dir`).
  template <class Emit>
  static void unitForce(const Data& data, int joint, int parent, bool revolute, double weight, Emit&& emit) {
    const auto& ws = detail::workspace(data);
    const Vector3d o = ws.jointP[joint];
    if (revolute) {
      const Vector3d a = ang(ws.S[joint]);
      int k = 0;
      a.cwiseAbs().minCoeff(&k);
      const Vector3d u = a.cross(Vector3d::Unit(k)).normalized();
      const Vector3d g = 0.5 * weight * a.cross(u);
      const Vector3d p1 = o + u, p2 = o - u;
      emit(joint, p1, g, 0.5 * std::abs(weight));
      emit(joint, p2, Vector3d(-g), 0.5 * std::abs(weight));
      emit(parent, p1, Vector3d(-g), 0.5 * std::abs(weight));
      emit(parent, p2, g, 0.5 * std::abs(weight));
    } else {
      const Vector3d g = weight * lin(ws.S[joint]);
      emit(joint, o, g, std::abs(weight));
      emit(parent, o, Vector3d(-g), std::abs(weight));
    }
  }
  template <class Emit>
  static void forces(const Data& data, const Constraint& c, Emit&& emit) {
    unitForce(data, c.a.joint, c.coupling.followerParent, c.coupling.followerRevolute, 1.0, emit);
    unitForce(data, c.b.joint, c.coupling.leaderParent, c.coupling.leaderRevolute, -c.coupling.multiplier, emit);
  }
  template <class Emit>
  static void forceTangents(const Data& data, const Direction& dir, const Constraint& c, Emit&& emit) {
    // Each joint's points and forces are fixed to that joint's body (see above).
    const auto tangentOf = [&](int joint) {
      return [&, joint](int body, const Vector3d& p, const Vector3d& g, double) {
        const bool moves = !dir.velocity && dir.moves(joint);
        const Vector3d dg = moves ? Vector3d(ang(dir.Sk).cross(g)) : Vector3d::Zero().eval();
        emit(body, p, pointDisplacement(dir, joint, p), g, dg);
      };
    };
    unitForce(data, c.a.joint, c.coupling.followerParent, c.coupling.followerRevolute, 1.0, tangentOf(c.a.joint));
    unitForce(data, c.b.joint, c.coupling.leaderParent, c.coupling.leaderRevolute, -c.coupling.multiplier,
              tangentOf(c.b.joint));
  }
};

/// The one dispatch on the kind: f(Kind{}) for c's kind.
template <class F>
inline decltype(auto) withConstraintKind(const Constraint& c, F&& f) {
  switch (c.type) {
    case ConstraintType::kDistance: return f(DistanceKind{});
    case ConstraintType::kPoint: return f(PointKind{});
    case ConstraintType::kPointOnPlane: return f(PointOnPlaneKind{});
    case ConstraintType::kKnifeEdge: return f(KnifeEdgeKind{});
    case ConstraintType::kCoordinateCoupling: return f(CoordinateCouplingKind{});
  }
  return f(KnifeEdgeKind{});  // not reached: every enumerator is handled above
}

// ---- The quantities the algorithms use, each defined once for every kind ----------------------

/// h, A q̇ and d/dt(A q̇) from the kinematics of the constraint's points (and direction).
inline ConstraintEval evaluateConstraint(const Data& data, const Constraint& c) {
  return withConstraintKind(c, [&](auto kind) { return decltype(kind)::value(data, c); });
}

/// Directional derivative of evaluateConstraint (uses the body tangents in data).
inline ConstraintEval constraintTangent(const Data& data, const Direction& dir, const Constraint& c) {
  return withConstraintKind(c, [&](auto kind) { return decltype(kind)::tangent(data, dir, c); });
}

/// constraintTangent of every row the direction moves, as out(r, eval) (rows it does not move
/// get zeros); consecutive point rows, and consecutive point-on-plane rows (a contact), on one
/// pair of body points share the pair's tangent. Always inlined into the tangent pass (its one
/// caller), as the loop before contacts shared their tangents was by itself: out of line, the
/// call and its callback's captures in memory cost every direction, free models' too (+30
/// instructions per direction on the planar 10-chain, +165 on hand.json; callgrind).
template <class Out>
inline __attribute__((always_inline)) void constraintTangents(const Model& model, const Data& data, const Direction& dir,
                                                              Out&& out) {
  const auto& cs = model.constraints();
  PointKin pair;
  int pairRow = -1;  // the row whose point pair `pair` belongs to
  ConstraintEval contact[PointOnPlaneKind::kContactRows];
  int contactRow = -1;  // the first row of the contact whose rows' tangents are in `contact`
  for (int r = 0; r < model.nc(); ++r) {
    const Constraint& c = cs[r];
    if (!dir.moves(c.a.joint) && !dir.moves(c.b.joint)) {
      out(r, ConstraintEval{});
    } else if (c.type == ConstraintType::kPoint) {
      if (pairRow < 0 || !PointKind::samePair(cs[pairRow], c)) {
        pair = PointKind::differenceTangent(data, dir, c);
        pairRow = r;
      }
      out(r, PointKind::fromDifferenceTangent(c, pair));
    } else if (c.type == ConstraintType::kPointOnPlane) {
      // A contact's rows (normal, two tangents) together, out of line, on its first row.
      if (contactRow < 0 || r - contactRow >= PointOnPlaneKind::kContactRows || !PointOnPlaneKind::samePair(cs[contactRow], c)) {
        PointOnPlaneKind::contactTangents(data, dir, &c, model.nc() - r, contact);
        contactRow = r;
      }
      out(r, contact[r - contactRow]);
    } else {
      out(r, constraintTangent(data, dir, c));
    }
  }
}

/// The constraint's row of A = ∂(A q̇)/∂q̇ (for holonomic rows, ∂h/∂q), and optionally, in
/// `bound`, the entry-wise size the row has when its gradients have their natural size
/// (Σ gScale ‖∂p/∂q_j‖): ‖A_r‖ / ‖bound‖ → 0 measures how close the row is to degenerate,
/// independently of the units and scale of h.
template <class Row>
inline void addConstraintJacobianRow(const Model& model, const Data& data, const Constraint& c, Row&& row,
                                     Eigen::VectorXd* bound = nullptr) {
  withConstraintKind(c, [&](auto kind) {
    decltype(kind)::forces(data, c, [&](int joint, const Vector3d& p, const Vector3d& g, double gScale) {
      addPointGradient(model, data, joint, p, g, row, bound, gScale);
    });
  });
}

/// Constraint forces Aᵀλ of one row as wrenches on the bodies (ws.fext).
inline void addConstraintWrenches(Data& data, const Constraint& c, double lambda) {
  DataWorkspace& ws = workspace(data);
  withConstraintKind(c, [&](auto kind) {
    decltype(kind)::forces(data, c, [&](int joint, const Vector3d& p, const Vector3d& g, double) {
      addBodyWrench(ws, joint, forceAt(p, lambda * g));
    });
  });
}

/// Tangent of addConstraintWrenches at fixed λ along a configuration direction; each body wrench
/// tangent is handed to emit(joint, δW).
template <class Emit>
inline void constraintWrenchTangents(const Data& data, const Direction& dir, const Constraint& c, double lambda,
                                     Emit&& emit) {
  withConstraintKind(c, [&](auto kind) {
    decltype(kind)::forceTangents(
        data, dir, c, [&](int joint, const Vector3d& p, const Vector3d& dp, const Vector3d& g, const Vector3d& dg) {
          emit(joint, forceAtTangent(p, dp, lambda * g, lambda * dg));
        });
  });
}

}  // namespace trellis::detail
