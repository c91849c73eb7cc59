// Internal: hyper-dual numbers and the small fixed-size vector algebra the second-order residual
// pass is written in (second_order.cpp). Not installed.
//
// A hyper-dual number x = v + s ε1 + t ε2 + st ε1ε2 with ε1² = ε2² = 0 (ε1ε2 ≠ 0) carries a value,
// its derivatives along two directions and the mixed second derivative: for any smooth g,
//   g(x) = g(v) + g'(v) s ε1 + g'(v) t ε2 + (g'(v) st + g''(v) s t) ε1ε2,
// so running a computation on x = z + a ε1 + b ε2 yields ∂²/∂s∂t of its result along (a, b)
// exactly (no step, no truncation; only rounding). The vector types are templates over the
// scalar so that constants stay plain doubles (a product with a double costs 4 multiplications,
// with a hyper-dual 9).
#pragma once

#include <cmath>
#include <utility>

namespace trellis::detail {

struct HyperDual {
  double v = 0.0, s = 0.0, t = 0.0, st = 0.0;
  HyperDual() = default;
  HyperDual(double value) : v(value) {}  // NOLINT: a constant is a hyper-dual with zero parts
  HyperDual(double value, double ds, double dt, double dst) : v(value), s(ds), t(dt), st(dst) {}
};

inline HyperDual operator+(const HyperDual& a, const HyperDual& b) { return {a.v + b.v, a.s + b.s, a.t + b.t, a.st + b.st}; }
inline HyperDual operator-(const HyperDual& a, const HyperDual& b) { return {a.v - b.v, a.s - b.s, a.t - b.t, a.st - b.st}; }
inline HyperDual operator-(const HyperDual& a) { return {-a.v, -a.s, -a.t, -a.st}; }
inline HyperDual operator+(const HyperDual& a, double b) { return {a.v + b, a.s, a.t, a.st}; }
inline HyperDual operator+(double b, const HyperDual& a) { return {a.v + b, a.s, a.t, a.st}; }
inline HyperDual operator-(const HyperDual& a, double b) { return {a.v - b, a.s, a.t, a.st}; }
inline HyperDual operator-(double b, const HyperDual& a) { return {b - a.v, -a.s, -a.t, -a.st}; }
inline HyperDual operator*(const HyperDual& a, const HyperDual& b) {
  return {a.v * b.v, a.s * b.v + a.v * b.s, a.t * b.v + a.v * b.t, a.st * b.v + a.s * b.t + a.t * b.s + a.v * b.st};
}
inline HyperDual operator*(const HyperDual& a, double b) { return {a.v * b, a.s * b, a.t * b, a.st * b}; }
inline HyperDual operator*(double b, const HyperDual& a) { return {a.v * b, a.s * b, a.t * b, a.st * b}; }
inline HyperDual& operator+=(HyperDual& a, const HyperDual& b) { return a = a + b; }
inline HyperDual& operator-=(HyperDual& a, const HyperDual& b) { return a = a - b; }

/// g(x) from g(v), g'(v), g''(v) (the chain rule of the file comment).
inline HyperDual applyScalar(const HyperDual& x, double g, double g1, double g2) {
  return {g, g1 * x.s, g1 * x.t, g1 * x.st + g2 * x.s * x.t};
}
inline HyperDual inverse(const HyperDual& x) {
  const double i = 1.0 / x.v;
  return applyScalar(x, i, -i * i, 2.0 * i * i * i);
}
inline double inverse(double x) { return 1.0 / x; }
inline HyperDual operator/(const HyperDual& a, const HyperDual& b) { return a * inverse(b); }
inline HyperDual operator/(double a, const HyperDual& b) { return a * inverse(b); }
inline HyperDual operator/(const HyperDual& a, double b) { return a * (1.0 / b); }
inline HyperDual sqrt(const HyperDual& x) {
  const double r = std::sqrt(x.v);
  return applyScalar(x, r, 0.5 / r, -0.25 / (r * x.v));
}
inline HyperDual sin(const HyperDual& x) {
  const double s = std::sin(x.v), c = std::cos(x.v);
  return applyScalar(x, s, c, -s);
}
inline HyperDual cos(const HyperDual& x) {
  const double s = std::sin(x.v), c = std::cos(x.v);
  return applyScalar(x, c, -s, -c);
}
inline double value(const HyperDual& x) { return x.v; }
inline double value(double x) { return x; }

// ---- 3-vectors, 3×3 matrices (by columns) and spatial 6-vectors over any scalar -----------------

template <class T>
struct Vec3 {
  T x{}, y{}, z{};
};
template <class T>
struct Mat3 {  ///< columns
  Vec3<T> c[3];
};
template <class T>
struct Vec6 {  ///< (linear, angular), as spatial.hpp
  Vec3<T> l, a;
};

template <class A, class B>
inline auto operator+(const Vec3<A>& a, const Vec3<B>& b) {
  return Vec3<decltype(a.x + b.x)>{a.x + b.x, a.y + b.y, a.z + b.z};
}
template <class A, class B>
inline auto operator-(const Vec3<A>& a, const Vec3<B>& b) {
  return Vec3<decltype(a.x - b.x)>{a.x - b.x, a.y - b.y, a.z - b.z};
}
template <class A>
inline Vec3<A> operator-(const Vec3<A>& a) {
  return {-a.x, -a.y, -a.z};
}
template <class S, class A>
inline auto operator*(const S& s, const Vec3<A>& a) {
  return Vec3<decltype(s * a.x)>{s * a.x, s * a.y, s * a.z};
}
template <class A, class B>
inline Vec3<A>& operator+=(Vec3<A>& a, const Vec3<B>& b) {
  a.x += b.x;
  a.y += b.y;
  a.z += b.z;
  return a;
}
template <class A, class B>
inline auto dot(const Vec3<A>& a, const Vec3<B>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class A, class B>
inline auto cross(const Vec3<A>& a, const Vec3<B>& b) {
  return Vec3<decltype(a.x * b.x)>{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class A>
inline const A& component(const Vec3<A>& a, int i) {
  return i == 0 ? a.x : (i == 1 ? a.y : a.z);
}
/// R v (R by columns).
template <class A, class B>
inline auto operator*(const Mat3<A>& R, const Vec3<B>& v) {
  return v.x * R.c[0] + v.y * R.c[1] + v.z * R.c[2];
}
/// Rᵀ v.
template <class A, class B>
inline auto transposeTimes(const Mat3<A>& R, const Vec3<B>& v) {
  return Vec3<decltype(dot(R.c[0], v))>{dot(R.c[0], v), dot(R.c[1], v), dot(R.c[2], v)};
}
template <class A, class B>
inline auto operator*(const Mat3<A>& R, const Mat3<B>& C) {
  using T = decltype(dot(R.c[0], C.c[0]));
  Mat3<T> out;
  for (int j = 0; j < 3; ++j) out.c[j] = R * C.c[j];
  return out;
}

template <class A, class B>
inline auto operator+(const Vec6<A>& a, const Vec6<B>& b) {
  using T = decltype(a.l.x + b.l.x);
  return Vec6<T>{a.l + b.l, a.a + b.a};
}
template <class A, class B>
inline auto operator-(const Vec6<A>& a, const Vec6<B>& b) {
  using T = decltype(a.l.x - b.l.x);
  return Vec6<T>{a.l - b.l, a.a - b.a};
}
template <class S, class A>
inline auto operator*(const S& s, const Vec6<A>& a) {
  using T = decltype(s * a.l.x);
  return Vec6<T>{s * a.l, s * a.a};
}
template <class A, class B>
inline Vec6<A>& operator+=(Vec6<A>& a, const Vec6<B>& b) {
  a.l += b.l;
  a.a += b.a;
  return a;
}
template <class A, class B>
inline auto dot(const Vec6<A>& a, const Vec6<B>& b) {
  return dot(a.l, b.l) + dot(a.a, b.a);
}
/// m × n for twists: [ω × n_v + v × n_ω; ω × n_ω].
template <class A, class B>
inline auto crossMotion(const Vec6<A>& m, const Vec6<B>& n) {
  using T = decltype(m.l.x * n.l.x);
  return Vec6<T>{cross(m.a, n.l) + cross(m.l, n.a), cross(m.a, n.a)};
}
/// m ×* f for a twist on a wrench: [ω × f; ω × n + v × f].
template <class A, class B>
inline auto crossForce(const Vec6<A>& m, const Vec6<B>& f) {
  using T = decltype(m.l.x * f.l.x);
  return Vec6<T>{cross(m.a, f.l), cross(m.a, f.a) + cross(m.l, f.l)};
}
/// The wrench [f; p × f] of a force f at the world point p.
template <class A, class B>
inline auto forceAt(const Vec3<A>& p, const Vec3<B>& f) {
  using T = decltype(p.x * f.x);
  return Vec6<T>{Vec3<T>{T(f.x), T(f.y), T(f.z)}, cross(p, f)};
}

}  // namespace trellis::detail
