// The tree factorization of the mass matrix (see mass_factor.hpp for the formulation).
#include "mass_factor.hpp"
#include "packs.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>

namespace trellis::detail {
namespace {
/// The four dot products of columns (a0, a1) with (b0, b1) over len entries, in one pass:
/// out = {a0·b0, a1·b0, a0·b1, a1·b1}.
inline void dot2x2(const double* a0, const double* a1, const double* b0, const double* b1, int len, double* out) {
  Pack s00 = Pack::Zero(), s10 = Pack::Zero(), s01 = Pack::Zero(), s11 = Pack::Zero();
  int t = 0;
  for (; t + 1 < len; t += 2) {
    const Pack x0 = loadPack(a0 + t), x1 = loadPack(a1 + t), y0 = loadPack(b0 + t), y1 = loadPack(b1 + t);
    s00 += x0 * y0;
    s10 += x1 * y0;
    s01 += x0 * y1;
    s11 += x1 * y1;
  }
  out[0] = s00[0] + s00[1];
  out[1] = s10[0] + s10[1];
  out[2] = s01[0] + s01[1];
  out[3] = s11[0] + s11[1];
  for (; t < len; ++t) {
    out[0] += a0[t] * b0[t];
    out[1] += a1[t] * b0[t];
    out[2] += a0[t] * b1[t];
    out[3] += a1[t] * b1[t];
  }
}

/// LTDL of one branched block [bs, be): eliminate the leaves first. With D_k = H(k, k) and
/// L(k, i) = H(i, k) / D_k for i an ancestor of k, H(j, i) −= H(i, k) H(j, k) / D_k for j an
/// ancestor of i (or i): ancestors of k only, no fill-in.
int factorTreeBlock(const Model& model, Data& data, int bs, int be, double tol) {
  auto& ws = detail::workspace(data);
  Eigen::MatrixXd& H = ws.massFactor;
  for (int k = be - 1; k >= bs; --k) {
    const double d = H(k, k);
    if (!(d > tol)) return k;
    double* hk = &H(0, k);
    forAncestorRuns(model.topology(), k, false, [&](int s, int e) {
      for (int i = s; i <= e; ++i) {
        const double a = hk[i] / d;
        if (a == 0.0) continue;
        double* hi = &H(0, i);
        forAncestorRuns(model.topology(), i, true, [&](int s2, int e2) { subtractScaled(hi + s2, hk + s2, a, e2 - s2 + 1); });
      }
    });
    const double dInv = 1.0 / d;
    forAncestorRuns(model.topology(), k, false, [&](int s, int e) {
      for (int t = s; t <= e; ++t) hk[t] *= dInv;
    });
  }
  return -1;
}

/// Dense Cholesky M_b = L Lᵀ of an unbranched block, in place in the lower triangle, column by
/// column (left-looking): L(k:, k) = (M(k:, k) − Σ_{t<k} L(k, t) L(k:, t)) / L(k, k), the sum taken
/// two columns t per pass. Eigen's blocked LLT spends 3× the instructions at n = 40 on setting up
/// its small panels (callgrind).
int factorChainBlock(Data& data, int bs, int nb, double tol) {
  auto& ws = detail::workspace(data);
  Eigen::MatrixXd& H = ws.massFactor;
  const int be = bs + nb;
  for (int k = bs; k < be; ++k) {
    double* hk = &H(0, k) + k;
    const int len = be - k;
    int t = bs;
    for (; t + 1 < k; t += 2) subtractScaled2(hk, &H(0, t) + k, H(k, t), &H(0, t + 1) + k, H(k, t + 1), len);
    if (t < k) subtractScaled(hk, &H(0, t) + k, H(k, t), len);
    const double d = hk[0];
    if (!(d > tol)) return k;
    const double l = std::sqrt(d), r = 1.0 / l;
    hk[0] = l;
    for (int i = 1; i < len; ++i) hk[i] *= r;
  }
  return -1;
}

void solveTreeBlock(const Model& model, Data& data, double* x, int bs, int be) {
  auto& ws = detail::workspace(data);
  const Eigen::MatrixXd& H = ws.massFactor;
  // Lᵀ y = x: y_i is final once every descendant is done; it then reaches the ancestors of i.
  for (int i = be - 1; i >= bs; --i) {
    const double yi = x[i];
    if (yi == 0.0) continue;
    const double* hi = &H(0, i);
    forAncestorRuns(model.topology(), i, false, [&](int s, int e) { subtractScaled(x + s, hi + s, yi, e - s + 1); });
  }
  for (int i = bs; i < be; ++i) x[i] /= H(i, i);
  // L x = z, from the roots down.
  for (int i = bs; i < be; ++i) {
    double acc = 0.0;
    const double* hi = &H(0, i);
    forAncestorRuns(model.topology(), i, false, [&](int s, int e) { acc += dotRun(hi + s, x + s, e - s + 1); });
    x[i] -= acc;
  }
}

void invertTreeBlock(const Model& model, Data& data, int bs, int be) {
  auto& ws = detail::workspace(data);
  const Eigen::MatrixXd& H = ws.massFactor;
  Eigen::MatrixXd& W = ws.massInverseFactor;
  Eigen::MatrixXd& Minv = ws.massInverse;
  const double* dis = ws.massPivotInvSqrt.data();
  for (int i = bs; i < be; ++i) ws.massPivotInvSqrt[i] = 1.0 / std::sqrt(H(i, i));
  // Column i of W holds row i of L⁻¹: from L W = I, W_i = e_i − Σ_{a ancestor of i} L(i, a) W_a,
  // and W_a is supported on the ancestors of a (and a), so everything stays on i's ancestors.
  for (int i = bs; i < be; ++i) {
    double* wi = &W(0, i);
    for (int t = bs; t < i; ++t) wi[t] = 0.0;
    wi[i] = 1.0;
    const double* hi = &H(0, i);
    forAncestorRuns(model.topology(), i, false, [&](int s, int e) {
      for (int a = s; a <= e; ++a) {
        const double l = hi[a];
        if (l == 0.0) continue;
        const double* wa = &W(0, a);
        forAncestorRuns(model.topology(), a, true, [&](int s2, int e2) { subtractScaled(wi + s2, wa + s2, l, e2 - s2 + 1); });
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
      forAncestorRuns(model.topology(), j, true, [&](int s, int e) { v += dotRun(wi + s, wj + s, e - s + 1); });
      Minv(i, j) = v;
      Minv(j, i) = v;
    }
  }
}

/// M_b⁻¹ = L⁻ᵀ L⁻¹ from the dense factor, in plain loops on contiguous columns (Eigen's
/// triangular-solve and rank-update kernels took twice the instructions at n = 40): column j of
/// W = L⁻¹ by forward substitution in axpy form, two pivots per pass; then M⁻¹(i, j) =
/// Σ_{k ≥ i} W(k, i) W(k, j) for i ≥ j in 2×2 tiles (W is stored with its zeros above the diagonal,
/// so a tile's four sums all run from k = i).
void invertChainBlock(Data& data, int bs, int nb) {
  auto& ws = detail::workspace(data);
  const Eigen::MatrixXd& F = ws.massFactor;
  Eigen::MatrixXd& W = ws.massInverseFactor;
  Eigen::MatrixXd& Minv = ws.massInverse;
  const int be = bs + nb;
  double* r = ws.massPivotInvSqrt.data();  // workspace here: 1 / L(k, k)
  for (int k = bs; k < be; ++k) r[k] = 1.0 / F(k, k);
  for (int j = bs; j < be; ++j) {
    double* x = &W(0, j);
    for (int t = bs; t < be; ++t) x[t] = 0.0;
    x[j] = 1.0;
    int k = j;
    for (; k + 1 < be; k += 2) {
      const double* f0 = &F(0, k);
      const double* f1 = &F(0, k + 1);
      const double x0 = x[k] * r[k];
      const double x1 = (x[k + 1] - x0 * f0[k + 1]) * r[k + 1];
      x[k] = x0;
      x[k + 1] = x1;
      subtractScaled2(x + k + 2, f0 + k + 2, x0, f1 + k + 2, x1, be - k - 2);
    }
    if (k < be) x[k] *= r[k];
  }
  for (int j = bs; j < be; j += 2) {
    for (int i = j; i < be; i += 2) {
      if (i + 1 < be && j + 1 < be) {
        double v[4];
        dot2x2(&W(i, i), &W(i, i + 1), &W(i, j), &W(i, j + 1), be - i, v);
        Minv(i, j) = Minv(j, i) = v[0];
        Minv(i + 1, j) = Minv(j, i + 1) = v[1];
        Minv(i, j + 1) = Minv(j + 1, i) = v[2];
        Minv(i + 1, j + 1) = Minv(j + 1, i + 1) = v[3];
        continue;
      }
      for (int jj = j; jj < std::min(j + 2, be); ++jj)
        for (int ii = std::max(i, jj); ii < std::min(i + 2, be); ++ii) {
          const double v = dotRun(&W(ii, ii), &W(ii, jj), be - ii);
          Minv(ii, jj) = v;
          Minv(jj, ii) = v;
        }
    }
  }
}

/// M_b⁻¹ of an unbranched block from the articulated factor. Column j of M⁻¹ is the forward
/// dynamics at rest for τ = e_j; all columns at once, each joint's 6-vectors side by side in
/// ws.articulatedColumns (column j for τ = e_j), and only j ≥ i for joint i (M⁻¹ symmetric):
///   from the tip, u_i(j) = δ_ij − S_i·p_j,  p_j += U_i u_i(j) / D_i   (p: the bias of the parent),
///   from the root, M⁻¹(i, j) = (u_i(j) − U_i·a_j) / D_i,  a_j += S_i M⁻¹(i, j)   (a: the parent's).
/// One joint has one child here, so p and a are updated in place. O(n_b²) 6-vector operations
/// (three two-lane packets each) against the dense factor's n_b³/2 multiply-adds.
void invertChainArticulated(Data& data, int bs, int be) {
  auto& ws = detail::workspace(data);
  Eigen::MatrixXd& Minv = ws.massInverse;
  double* W = ws.articulatedColumns.data();  // column j at W + 6 j
  const auto dot6 = [](const Pack* x, const double* y) {
    const Pack t = x[0] * loadPack(y) + x[1] * loadPack(y + 2) + x[2] * loadPack(y + 4);
    return t[0] + t[1];
  };
  const auto axpy6 = [](double* y, const Pack* x, double a) {
    const Pack av = Pack::Constant(a);
    storePack(y, loadPack(y) + x[0] * av);
    storePack(y + 2, loadPack(y + 2) + x[1] * av);
    storePack(y + 4, loadPack(y + 4) + x[2] * av);
  };
  const auto load6 = [](const Vector6d& v, double scale, Pack* out) {
    for (int t = 0; t < 3; ++t) out[t] = loadPack(v.data() + 2 * t) * scale;
  };
  std::fill(W + 6 * bs, W + 6 * be, 0.0);
  for (int i = be - 1; i >= bs; --i) {
    Pack S[3], Ud[3];
    load6(ws.S[i], 1.0, S);
    load6(ws.articulatedU[i], 1.0 / ws.articulatedPivot[i], Ud);
    double* col = &Minv(0, i);  // u_i(j) in M⁻¹(j, i) until the second sweep
    for (int j = i; j < be; ++j) {
      double* p = W + 6 * j;
      const double uij = (j == i ? 1.0 : 0.0) - dot6(S, p);
      col[j] = uij;
      axpy6(p, Ud, uij);
    }
  }
  std::fill(W + 6 * bs, W + 6 * be, 0.0);
  for (int i = bs; i < be; ++i) {
    Pack S[3], U[3];
    load6(ws.S[i], 1.0, S);
    load6(ws.articulatedU[i], 1.0, U);
    const double dInv = 1.0 / ws.articulatedPivot[i];
    double* col = &Minv(0, i);
    for (int j = i; j < be; ++j) {
      double* a = W + 6 * j;
      const double x = (col[j] - dot6(U, a)) * dInv;
      col[j] = x;
      Minv(i, j) = x;
      axpy6(a, S, x);
    }
  }
}

/// Unbranched blocks of at least this many joints use the dense Cholesky kernels: with no
/// branching there is nothing for the tree to skip, and Eigen's blocked kernels run the O(n³)
/// work with fewer instructions than the run loops (measured with callgrind on chains of 10–40).
constexpr int kDenseChain = 6;
/// Models whose blocks are all chains, the longest of at least this many joints, take the
/// articulated factor in factorMass (the constrained models: computeDynamics takes it for every
/// chain model without constraints). Timed interleaved against the tree and dense factors
/// (bench/closed_loop_bench.cpp, the 3D chain with its tip pinned): at 5 joints the tree factor
/// is faster (1.07 against 1.16 µs for q̈), from 10 on the articulated one (1.96 against 2.12 µs;
/// 7.8 against 11.1 µs at 40); the hand's 4-joint digits keep the tree factor.
constexpr int kArticulatedChain = 8;
bool denseBlock(const Model& model, int bs, int be) {
  return be - bs >= kDenseChain && model.topology().runStart[static_cast<size_t>(be - 1)] == bs;
}
}  // namespace

/// factorArticulated, marking the factor current on success. (Out of line: inlined into
/// factorMass it cost the tree factor's path ~60 instructions per call, Panda q̈.)
static __attribute__((noinline)) int factorArticulatedCurrent(const Model& model, Data& data, double tol) {
  const int bad = factorArticulated(model, data, tol);
  detail::workspace(data).articulatedCurrent = bad < 0;
  return bad;
}

bool suitsArticulatedFactor(const Model& model) {
  int longest = 0;
  for (size_t b = 0; b + 1 < model.topology().blockStart.size(); ++b)
    longest = std::max(longest, model.topology().blockStart[b + 1] - model.topology().blockStart[b]);
  return blocksAreChains(model) && longest >= kArticulatedChain;
}

int factorMass(const Model& model, Data& data, double tol) {
  auto& ws = detail::workspace(data);
  ws.massInverseCurrent = false;
  ws.articulatedCurrent = false;
  // Long chains: the articulated factor, O(n) against the dense factor's n³/6 (mass_factor.hpp).
  if (ws.articulatedModel) return factorArticulatedCurrent(model, data, tol);
  ws.massFactor = data.M;  // zero off the ancestor pattern, as M is
  for (size_t b = 0; b + 1 < model.topology().blockStart.size(); ++b) {
    const int bs = model.topology().blockStart[b], be = model.topology().blockStart[b + 1];
    const int bad = denseBlock(model, bs, be) ? factorChainBlock(data, bs, be - bs, tol) : factorTreeBlock(model, data, bs, be, tol);
    if (bad >= 0) return bad;
  }
  return -1;
}

namespace {
/// K columns x + c stride (c < K) ← M_b⁻¹ x on the chain block [bs, be) with the articulated
/// factor, in one sweep each way (solveArticulated's recursion with one child per joint: p and a
/// are the running bias and acceleration of the parent): the columns share the loads of S_i,
/// U_i, D_i and their recursions run side by side instead of one after the other.
template <int K>
__attribute__((noinline)) void solveChainArticulated(const DataWorkspace& ws, double* x, Eigen::Index stride, int bs, int be) {
  Pack p[K][3], a[K][3];
  for (int c = 0; c < K; ++c)
    for (int t = 0; t < 3; ++t) p[c][t] = a[c][t] = Pack::Zero();
  for (int i = be - 1; i >= bs; --i) {
    const double* S = ws.S[i].data();
    const double* U = ws.articulatedU[i].data();
    const Pack S0 = loadPack(S), S1 = loadPack(S + 2), S2 = loadPack(S + 4);
    const Pack U0 = loadPack(U), U1 = loadPack(U + 2), U2 = loadPack(U + 4);
    const double dInv = 1.0 / ws.articulatedPivot[i];
    for (int c = 0; c < K; ++c) {
      const Pack d = S0 * p[c][0] + S1 * p[c][1] + S2 * p[c][2];
      const double u = x[c * stride + i] - (d[0] + d[1]);
      x[c * stride + i] = u;
      const Pack f = Pack::Constant(u * dInv);
      p[c][0] += U0 * f;
      p[c][1] += U1 * f;
      p[c][2] += U2 * f;
    }
  }
  for (int i = bs; i < be; ++i) {
    const double* S = ws.S[i].data();
    const double* U = ws.articulatedU[i].data();
    const Pack S0 = loadPack(S), S1 = loadPack(S + 2), S2 = loadPack(S + 4);
    const Pack U0 = loadPack(U), U1 = loadPack(U + 2), U2 = loadPack(U + 4);
    const double dInv = 1.0 / ws.articulatedPivot[i];
    for (int c = 0; c < K; ++c) {
      const Pack d = U0 * a[c][0] + U1 * a[c][1] + U2 * a[c][2];
      const double xi = (x[c * stride + i] - (d[0] + d[1])) * dInv;
      x[c * stride + i] = xi;
      const Pack f = Pack::Constant(xi);
      a[c][0] += S0 * f;
      a[c][1] += S1 * f;
      a[c][2] += S2 * f;
    }
  }
}
}  // namespace

namespace {
/// x ← M_b⁻¹ x, one column, on an unbranched block of NB < kDenseChain joints under the tree
/// factor (h: the block's storage from (bs, bs), column stride ld): solveTreeBlock with its one
/// run per joint (the ancestors of i are 0 … i − 1) fixed at compile time, same operations.
template <int NB>
inline void solveChainTreeBlock(const double* h, Eigen::Index ld, double* x) {
#pragma GCC unroll 8
  for (int i = NB - 1; i > 0; --i) subtractScaled(x, h + i * ld, x[i], i);
#pragma GCC unroll 8
  for (int i = 0; i < NB; ++i) x[i] /= h[i * ld + i];
#pragma GCC unroll 8
  for (int i = 1; i < NB; ++i) x[i] -= dotRun(h + i * ld, x, i);
}
/// The same on an unbranched block of nb ≥ kDenseChain joints under its dense factor L Lᵀ
/// (f: from (bs, bs)): L y = x in axpy form, then Lᵀ z = y in dot form, on contiguous columns.
/// NB > 0 fixes nb = NB at compile time, unrolled (a free body's 6: −4.7k instructions of the hand
/// with a ball's q̈, which solves 16 columns on it; the tree kernels above likewise); NB = 0 reads nb.
template <int NB>
inline void solveChainDenseBlock(const double* f, Eigen::Index ld, int nbRuntime, double* x) {
  const int nb = NB > 0 ? NB : nbRuntime;
#pragma GCC unroll 8
  for (int k = 0; k < nb; ++k) {
    const double* fk = f + k * ld;
    x[k] /= fk[k];
    subtractScaled(x + k + 1, fk + k + 1, x[k], nb - k - 1);
  }
#pragma GCC unroll 8
  for (int k = nb - 1; k >= 0; --k) x[k] = (x[k] - dotRun(f + k * ld + k + 1, x + k + 1, nb - k - 1)) / f[k * ld + k];
}
/// Every column of solveMassColumns on one block: the block's kind is looked at once, the digit
/// and ball sizes get fixed loops (the hand's contacts: 3 columns on a 4-joint digit and on the
/// 6-joint free ball each).
template <class F>
inline void forColumns(double* x, Eigen::Index stride, int cols, F&& f) {
  for (int c = 0; c < cols; ++c) f(x + c * stride);
}
}  // namespace

/// solveMassColumns with the tree and dense factors: block by block, all columns in each (only
/// the blocks inside [lo, hi): a contact's rows touch two of the hand's six).
static inline __attribute__((always_inline)) void solveFactorColumns(const Model& model, Data& data, double* x, Eigen::Index stride, int cols, int lo, int hi) {
  const ModelTopology& topo = model.topology();
  const Eigen::MatrixXd& H = detail::workspace(data).massFactor;
  const Eigen::Index ld = H.outerStride();
  for (size_t b = 0; b + 1 < topo.blockStart.size(); ++b) {
    const int bs = topo.blockStart[b], be = topo.blockStart[b + 1];
    if (be <= lo || bs >= hi) continue;
    const double* h = &H(bs, bs);
    double* xb = x + bs;
    if (topo.runStart[static_cast<size_t>(be - 1)] != bs) {
      forColumns(xb, stride, cols, [&](double* y) { solveTreeBlock(model, data, y - bs, bs, be); });
      continue;
    }
    static_assert(kDenseChain == 6, "the cases below follow denseBlock");
    switch (be - bs) {  // unbranched: the tree factor below kDenseChain joints, else the dense one
      case 1: forColumns(xb, stride, cols, [&](double* y) { solveChainTreeBlock<1>(h, ld, y); }); break;
      case 2: forColumns(xb, stride, cols, [&](double* y) { solveChainTreeBlock<2>(h, ld, y); }); break;
      case 3: forColumns(xb, stride, cols, [&](double* y) { solveChainTreeBlock<3>(h, ld, y); }); break;
      case 4: forColumns(xb, stride, cols, [&](double* y) { solveChainTreeBlock<4>(h, ld, y); }); break;
      case 5: forColumns(xb, stride, cols, [&](double* y) { solveChainTreeBlock<5>(h, ld, y); }); break;
      case 6: forColumns(xb, stride, cols, [&](double* y) { solveChainDenseBlock<6>(h, ld, 6, y); }); break;
      default: forColumns(xb, stride, cols, [&](double* y) { solveChainDenseBlock<0>(h, ld, be - bs, y); }); break;
    }
  }
}

void solveMassColumns(const Model& model, Data& data, double* x, Eigen::Index stride, int cols, int lo, int hi) {
  auto& ws = detail::workspace(data);
  if (!ws.articulatedCurrent) {
    solveFactorColumns(model, data, x, stride, cols, lo, hi);
    return;
  }
  for (size_t b = 0; b + 1 < model.topology().blockStart.size(); ++b) {
    const int bs = model.topology().blockStart[b], be = model.topology().blockStart[b + 1];
    if (be <= lo || bs >= hi) continue;
    int c = 0;
    for (; c + 3 <= cols; c += 3) solveChainArticulated<3>(ws, x + c * stride, stride, bs, be);
    if (cols - c == 2) solveChainArticulated<2>(ws, x + c * stride, stride, bs, be);
    if (cols - c == 1) solveChainArticulated<1>(ws, x + c * stride, stride, bs, be);
  }
}

void solveMassVector(const Model& model, Data& data, Eigen::Ref<Eigen::VectorXd> x, int lo, int hi) {
  solveMassColumns(model, data, x.data(), x.size(), 1, lo, hi);
}

bool blocksAreChains(const Model& model) {
  for (size_t b = 0; b + 1 < model.topology().blockStart.size(); ++b)
    if (model.topology().runStart[static_cast<size_t>(model.topology().blockStart[b + 1] - 1)] != model.topology().blockStart[b]) return false;
  return true;
}

void invertMass(const Model& model, Data& data) {
  auto& ws = detail::workspace(data);
  for (size_t b = 0; b + 1 < model.topology().blockStart.size(); ++b) {
    const int bs = model.topology().blockStart[b], be = model.topology().blockStart[b + 1];
    if (ws.articulatedCurrent) {
      invertChainArticulated(data, bs, be);
    } else if (denseBlock(model, bs, be)) {
      invertChainBlock(data, bs, be - bs);
    } else {
      invertTreeBlock(model, data, bs, be);
    }
  }
  ws.massInverseCurrent = true;
}

int factorArticulated(const Model& model, Data& data, double tol) {
  auto& ws = detail::workspace(data);
  // On a chain joint i has one child c: IA_i = I_i + IA_c − U_c U_cᵀ / D_c, carried from the tip
  // of each block to its root in one running 6×6 matrix.
  Eigen::Matrix<double, 6, 6> IA;
  for (size_t b = 0; b + 1 < model.topology().blockStart.size(); ++b) {
    const int bs = model.topology().blockStart[b], be = model.topology().blockStart[b + 1];
    IA.setZero();
    for (int i = be - 1; i >= bs; --i) {
      // + I_i = [[m E, −ĥ], [ĥ, I_O]] (applyInertia as a matrix), entry by entry.
      const Eigen::Vector3d& h = ws.wh[i];
      const double m = ws.wm[i];
      IA(0, 0) += m;
      IA(1, 1) += m;
      IA(2, 2) += m;
      IA(0, 4) += h[2];
      IA(0, 5) -= h[1];
      IA(1, 3) -= h[2];
      IA(1, 5) += h[0];
      IA(2, 3) += h[1];
      IA(2, 4) -= h[0];
      IA(3, 1) -= h[2];
      IA(3, 2) += h[1];
      IA(4, 0) += h[2];
      IA(4, 2) -= h[0];
      IA(5, 0) -= h[1];
      IA(5, 1) += h[0];
      IA.bottomRightCorner<3, 3>() += ws.wI[i];
      Vector6d& U = ws.articulatedU[i];
      U.noalias() = IA * ws.S[i];
      const double d = ws.S[i].dot(U);
      if (!(d > tol)) return i;
      ws.articulatedPivot[i] = d;
      IA.noalias() -= (U / d) * U.transpose();
    }
  }
  return -1;
}

void solveArticulated(const Model& model, Data& data, Eigen::VectorXd& x) {
  auto& ws = detail::workspace(data);
  const auto& joints = model.joints();
  const int n = model.nq();
  std::vector<Vector6d>& w = ws.articulatedWork;  // p_i from the leaves, then a_i from the roots
  for (int i = 0; i < n; ++i) w[i].setZero();
  for (int i = n - 1; i >= 0; --i) {
    const double ui = x[i] - ws.S[i].dot(w[i]);
    x[i] = ui;
    const int p = joints[i].parent;
    if (p != kWorld) w[p] += w[i] + ws.articulatedU[i] * (ui / ws.articulatedPivot[i]);
  }
  for (int i = 0; i < n; ++i) {
    const int p = joints[i].parent;
    if (p == kWorld) {
      x[i] /= ws.articulatedPivot[i];
      w[i] = ws.S[i] * x[i];
    } else {
      x[i] = (x[i] - ws.articulatedU[i].dot(w[p])) / ws.articulatedPivot[i];
      w[i] = w[p] + ws.S[i] * x[i];
    }
  }
}

void applyMassInverse(const Model& model, Data& data, Eigen::Ref<Eigen::MatrixXd> X) {
  auto& ws = detail::workspace(data);
  for (size_t b = 0; b + 1 < model.topology().blockStart.size(); ++b) {
    const int bs = model.topology().blockStart[b], nb = model.topology().blockStart[b + 1] - bs;
    if (nb <= 8) {
      // Small blocks (a digit): plain dot products with the symmetric block, column by column;
      // Eigen's product kernels cost several times the few multiply-adds here.
      double t[8];
      for (Eigen::Index c = 0; c < X.cols(); ++c) {
        double* x = &X(bs, c);
        for (int i = 0; i < nb; ++i) t[i] = dotRun(&ws.massInverse(bs, bs + i), x, nb);
        for (int i = 0; i < nb; ++i) x[i] = t[i];
      }
      continue;
    }
    auto Xb = X.middleRows(bs, nb);
    Eigen::Ref<Eigen::MatrixXd> t = ws.tmpNX.topLeftCorner(nb, X.cols());
    t.noalias() = ws.massInverse.block(bs, bs, nb, nb) * Xb;
    Xb = t;
  }
}

void applyMassInverse(const Model& model, Data& data, const Eigen::Ref<const Eigen::MatrixXd>& R, Eigen::Ref<Eigen::MatrixXd> X) {
  auto& ws = detail::workspace(data);
  for (size_t b = 0; b + 1 < model.topology().blockStart.size(); ++b) {
    const int bs = model.topology().blockStart[b], nb = model.topology().blockStart[b + 1] - bs;
    if (nb <= 8) {
      for (Eigen::Index c = 0; c < X.cols(); ++c) {
        const double* r = R.data() + c * R.outerStride() + bs;
        double* x = &X(bs, c);
        for (int i = 0; i < nb; ++i) x[i] = dotRun(&ws.massInverse(bs, bs + i), r, nb);
      }
      continue;
    }
    X.middleRows(bs, nb).noalias() = ws.massInverse.block(bs, bs, nb, nb) * R.middleRows(bs, nb);
  }
}

}  // namespace trellis::detail
