// The tree factorization of the mass matrix (see mass_factor.hpp for the formulation).
#include "mass_factor.hpp"

#include <Eigen/Cholesky>

#include <cmath>

namespace trellis::detail {
namespace {
// Plain loops for the short runs of the tree: Eigen's segment expressions spend more on setting
// up a dynamic-size operation than on the few multiply-adds of a run (measured with callgrind).
inline void subtractScaled(double* y, const double* x, double a, int len) {
  for (int t = 0; t < len; ++t) y[t] -= a * x[t];
}
inline double dotRun(const double* x, const double* y, int len) {
  double s0 = 0.0, s1 = 0.0;
  int t = 0;
  for (; t + 1 < len; t += 2) {
    s0 += x[t] * y[t];
    s1 += x[t + 1] * y[t + 1];
  }
  if (t < len) s0 += x[t] * y[t];
  return s0 + s1;
}

/// LTDL of one branched block [bs, be): eliminate the leaves first. With D_k = H(k, k) and
/// L(k, i) = H(i, k) / D_k for i an ancestor of k, H(j, i) −= H(i, k) H(j, k) / D_k for j an
/// ancestor of i (or i): ancestors of k only, no fill-in.
int factorTreeBlock(Data& data, int bs, int be, double tol) {
  Eigen::MatrixXd& H = data.massFactor;
  for (int k = be - 1; k >= bs; --k) {
    const double d = H(k, k);
    if (!(d > tol)) return k;
    double* hk = &H(0, k);
    forAncestorRuns(data, k, false, [&](int s, int e) {
      for (int i = s; i <= e; ++i) {
        const double a = hk[i] / d;
        if (a == 0.0) continue;
        double* hi = &H(0, i);
        forAncestorRuns(data, i, true, [&](int s2, int e2) { subtractScaled(hi + s2, hk + s2, a, e2 - s2 + 1); });
      }
    });
    const double dInv = 1.0 / d;
    forAncestorRuns(data, k, false, [&](int s, int e) {
      for (int t = s; t <= e; ++t) hk[t] *= dInv;
    });
  }
  return -1;
}

/// Dense Cholesky M_b = L Lᵀ of an unbranched block, in place in the lower triangle.
int factorChainBlock(Data& data, int bs, int nb, double tol) {
  Eigen::Ref<Eigen::MatrixXd> blk = data.massFactor.block(bs, bs, nb, nb);
  Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>, Eigen::Lower> llt(blk);
  if (llt.info() != Eigen::Success) return bs;
  for (int i = 0; i < nb; ++i)
    if (!(blk(i, i) * blk(i, i) > tol)) return bs + i;
  return -1;
}

void solveTreeBlock(Data& data, double* x, int bs, int be) {
  const Eigen::MatrixXd& H = data.massFactor;
  // Lᵀ y = x: y_i is final once every descendant is done; it then reaches the ancestors of i.
  for (int i = be - 1; i >= bs; --i) {
    const double yi = x[i];
    if (yi == 0.0) continue;
    const double* hi = &H(0, i);
    forAncestorRuns(data, i, false, [&](int s, int e) { subtractScaled(x + s, hi + s, yi, e - s + 1); });
  }
  for (int i = bs; i < be; ++i) x[i] /= H(i, i);
  // L x = z, from the roots down.
  for (int i = bs; i < be; ++i) {
    double acc = 0.0;
    const double* hi = &H(0, i);
    forAncestorRuns(data, i, false, [&](int s, int e) { acc += dotRun(hi + s, x + s, e - s + 1); });
    x[i] -= acc;
  }
}

void invertTreeBlock(Data& data, int bs, int be) {
  const Eigen::MatrixXd& H = data.massFactor;
  Eigen::MatrixXd& W = data.massInverseFactor;
  Eigen::MatrixXd& Minv = data.massInverse;
  const double* dis = data.massPivotInvSqrt.data();
  for (int i = bs; i < be; ++i) data.massPivotInvSqrt[i] = 1.0 / std::sqrt(H(i, i));
  // Column i of W holds row i of L⁻¹: from L W = I, W_i = e_i − Σ_{a ancestor of i} L(i, a) W_a,
  // and W_a is supported on the ancestors of a (and a), so everything stays on i's ancestors.
  for (int i = bs; i < be; ++i) {
    double* wi = &W(0, i);
    for (int t = bs; t < i; ++t) wi[t] = 0.0;
    wi[i] = 1.0;
    const double* hi = &H(0, i);
    forAncestorRuns(data, i, false, [&](int s, int e) {
      for (int a = s; a <= e; ++a) {
        const double l = hi[a];
        if (l == 0.0) continue;
        const double* wa = &W(0, a);
        forAncestorRuns(data, a, true, [&](int s2, int e2) { subtractScaled(wi + s2, wa + s2, l, e2 - s2 + 1); });
      }
    });
  }
  // G = W D^(−1/2) (column i of the storage = row i of G), then M⁻¹ = G Gᵀ: M⁻¹(i, j) is the
  // dot product of rows i and j of G over the common support, the ancestors of j (j ≤ i).
  for (int i = bs; i < be; ++i) {
    double* wi = &W(0, i);
    for (int t = bs; t <= i; ++t) wi[t] *= dis[t];
  }
  for (int j = bs; j < be; ++j) {
    const double* wj = &W(0, j);
    for (int i = j; i < be; ++i) {
      const double* wi = &W(0, i);
      double v = 0.0;
      forAncestorRuns(data, j, true, [&](int s, int e) { v += dotRun(wi + s, wj + s, e - s + 1); });
      Minv(i, j) = v;
      Minv(j, i) = v;
    }
  }
}

/// M_b⁻¹ = L⁻ᵀ L⁻¹ from the dense factor, in plain loops on contiguous columns (Eigen's
/// triangular-solve and rank-update kernels took twice the instructions at n = 40): column j of
/// L⁻¹ by forward substitution in axpy form, then M⁻¹(i, j) = Σ_{k ≥ i} L⁻¹(k, i) L⁻¹(k, j), i ≥ j.
void invertChainBlock(Data& data, int bs, int nb) {
  const Eigen::MatrixXd& F = data.massFactor;
  Eigen::MatrixXd& W = data.massInverseFactor;
  Eigen::MatrixXd& Minv = data.massInverse;
  for (int j = bs; j < bs + nb; ++j) {
    double* x = &W(0, j);
    for (int t = j; t < bs + nb; ++t) x[t] = 0.0;
    x[j] = 1.0;
    for (int k = j; k < bs + nb; ++k) {
      x[k] /= F(k, k);
      subtractScaled(x + k + 1, &F(0, k) + k + 1, x[k], bs + nb - k - 1);
    }
  }
  for (int j = bs; j < bs + nb; ++j) {
    const double* wj = &W(0, j);
    for (int i = j; i < bs + nb; ++i) {
      const double v = dotRun(&W(i, i), wj + i, bs + nb - i);
      Minv(i, j) = v;
      Minv(j, i) = v;
    }
  }
}

/// Unbranched blocks of at least this many joints use the dense Cholesky kernels: with no
/// branching there is nothing for the tree to skip, and Eigen's blocked kernels run the O(n³)
/// work with fewer instructions than the run loops (measured with callgrind on chains of 10–40).
constexpr int kDenseChain = 12;
bool denseBlock(const Data& data, int bs, int be) {
  return be - bs >= kDenseChain && data.runStart[static_cast<size_t>(be - 1)] == bs;
}
}  // namespace

int factorMass(const Model& model, Data& data, double tol) {
  (void)model;
  data.massInverseCurrent = false;
  data.massFactor = data.M;  // zero off the ancestor pattern, as M is
  for (size_t b = 0; b + 1 < data.blockStart.size(); ++b) {
    const int bs = data.blockStart[b], be = data.blockStart[b + 1];
    const int bad = denseBlock(data, bs, be) ? factorChainBlock(data, bs, be - bs, tol) : factorTreeBlock(data, bs, be, tol);
    if (bad >= 0) return bad;
  }
  return -1;
}

void solveMassVector(Data& data, Eigen::Ref<Eigen::VectorXd> x, int lo, int hi) {
  for (size_t b = 0; b + 1 < data.blockStart.size(); ++b) {
    const int bs = data.blockStart[b], be = data.blockStart[b + 1];
    if (be <= lo || bs >= hi) continue;
    if (denseBlock(data, bs, be)) {
      const auto L = data.massFactor.block(bs, bs, be - bs, be - bs).triangularView<Eigen::Lower>();
      auto xb = x.segment(bs, be - bs);
      L.solveInPlace(xb);
      L.transpose().solveInPlace(xb);
    } else {
      solveTreeBlock(data, x.data(), bs, be);
    }
  }
}

void invertMass(Data& data) {
  for (size_t b = 0; b + 1 < data.blockStart.size(); ++b) {
    const int bs = data.blockStart[b], be = data.blockStart[b + 1];
    if (denseBlock(data, bs, be)) {
      invertChainBlock(data, bs, be - bs);
    } else {
      invertTreeBlock(data, bs, be);
    }
  }
  data.massInverseCurrent = true;
}

void applyMassInverse(Data& data, Eigen::Ref<Eigen::MatrixXd> X) {
  for (size_t b = 0; b + 1 < data.blockStart.size(); ++b) {
    const int bs = data.blockStart[b], nb = data.blockStart[b + 1] - bs;
    if (nb <= 8) {
      // Small blocks (a digit): plain dot products with the symmetric block, column by column;
      // Eigen's product kernels cost several times the few multiply-adds here.
      double t[8];
      for (Eigen::Index c = 0; c < X.cols(); ++c) {
        double* x = &X(bs, c);
        for (int i = 0; i < nb; ++i) t[i] = dotRun(&data.massInverse(bs, bs + i), x, nb);
        for (int i = 0; i < nb; ++i) x[i] = t[i];
      }
      continue;
    }
    auto Xb = X.middleRows(bs, nb);
    Eigen::Ref<Eigen::MatrixXd> t = data.tmpNX.topLeftCorner(nb, X.cols());
    t.noalias() = data.massInverse.block(bs, bs, nb, nb) * Xb;
    Xb = t;
  }
}

}  // namespace trellis::detail
