// Exact second derivatives of the constrained dynamics (see second_order.hpp for the formulation).
//
// The residual F = [r; c] is evaluated here by its own recursive pass, templated on the scalar
// (hyper_dual.hpp), from the Model's public description and nothing else: joint kinematics from
// the world outwards, the external wrenches of every force element and of the constraint forces
// at fixed λ, the Newton-Euler subtree sums inwards, the forces that act on coordinates, and the
// constraint accelerations c = A q̈ + Ȧ q̇. It is the computation dynamics.cpp performs (same
// formulas, same constraint forms), so at double precision r and c vanish at the solved q̈, λ —
// and in hyper-dual arithmetic it yields G[a, b] of the header exactly.
#include "trellis/core/second_order.hpp"

#include "trellis/core/linearization.hpp"
#include "adjoint_tape.hpp"
#include "internal.hpp"
#include "hyper_dual.hpp"
#include "second_order_tree.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace trellis {
namespace detail {

namespace {

Vec3<double> vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
Mat3<double> mat3(const Eigen::Matrix3d& m) {
  Mat3<double> r;
  for (int j = 0; j < 3; ++j) r.c[j] = vec3(m.col(j));
  return r;
}
template <class T, class U>
Vec3<T> lift(const Vec3<U>& v) {
  return {T(v.x), T(v.y), T(v.z)};
}
template <class T, class U>
Mat3<T> lift(const Mat3<U>& m) {
  Mat3<T> r;
  for (int j = 0; j < 3; ++j) r.c[j] = lift<T>(m.c[j]);
  return r;
}

}  // namespace

/// The constants of one joint in the fixed-size types of the pass.
struct JointConstants {
  int parent = kWorld, axis = 2;
  bool revolute = true;
  Mat3<double> R0, inertia;  ///< placement in the parent body; rotational inertia about the origin
  Vec3<double> p0, firstMoment;
  double mass = 0.0;
};

/// The residual pass over scalar T: inputs q, dq, qdd (n), u (m), lambda (nc); outputs r (n), c (nc).
template <class T>
struct ResidualPass {
  std::vector<T> q, dq, qdd, u, lambda, r, c;
  std::vector<Mat3<T>> R;
  std::vector<Vec3<T>> p;
  std::vector<Vec6<T>> S, v, a, f;

  void resize(int n, int m, int nc) {
    for (auto* x : {&q, &dq, &qdd, &r}) x->assign(n, T{});
    u.assign(m, T{});
    lambda.assign(nc, T{});
    c.assign(nc, T{});
    R.assign(n, Mat3<T>{});
    p.assign(n, Vec3<T>{});
    for (auto* x : {&S, &v, &a, &f}) x->assign(n, Vec6<T>{});
  }

  struct Point {
    Vec3<T> p, v, a;
  };

  Vec3<T> position(const BodyPoint& bp) const {
    if (bp.joint == kWorld) return lift<T>(vec3(bp.local));
    return p[bp.joint] + R[bp.joint] * vec3(bp.local);
  }
  /// ṗ = v + ω × p, p̈ = a_v + α × p + ω × ṗ.
  Point kinematics(const BodyPoint& bp) const {
    Point k{position(bp), {}, {}};
    if (bp.joint == kWorld) return k;
    const Vec6<T>&vj = v[bp.joint], &aj = a[bp.joint];
    k.v = vj.l + cross(vj.a, k.p);
    k.a = aj.l + cross(aj.a, k.p) + cross(vj.a, k.v);
    return k;
  }
  /// A direction d fixed on body `joint`: n = R d, ṅ = ω × n, n̈ = α × n + ω × ṅ.
  Point direction(int joint, const Eigen::Vector3d& local) const {
    if (joint == kWorld) return {lift<T>(vec3(local)), {}, {}};
    Point k;
    k.p = R[joint] * vec3(local);
    k.v = cross(v[joint].a, k.p);
    k.a = cross(a[joint].a, k.p) + cross(v[joint].a, k.v);
    return k;
  }
  void addWrench(int joint, const Vec6<T>& w) {
    if (joint != kWorld) f[joint] = f[joint] - w;  // f holds −F_ext until the inertial terms are added
  }
  /// Equal and opposite forces τ d on a, −τ d on b, d = p_b − p_a.
  void addSegment(int ja, int jb, const Vec3<T>& pa, const Vec3<T>& pb, const T& tau) {
    const Vec3<T> force = tau * (pb - pa);
    addWrench(ja, forceAt(pa, force));
    addWrench(jb, forceAt(pb, -force));
  }

  /// The inertial wrench of joint i's body, I (a − g) + v ×* I v at the world origin, evaluated in
  /// the body's axes about its origin, where the inertia is constant (h = m c, I about the origin:
  /// f = [m x_v + x_ω × h; h × x_v + I x_ω]): the twists go in as x_b = (Rᵀ (x_v + x_ω × p), Rᵀ x_ω),
  /// the wrench comes back as [R f; R n + p × R f]. (The same quantity as the world-axes form with
  /// I_world = R I Rᵀ + parallel-axis terms, in fewer operations: two rotations per twist instead
  /// of the world inertia applied twice.)
  Vec6<T> inertialWrench(const JointConstants& jc, int i, const Vec6<T>& acc, const Vec6<T>& vel) const {
    const Mat3<T>& Ri = R[i];
    const Vec3<T>& pi = p[i];
    auto toBody = [&](const Vec6<T>& x) {
      return Vec6<T>{transposeTimes(Ri, x.l + cross(x.a, pi)), transposeTimes(Ri, x.a)};
    };
    auto inertia = [&](const Vec6<T>& x) {
      return Vec6<T>{jc.mass * x.l + cross(x.a, jc.firstMoment), cross(jc.firstMoment, x.l) + jc.inertia * x.a};
    };
    const Vec6<T> vb = toBody(vel);
    const Vec6<T> fb = inertia(toBody(acc)) + crossForce(vb, inertia(vb));
    const Vec3<T> force = Ri * fb.l;
    return {force, Ri * fb.a + cross(pi, force)};
  }

  void evaluate(const Model& model, const std::vector<JointConstants>& jcs, const Vec3<double>& gravity) {
    const int n = model.nq();
    // Joint kinematics (kinematics.cpp: updateJoints) and accelerations a = a_p + S q̈ + (v × S) q̇.
    for (int i = 0; i < n; ++i) {
      const JointConstants& jc = jcs[i];
      Mat3<T> Rpre;
      Vec3<T> ppre;
      Vec6<T> vParent, aParent;
      if (jc.parent == kWorld) {
        Rpre = lift<T>(jc.R0);
        ppre = lift<T>(jc.p0);
      } else {
        Rpre = R[jc.parent] * jc.R0;
        ppre = p[jc.parent] + R[jc.parent] * jc.p0;
        vParent = v[jc.parent];
        aParent = a[jc.parent];
      }
      const Vec3<T> e = Rpre.c[jc.axis];
      if (jc.revolute) {
        const T cq = cos(q[i]), sq = sin(q[i]);
        const int a1 = (jc.axis + 1) % 3, a2 = (jc.axis + 2) % 3;
        R[i].c[jc.axis] = e;
        R[i].c[a1] = cq * Rpre.c[a1] + sq * Rpre.c[a2];
        R[i].c[a2] = (-sq) * Rpre.c[a1] + cq * Rpre.c[a2];
        p[i] = ppre;
        S[i] = {cross(ppre, e), e};
      } else {
        R[i] = Rpre;
        p[i] = ppre + q[i] * e;
        S[i] = {e, Vec3<T>{}};
      }
      v[i] = vParent + dq[i] * S[i];
      a[i] = aParent + qdd[i] * S[i] + dq[i] * crossMotion(v[i], S[i]);
      f[i] = Vec6<T>{};
    }
    // External wrenches (force_elements.hpp), collected negated in f.
    for (const LinearSpring& s : model.linearSprings()) {
      const Vec3<T> pa = position(s.a), pb = position(s.b);
      const T L = sqrt(dot(pb - pa, pb - pa));
      addSegment(s.a.joint, s.b.joint, pa, pb, s.k * (1.0 - s.x0 / L));
    }
    for (const Tendon& t : model.tendons()) {
      const T& tension = u[t.input];
      for (size_t k = 0; k + 1 < t.path.size(); ++k) {
        if (t.path[k].joint == t.path[k + 1].joint) continue;  // within one body: no net wrench
        const Vec3<T> pa = position(t.path[k]), pb = position(t.path[k + 1]);
        addSegment(t.path[k].joint, t.path[k + 1].joint, pa, pb, tension / sqrt(dot(pb - pa, pb - pa)));
      }
    }
    for (const BodyWrench& bw : model.bodyWrenches()) {
      if (bw.joint == kWorld) continue;
      Vec3<T> fl, tl;  // the wrench in the frame's axes
      for (int k = 0; k < 6; ++k) {
        const T entry = bw.input[k] >= 0 ? u[bw.input[k]] : T(bw.constant[k]);
        T& slot = k < 3 ? (k == 0 ? fl.x : (k == 1 ? fl.y : fl.z)) : (k == 3 ? tl.x : (k == 4 ? tl.y : tl.z));
        slot = entry;
      }
      const Mat3<T> Rf = R[bw.joint] * mat3(bw.R);
      const Vec3<T> pf = p[bw.joint] + R[bw.joint] * vec3(bw.p);
      const Vec3<T> force = Rf * fl;
      addWrench(bw.joint, Vec6<T>{force, cross(pf, force) + Rf * tl});
    }
    // Constraint forces Aᵀλ as point forces (constraint_kinds.hpp: forces()).
    const auto& cs = model.constraints();
    for (int k = 0; k < model.nc(); ++k) {
      const Constraint& con = cs[k];
      const T& lam = lambda[k];
      switch (con.type) {
        case ConstraintType::kDistance: {
          const Vec3<T> pa = position(con.a), pb = position(con.b);
          const Vec3<T> g = (2.0 * lam) * (pa - pb);
          addWrench(con.a.joint, forceAt(pa, g));
          addWrench(con.b.joint, forceAt(pb, -g));
          break;
        }
        case ConstraintType::kPoint: {
          Vec3<T> g;
          (con.axis == 0 ? g.x : (con.axis == 1 ? g.y : g.z)) = lam;
          addWrench(con.a.joint, forceAt(position(con.a), g));
          addWrench(con.b.joint, forceAt(position(con.b), -g));
          break;
        }
        case ConstraintType::kPointOnPlane: {
          const Vec3<T> pb = position(con.b);
          const Vec3<T> g = lam * direction(con.a.joint, con.direction).p;
          addWrench(con.a.joint, forceAt(pb, g));
          addWrench(con.b.joint, forceAt(pb, -g));
          break;
        }
        case ConstraintType::kKnifeEdge:
          addWrench(con.a.joint, forceAt(position(con.a), lam * direction(con.a.joint, con.direction).p));
          break;
        case ConstraintType::kCoordinateCoupling:
          break;  // generalized forces on two coordinates: added to r below
      }
    }
    // Newton-Euler: F_i = I (a − g) + v ×* I v − F_ext, then subtree sums; r_i = S_i · F_i.
    for (int i = 0; i < n; ++i) {
      Vec6<T> ag = a[i];
      ag.l = ag.l - gravity;
      f[i] += inertialWrench(jcs[i], i, ag, v[i]);
    }
    for (int i = n - 1; i >= 0; --i) {
      r[i] = dot(S[i], f[i]);
      if (jcs[i].parent != kWorld) f[jcs[i].parent] += f[i];
    }
    // Forces on coordinates enter r = ID − Q with a minus sign.
    for (const ConfigForce& cf : model.configForces()) r[cf.config] -= u[cf.input];
    for (int k = 0; k < model.nc(); ++k) {  // a coupling's Aᵀλ: λ on q_j, −m λ on q_i
      const Constraint& con = cs[k];
      if (con.type != ConstraintType::kCoordinateCoupling) continue;
      r[con.a.joint] -= lambda[k];
      r[con.b.joint] += con.coupling.multiplier * lambda[k];
    }
    for (const ConfigSpring& s : model.configSprings()) r[s.config] += s.k * (q[s.config] - s.q0);
    const Eigen::VectorXd& damping = model.damping();
    for (int i = 0; i < std::min<int>(n, static_cast<int>(damping.size())); ++i)
      if (damping[i] != 0.0) r[i] += damping[i] * dq[i];
    // Constraint accelerations c = A q̈ + Ȧ q̇ (constraint_kinds.hpp: value().c).
    for (int k = 0; k < model.nc(); ++k) {
      const Constraint& con = cs[k];
      switch (con.type) {
        case ConstraintType::kDistance: {
          const Point pa = kinematics(con.a), pb = kinematics(con.b);
          const Vec3<T> d = pa.p - pb.p, dd = pa.v - pb.v, ddd = pa.a - pb.a;
          c[k] = 2.0 * dot(dd, dd) + 2.0 * dot(d, ddd);
          break;
        }
        case ConstraintType::kPoint:
          c[k] = component(kinematics(con.a).a - kinematics(con.b).a, con.axis);
          break;
        case ConstraintType::kPointOnPlane: {
          const Point pa = kinematics(con.a), pb = kinematics(con.b), nk = direction(con.a.joint, con.direction);
          const Vec3<T> d = pa.p - pb.p, dd = pa.v - pb.v, ddd = pa.a - pb.a;
          c[k] = dot(nk.a, d) + 2.0 * dot(nk.v, dd) + dot(nk.p, ddd);
          break;
        }
        case ConstraintType::kKnifeEdge: {
          const Point pa = kinematics(con.a), nk = direction(con.a.joint, con.direction);
          c[k] = dot(nk.v, pa.v) + dot(nk.p, pa.a);
          break;
        }
        case ConstraintType::kCoordinateCoupling:
          c[k] = qdd[con.a.joint] - con.coupling.multiplier * qdd[con.b.joint];
          break;
      }
    }
  }
};

namespace {

/// One block of L = 4, 8 or 16 directions: the tangent and second-order reverse sweeps
/// (adjoint_tape.hpp), then the block's rows of ∇²φ, out(b, l) = x̄̇_z(b, l) + Σ_i Y(i, b) x̄̇_y(i, l)
/// (N rows of L lanes; Y is (ny = n + nc)×N, by columns), then the input rows of x̄̇ cleared (the
/// sweep cleared the others: x̄̇ is zero again for the next block). Compiled for the baseline and,
/// chosen at run time when the CPU has them, for AVX2 and FMA (the same source; FMA contraction
/// changes results at rounding level only).
struct BlockArgs {
  const Tape* tape;
  int inputs, N, ny;
  const double* xbar;
  const double* Y;
  double *xdot, *xdotbar, *out;
};
template <int W, int L>
TRELLIS_TAPE_INLINE void sweepBlockBody(const BlockArgs& b) {
  using V = typename TapeChunk<W>::type;
  tangentSweepLanesBody<W, L>(*b.tape, b.inputs, b.xdot);
  secondOrderReverseSweepLanesBody<W, L>(*b.tape, b.inputs, b.xbar, b.xdot, b.xdotbar);
  const double* xdotbar = b.xdotbar;
  for (int col = 0; col < b.N; ++col) {
    V acc[L / W];
    for (int c = 0; c < L / W; ++c) acc[c] = TRELLIS_TAPE_LANES(W, L, xdotbar, 1 + col, c);
    const double* y = b.Y + static_cast<size_t>(col) * b.ny;
    for (int i = 0; i < b.ny; ++i) {
      const double yi = y[i];
      for (int c = 0; c < L / W; ++c) acc[c] += yi * TRELLIS_TAPE_LANES(W, L, xdotbar, 1 + b.N + i, c);
    }
    for (int c = 0; c < L / W; ++c) TRELLIS_TAPE_LANES(W, L, b.out, col, c) = acc[c];
  }
  for (int row = 0; row <= b.N + b.ny; ++row)  // (row 0, the constant sink, is never written)
    for (int c = 0; c < L / W; ++c) TRELLIS_TAPE_LANES(W, L, b.xdotbar, row, c) = V{};
}
void sweepBlockGeneric(int lanes, const BlockArgs& b) {
  if (lanes == 4)
    sweepBlockBody<2, 4>(b);
  else if (lanes == 8)
    sweepBlockBody<2, 8>(b);
  else
    sweepBlockBody<2, 16>(b);
}
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target("avx2,fma"))) void sweepBlockAvx2(int lanes, const BlockArgs& b) {
  if (lanes == 4)
    sweepBlockBody<4, 4>(b);
  else if (lanes == 8)
    sweepBlockBody<4, 8>(b);
  else
    sweepBlockBody<4, 16>(b);
}
bool cpuHasAvx2Fma() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}
const bool kSweepAvx2 = cpuHasAvx2Fma();
#else
constexpr bool kSweepAvx2 = false;
#endif
bool sweepForceGeneric = false;

void sweepBlock(int lanes, const BlockArgs& b) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (kSweepAvx2 && !sweepForceGeneric) return sweepBlockAvx2(lanes, b);
#endif
  sweepBlockGeneric(lanes, b);
}

}  // namespace

bool secondOrderSweepsUseAvx2() { return kSweepAvx2 && !sweepForceGeneric; }
void secondOrderSweepsForceGeneric(bool force) { sweepForceGeneric = force; }

struct SecondOrderImpl {
  int n, m, nc, N;
  std::vector<JointConstants> joints;
  Vec3<double> gravity;
  ResidualPass<HyperDual> pass;
  Eigen::MatrixXd Y;                   ///< (n + nc)×N: ∂[q̈; λ]/∂z from the linearization
  Eigen::VectorXd z, y;                ///< the point: [q; q̇; u], [q̈; λ]
  std::vector<std::pair<int, int>> pairs;  ///< (a ≤ b), every pair but (u, u)
  static constexpr int kChunk = 32;    ///< pairs per block solve of the tensors
  Eigen::MatrixXd G;                   ///< (n + nc)×kChunk: G[a, b] of a block of pairs
  Eigen::MatrixXd Xr, Xc;              ///< n×kChunk, nc×kChunk
  Eigen::VectorXd muR, muC, tmpC;      ///< the adjoint μ = K⁻ᵀ [w; ρ]
  // The contraction's recording (adjoint_tape.hpp): inputs are nodes 1 … N (z) and N + 1 … N + n + nc (y).
  Tape tape;
  ResidualPass<TapeVar> recorded;
  int inputs = 0;
  int recordedNodes = 0;               ///< the tape's size, the same at every state (buffers sized to it)
  Eigen::VectorXd xbar;                ///< per node: the adjoint
  Eigen::VectorXd xdot, xdotbar;       ///< per node and lane (node-major): tangent, tangent of the adjoint
  int lastStride = 0;                  ///< lanes of the last block swept (its layout of xdot)
  Eigen::VectorXd laneRows;            ///< N rows × kTapeLanesMax lanes: one block's rows of ∇²φ
  Eigen::MatrixXd rows;                ///< N×2n: ∇²φ e_a for the q and q̇ directions a
  // computeImplicitSecondOrder: two first-order residual evaluations and their inputs.
  ImplicitDynamics implicitA, implicitB;
  Eigen::VectorXd zeroN, zeroC, negEta;
  /// The contraction's tree pass (second_order_tree.hpp) where it covers the model, chosen here
  /// once; null: the contraction runs the recording.
  std::unique_ptr<TreeSecondOrder> tree;

  SecondOrderImpl(const Model& model, bool forceRecording)
      : n(model.nq()),
        m(model.nu()),
        nc(model.nc()),
        N(2 * model.nq() + model.nu()) {
    joints.resize(n);
    for (int i = 0; i < n; ++i) {
      const Joint& j = model.joints()[i];
      JointConstants& jc = joints[i];
      jc.parent = j.parent;
      jc.axis = j.axis;
      jc.revolute = j.revolute;
      jc.R0 = mat3(j.R0);
      jc.p0 = vec3(j.p0);
      jc.inertia = mat3(j.inertiaAtOrigin);
      jc.firstMoment = vec3(j.firstMoment);
      jc.mass = j.mass;
    }
    gravity = vec3(model.gravity());
    pass.resize(n, m, nc);
    Y = Eigen::MatrixXd::Zero(n + nc, N);
    z = Eigen::VectorXd::Zero(N);
    y = Eigen::VectorXd::Zero(n + nc);
    for (int a = 0; a < N; ++a)
      for (int b = a; b < N; ++b)
        if (a < 2 * n) pairs.emplace_back(a, b);
    G = Eigen::MatrixXd::Zero(n + nc, kChunk);
    Xr = Eigen::MatrixXd::Zero(n, kChunk);
    Xc = Eigen::MatrixXd::Zero(nc, kChunk);
    muR = Eigen::VectorXd::Zero(n);
    muC = Eigen::VectorXd::Zero(nc);
    tmpC = Eigen::VectorXd::Zero(nc);
    rows = Eigen::MatrixXd::Zero(N, 2 * n);
    implicitA = ImplicitDynamics(model);
    implicitB = ImplicitDynamics(model);
    zeroN = Eigen::VectorXd::Zero(n);
    zeroC = Eigen::VectorXd::Zero(nc);
    negEta = Eigen::VectorXd::Zero(nc);
    if (treeSecondOrderApplies(model) && !secondOrderTapeForced() && !forceRecording) {
      tree = std::make_unique<TreeSecondOrder>(model);
      return;
    }
    // One recording at z = 0 sizes the tape: its node count depends on the model only (which
    // operands are constant is structural), so later recordings fit.
    inputs = N + n + nc;
    recorded.resize(n, m, nc);
    record(model);
    tape.nodes.resize(static_cast<size_t>(tape.size));
    recordedNodes = tape.size;
    xbar = Eigen::VectorXd::Zero(tape.size);
    xdot = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(tape.size) * kTapeLanesMax);
    xdotbar = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(tape.size) * kTapeLanesMax);
    laneRows = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(N) * kTapeLanesMax);
  }

  /// record() at (z, y), checked against the size the buffers were made for (a folding rule that
  /// depended on the state would overrun them).
  void recordChecked(const Model& model, const char* what) {
    record(model);
    if (tape.size != recordedNodes)
      throw std::logic_error(std::string(what) + ": internal error: the recording has " + std::to_string(tape.size) +
                             " nodes at this state, " + std::to_string(recordedNodes) + " when the workspace was sized");
  }

  /// rows(:, a) = ∇²φ e_a for the 2n q and q̇ directions a, φ(z') = wrᵀ r + wcᵀ c on the recording
  /// at (z, y) with y' = y + Y (z' − z): one reverse sweep gives φ's adjoints; per block of up to
  /// 16 directions a tangent sweep (z' = z + s e_a, y + s Y e_a) and a second reverse sweep give
  /// ∇²φ e_a = x̄̇_z + Yᵀ x̄̇_y (blocks of L = 16, the last one of 4, 8 or 16).
  void sweepRows(const Eigen::VectorXd& wr, const Eigen::VectorXd& wc) {
    const int size = tape.size;
    xbar.head(size).setZero();
    for (int i = 0; i < n; ++i) xbar[recorded.r[i].idx] += wr[i];
    for (int k = 0; k < nc; ++k) xbar[recorded.c[k].idx] += wc[k];
    xbar[0] = 0.0;  // a constant output (index 0) has no adjoint
    reverseSweep(tape, xbar.data());
    double* xd = xdot.data();
    double* xdb = xdotbar.data();
    for (int a0 = 0, L = 0; a0 < 2 * n; a0 += L) {
      const int lanes = std::min(kTapeLanesMax, 2 * n - a0);
      L = lanes <= 4 ? 4 : (lanes <= 8 ? 8 : 16);
      // Seeds: lane l is the direction a0 + l (unused lanes and all other input rows zero: the
      // seeds of the previous block are reset below; after a block of another stride, the input
      // rows of this one may hold its tangents).
      if (lastStride != L) std::fill(xd, xd + static_cast<size_t>(inputs + 1) * L, 0.0);
      lastStride = L;
      auto seed = [&](bool set) {
        for (int l = 0; l < lanes; ++l) {
          xd[static_cast<size_t>(1 + a0 + l) * L + l] = set ? 1.0 : 0.0;
          for (int i = 0; i < n + nc; ++i) xd[static_cast<size_t>(1 + N + i) * L + l] = set ? Y(i, a0 + l) : 0.0;
        }
      };
      seed(true);
      sweepBlock(L, {&tape, inputs, N, n + nc, xbar.data(), Y.data(), xd, xdb, laneRows.data()});
      for (int l = 0; l < lanes; ++l)
        for (int b = 0; b < N; ++b) rows(b, a0 + l) = laneRows[static_cast<Eigen::Index>(b) * L + l];
      seed(false);
    }
  }

  static bool usesTree(const SecondOrderWorkspace& ws) { return ws.impl_->tree != nullptr; }

  /// Records the residual pass at (z, y) on the tape.
  void record(const Model& model) {
    tape.clear();
    activeTape = &tape;
    for (int k = 0; k < inputs; ++k) tape.push({});
    for (int i = 0; i < n; ++i) {
      recorded.q[i] = TapeVar(z[i], 1 + i);
      recorded.dq[i] = TapeVar(z[n + i], 1 + n + i);
      recorded.qdd[i] = TapeVar(y[i], 1 + N + i);
    }
    for (int k = 0; k < m; ++k) recorded.u[k] = TapeVar(z[2 * n + k], 1 + 2 * n + k);
    for (int k = 0; k < nc; ++k) recorded.lambda[k] = TapeVar(y[n + k], 1 + N + n + k);
    recorded.evaluate(model, joints, gravity);
    activeTape = nullptr;
  }

  /// After computeLinearization: the point and Y. The KKT solves below reuse the first-order
  /// factorization that computeLinearization left in data (detail::solveKkt: the factor of M, M⁻¹Aᵀ
  /// and the factor of A M⁻¹ Aᵀ, its zero and redundant rows handled as there), so that the
  /// second derivatives solve exactly the system whose solution the first ones differentiate.
  void prepare(const Data& data, const Eigen::VectorXd& q, const Eigen::VectorXd& dq, const Eigen::VectorXd& u) {
    z.head(n) = q;
    z.segment(n, n) = dq;
    z.tail(m) = u;
    y.head(n) = data.qdd;
    y.tail(nc) = data.lambda;
    Y.topLeftCorner(n, n) = data.dqdd_dq;
    Y.block(0, n, n, n) = data.dqdd_ddq;
    if (m > 0) Y.topRightCorner(n, m) = data.dqdd_du;
    if (nc > 0) Y.bottomRows(nc) = data.dlambda_dx;
  }

  /// G[e_a, e_b] (n + nc) into `out`: one hyper-dual residual pass with z + ε1 e_a + ε2 e_b and
  /// y + ε1 Y e_a + ε2 Y e_b.
  template <class Out>
  void mixedSecondDerivative(const Model& model, int a, int b, Out&& out) {
    auto seed = [&](std::vector<HyperDual>& x, int offset, int count) {
      for (int i = 0; i < count; ++i) {
        const int k = offset + i;
        x[i] = HyperDual(z[k], k == a ? 1.0 : 0.0, k == b ? 1.0 : 0.0, 0.0);
      }
    };
    seed(pass.q, 0, n);
    seed(pass.dq, n, n);
    seed(pass.u, 2 * n, m);
    for (int i = 0; i < n; ++i) pass.qdd[i] = HyperDual(y[i], Y(i, a), Y(i, b), 0.0);
    for (int k = 0; k < nc; ++k) pass.lambda[k] = HyperDual(y[n + k], Y(n + k, a), Y(n + k, b), 0.0);
    pass.evaluate(model, joints, gravity);
    for (int i = 0; i < n; ++i) out(i, pass.r[i].st);
    for (int k = 0; k < nc; ++k) out(n + k, pass.c[k].st);
  }
};

bool secondOrderUsesTreePath(const SecondOrderWorkspace& ws) { return SecondOrderImpl::usesTree(ws); }

}  // namespace detail

namespace {

void checkWorkspace(const Model& model, const SecondOrderWorkspace& ws, const char* what) {
  if (ws.n() != model.nq() || ws.m() != model.nu() || ws.nc() != model.nc())
    throw std::invalid_argument(std::string(what) + ": the workspace was built for a model with (n, m, nc) = (" +
                                std::to_string(ws.n()) + ", " + std::to_string(ws.m()) + ", " + std::to_string(ws.nc()) +
                                "), this model has (" + std::to_string(model.nq()) + ", " + std::to_string(model.nu()) +
                                ", " + std::to_string(model.nc()) + ")");
}

bool usable(const DynamicsStatus& s) {
  return s.code != DynamicsStatus::Code::kSingularMassMatrix && s.code != DynamicsStatus::Code::kNonFinite;
}

}  // namespace

SecondOrderWorkspace::SecondOrderWorkspace(const Model& model, bool withTensors, bool recording)
    : n_(model.nq()), m_(model.nu()), nc_(model.nc()), withTensors_(withTensors),
      impl_(std::make_unique<detail::SecondOrderImpl>(model, recording)) {
  const int N = 2 * n_ + m_;
  if (withTensors) {
    qddHessian.assign(n_, Eigen::MatrixXd::Zero(N, N));
    lambdaHessian.assign(nc_, Eigen::MatrixXd::Zero(N, N));
  }
}
SecondOrderWorkspace::~SecondOrderWorkspace() = default;
SecondOrderWorkspace::SecondOrderWorkspace(SecondOrderWorkspace&&) noexcept = default;
SecondOrderWorkspace& SecondOrderWorkspace::operator=(SecondOrderWorkspace&&) noexcept = default;

std::vector<Eigen::MatrixXd> SecondOrderWorkspace::qddBlock(Block block) const {
  const int n = n_, m = m_;
  int r0 = 0, c0 = 0, rows = n, cols = n;
  switch (block) {
    case Block::kQQ: break;
    case Block::kQDq: c0 = n; break;
    case Block::kDqDq: r0 = c0 = n; break;
    case Block::kUQ: r0 = 2 * n; rows = m; break;
    case Block::kUDq: r0 = 2 * n; c0 = n; rows = m; break;
    case Block::kUU: r0 = c0 = 2 * n; rows = cols = m; break;
  }
  std::vector<Eigen::MatrixXd> out;
  out.reserve(qddHessian.size());
  for (const Eigen::MatrixXd& H : qddHessian) out.emplace_back(H.block(r0, c0, rows, cols));
  return out;
}

DynamicsStatus computeSecondOrderTensors(const Model& model, Data& data, SecondOrderWorkspace& ws,
                                         const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                         const Eigen::VectorXd& u) {
  checkWorkspace(model, ws, "computeSecondOrderTensors");
  if (!ws.hasTensors())
    throw std::invalid_argument("computeSecondOrderTensors: the workspace was built without tensors (withTensors = false)");
  const DynamicsStatus& status = computeLinearization(model, data, q, dq, u);  // checks the sizes
  if (!usable(status)) return status;
  detail::SecondOrderImpl& s = *ws.impl_;
  const int n = s.n, nc = s.nc, N = s.N;
  s.prepare(data, q, dq, u);
  for (auto& H : ws.qddHessian) H.bottomRightCorner(N - 2 * n, N - 2 * n).setZero();  // (u, u): 0
  for (auto& H : ws.lambdaHessian) H.bottomRightCorner(N - 2 * n, N - 2 * n).setZero();
  const int total = static_cast<int>(s.pairs.size());
  for (int first = 0; first < total; first += s.kChunk) {
    const int cols = std::min<int>(s.kChunk, total - first);
    for (int j = 0; j < cols; ++j) {
      const auto [a, b] = s.pairs[static_cast<size_t>(first + j)];
      s.mixedSecondDerivative(model, a, b, [&](int i, double g) { s.G(i, j) = g; });
    }
    // K [δq̈; δλ] = −G with K = [M −Aᵀ; A 0]: M δq̈ = −G_r + Aᵀ δλ, A δq̈ = −G_c, the first-order
    // system of solveKkt (M X = R + Aᵀ Λ, A X = C) with R = −G_r, C = −G_c.
    // (Column by column: the vector solves never allocate.)
    auto Xr = s.Xr.leftCols(cols);
    auto Xc = s.Xc.leftCols(cols);
    Xr = -s.G.topLeftCorner(n, cols);
    Xc = -s.G.block(n, 0, nc, cols);
    for (int j = 0; j < cols; ++j) detail::solveKkt(model, data, Xr.col(j), Xc.col(j));
    for (int j = 0; j < cols; ++j) {
      const auto [a, b] = s.pairs[static_cast<size_t>(first + j)];
      for (int i = 0; i < n; ++i) ws.qddHessian[i](a, b) = ws.qddHessian[i](b, a) = Xr(i, j);
      for (int k = 0; k < nc; ++k) ws.lambdaHessian[k](a, b) = ws.lambdaHessian[k](b, a) = Xc(k, j);
    }
  }
  return status;
}

DynamicsStatus computeSecondOrderContraction(const Model& model, Data& data, SecondOrderWorkspace& ws,
                                             const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                             const Eigen::VectorXd& u, const Eigen::VectorXd& w,
                                             const Eigen::VectorXd& rho, Eigen::Ref<Eigen::MatrixXd> H) {
  checkWorkspace(model, ws, "computeSecondOrderContraction");
  const int n = model.nq(), nc = model.nc(), N = 2 * n + model.nu();
  if (w.size() != n)
    throw std::invalid_argument("computeSecondOrderContraction: w: expected " + std::to_string(n) + " entries, got " +
                                std::to_string(w.size()));
  if (rho.size() != 0 && rho.size() != nc)
    throw std::invalid_argument("computeSecondOrderContraction: rho: expected " + std::to_string(nc) +
                                " entries (or none), got " + std::to_string(rho.size()));
  if (H.rows() != N || H.cols() != N)
    throw std::invalid_argument("computeSecondOrderContraction: H: expected " + std::to_string(N) + "×" +
                                std::to_string(N) + ", got " + std::to_string(H.rows()) + "×" + std::to_string(H.cols()));
  const DynamicsStatus& status = computeLinearization(model, data, q, dq, u);
  if (!usable(status)) return status;
  detail::SecondOrderImpl& s = *ws.impl_;
  s.prepare(data, q, dq, u);
  // μ = K⁻ᵀ [w; ρ], Kᵀ = [M Aᵀ; −A 0]: M μ_r = w − Aᵀ μ_c, A μ_r = −ρ, solveKkt's system
  // (M X = R + Aᵀ Λ, A X = C) with R = w, C = −ρ, X = μ_r, Λ = −μ_c.
  s.muR = w;
  if (rho.size() == nc) s.muC = -rho;
  else s.muC.setZero();
  detail::solveKkt(model, data, s.muR, s.muC);
  s.muC = -s.muC;
  // wᵀ δq̈ + ρᵀ δλ = −μᵀ G[a, b] = −∂²φ/∂z_a∂z_b with φ(z') = μᵀ F(z', y + Y (z' − z)): the
  // Hessian of one scalar, by forward-over-reverse on the recorded residual pass. One reverse
  // sweep gives φ's adjoints; per q or q̇ direction a, a tangent sweep (z' = z + s e_a, y + s Y e_a)
  // and a second reverse sweep give ∇²φ e_a = x̄̇_z + Yᵀ x̄̇_y, up to 16 directions per pair of
  // sweeps (blocks of L = 16, the last one of 4, 8 or 16).
  // The u directions follow by symmetry, and the (u, u) block is 0 (F is linear in u, K does not
  // depend on u).
  if (s.tree) {
    // The tree pass: the same rows by forward mode over the closed-form gradient (second_order_tree.hpp).
    s.tree->computeRows(model, q, dq, data.qdd, u, data.lambda, s.muR, s.muC, s.Y, s.rows);
  } else {
    s.recordChecked(model, "computeSecondOrderContraction");
    s.sweepRows(s.muR, s.muC);
  }
  // H = −∇²φ; the (q, q̇) block symmetrized (its two halves agree to rounding).
  H.topLeftCorner(2 * n, 2 * n) = -0.5 * (s.rows.topRows(2 * n) + s.rows.topRows(2 * n).transpose());
  H.bottomLeftCorner(N - 2 * n, 2 * n) = -s.rows.bottomRows(N - 2 * n);
  H.topRightCorner(2 * n, N - 2 * n) = -s.rows.bottomRows(N - 2 * n).transpose();
  H.bottomRightCorner(N - 2 * n, N - 2 * n).setZero();
  return status;
}

DynamicsStatus computeImplicitSecondOrder(const Model& model, Data& data, SecondOrderWorkspace& ws,
                                          const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                          const Eigen::VectorXd& qdd, const Eigen::VectorXd& u,
                                          const Eigen::VectorXd& lambda, const Eigen::VectorXd& nu,
                                          const Eigen::VectorXd& eta, Eigen::Ref<Eigen::MatrixXd> Hzz,
                                          Eigen::Ref<Eigen::MatrixXd> Hyz) {
  checkWorkspace(model, ws, "computeImplicitSecondOrder");
  detail::SecondOrderImpl& s = *ws.impl_;
  const int n = s.n, m = s.m, nc = s.nc, N = s.N;
  if (s.tree)
    throw std::invalid_argument("computeImplicitSecondOrder: the workspace runs the tree pass; build it with "
                                "SecondOrderWorkspace(model, withTensors, /*recording=*/true)");
  const auto size = [](const char* what, Eigen::Index got, int expected) {
    if (got != expected)
      throw std::invalid_argument(std::string("computeImplicitSecondOrder: ") + what + ": expected " +
                                  std::to_string(expected) + " entries, got " + std::to_string(got));
  };
  size("nu", nu.size(), n);
  size("eta", eta.size(), nc);
  if (Hzz.rows() != N || Hzz.cols() != N || Hyz.rows() != n + nc || Hyz.cols() != 2 * n)
    throw std::invalid_argument("computeImplicitSecondOrder: Hzz must be " + std::to_string(N) + "×" + std::to_string(N) +
                                " and Hyz " + std::to_string(n + nc) + "×" + std::to_string(2 * n));
  // (The first-order call checks q, q̇, q̈, u, λ and their finiteness.) Hyz from r, c being affine
  // in (q̈, λ): ∂φ/∂q̈ = M ν + Aᵀη, ∂φ/∂λ = −A ν, so with q̇ = 0 (no velocity terms),
  //   ∂(M ν + Aᵀη)/∂q = ∂r/∂q (q̈ = ν, λ = −η) − ∂r/∂q (q̈ = 0, λ = 0),   ∂(A ν)/∂q = ∂c/∂q (q̈ = ν),
  // and neither depends on q̇ or u (b's u-part cancels in the difference).
  s.negEta = -eta;
  DynamicsStatus status = computeImplicitDynamics(model, data, q, s.zeroN, nu, u, s.negEta, s.implicitA);
  if (!status.ok()) return status;
  status = computeImplicitDynamics(model, data, q, s.zeroN, s.zeroN, u, s.zeroC, s.implicitB);
  if (!status.ok()) return status;
  Hyz.setZero();
  Hyz.topLeftCorner(n, n) = s.implicitA.dr_dx.leftCols(n) - s.implicitB.dr_dx.leftCols(n);
  if (nc > 0) Hyz.bottomLeftCorner(nc, n) = -s.implicitA.dc_dx.leftCols(n);
  size("dq", dq.size(), n);
  size("qdd", qdd.size(), n);
  size("lambda", lambda.size(), nc);
  if (!dq.allFinite() || !qdd.allFinite() || !lambda.allFinite()) {
    data.status.code = DynamicsStatus::Code::kNonFinite;
    data.status.message = "computeImplicitSecondOrder: non-finite dq, qdd or lambda";
    return data.status;
  }
  // Hzz: φ(z) = νᵀ r(z, y) + ηᵀ c(z, y) at the fixed y = [q̈; λ], by forward-over-reverse on the
  // recorded residual pass (as computeSecondOrderContraction with Y = 0 and μ = [ν; η]).
  s.z.head(n) = q;
  s.z.segment(n, n) = dq;
  s.z.tail(m) = u;
  s.y.head(n) = qdd;
  s.y.tail(nc) = lambda;
  s.Y.setZero();
  s.recordChecked(model, "computeImplicitSecondOrder");
  s.sweepRows(nu, eta);
  Hzz.topLeftCorner(2 * n, 2 * n) = 0.5 * (s.rows.topRows(2 * n) + s.rows.topRows(2 * n).transpose());
  Hzz.bottomLeftCorner(m, 2 * n) = s.rows.bottomRows(m);
  Hzz.topRightCorner(2 * n, m) = s.rows.bottomRows(m).transpose();
  Hzz.bottomRightCorner(m, m).setZero();
  return status;
}

}  // namespace trellis
