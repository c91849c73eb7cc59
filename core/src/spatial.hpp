// Internal: spatial-vector algebra in world axes at the world origin, ordering (linear, angular).
// Twists m = [v; ω], wrenches f = [f; n]. Rigid-body inertia as (mass, h = m c, I about origin).
#pragma once

#include "trellis/core/model.hpp"

namespace trellis::spatial {

using Eigen::Vector3d;

inline Vector3d lin(const Vector6d& x) { return x.head<3>(); }
inline Vector3d ang(const Vector6d& x) { return x.tail<3>(); }

inline Vector6d make(const Vector3d& l, const Vector3d& a) {
  Vector6d x;
  x << l, a;
  return x;
}

/// The cross-product matrix: skew(a) b = a × b.
inline Eigen::Matrix3d skew(const Vector3d& a) {
  Eigen::Matrix3d m;
  m << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  return m;
}

/// m × n for twists (the Lie bracket): [ω × n_v + v × n_ω; ω × n_ω].
inline Vector6d crossMotion(const Vector6d& m, const Vector6d& n) {
  const Vector3d v = lin(m), w = ang(m), nv = lin(n), nw = ang(n);
  return make(w.cross(nv) + v.cross(nw), w.cross(nw));
}

/// m ×* f for a twist acting on a wrench: [ω × f; ω × n + v × f].
inline Vector6d crossForce(const Vector6d& m, const Vector6d& f) {
  const Vector3d v = lin(m), w = ang(m), ff = lin(f), fn = ang(f);
  return make(w.cross(ff), w.cross(fn) + v.cross(ff));
}

/// Spatial inertia applied to a twist: [m v + ω × h; h × v + I ω].
inline Vector6d applyInertia(double m, const Vector3d& h, const Eigen::Matrix3d& I, const Vector6d& x) {
  const Vector3d v = lin(x), w = ang(x);
  return make(m * v + w.cross(h), h.cross(v) + I * w);
}

/// Velocity of the world point p moving with twist m: v + ω × p.
inline Vector3d pointVelocity(const Vector6d& m, const Vector3d& p) { return lin(m) + ang(m).cross(p); }

/// Wrench of a force f applied at the world point p: [f; p × f].
inline Vector6d forceAt(const Vector3d& p, const Vector3d& f) { return make(f, p.cross(f)); }

}  // namespace trellis::spatial
