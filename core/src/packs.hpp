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

}  // namespace trellis::detail
