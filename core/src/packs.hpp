// Internal: plain loops on two-lane packets (Eigen::Array2d: one SSE2/NEON register, or two
// scalars) for the short runs of numbers the tree and constraint kernels walk (mass_factor.cpp,
// dynamics.cpp): Eigen's dynamic-size segment expressions spend more on setting up than on the few
// multiply-adds of a digit's run, and GCC leaves the scalar reductions unvectorized without
// -ffast-math (the lane order below is fixed, so results do not depend on the build).
#pragma once

#include <Eigen/Core>

namespace trellis::detail {

using Pack = Eigen::Array2d;
inline Pack loadPack(const double* x) { return Eigen::Map<const Pack>(x); }
inline void storePack(double* y, const Pack& v) {
  Eigen::Map<Pack> m(y);
  m = v;
}

/// x·y over len entries.
inline double dotRun(const double* x, const double* y, int len) {
  Pack s0 = Pack::Zero(), s1 = Pack::Zero();
  int t = 0;
  for (; t + 3 < len; t += 4) {
    s0 += loadPack(x + t) * loadPack(y + t);
    s1 += loadPack(x + t + 2) * loadPack(y + t + 2);
  }
  s0 += s1;
  double s = s0[0] + s0[1];
  for (; t < len; ++t) s += x[t] * y[t];
  return s;
}

/// y −= a x over len entries.
inline void subtractScaled(double* y, const double* x, double a, int len) {
  const Pack av = Pack::Constant(a);
  int t = 0;
  for (; t + 3 < len; t += 4) {
    storePack(y + t, loadPack(y + t) - av * loadPack(x + t));
    storePack(y + t + 2, loadPack(y + t + 2) - av * loadPack(x + t + 2));
  }
  for (; t < len; ++t) y[t] -= a * x[t];
}
/// y −= a0 x0 + a1 x1 over len entries (two columns per pass over y).
inline void subtractScaled2(double* y, const double* x0, double a0, const double* x1, double a1, int len) {
  const Pack a0v = Pack::Constant(a0), a1v = Pack::Constant(a1);
  int t = 0;
  for (; t + 1 < len; t += 2) storePack(y + t, loadPack(y + t) - a0v * loadPack(x0 + t) - a1v * loadPack(x1 + t));
  for (; t < len; ++t) y[t] -= a0 * x0[t] + a1 * x1[t];
}

}  // namespace trellis::detail
