// The second-order contraction of a joint tree: forward mode over the closed-form gradient of the
// linearization (see second_order_tree.hpp for the formulation).
#include "second_order_tree.hpp"

#include "adjoint_tape.hpp"  // the sweeps' build switch, shared
#include "hyper_dual.hpp"   // Vec3, Mat3, Vec6 over any scalar

#include <algorithm>
#include <cmath>
#include <vector>

namespace trellis::detail {

namespace {

#define TRELLIS_LANES_INLINE inline __attribute__((always_inline))

/// A value with L tangents (forward mode along L directions at once): g(x) = g(v) + g'(v) d.
/// The tangents are processed W at a time as vectors (W = 2: SSE2, W = 4: AVX2), loaded and
/// stored through an 8-byte aligned may_alias type (adjoint_tape.hpp: TapeChunk), so that the
/// lane loops are vector instructions in either build.
struct NoTangents {};  ///< tag: tangents left for the caller to write

template <int L, int W>
struct Lanes {
  double d[L];
  double v;
  Lanes() : d{}, v(0.0) {}
  Lanes(double value) : d{}, v(value) {}  // NOLINT: a constant has zero tangents
  Lanes(double value, NoTangents) : v(value) {}  // every lane written next (no zero fill first)
};

template <int W>
using LaneChunk = typename TapeChunk<W>::type;
/// The W lanes at x as a vector lvalue (macros, not functions: a vector passed or returned by
/// value would change the ABI between the two builds).
#if defined(__clang__)
#define TRELLIS_LANES_AT(W, x) (reinterpret_cast<typename TapeChunk<W>::Access*>(x)->v)
#define TRELLIS_LANES_AT_C(W, x) (reinterpret_cast<const typename TapeChunk<W>::Access*>(x)->v)
#else
#define TRELLIS_LANES_AT(W, x) (*reinterpret_cast<typename TapeChunk<W>::Access*>(x))
#define TRELLIS_LANES_AT_C(W, x) (*reinterpret_cast<const typename TapeChunk<W>::Access*>(x))
#endif
/// r.d = f(chunks of the operands), chunk by chunk.
#define TRELLIS_LANES_MAP(expr)                                             \
  for (int c = 0; c < L; c += W) {                                          \
    TRELLIS_LANES_AT(W, r.d + c) = (expr);                                  \
  }

template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator+(const Lanes<L, W>& a, const Lanes<L, W>& b) {
  Lanes<L, W> r(a.v + b.v, NoTangents{});
  TRELLIS_LANES_MAP(TRELLIS_LANES_AT_C(W, a.d + c) + TRELLIS_LANES_AT_C(W, b.d + c));
  return r;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator-(const Lanes<L, W>& a, const Lanes<L, W>& b) {
  Lanes<L, W> r(a.v - b.v, NoTangents{});
  TRELLIS_LANES_MAP(TRELLIS_LANES_AT_C(W, a.d + c) - TRELLIS_LANES_AT_C(W, b.d + c));
  return r;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator-(const Lanes<L, W>& a) {
  Lanes<L, W> r(-a.v, NoTangents{});
  TRELLIS_LANES_MAP(-TRELLIS_LANES_AT_C(W, a.d + c));
  return r;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator*(const Lanes<L, W>& a, const Lanes<L, W>& b) {
  Lanes<L, W> r(a.v * b.v, NoTangents{});
  TRELLIS_LANES_MAP(TRELLIS_LANES_AT_C(W, a.d + c) * b.v + a.v * TRELLIS_LANES_AT_C(W, b.d + c));
  return r;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator*(const Lanes<L, W>& a, double b) {
  Lanes<L, W> r(a.v * b, NoTangents{});
  TRELLIS_LANES_MAP(TRELLIS_LANES_AT_C(W, a.d + c) * b);
  return r;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator*(double b, const Lanes<L, W>& a) {
  return a * b;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator+(const Lanes<L, W>& a, double b) {
  Lanes<L, W> r = a;
  r.v += b;
  return r;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator+(double b, const Lanes<L, W>& a) {
  return a + b;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator-(const Lanes<L, W>& a, double b) {
  return a + (-b);
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> operator-(double b, const Lanes<L, W>& a) {
  return -a + b;
}
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W>& operator+=(Lanes<L, W>& a, const Lanes<L, W>& b) {
  a.v += b.v;
  for (int c = 0; c < L; c += W) TRELLIS_LANES_AT(W, a.d + c) = (TRELLIS_LANES_AT_C(W, a.d + c) + TRELLIS_LANES_AT_C(W, b.d + c));
  return a;
}
/// 1/√x.
template <int L, int W>
TRELLIS_LANES_INLINE Lanes<L, W> invSqrt(const Lanes<L, W>& x) {
  const double v = 1.0 / std::sqrt(x.v), dv = -0.5 * v * v * v;
  Lanes<L, W> r(v, NoTangents{});
  TRELLIS_LANES_MAP(dv * TRELLIS_LANES_AT_C(W, x.d + c));
  return r;
}
/// sin x and cos x together.
template <int L, int W>
TRELLIS_LANES_INLINE void sinCos(const Lanes<L, W>& x, Lanes<L, W>& s, Lanes<L, W>& c) {
  const double sv = std::sin(x.v), cv = std::cos(x.v);
  s.v = sv;
  c.v = cv;
  for (int i = 0; i < L; i += W) {
    TRELLIS_LANES_AT(W, s.d + i) = (cv * TRELLIS_LANES_AT_C(W, x.d + i));
    TRELLIS_LANES_AT(W, c.d + i) = (-sv * TRELLIS_LANES_AT_C(W, x.d + i));
  }
}

template <class T>
TRELLIS_LANES_INLINE Mat3<T>& operator+=(Mat3<T>& a, const Mat3<T>& b) {
  for (int j = 0; j < 3; ++j) a.c[j] += b.c[j];
  return a;
}
template <class T>
TRELLIS_LANES_INLINE T& entry(Mat3<T>& m, int r, int c) {
  return r == 0 ? m.c[c].x : (r == 1 ? m.c[c].y : m.c[c].z);
}
template <class T>
TRELLIS_LANES_INLINE const T& entry(const Mat3<T>& m, int r, int c) {
  return r == 0 ? m.c[c].x : (r == 1 ? m.c[c].y : m.c[c].z);
}

/// Spatial inertia (m, h, I about the world origin) applied to a twist: [m x_v + x_ω × h; h × x_v + I x_ω].
template <class M, class K, class X>
TRELLIS_LANES_INLINE auto applyInertia(const M& m, const Vec3<K>& h, const Mat3<K>& I, const Vec6<X>& x) {
  const auto lin = m * x.l + cross(x.a, h);
  return Vec6<decltype(lin.x)>{lin, cross(h, x.l) + I * x.a};
}
/// The angular part of D x + x ×* H (linearization.cpp: dPlusCrossAngular), H = [p; L] the
/// subtree momentum, B the 3×3 block of D. Its transpose partner D x − x ×* H (linearization.cpp:
/// dMinusCross) enters here only contracted, as ψ · (D x − x ×* H) = x_ω · (this at ψ).
template <class T, class X>
TRELLIS_LANES_INLINE Vec3<T> dPlusCrossAngular(const Vec6<T>& H, const Mat3<T>& B, const Vec6<X>& x) {
  return 2.0 * cross(x.l, H.l) + B * x.a + cross(x.a, H.a);
}
/// sin x and cos x of a plain value (the q̇ blocks' kinematics).
TRELLIS_LANES_INLINE void sinCos(double x, double& s, double& c) {
  s = std::sin(x);
  c = std::cos(x);
}

struct TreeJoint {
  int parent = kWorld, axis = 2;
  bool revolute = true;
  bool R0identity = false;  ///< R0 = E exactly (the placement only translates)
  Mat3<double> R0, inertia;  ///< placement in the parent body; rotational inertia about the origin (body axes)
  Vec3<double> p0, firstMoment;
  double mass = 0.0, subtreeMass = 0.0;
};

/// One point of a point constraint pair (the header's sites): on body `joint` at `local` (body
/// axes), entering its rows first … first + count − 1 with sign +1 (point a) or −1 (point b), the
/// rows along the world axes axis[0 … count − 1].
struct PointSite {
  int joint = kWorld, first = 0, count = 0;
  int axis[3] = {0, 0, 0};
  double sign = 1.0;
  Vec3<double> local;
};

/// One straight segment of a tendon between points on two different bodies (header: tendons).
struct TendonSegment {
  int a = kWorld, b = kWorld, input = 0;  ///< the bodies (kWorld: the world); the tension's input
  Vec3<double> localA, localB;
};

/// The world axis k (0, 1, 2) entry of x, writable.
template <class T>
TRELLIS_LANES_INLINE T& axisEntry(Vec3<T>& x, int k) {
  return k == 0 ? x.x : (k == 1 ? x.y : x.z);
}

Vec3<double> vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
Mat3<double> mat3(const Eigen::Matrix3d& m) {
  Mat3<double> r;
  for (int j = 0; j < 3; ++j) r.c[j] = vec3(m.col(j));
  return r;
}

/// R v for a constant v, with the terms of v's zero entries left out (placements along one axis,
/// first moments on one axis and diagonal inertias are common: each zero saves a lane product).
template <class T>
TRELLIS_LANES_INLINE Vec3<T> timesConstant(const Mat3<T>& R, const Vec3<double>& v) {
  const double e[3] = {v.x, v.y, v.z};
  Vec3<T> r;
  bool first = true;
  for (int j = 0; j < 3; ++j) {
    if (e[j] == 0.0) continue;
    if (first) r = e[j] * R.c[j];
    else r += e[j] * R.c[j];
    first = false;
  }
  return r;
}

/// Joint i's pose (body axes R, origin p in the world) and motion subspace S (world axes, about
/// the world origin) from its parent's pose (in R, p) and q_i; T is a plain value or lanes.
template <class T>
TRELLIS_LANES_INLINE void placeJoint(const TreeJoint& jc, const Mat3<T>* R, const Vec3<T>* p, const T& qi, Mat3<T>& Ri,
                                     Vec3<T>& pi, Vec6<T>& Si) {
  Mat3<T> Rpre;
  Vec3<T> ppre;
  if (jc.parent == kWorld) {
    for (int c = 0; c < 3; ++c) Rpre.c[c] = {T(jc.R0.c[c].x), T(jc.R0.c[c].y), T(jc.R0.c[c].z)};
    ppre = {T(jc.p0.x), T(jc.p0.y), T(jc.p0.z)};
  } else {
    if (jc.R0identity) {
      Rpre = R[jc.parent];
    } else {
      for (int c = 0; c < 3; ++c) Rpre.c[c] = timesConstant(R[jc.parent], jc.R0.c[c]);
    }
    ppre = p[jc.parent] + timesConstant(R[jc.parent], jc.p0);
  }
  const Vec3<T> e = Rpre.c[jc.axis];
  if (jc.revolute) {
    T sq, cq;
    sinCos(qi, sq, cq);
    const int a1 = (jc.axis + 1) % 3, a2 = (jc.axis + 2) % 3;
    Ri.c[jc.axis] = e;
    Ri.c[a1] = cq * Rpre.c[a1] + sq * Rpre.c[a2];
    Ri.c[a2] = (-sq) * Rpre.c[a1] + cq * Rpre.c[a2];
    pi = ppre;
    Si = {cross(ppre, e), e};
  } else {
    Ri = Rpre;
    pi = ppre + qi * e;
    Si = {e, Vec3<T>{}};
  }
}

/// Body i's inertia about the world origin: h = m p + h_B, I = I_B + m (|p|² E − p pᵀ) + 2 (p·h_B) E
/// − p h_Bᵀ − h_B pᵀ, with h_B = R h_b and I_B = R I_b Rᵀ about the body origin.
template <class T>
TRELLIS_LANES_INLINE void worldInertia(const TreeJoint& jc, const Mat3<T>& Ri, const Vec3<T>& pi, Mat3<T>& I, Vec3<T>& h) {
  const Vec3<T> hB = timesConstant(Ri, jc.firstMoment);
  Mat3<T> RI;
  for (int c = 0; c < 3; ++c) RI.c[c] = timesConstant(Ri, jc.inertia.c[c]);
  const T shift = jc.mass * dot(pi, pi) + 2.0 * dot(pi, hB);
  for (int c = 0; c < 3; ++c)
    for (int r = c; r < 3; ++r) {
      T x = component(RI.c[0], r) * component(Ri.c[0], c) + component(RI.c[1], r) * component(Ri.c[1], c) +
            component(RI.c[2], r) * component(Ri.c[2], c) - jc.mass * (component(pi, r) * component(pi, c)) -
            component(pi, r) * component(hB, c) - component(hB, r) * component(pi, c);
      if (r == c) x += shift;
      entry(I, r, c) = x;
      if (r != c) entry(I, c, r) = x;
    }
  h = jc.mass * pi + hB;
}

/// B = X + Xᵀ − 2 (h·v) E with X = I ω̂ + v hᵀ (linearization.cpp: compositePass), for the body
/// inertia (I, h) and twist v.
template <class K, class T>
TRELLIS_LANES_INLINE void momentumBlock(const Mat3<K>& I, const Vec3<K>& h, const Vec6<T>& v, Mat3<T>& B) {
  const Vec3<T>& w = v.a;
  Mat3<T> X;
  X.c[0] = w.z * I.c[1] - w.y * I.c[2] + h.x * v.l;
  X.c[1] = w.x * I.c[2] - w.z * I.c[0] + h.y * v.l;
  X.c[2] = w.y * I.c[0] - w.x * I.c[1] + h.z * v.l;
  const T hv2 = 2.0 * dot(h, v.l);
  for (int c = 0; c < 3; ++c)
    for (int r = c; r < 3; ++r) {
      T x = entry(X, r, c) + entry(X, c, r);
      if (r == c) x = x - hv2;
      entry(B, r, c) = x;
      if (r != c) entry(B, c, r) = x;
    }
}

/// x as lanes with zero tangents.
template <class T>
TRELLIS_LANES_INLINE void lift(const Vec3<double>& x, Vec3<T>& y) {
  y = {T(x.x), T(x.y), T(x.z)};
}
template <class T>
TRELLIS_LANES_INLINE void lift(const Vec6<double>& x, Vec6<T>& y) {
  lift(x.l, y.l);
  lift(x.a, y.a);
}
template <class T>
TRELLIS_LANES_INLINE void lift(const Mat3<double>& x, Mat3<T>& y) {
  for (int c = 0; c < 3; ++c) lift(x.c[c], y.c[c]);
}

/// The values (no tangents) that blocks read as constants, one plain pass per call: a q̇ block
/// reads the kinematics, inertias, ψ and β (they do not depend on q̇; μ is fixed); a q block reads
/// the per-body terms of the joints none of whose ancestors (or itself) is one of its directions
/// (their pose, twist and inertia do not depend on those q).
struct TreeValues {
  std::vector<Mat3<double>> R, I, Ic, B;          ///< pose; body inertia (world, about the origin); subtree sum; body B
  std::vector<Vec3<double>> p, h, hc;             ///< origin; body first moment; subtree sum
  std::vector<Vec6<double>> S, psi, beta, v, Iv;  ///< motion subspace; ψ; Σ_{j∈sub(k)} μ_j Ic_j S_j; twist; I v
  std::vector<Vec6<double>> vS, vIv;              ///< q̇_i v × S_i; v ×* I v
  std::vector<Vec6<double>> betaX, Spsi;           ///< β_k + Ic_k ψ_P; S_k × ψ_P (ψ_P: the parent's ψ)
  std::vector<Vec3<double>> siteP, siteG;         ///< per site: its world position; G = ±Σ μ_c,r e_r
  std::vector<Vec6<double>> sumTA;                ///< per joint: Σ T_A = Σ [G; p × G] over the sites below it

  TreeValues(int n, int sites) {
    for (auto* x : {&R, &I, &Ic, &B}) x->assign(n, Mat3<double>{});
    for (auto* x : {&p, &h, &hc}) x->assign(n, Vec3<double>{});
    for (auto* x : {&S, &psi, &beta, &v, &Iv, &vS, &vIv, &betaX, &Spsi, &sumTA}) x->assign(n, Vec6<double>{});
    for (auto* x : {&siteP, &siteG}) x->assign(sites, Vec3<double>{});
  }
  /// The sites' positions and G, and ΣT_A per joint (after compute: the poses).
  void computeSites(const std::vector<TreeJoint>& joints, const std::vector<PointSite>& sites, const double* muC) {
    const int n = static_cast<int>(joints.size());
    if (sites.empty()) return;
    for (int i = 0; i < n; ++i) sumTA[i] = Vec6<double>{};
    for (size_t s = 0; s < sites.size(); ++s) {
      const PointSite& site = sites[s];
      const int j = site.joint;
      siteP[s] = p[j] + R[j] * site.local;
      Vec3<double> G;
      for (int r = 0; r < site.count; ++r) axisEntry(G, site.axis[r]) += site.sign * muC[site.first + r];
      siteG[s] = G;
      sumTA[j] += forceAt(siteP[s], G);
    }
    for (int k = n - 1; k >= 0; --k)
      if (joints[k].parent != kWorld) sumTA[joints[k].parent] += sumTA[k];
  }
  void compute(const std::vector<TreeJoint>& joints, const double* q, const double* dq, const double* mu) {
    const int n = static_cast<int>(joints.size());
    for (int i = 0; i < n; ++i) {
      const TreeJoint& jc = joints[i];
      placeJoint(jc, R.data(), p.data(), q[i], R[i], p[i], S[i]);
      psi[i] = mu[i] * S[i];
      v[i] = dq[i] * S[i];
      if (jc.parent != kWorld) {
        psi[i] += psi[jc.parent];
        v[i] += v[jc.parent];
      }
      worldInertia(jc, R[i], p[i], I[i], h[i]);
      Iv[i] = applyInertia(jc.mass, h[i], I[i], v[i]);
      momentumBlock(I[i], h[i], v[i], B[i]);
      vS[i] = dq[i] * crossMotion(v[i], S[i]);
      vIv[i] = crossForce(v[i], Iv[i]);
      Ic[i] = I[i];
      hc[i] = h[i];
      beta[i] = Vec6<double>{};
    }
    for (int k = n - 1; k >= 0; --k) {
      beta[k] += mu[k] * applyInertia(joints[k].subtreeMass, hc[k], Ic[k], S[k]);
      const int par = joints[k].parent;
      Vec6<double> psiP;
      if (par != kWorld) psiP = psi[par];
      betaX[k] = beta[k] + applyInertia(joints[k].subtreeMass, hc[k], Ic[k], psiP);
      Spsi[k] = crossMotion(S[k], psiP);
      if (par == kWorld) continue;
      Ic[par] += Ic[k];
      hc[par] += hc[k];
      beta[par] += beta[k];
    }
  }
};

/// What one block of directions reads and writes.
struct BlockIO {
  int lanes = 0, n = 0, N = 0;
  /// The block's directions: joints dirs[0 … lanes − 1] (q or q̇ coordinates of the same index),
  /// all in one component (a subtree hanging from the world), whose joints are members[0 … count − 1]
  /// in increasing order (parents first) and whose z entries are zcols[0 … zcount − 1] (its q, its
  /// q̇, every u). Seed position: dirs[l] = members[first + l].
  const int *dirs = nullptr, *members = nullptr, *zcols = nullptr;
  int first = 0, count = 0, zcount = 0;
  const double *q = nullptr, *dq = nullptr, *qdd = nullptr, *mu = nullptr;
  /// The component's point constraint rows crows[0 … crowCount − 1], its sites siteIdx[0 …
  /// siteCount − 1] (into sites) and the members cmembers[0 … cmemberCount − 1] that have a site
  /// in their subtree (increasing order); λ and μ_c of all rows.
  const int *crows = nullptr, *siteIdx = nullptr, *cmembers = nullptr;
  int crowCount = 0, siteCount = 0, cmemberCount = 0;
  const PointSite* sites = nullptr;
  const double *lambda = nullptr, *muC = nullptr;
  /// The component's tendon segments segIdx[0 … segCount − 1] (into segments), the inputs they
  /// use inputs[0 … inputCount − 1], and u.
  const int *segIdx = nullptr, *inputs = nullptr;
  int segCount = 0, inputCount = 0;
  const TendonSegment* segments = nullptr;
  const double* u = nullptr;
  const Eigen::MatrixXd* Y = nullptr;  ///< (n + nc)×N
  Eigen::MatrixXd* rows = nullptr;     ///< N×2n
  const std::vector<TreeJoint>* joints = nullptr;
  const TreeValues* values = nullptr;  ///< the plain values (computed for this call)
  Vec3<double> gravity;
};

/// The buffers of one block of L q directions (per joint, the lanes of every quantity the pass keeps).
template <int L, int W>
struct TreePass {
  using T = Lanes<L, W>;
  std::vector<T> q, dq, qdd;
  std::vector<Mat3<T>> R, cI, B;
  std::vector<Vec3<T>> p, ch, gammaMu;
  std::vector<Vec6<T>> S, v, a, psi, fin, H, betaMu;
  std::vector<T> gq, gv, mmu;  ///< outputs: −∂φ̃/∂q_k, −∂φ̃/∂q̇_k, (M μ)_k
  std::vector<char> moving;    ///< whether joint i or an ancestor is one of the block's directions
  std::vector<char> busy;      ///< whether a joint of sub(k) moves
  std::vector<T> lam, glam;    ///< per constraint row: seeded λ; ∂φ̃/∂λ_r
  std::vector<T> gu;           ///< per input: ∂φ̃/∂u (tendon tensions)
  std::vector<Vec6<T>> cOmega, cTheta, cTPsi, cTA;  ///< the header's subtree sums over the sites

  TreePass(int n, int nc, int m) {
    gu.assign(m, T{});
    moving.assign(n, 0);
    busy.assign(n, 0);
    for (auto* x : {&q, &dq, &qdd, &gq, &gv, &mmu}) x->assign(n, T{});
    for (auto* x : {&lam, &glam}) x->assign(nc, T{});
    for (auto* x : {&R, &cI, &B}) x->assign(n, Mat3<T>{});
    for (auto* x : {&p, &ch, &gammaMu}) x->assign(n, Vec3<T>{});
    for (auto* x : {&S, &v, &a, &psi, &fin, &H, &betaMu, &cOmega, &cTheta, &cTPsi, &cTA}) x->assign(n, Vec6<T>{});
  }

  /// The point constraint terms of the header after run: each site's adjoints from its body's
  /// pose, twist, ψ and acceleration (lanes where the body moves, lifted plain values where it
  /// does not; a carries q̈'s tangents everywhere, λ its own), summed inwards over the members
  /// with a site below them, and added to −∂φ̃/∂q_k, −∂φ̃/∂q̇_k and (M μ + Aᵀ μ_c)_k; ∂φ̃/∂λ_r
  /// into glam.
  TRELLIS_LANES_INLINE void constraintTerms(const BlockIO& io) {
    const TreeValues& cv = *io.values;
    const std::vector<TreeJoint>& joints = *io.joints;
    for (int idx = 0; idx < io.cmemberCount; ++idx) {
      const int k = io.cmembers[idx];
      cOmega[k] = cTheta[k] = cTPsi[k] = cTA[k] = Vec6<T>{};
    }
    for (int r = 0; r < io.crowCount; ++r) glam[io.crows[r]] = T(0.0);
    for (int si = 0; si < io.siteCount; ++si) {
      const int sIndex = io.siteIdx[si];
      const PointSite& site = io.sites[sIndex];
      const int j = site.joint;
      Vec3<T> P;
      Vec6<T> V, Psi;
      if (moving[j]) {
        P = p[j] + timesConstant(R[j], site.local);
        V = v[j];
        Psi = psi[j];
      } else {
        lift(cv.siteP[sIndex], P);
        lift(cv.v[j], V);
        lift(cv.psi[j], Psi);
      }
      const Vec6<T>& A = a[j];
      const Vec3<double>& G = cv.siteG[sIndex];
      Vec3<T> F;
      for (int r = 0; r < site.count; ++r) axisEntry(F, site.axis[r]) = axisEntry(F, site.axis[r]) - site.sign * lam[site.first + r];
      const Vec3<T> vpsi = Psi.l + cross(Psi.a, P);  // ψ(P)
      for (int r = 0; r < site.count; ++r) glam[site.first + r] = glam[site.first + r] - site.sign * component(vpsi, site.axis[r]);
      const Vec3<T>& w = V.a;
      const Vec3<T> pdot = V.l + cross(w, P);
      const Vec3<T> Gw = cross(G, w);
      const Vec6<T> TV{Gw, cross(pdot, G) + cross(P, Gw)};
      const Vec6<T> TA = forceAt(P, G);
      const Vec6<T> TPsi = forceAt(P, F);
      const Vec3<T> Tp = cross(F, Psi.a) + cross(G, A.a) + cross(Gw, w);
      cOmega[j] += forceAt(P, Tp) + crossForce(V, TV) + crossForce(Psi, TPsi) + crossForce(A, TA);
      cTheta[j] += TV + crossForce(V, TA);
      cTPsi[j] += TPsi;
      cTA[j] += TA;
    }
    // Tendon segments (header): the point P's ψ(P) = Ψ_l + Ψ_ω × P, lanes where its body moves.
    auto pointOf = [&](int j, const Vec3<double>& local, Vec3<T>& P, Vec6<T>& Psi) {
      if (j == kWorld) {
        lift(local, P);
        Psi = Vec6<T>{};
      } else if (moving[j]) {
        P = p[j] + timesConstant(R[j], local);
        Psi = psi[j];
      } else {
        lift(cv.p[j] + cv.R[j] * local, P);
        lift(cv.psi[j], Psi);
      }
    };
    for (int ii = 0; ii < io.inputCount; ++ii) gu[io.inputs[ii]] = T(0.0);
    for (int si = 0; si < io.segCount; ++si) {
      const TendonSegment& seg = io.segments[io.segIdx[si]];
      Vec3<T> PA, PB;
      Vec6<T> PsiA, PsiB;
      pointOf(seg.a, seg.localA, PA, PsiA);
      pointOf(seg.b, seg.localB, PB, PsiB);
      const Vec3<T> d = PB - PA;
      const T invL = invSqrt(dot(d, d));
      const Vec3<T> nd = invL * d;
      const Vec3<T> E = (PsiA.l + cross(PsiA.a, PA)) - (PsiB.l + cross(PsiB.a, PB));
      const T nE = dot(nd, E);
      gu[seg.input] = gu[seg.input] - nE;
      const double tau = io.u[seg.input];
      const Vec3<T> tPE = (tau * invL) * (E - nE * nd);  // τ ∂(n·E)/∂d
      if (seg.a != kWorld) {
        const Vec3<T> F = (-tau) * nd;
        const Vec6<T> TPsi = forceAt(PA, F);
        cOmega[seg.a] += forceAt(PA, tPE + cross(F, PsiA.a)) + crossForce(PsiA, TPsi);
        cTPsi[seg.a] += TPsi;
      }
      if (seg.b != kWorld) {
        const Vec3<T> F = tau * nd;
        const Vec6<T> TPsi = forceAt(PB, F);
        cOmega[seg.b] += forceAt(PB, cross(F, PsiB.a) - tPE) + crossForce(PsiB, TPsi);
        cTPsi[seg.b] += TPsi;
      }
    }
    for (int idx = io.cmemberCount - 1; idx >= 0; --idx) {
      const int k = io.cmembers[idx];
      const int par = joints[k].parent;
      Vec6<T> Sk, vP, psiP, aP;
      if (moving[k]) {
        Sk = S[k];
        if (par != kWorld) {
          vP = v[par];
          psiP = psi[par];
        }
      } else {
        lift(cv.S[k], Sk);
        if (par != kWorld) {
          lift(cv.v[par], vP);
          lift(cv.psi[par], psiP);
        }
      }
      if (par != kWorld) aP = a[par];
      const Vec6<T> w = crossMotion(Sk, vP);
      const T dq = dot(Sk, cOmega[k]) - dot(w, cTheta[k]) - dot(crossMotion(Sk, psiP), cTPsi[k]) -
                   dot(crossMotion(Sk, aP), cTA[k]) + dot(crossMotion(w, vP), cTA[k]);
      const T ddq = dot(Sk, cTheta[k]) - 2.0 * dot(w, cTA[k]);
      gq[k] = gq[k] - dq;
      gv[k] = gv[k] - ddq;
      mmu[k] += dot(Sk, cTA[k]);
      if (par == kWorld) continue;
      cOmega[par] += cOmega[k];
      cTheta[par] += cTheta[k];
      cTPsi[par] += cTPsi[k];
      cTA[par] += cTA[k];
    }
  }

  /// Joint k's entries of the gradient, where a joint of sub(k) moves: −∂φ̃/∂q_k, −∂φ̃/∂q̇_k and
  /// (M μ)_k from the subtree sums at k, and β, γ updated for the parent's sums. X: lanes where k
  /// moves, plain values where only joints below it do (fewer lane products).
  template <class X>
  TRELLIS_LANES_INLINE void busyTerms(int k, double mk, double muk, const Vec6<X>& Sk, const Vec6<X>& vP,
                                      const Vec6<X>& psiP, const Vec6<T>& aPg) {
    const Vec6<T> IcS = applyInertia(mk, ch[k], cI[k], Sk);  // β_k
    betaMu[k] += muk * IcS;
    gammaMu[k] += muk * dPlusCrossAngular(H[k], B[k], Sk);
    const Vec6<X> w = crossMotion(Sk, vP);
    const Vec6<T> c = crossMotion(Sk, aPg) - crossMotion(w, vP);
    // With δF_q = S ×* F − Ic c + (D w − w ×* H) and δF_v = −(D S − S ×* H) − 2 Ic w (the
    // columns of linearization.cpp) contracted with ψ_P, moved onto the other factor: Ic is
    // symmetric (6×6), (m ×* f)·x = −f·(m × x), and ψ_P · (D x − x ×* H) = x_ω · Z with
    // Z = D ψ_P + ψ_P ×* H's angular part (dPlusCrossAngular; B symmetric). So one Ic ψ_P and
    // one Z serve gq, gv and (M μ)_k.
    const Vec6<T> Bm = betaMu[k] + applyInertia(mk, ch[k], cI[k], psiP);
    const Vec3<T> Gm = gammaMu[k] + dPlusCrossAngular(H[k], B[k], psiP);
    gq[k] = dot(c, Bm) - dot(w.a, Gm) + dot(crossMotion(Sk, psiP), fin[k]);
    gv[k] = 2.0 * dot(w, Bm) + dot(Sk.a, Gm);
    mmu[k] = dot(Sk, Bm);
  }

  /// The gradient pass of the header at the seeded q, q̇, q̈: one sweep outwards (kinematics,
  /// world inertias, per-body terms), one inwards (subtree sums and, as each joint's subtree is
  /// complete, its two gradient entries and (M μ)_k).
  TRELLIS_LANES_INLINE void run(const std::vector<TreeJoint>& joints, const Vec3<double>& gravity, const double* mu,
                                const TreeValues& cv, const int* members, int count) {
    for (int idx = 0; idx < count; ++idx) {
      const int i = members[idx];
      const TreeJoint& jc = joints[i];
      Vec6<T> aP;
      if (jc.parent != kWorld) aP = a[jc.parent];
      if (!moving[i]) {
        // Nothing above joint i moves in these directions: its pose, twist, inertia and momenta
        // are the plain values; only a (through q̈) and the force moving it carry tangents. (Its
        // pose, twist and ψ are lifted below if a child moves; the sums start from its inertia,
        // momentum and B.)
        lift(cv.I[i], cI[i]);
        lift(cv.h[i], ch[i]);
        lift(cv.Iv[i], H[i]);
        lift(cv.B[i], B[i]);
        a[i] = aP + qdd[i] * cv.S[i] + cv.vS[i];
        Vec6<T> ag = a[i];
        ag.l = ag.l - gravity;
        fin[i] = applyInertia(jc.mass, cv.h[i], cv.I[i], ag) + cv.vIv[i];
        betaMu[i] = Vec6<T>{};
        gammaMu[i] = Vec3<T>{};
        continue;
      }
      if (jc.parent != kWorld && !moving[jc.parent]) {
        const int par = jc.parent;
        lift(cv.R[par], R[par]);
        lift(cv.p[par], p[par]);
        lift(cv.v[par], v[par]);
        lift(cv.psi[par], psi[par]);
      }
      placeJoint(jc, R.data(), p.data(), q[i], R[i], p[i], S[i]);
      Vec6<T> vP, psiP;
      if (jc.parent != kWorld) {
        vP = v[jc.parent];
        psiP = psi[jc.parent];
      }
      v[i] = vP + dq[i] * S[i];
      a[i] = aP + qdd[i] * S[i] + dq[i] * crossMotion(v[i], S[i]);
      psi[i] = psiP + mu[i] * S[i];
      const Mat3<T>& I = cI[i];
      const Vec3<T>& h = ch[i];
      worldInertia(jc, R[i], p[i], cI[i], ch[i]);
      const Vec6<T>& vi = v[i];
      const Vec6<T> Iv = applyInertia(jc.mass, h, I, vi);
      Vec6<T> ag = a[i];
      ag.l = ag.l - gravity;
      fin[i] = applyInertia(jc.mass, h, I, ag) + crossForce(vi, Iv);
      H[i] = Iv;
      momentumBlock(I, h, vi, B[i]);
      betaMu[i] = Vec6<T>{};
      gammaMu[i] = Vec3<T>{};
    }

    const Vec6<double> g{gravity, Vec3<double>{}};
    for (int idx = count - 1; idx >= 0; --idx) {
      // The subtree sums at k are complete (its descendants have larger indices).
      const int k = members[idx];
      const TreeJoint& jc = joints[k];
      Vec6<T> aPg = jc.parent == kWorld ? Vec6<T>{} - g : a[jc.parent] - g;
      if (!busy[k]) {
        // Nothing in sub(k) moves with the block's directions: S_k, the parent's v and ψ, and the
        // subtree sums of I, I v, B, β and γ keep their plain values; only a and the inertial
        // forces move (through q̈). So −∂φ̃/∂q̇_k and (M μ)_k have no tangents, and of −∂φ̃/∂q_k
        // only c = S_k × (a_λ − g) and the S_k ×* F_k − Ic c part of δF_k move (tangents only:
        // gq's value here is not −∂φ̃/∂q_k, and only tangents are read).
        // (−ψ_P · (S ×* F − Ic c) = (S × ψ_P) · F + (Ic ψ_P) · c: TreeValues::Spsi, betaX.)
        const Vec6<T> c = crossMotion(cv.S[k], aPg);
        gq[k] = dot(c, cv.betaX[k]) + dot(cv.Spsi[k], fin[k]);
        gv[k] = T(0.0);
        mmu[k] = T(0.0);
        // The value of β that the parent's sums read. (γ's is not needed: no joint above k moves,
        // and at a joint that does not move, S and w have no tangents, so γ enters its rows
        // only through γ's tangents.)
        lift(cv.beta[k], betaMu[k]);
      } else if (moving[k]) {
        Vec6<T> vP, psiP;
        if (jc.parent != kWorld) {
          vP = v[jc.parent];
          psiP = psi[jc.parent];
        }
        busyTerms(k, jc.subtreeMass, mu[k], S[k], vP, psiP, aPg);
      } else {
        // Joints below k move, k and its ancestors do not: S_k, v_P and ψ_P are plain values.
        Vec6<double> vP, psiP;
        if (jc.parent != kWorld) {
          vP = cv.v[jc.parent];
          psiP = cv.psi[jc.parent];
        }
        busyTerms(k, jc.subtreeMass, mu[k], cv.S[k], vP, psiP, aPg);
      }
      const int par = jc.parent;
      if (par == kWorld) continue;
      ch[par] += ch[k];
      cI[par] += cI[k];
      fin[par] += fin[k];
      H[par] += H[k];
      B[par] += B[k];
      betaMu[par] += betaMu[k];
      gammaMu[par] += gammaMu[k];
    }
  }

  /// The block of q directions io.dirs (one component): seeds (e_a, Y e_a), the pass over the
  /// component's joints and sites, then the rows ∇²φ e_a = −ġ_z + Yᵀ (d/dε ∂φ̃/∂y) (the u entries
  /// of ġ: the tendons' d/dε ∂φ̃/∂u; Q is otherwise affine in u). Entries outside the component are
  /// zero: no joint of another component moves along e_a, and q̈, λ of another component do not
  /// depend on the component's q, q̇ (M and A are block diagonal by component, and the other
  /// forces the tree pass covers act on one coordinate each), so those rows of Y are not read.
  TRELLIS_LANES_INLINE void block(const BlockIO& io) {
    const int n = io.n, N = io.N;
    const Eigen::MatrixXd& Y = *io.Y;
    for (int idx = 0; idx < io.count; ++idx) {
      const int i = io.members[idx];
      const int par = (*io.joints)[i].parent;
      const int lane = idx - io.first;  // the lane seeded at joint i, if any
      moving[i] = (lane >= 0 && lane < io.lanes) || (par != kWorld && moving[par]);
      busy[i] = moving[i];
      q[i] = T(io.q[i]);
      dq[i] = T(io.dq[i]);
      qdd[i] = T(io.qdd[i]);
      for (int l = 0; l < io.lanes; ++l) {
        q[i].d[l] = l == lane ? 1.0 : 0.0;
        qdd[i].d[l] = Y(i, io.dirs[l]);
      }
    }
    for (int idx = io.count - 1; idx >= 0; --idx) {
      const int k = io.members[idx];
      const int par = (*io.joints)[k].parent;
      if (par != kWorld && busy[k]) busy[par] = 1;
    }
    for (int ri = 0; ri < io.crowCount; ++ri) {
      const int r = io.crows[ri];
      lam[r] = T(io.lambda[r]);
      for (int l = 0; l < io.lanes; ++l) lam[r].d[l] = Y(n + r, io.dirs[l]);
    }
    run(*io.joints, io.gravity, io.mu, *io.values, io.members, io.count);
    if (io.siteCount > 0 || io.segCount > 0) constraintTerms(io);
    Eigen::MatrixXd& rows = *io.rows;
    for (int l = 0; l < io.lanes; ++l) {
      double* col = rows.data() + static_cast<Eigen::Index>(io.dirs[l]) * N;
      std::fill(col, col + N, 0.0);
      for (int idx = 0; idx < io.count; ++idx) {
        const int k = io.members[idx];
        col[k] = -gq[k].d[l];
        col[n + k] = -gv[k].d[l];
      }
    }
    for (int zi = 0; zi < io.zcount; ++zi) {
      const int b = io.zcols[zi];
      LaneChunk<W> acc[L / W] = {};
      const double* y = Y.data() + static_cast<Eigen::Index>(b) * Y.rows();
      for (int idx = 0; idx < io.count; ++idx) {
        const int k = io.members[idx];
        const double yk = y[k];
        for (int c = 0; c < L / W; ++c) acc[c] += yk * TRELLIS_LANES_AT_C(W, mmu[k].d + c * W);
      }
      for (int ri = 0; ri < io.crowCount; ++ri) {  // the λ part of Yᵀ (d/dε ∂φ̃/∂y)
        const int r = io.crows[ri];
        const double yr = y[n + r];
        for (int c = 0; c < L / W; ++c) acc[c] += yr * TRELLIS_LANES_AT_C(W, glam[r].d + c * W);
      }
      double sum[L];
      for (int c = 0; c < L / W; ++c) TRELLIS_LANES_AT(W, sum + c * W) = (acc[c]);
      for (int l = 0; l < io.lanes; ++l) rows(b, io.dirs[l]) += sum[l];
    }
    for (int ii = 0; ii < io.inputCount; ++ii) {  // the tendons' d/dε ∂φ̃/∂u
      const int k = io.inputs[ii];
      for (int l = 0; l < io.lanes; ++l) rows(2 * n + k, io.dirs[l]) += gu[k].d[l];
    }
  }
};

/// The buffers of one block of L q̇ directions. Along e_a for a q̇ coordinate only twists and
/// momenta move: kinematics, inertias, ψ and β are the constants of TreeValues; M μ does not
/// move (so no Yᵀ term); and the q̇ rows of ∇²φ need no q̈ tangent (−∂r/∂q̇ holds no q̈), so no
/// acceleration or force term is computed. The block gives the (q̇, q̇) rows; the (q, q̇) rows are
/// the transpose of the q blocks' (q̇, q) rows (∇²φ is symmetric), the (u, q̇) rows are zero.
template <int L, int W>
struct VelocityPass {
  using T = Lanes<L, W>;
  std::vector<T> dq, gv;  ///< seeded q̇; output −∂φ̃/∂q̇_k
  std::vector<Mat3<T>> B;
  std::vector<Vec3<T>> gammaMu;
  std::vector<Vec6<T>> v, H, cTheta;  ///< cTheta: the header's Θ (tangents only)
  std::vector<char> moving;  ///< whether joint i or an ancestor is one of the block's directions

  VelocityPass(int n, int, int) {
    for (auto* x : {&dq, &gv}) x->assign(n, T{});
    B.assign(n, Mat3<T>{});
    gammaMu.assign(n, Vec3<T>{});
    for (auto* x : {&v, &H, &cTheta}) x->assign(n, Vec6<T>{});
    moving.assign(n, 0);
  }

  /// The point constraint terms of −∂φ̃/∂q̇_k = −(S_k·Θ − 2 w·ΣT_A) (header): T_A and S_k do not
  /// depend on q̇, T_V and w are linear in the twists (zero lanes where nothing moves: only
  /// tangents are read, as in run).
  TRELLIS_LANES_INLINE void constraintTerms(const BlockIO& io) {
    const TreeValues& cv = *io.values;
    const std::vector<TreeJoint>& joints = *io.joints;
    for (int idx = 0; idx < io.cmemberCount; ++idx) cTheta[io.cmembers[idx]] = Vec6<T>{};
    for (int si = 0; si < io.siteCount; ++si) {
      const int sIndex = io.siteIdx[si];
      const int j = io.sites[sIndex].joint;
      if (!moving[j]) continue;
      const Vec3<double>& P = cv.siteP[sIndex];
      const Vec3<double>& G = cv.siteG[sIndex];
      const Vec6<T>& V = v[j];
      const Vec3<T>& w = V.a;
      const Vec3<T> pdot = V.l + cross(w, P);
      const Vec3<T> Gw = cross(G, w);
      cTheta[j] += Vec6<T>{Gw, cross(pdot, G) + cross(P, Gw)} + crossForce(V, forceAt(P, G));
    }
    for (int idx = io.cmemberCount - 1; idx >= 0; --idx) {
      const int k = io.cmembers[idx];
      const int par = joints[k].parent;
      const Vec6<double>& Sk = cv.S[k];
      T ddq = dot(Sk, cTheta[k]);
      if (par != kWorld && moving[par]) ddq = ddq - 2.0 * dot(crossMotion(Sk, v[par]), cv.sumTA[k]);
      gv[k] = gv[k] - ddq;
      if (par != kWorld) cTheta[par] += cTheta[k];
    }
  }

  /// TreePass::run's terms of −∂φ̃/∂q̇ with everything that does not depend on q̇ taken from c.
  /// Only tangents are read, and the twists, momenta, B and w are linear in q̇: where no joint at
  /// or above i is one of the block's directions their tangents are zero, so they are set to
  /// zero rather than computed (only their values would differ, and no value is read).
  TRELLIS_LANES_INLINE void run(const std::vector<TreeJoint>& joints, const TreeValues& c, const double* mu,
                                const int* members, int count) {
    for (int idx = 0; idx < count; ++idx) {
      const int i = members[idx];
      const TreeJoint& jc = joints[i];
      gammaMu[i] = Vec3<T>{};
      if (!moving[i]) {
        v[i] = Vec6<T>{};
        H[i] = Vec6<T>{};
        B[i] = Mat3<T>{};
        continue;
      }
      v[i] = dq[i] * c.S[i];
      if (jc.parent != kWorld) v[i] += v[jc.parent];
      H[i] = applyInertia(jc.mass, c.h[i], c.I[i], v[i]);
      momentumBlock(c.I[i], c.h[i], v[i], B[i]);
    }
    for (int idx = count - 1; idx >= 0; --idx) {
      const int k = members[idx];
      const TreeJoint& jc = joints[k];
      const Vec6<double>& Sk = c.S[k];
      Vec6<double> psiP;
      if (jc.parent != kWorld) psiP = c.psi[jc.parent];
      gammaMu[k] += mu[k] * dPlusCrossAngular(H[k], B[k], Sk);
      // TreePass::run's gv, with Ic ψ_P plain (in betaX); w = S_k × v_P has no tangents where the
      // parent does not move.
      gv[k] = dot(Sk.a, gammaMu[k] + dPlusCrossAngular(H[k], B[k], psiP));
      if (jc.parent != kWorld && moving[jc.parent]) gv[k] += 2.0 * dot(crossMotion(Sk, v[jc.parent]), c.betaX[k]);
      const int par = jc.parent;
      if (par == kWorld) continue;
      H[par] += H[k];
      B[par] += B[k];
      gammaMu[par] += gammaMu[k];
    }
  }

  /// The block of q̇ directions n + io.dirs (one component): their (q̇, q̇) rows, zero outside the
  /// component, the (u, q̇) rows zero (computeRows fills the (q, q̇) rows once the q blocks are done).
  TRELLIS_LANES_INLINE void block(const BlockIO& io) {
    const int n = io.n, N = io.N;
    for (int idx = 0; idx < io.count; ++idx) {
      const int i = io.members[idx];
      const int lane = idx - io.first;
      const int par = (*io.joints)[i].parent;
      moving[i] = (lane >= 0 && lane < io.lanes) || (par != kWorld && moving[par]);
      dq[i] = T(io.dq[i]);
      for (int l = 0; l < io.lanes; ++l) dq[i].d[l] = l == lane ? 1.0 : 0.0;
    }
    run(*io.joints, *io.values, io.mu, io.members, io.count);
    if (io.siteCount > 0) constraintTerms(io);
    Eigen::MatrixXd& rows = *io.rows;
    for (int l = 0; l < io.lanes; ++l) {
      double* col = rows.data() + static_cast<Eigen::Index>(n + io.dirs[l]) * N;
      std::fill(col, col + N, 0.0);
      for (int idx = 0; idx < io.count; ++idx) {
        const int k = io.members[idx];
        col[n + k] = -gv[k].d[l];
      }
    }
  }
};

/// The passes of one kind for the block widths a model needs (L = 4, 8, 12 or 16).
template <template <int, int> class P, int W>
struct ByWidth {
  std::unique_ptr<P<4, W>> w4;
  std::unique_ptr<P<8, W>> w8;
  std::unique_ptr<P<12, W>> w12;
  std::unique_ptr<P<16, W>> w16;
  void make(int L, int n, int nc, int m) {
    if (L == 4 && !w4) w4 = std::make_unique<P<4, W>>(n, nc, m);
    if (L == 8 && !w8) w8 = std::make_unique<P<8, W>>(n, nc, m);
    if (L == 12 && !w12) w12 = std::make_unique<P<12, W>>(n, nc, m);
    if (L == 16 && !w16) w16 = std::make_unique<P<16, W>>(n, nc, m);
  }
  template <class F>
  void with(int L, F&& f) {
    if (L == 4) f(*w4);
    else if (L == 8) f(*w8);
    else if (L == 12) f(*w12);
    else f(*w16);
  }
};

/// A block, compiled for the baseline (W = 2) and, chosen when the workspace is built on a CPU
/// with AVX2 and FMA (as the tape's sweeps are), for those (W = 4; the same source; FMA
/// contraction changes results at rounding level only).
template <class P>
void blockGeneric(P& pass, const BlockIO& io) {
  pass.block(io);
}
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
template <class P>
__attribute__((target("avx2,fma"), flatten)) void blockAvx2(P& pass, const BlockIO& io) {
  pass.block(io);
}
constexpr bool kHaveAvx2Build = true;
#else
constexpr bool kHaveAvx2Build = false;
#endif

/// The q passes and the q̇ passes of one vector width.
template <int W>
struct PassSet {
  ByWidth<TreePass, W> positions;
  ByWidth<VelocityPass, W> velocities;
};

/// The block widths: 16 directions each, the last block 4, 8, 12 or 16 wide.
int blockWidth(int lanes) { return (lanes + 3) / 4 * 4; }

}  // namespace

struct TreeSecondOrderImpl {
  int n = 0, N = 0, nc = 0;
  std::vector<TreeJoint> joints;
  std::vector<PointSite> sites;  ///< the point constraint rows' points on bodies (pairs in row order)
  std::vector<TendonSegment> segments;  ///< the tendons' segments between two bodies
  Vec3<double> gravity;
  bool avx2 = false;  ///< the W = 4 build (chosen at construction)
  PassSet<2> generic;
  PassSet<4> wide;
  TreeValues values{0, 0};
  /// The components (subtrees hanging from the world, joined where a constraint row links two):
  /// their joints in increasing order, their z entries (q, q̇, then every u), their constraint
  /// rows, sites and the members with a site below them, and the blocks of up to 16 directions
  /// each, within one component.
  struct Component {
    std::vector<int> members, zcols, crows, sites, cmembers, segments, inputs;
  };
  struct Block {
    int component = 0, first = 0, lanes = 0;
  };
  std::vector<Component> components;
  std::vector<Block> blocks;
};

bool treeSecondOrderApplies(const Model& model) {
  for (const Constraint& c : model.constraints())
    if (c.type != ConstraintType::kPoint) return false;
  return model.linearSprings().empty() && model.bodyWrenches().empty();
}

namespace {
bool forceTape = false;
}
void secondOrderForceTape(bool force) { forceTape = force; }
bool secondOrderTapeForced() { return forceTape; }

TreeSecondOrder::TreeSecondOrder(const Model& model) : impl_(std::make_unique<TreeSecondOrderImpl>()) {
  TreeSecondOrderImpl& s = *impl_;
  s.n = model.nq();
  s.N = 2 * model.nq() + model.nu();
  s.nc = model.nc();
  s.joints.resize(s.n);
  for (int i = 0; i < s.n; ++i) {
    const Joint& j = model.joints()[i];
    TreeJoint& jc = s.joints[i];
    jc.parent = j.parent;
    jc.axis = j.axis;
    jc.revolute = j.revolute;
    jc.R0 = mat3(j.R0);
    jc.R0identity = j.R0 == Eigen::Matrix3d::Identity();
    jc.p0 = vec3(j.p0);
    jc.inertia = mat3(j.inertiaAtOrigin);
    jc.firstMoment = vec3(j.firstMoment);
    jc.mass = j.mass;
    jc.subtreeMass = j.mass;
  }
  for (int i = s.n - 1; i >= 0; --i)
    if (s.joints[i].parent != kWorld) s.joints[s.joints[i].parent].subtreeMass += s.joints[i].subtreeMass;
  s.gravity = vec3(model.gravity());
  s.avx2 = kHaveAvx2Build && secondOrderSweepsUseAvx2();
  // The sites: per pair of points (consecutive rows on the same two points), one site per point
  // on a body.
  const auto& cs = model.constraints();
  for (int r = 0; r < s.nc;) {
    int e = r + 1;
    while (e < s.nc && e - r < 3 && cs[e].a.joint == cs[r].a.joint && cs[e].b.joint == cs[r].b.joint &&
           cs[e].a.local == cs[r].a.local && cs[e].b.local == cs[r].b.local)
      ++e;
    for (const bool first : {true, false}) {
      const BodyPoint& bp = first ? cs[r].a : cs[r].b;
      if (bp.joint == kWorld) continue;
      PointSite site;
      site.joint = bp.joint;
      site.local = vec3(bp.local);
      site.sign = first ? 1.0 : -1.0;
      site.first = r;
      site.count = e - r;
      for (int k = r; k < e; ++k) site.axis[k - r] = cs[k].axis;
      s.sites.push_back(site);
    }
    r = e;
  }
  s.values = TreeValues(s.n, static_cast<int>(s.sites.size()));
  for (const Tendon& t : model.tendons())
    for (size_t k = 0; k + 1 < t.path.size(); ++k) {
      if (t.path[k].joint == t.path[k + 1].joint) continue;  // within one body: no net wrench
      s.segments.push_back({t.path[k].joint, t.path[k + 1].joint, t.input, vec3(t.path[k].local), vec3(t.path[k + 1].local)});
    }
  // Components: the subtrees from the world (by their root joint), joined (union-find on the
  // roots) where a row links two of them.
  std::vector<int> root(s.n), link(s.n);
  for (int i = 0; i < s.n; ++i) {
    const int par = s.joints[i].parent;
    root[i] = par == kWorld ? i : root[par];
    link[i] = i;
  }
  auto find = [&](int x) {
    while (link[x] != x) x = link[x] = link[link[x]];
    return x;
  };
  auto join = [&](int a, int b) {
    if (a == kWorld || b == kWorld) return;
    const int x = find(root[a]), y = find(root[b]);
    if (x != y) link[std::max(x, y)] = std::min(x, y);
  };
  for (const Constraint& c : cs) join(c.a.joint, c.b.joint);
  for (const TendonSegment& seg : s.segments) join(seg.a, seg.b);
  std::vector<int> componentOf(s.n, -1);
  for (int i = 0; i < s.n; ++i) {
    const int rep = find(root[i]);
    if (componentOf[rep] < 0) {
      componentOf[rep] = static_cast<int>(s.components.size());
      s.components.emplace_back();
    }
    s.components[componentOf[rep]].members.push_back(i);
  }
  auto componentOfJoint = [&](int j) { return componentOf[find(root[j])]; };
  for (int r = 0; r < s.nc; ++r) {
    const int j = cs[r].a.joint != kWorld ? cs[r].a.joint : cs[r].b.joint;
    if (j != kWorld) s.components[componentOfJoint(j)].crows.push_back(r);
  }
  std::vector<char> hasSite(s.n, 0);
  for (int si = 0; si < static_cast<int>(s.sites.size()); ++si) {
    const int j = s.sites[si].joint;
    s.components[componentOfJoint(j)].sites.push_back(si);
    for (int k = j; k != kWorld; k = s.joints[k].parent) hasSite[k] = 1;
  }
  for (int si = 0; si < static_cast<int>(s.segments.size()); ++si) {
    const TendonSegment& seg = s.segments[si];
    TreeSecondOrderImpl::Component& comp = s.components[componentOfJoint(seg.a != kWorld ? seg.a : seg.b)];
    comp.segments.push_back(si);
    if (std::find(comp.inputs.begin(), comp.inputs.end(), seg.input) == comp.inputs.end()) comp.inputs.push_back(seg.input);
    for (const int j : {seg.a, seg.b})
      for (int k = j; k != kWorld; k = s.joints[k].parent) hasSite[k] = 1;
  }
  for (int c = 0; c < static_cast<int>(s.components.size()); ++c) {
    TreeSecondOrderImpl::Component& comp = s.components[c];
    for (const int k : comp.members)
      if (hasSite[k]) comp.cmembers.push_back(k);
    comp.zcols = comp.members;
    for (const int k : comp.members) comp.zcols.push_back(s.n + k);
    for (int b = 2 * s.n; b < s.N; ++b) comp.zcols.push_back(b);
    const int count = static_cast<int>(comp.members.size());
    for (int first = 0; first < count; first += 16) s.blocks.push_back({c, first, std::min(16, count - first)});
  }
  for (const TreeSecondOrderImpl::Block& blk : s.blocks) {
    const int L = blockWidth(blk.lanes);
    if (s.avx2) {
      s.wide.positions.make(L, s.n, s.nc, s.N - 2 * s.n);
      s.wide.velocities.make(L, s.n, s.nc, s.N - 2 * s.n);
    } else {
      s.generic.positions.make(L, s.n, s.nc, s.N - 2 * s.n);
      s.generic.velocities.make(L, s.n, s.nc, s.N - 2 * s.n);
    }
  }
}
TreeSecondOrder::~TreeSecondOrder() = default;
TreeSecondOrder::TreeSecondOrder(TreeSecondOrder&&) noexcept = default;
TreeSecondOrder& TreeSecondOrder::operator=(TreeSecondOrder&&) noexcept = default;

void TreeSecondOrder::computeRows(const Model&, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                  const Eigen::VectorXd& qdd, const Eigen::VectorXd& u, const Eigen::VectorXd& lambda,
                                  const Eigen::VectorXd& mu,
                                  const Eigen::VectorXd& muC, const Eigen::MatrixXd& Y, Eigen::MatrixXd& rows) {
  TreeSecondOrderImpl& s = *impl_;
  const int n = s.n;
  s.values.compute(s.joints, q.data(), dq.data(), mu.data());
  s.values.computeSites(s.joints, s.sites, muC.data());
  BlockIO io;
  io.n = n;
  io.N = s.N;
  io.q = q.data();
  io.dq = dq.data();
  io.qdd = qdd.data();
  io.mu = mu.data();
  io.lambda = lambda.data();
  io.muC = muC.data();
  io.sites = s.sites.data();
  io.segments = s.segments.data();
  io.u = u.data();
  io.Y = &Y;
  io.rows = &rows;
  io.joints = &s.joints;
  io.values = &s.values;
  io.gravity = s.gravity;
  // The q directions (blocks of TreePass), then the q̇ directions (blocks of VelocityPass), each
  // block within one component.
  for (const bool velocity : {false, true})
    for (const TreeSecondOrderImpl::Block& blk : s.blocks) {
      const TreeSecondOrderImpl::Component& comp = s.components[blk.component];
      io.members = comp.members.data();
      io.count = static_cast<int>(comp.members.size());
      io.zcols = comp.zcols.data();
      io.zcount = static_cast<int>(comp.zcols.size());
      io.crows = comp.crows.data();
      io.crowCount = static_cast<int>(comp.crows.size());
      io.siteIdx = comp.sites.data();
      io.siteCount = static_cast<int>(comp.sites.size());
      io.cmembers = comp.cmembers.data();
      io.cmemberCount = static_cast<int>(comp.cmembers.size());
      io.segIdx = comp.segments.data();
      io.segCount = static_cast<int>(comp.segments.size());
      io.inputs = comp.inputs.data();
      io.inputCount = static_cast<int>(comp.inputs.size());
      io.first = blk.first;
      io.dirs = comp.members.data() + blk.first;
      io.lanes = blk.lanes;
      const int L = blockWidth(io.lanes);
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
      if (s.avx2) {
        auto run = [&](auto& pass) { blockAvx2(pass, io); };
        if (velocity) s.wide.velocities.with(L, run);
        else s.wide.positions.with(L, run);
        continue;
      }
#endif
      auto run = [&](auto& pass) { blockGeneric(pass, io); };
      if (velocity) s.generic.velocities.with(L, run);
      else s.generic.positions.with(L, run);
    }
  // The (q, q̇) rows: ∇²φ is symmetric, so row k of the q̇ direction n + j is row n + j of the q
  // direction k.
  for (int j = 0; j < n; ++j)
    for (int k = 0; k < n; ++k) rows(k, n + j) = rows(n + j, k);
}

}  // namespace trellis::detail
