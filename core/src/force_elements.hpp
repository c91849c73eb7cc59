// Internal: each force element kind as one unit — the forces it applies, its columns of
// ∂Q/∂u, its potential energy and the derivatives of its forces along a state direction — and
// the one visitor over the model's elements. Adding a kind is one struct here and one loop in
// forEachForceElement (besides its storage in Model).
//
// Every quantity has a default that contributes nothing (ForceKindBase); a kind defines what it has:
//   wrenches(model, data, e, i, u, emit)    body wrenches as emit(joint, W) (world axes, at the origin)
//   generalizedForce(q, dq, u, e, Q)    forces that act on coordinates directly, Q += …
//   addInputColumns(model, data, e, i, Bq)  Bq += ∂Q/∂u
//   wrenchTangents(model, data, dir, e, i, u, emit)  ∂W/∂q_k as emit(joint, δW) (q-directions only)
//   generalizedForceTangent(dir, e, add)  add(i, ∂Q_i/∂q_k or ∂Q_i/∂q̇_k) for the direction's k
//   potential(data, q, e)               V (conservative kinds)
// `conservative` says whether the element's forces derive from its potential.
// i is the element's index in its list (tendons use it to find their paths in model.topology()).
#pragma once

#include "point_kinematics.hpp"

namespace trellis::detail {

/// Equal and opposite forces along the segment a → b: τ d on a, −τ d on b, d = p_b − p_a.
template <class Emit>
inline void segmentWrenches(int ja, int jb, const Vector3d& pa, const Vector3d& pb, double tau, Emit&& emit) {
  const Vector3d f = tau * (pb - pa);
  emit(ja, forceAt(pa, f));
  emit(jb, forceAt(pb, Vector3d(-f)));
}

/// Tangent of segmentWrenches with τ = τ(L), L = ‖d‖: δL = d·δd / L, δf = τ'(L) δL d + τ δd.
template <class Emit>
inline void segmentWrenchTangents(const Direction& dir, int ja, int jb, const Vector3d& pa, const Vector3d& pb,
                                  double tau, double dtaudL, Emit&& emit) {
  const Vector3d dpa = pointDisplacement(dir, ja, pa), dpb = pointDisplacement(dir, jb, pb);
  const Vector3d d = pb - pa, dd = dpb - dpa;
  const double dL = d.dot(dd) / d.norm();
  const Vector3d f = tau * d, df = dtaudL * dL * d + tau * dd;
  emit(ja, forceAtTangent(pa, dpa, f, df));
  emit(jb, forceAtTangent(pb, dpb, Vector3d(-f), Vector3d(-df)));
}

struct ForceKindBase {
  static constexpr bool conservative = false;
  template <class E, class Emit>
  static void wrenches(const Model&, Data&, const E&, size_t, const Eigen::VectorXd&, Emit&&) {}
  template <class E>
  static void generalizedForce(const Eigen::VectorXd&, const Eigen::VectorXd&, const Eigen::VectorXd&, const E&,
                               Eigen::VectorXd&) {}
  template <class E>
  static void addInputColumns(const Model&, const Data&, const E&, size_t, Eigen::MatrixXd&) {}
  template <class E, class Emit>
  static void wrenchTangents(const Model&, const Data&, const Direction&, const E&, size_t, const Eigen::VectorXd&, Emit&&) {}
  template <class E, class Add>
  static void generalizedForceTangent(const Direction&, const E&, Add&&) {}
  template <class E>
  static double potential(const Data&, const Eigen::VectorXd&, const E&) { return 0.0; }
};

/// V = ½ k (L − x0)², L = ‖p_b − p_a‖: tension per unit length τ(L) = k (1 − x0/L) pulls a
/// toward b, τ'(L) = k x0 / L².
struct LinearSpringKind : ForceKindBase {
  static constexpr bool conservative = true;
  template <class Emit>
  static void wrenches(const Model&, Data& data, const LinearSpring& s, size_t, const Eigen::VectorXd&, Emit&& emit) {
    const Vector3d pa = pointPosition(data, s.a), pb = pointPosition(data, s.b);
    segmentWrenches(s.a.joint, s.b.joint, pa, pb, springTensionPerLength(s, (pb - pa).norm()), emit);
  }
  template <class Emit>
  static void wrenchTangents(const Model&, const Data& data, const Direction& dir, const LinearSpring& s, size_t,
                             const Eigen::VectorXd&, Emit&& emit) {
    if (!dir.moves(s.a.joint) && !dir.moves(s.b.joint)) return;
    const Vector3d pa = pointPosition(data, s.a), pb = pointPosition(data, s.b);
    const double L = (pb - pa).norm();
    segmentWrenchTangents(dir, s.a.joint, s.b.joint, pa, pb, springTensionPerLength(s, L),
                          springTensionPerLengthDerivative(s, L), emit);
  }
  static double potential(const Data& data, const Eigen::VectorXd&, const LinearSpring& s) {
    const double L = (pointPosition(data, s.b) - pointPosition(data, s.a)).norm();
    return 0.5 * s.k * (L - s.x0) * (L - s.x0);
  }
};

/// A cable of tension T = u[input] through its path points: on each segment the force T/L · d.
/// Segments within one body exert no net wrench and are skipped (model.topology().tendonSegmentPoint); a
/// direction q_k moves only the segments with an end in the subtree of k (the ancestors' rule).
/// wrenches() and addInputColumns() store the world path points in ws.tendonPoint, where
/// wrenchTangents() finds them (the linearization calls it after the nominal pass).
struct TendonKind : ForceKindBase {
  template <class Emit>
  static void wrenches(const Model& model, Data& data, const Tendon& t, size_t i, const Eigen::VectorXd& u, Emit&& emit) {
    storePoints(model, data, t, i);
    // Local pointers: the wrenches emitted below are stored through Eigen's packet types, which
    // may alias anything, so members read in the loop would be loaded again on every segment.
    const ModelTopology& topo = model.topology();
    const int* segment = topo.tendonSegmentPoint.data();
    const int* joint = topo.tendonPointJoint.data();
    const Vector3d* point = detail::workspace(data).tendonPoint.data();
    const int s0 = topo.tendonSegmentStart[i], s1 = topo.tendonSegmentStart[i + 1];
    const double T = u[t.input];
    for (int s = s0; s < s1; ++s) {
      const int a = segment[s];
      const Vector3d &pa = point[a], &pb = point[a + 1];
      segmentWrenches(joint[a], joint[a + 1], pa, pb, T / (pb - pa).norm(), emit);
    }
  }
  static void storePoints(const Model& model, Data& data, const Tendon& t, size_t i) {
    auto& ws = detail::workspace(data);
    Vector3d* p = &ws.tendonPoint[static_cast<size_t>(model.topology().tendonFirst[i])];
    for (size_t k = 0; k < t.path.size(); ++k) p[k] = pointPosition(data, t.path[k]);
  }
  static void addInputColumns(const Model& model, Data& data, const Tendon& t, size_t i, Eigen::MatrixXd& Bq) {
    auto& ws = detail::workspace(data);
    // ∂l/∂q with l = Σ L: a unit tension pulls a toward b and b toward a, Q = −(∂l/∂q)ᵀ u.
    storePoints(model, data, t, i);
    for (int s = model.topology().tendonSegmentStart[i]; s < model.topology().tendonSegmentStart[i + 1]; ++s) {
      const int a = model.topology().tendonSegmentPoint[static_cast<size_t>(s)];
      const Vector3d &pa = ws.tendonPoint[a], &pb = ws.tendonPoint[a + 1];
      const Vector3d e = (pb - pa).normalized();
      addPointGradient(model, data, model.topology().tendonPointJoint[a], pa, e, Bq.col(t.input));
      addPointGradient(model, data, model.topology().tendonPointJoint[a + 1], pb, Vector3d(-e), Bq.col(t.input));
    }
  }
  template <class Emit>
  static void wrenchTangents(const Model& model, const Data& data, const Direction& dir, const Tendon& t, size_t i,
                             const Eigen::VectorXd& u, Emit&& emit) {
    auto& ws = detail::workspace(data);
    if (model.topology().tendonJointHi[i] < dir.k || model.topology().tendonJointLo[i] >= dir.end) return;
    const double T = u[t.input];
    for (int s = model.topology().tendonSegmentStart[i]; s < model.topology().tendonSegmentStart[i + 1]; ++s) {
      const int a = model.topology().tendonSegmentPoint[static_cast<size_t>(s)];
      const int ja = model.topology().tendonPointJoint[a], jb = model.topology().tendonPointJoint[a + 1];
      if (!dir.moves(ja) && !dir.moves(jb)) continue;
      const Vector3d &pa = ws.tendonPoint[a], &pb = ws.tendonPoint[a + 1];
      const double L = (pb - pa).norm();
      segmentWrenchTangents(dir, ja, jb, pa, pb, T / L, -T / (L * L), emit);
    }
  }
};

/// w = [f; τ] in the frame's axes at its origin, each entry a constant or an input; carried
/// rigidly by its body, so δW = S_k ×* W.
struct BodyWrenchKind : ForceKindBase {
  static Vector6d local(const BodyWrench& bw, const Eigen::VectorXd& u) {
    Vector6d w;
    for (int k = 0; k < 6; ++k) w[k] = bw.input[k] >= 0 ? u[bw.input[k]] : bw.constant[k];
    return w;
  }
  template <class Emit>
  static void wrenches(const Model&, Data& data, const BodyWrench& bw, size_t, const Eigen::VectorXd& u, Emit&& emit) {
    if (bw.joint != kWorld) emit(bw.joint, bodyWrenchWorld(data, bw, local(bw, u)));
  }
  static void addInputColumns(const Model& model, const Data& data, const BodyWrench& bw, size_t, Eigen::MatrixXd& Bq) {
    auto& ws = detail::workspace(data);
    if (bw.joint == kWorld) return;
    const Eigen::Matrix3d R = ws.jointR[bw.joint] * bw.R;
    const Vector3d p = ws.jointP[bw.joint] + ws.jointR[bw.joint] * bw.p;
    for (int k = 0; k < 6; ++k) {
      if (bw.input[k] < 0) continue;
      const Vector3d e = R.col(k % 3);
      const Vector6d w = k < 3 ? forceAt(p, e) : make(Vector3d::Zero(), e);
      for (int j = bw.joint; j != kWorld; j = model.joints()[j].parent) Bq(j, bw.input[k]) += ws.S[j].dot(w);
    }
  }
  template <class Emit>
  static void wrenchTangents(const Model&, const Data& data, const Direction& dir, const BodyWrench& bw, size_t,
                             const Eigen::VectorXd& u, Emit&& emit) {
    if (dir.moves(bw.joint)) emit(bw.joint, crossForce(dir.Sk, bodyWrenchWorld(data, bw, local(bw, u))));
  }
};

/// Q[config] += u[input].
struct ConfigForceKind : ForceKindBase {
  static void generalizedForce(const Eigen::VectorXd&, const Eigen::VectorXd&, const Eigen::VectorXd& u,
                               const ConfigForce& cf, Eigen::VectorXd& Q) {
    Q[cf.config] += u[cf.input];
  }
  static void addInputColumns(const Model&, const Data&, const ConfigForce& cf, size_t, Eigen::MatrixXd& Bq) {
    Bq(cf.config, cf.input) += 1.0;
  }
};

/// V = ½ k (q_i − q0)²: Q_i = −k (q_i − q0), ∂Q_i/∂q_i = −k.
struct ConfigSpringKind : ForceKindBase {
  static constexpr bool conservative = true;
  static void generalizedForce(const Eigen::VectorXd& q, const Eigen::VectorXd&, const Eigen::VectorXd&,
                               const ConfigSpring& s, Eigen::VectorXd& Q) {
    Q[s.config] -= s.k * (q[s.config] - s.q0);
  }
  template <class Add>
  static void generalizedForceTangent(const Direction& dir, const ConfigSpring& s, Add&& add) {
    if (!dir.velocity && s.config == dir.k) add(dir.k, -s.k);
  }
  static double potential(const Data&, const Eigen::VectorXd& q, const ConfigSpring& s) {
    return 0.5 * s.k * (q[s.config] - s.q0) * (q[s.config] - s.q0);
  }
};

/// Q_i −= c_i q̇_i for every coordinate (the model's damping vector is one element).
struct DampingKind : ForceKindBase {
  static void generalizedForce(const Eigen::VectorXd&, const Eigen::VectorXd& dq, const Eigen::VectorXd&,
                               const Eigen::VectorXd& c, Eigen::VectorXd& Q) {
    Q.array() -= c.array() * dq.array();
  }
  template <class Add>
  static void generalizedForceTangent(const Direction& dir, const Eigen::VectorXd& c, Add&& add) {
    if (dir.velocity) add(dir.k, -c[dir.k]);
  }
};

/// The one visitor: f(Kind{}, element, index) for every force element of the model.
template <class F>
inline void forEachForceElement(const Model& model, F&& f) {
  for (size_t i = 0; i < model.linearSprings().size(); ++i) f(LinearSpringKind{}, model.linearSprings()[i], i);
  for (size_t i = 0; i < model.tendons().size(); ++i) f(TendonKind{}, model.tendons()[i], i);
  for (size_t i = 0; i < model.bodyWrenches().size(); ++i) f(BodyWrenchKind{}, model.bodyWrenches()[i], i);
  for (size_t i = 0; i < model.configForces().size(); ++i) f(ConfigForceKind{}, model.configForces()[i], i);
  for (size_t i = 0; i < model.configSprings().size(); ++i) f(ConfigSpringKind{}, model.configSprings()[i], i);
  f(DampingKind{}, model.damping(), size_t{0});
}

}  // namespace trellis::detail
