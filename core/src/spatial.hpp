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
  x.head<3>() = l;
  x.tail<3>() = a;
  return x;
}

/// The cross-product matrix: skew(a) b = a × b.
inline Eigen::Matrix3d skew(const Vector3d& a) {
  Eigen::Matrix3d m;
  m << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  return m;
}

/// m × n for twists (the Lie bracket): [ω × n_v + v × n_ω; ω × n_ω].
// (Written out entry by entry, in the order of operations of the Eigen cross products they
// replace, whose 3-vector temporaries cost about twice the instructions; these run a few times
// per joint and direction.)
inline Vector6d crossMotion(const Vector6d& m, const Vector6d& n) {
  Vector6d r;
  r[0] = (m[4] * n[2] - m[5] * n[1]) + (m[1] * n[5] - m[2] * n[4]);
  r[1] = (m[5] * n[0] - m[3] * n[2]) + (m[2] * n[3] - m[0] * n[5]);
  r[2] = (m[3] * n[1] - m[4] * n[0]) + (m[0] * n[4] - m[1] * n[3]);
  r[3] = m[4] * n[5] - m[5] * n[4];
  r[4] = m[5] * n[3] - m[3] * n[5];
  r[5] = m[3] * n[4] - m[4] * n[3];
  return r;
}

/// m ×* f for a twist acting on a wrench: [ω × f; ω × n + v × f].
inline Vector6d crossForce(const Vector6d& m, const Vector6d& f) {
  Vector6d r;
  r[0] = m[4] * f[2] - m[5] * f[1];
  r[1] = m[5] * f[0] - m[3] * f[2];
  r[2] = m[3] * f[1] - m[4] * f[0];
  r[3] = (m[4] * f[5] - m[5] * f[4]) + (m[1] * f[2] - m[2] * f[1]);
  r[4] = (m[5] * f[3] - m[3] * f[5]) + (m[2] * f[0] - m[0] * f[2]);
  r[5] = (m[3] * f[4] - m[4] * f[3]) + (m[0] * f[1] - m[1] * f[0]);
  return r;
}

/// Spatial inertia applied to a twist: [m v + ω × h; h × v + I ω].
inline Vector6d applyInertia(double m, const Vector3d& h, const Eigen::Matrix3d& I, const Vector6d& x) {
  const Vector3d Iw = I * x.tail<3>();
  Vector6d r;
  r[0] = m * x[0] + (x[4] * h[2] - x[5] * h[1]);
  r[1] = m * x[1] + (x[5] * h[0] - x[3] * h[2]);
  r[2] = m * x[2] + (x[3] * h[1] - x[4] * h[0]);
  r[3] = (h[1] * x[2] - h[2] * x[1]) + Iw[0];
  r[4] = (h[2] * x[0] - h[0] * x[2]) + Iw[1];
  r[5] = (h[0] * x[1] - h[1] * x[0]) + Iw[2];
  return r;
}

/// Velocity of the world point p moving with twist m: v + ω × p.
inline Vector3d pointVelocity(const Vector6d& m, const Vector3d& p) { return lin(m) + ang(m).cross(p); }

/// Wrench of a force f applied at the world point p: [f; p × f].
inline Vector6d forceAt(const Vector3d& p, const Vector3d& f) { return make(f, p.cross(f)); }

}  // namespace trellis::spatial
