// Internal: a recording of one residual pass as elementary operations, for the second-order
// adjoint of the contraction (second_order.cpp). Not installed.
//
// Running a computation on TapeVar (a value and the index of the node that produced it) records
// every elementary operation x_k = g(x_i, x_j) with its partials ∂g/∂x_i, ∂g/∂x_j and second
// partials. With the recording, for a scalar φ = Σ μ_k x_out(k):
//  - one reverse sweep gives the adjoints x̄ = ∂φ/∂x of every node (seeded with μ);
//  - per direction d (L of them at once), a forward sweep gives the tangents ẋ = ∂x/∂d, and a
//    second reverse sweep the tangents of the adjoints, x̄̇_i = Σ_k [∂g_k/∂x_i x̄̇_k + x̄_k (∂²g_k/∂x_i∂x_i ẋ_i + ∂²g_k/∂x_i∂x_j ẋ_j)],
//    whose entries at the inputs are the row ∇²φ d (forward-over-reverse: a Hessian-vector
//    product for the cost of a few passes, instead of one pass per pair of directions).
// Node 0 is the constant sink: constants have index 0, unary operations name it as their second
// operand with zero partials, so that the first-order sweep needs no branch. Inputs are the first nodes.
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

namespace trellis::detail {

#define TRELLIS_TAPE_INLINE inline __attribute__((always_inline))

/// What the second-order sweep of a node needs: an affine node (all second partials zero) passes
/// the adjoint tangent on; a product (x_i · x_j scaled: ∂²g/∂x_i∂x_j the only second partial) and a
/// nonlinear unary g(x_i) (∂²g/∂x_i² the only one) add x̄_k times it. These are all the operations
/// below record, so one second partial per node suffices.
enum class TapeKind : unsigned char { kAffine1, kAffine2, kProduct, kNonlinear1 };

struct TapeNode {
  int i = 0, j = 0;
  double di = 0.0, dj = 0.0;  ///< ∂g/∂x_i, ∂g/∂x_j
  double d2 = 0.0;            ///< ∂²g/∂x_i∂x_j (kProduct), ∂²g/∂x_i² (kNonlinear1), else 0
  TapeKind kind = TapeKind::kAffine1;
};

struct Tape {
  std::vector<TapeNode> nodes = std::vector<TapeNode>(1);
  int size = 1;  ///< nodes in use (node 0 included)
  TRELLIS_TAPE_INLINE int push(const TapeNode& node) {
    if (size == static_cast<int>(nodes.size())) nodes.resize(2 * nodes.size());  // only before sizing
    nodes[static_cast<size_t>(size)] = node;
    return size++;
  }
  void clear() { size = 1; }
};

/// The tape operations record to (set for the duration of one recording).
inline thread_local Tape* activeTape = nullptr;

struct TapeVar {
  double v = 0.0;
  int idx = 0;  ///< 0: a constant
  TapeVar() = default;
  TapeVar(double value) : v(value) {}  // NOLINT: a constant
  TapeVar(double value, int index) : v(value), idx(index) {}
};

TRELLIS_TAPE_INLINE TapeVar recordUnary(const TapeVar& x, double g, double g1, double g2) {
  if (x.idx == 0) return TapeVar(g);
  return TapeVar(g, activeTape->push({x.idx, 0, g1, 0.0, g2, g2 == 0.0 ? TapeKind::kAffine1 : TapeKind::kNonlinear1}));
}
TRELLIS_TAPE_INLINE TapeVar recordBinary(const TapeVar& a, const TapeVar& b, double g, double da, double db, double dab) {
  if (a.idx == 0 && b.idx == 0) return TapeVar(g);
  return TapeVar(g, activeTape->push({a.idx, b.idx, da, db, dab, dab == 0.0 ? TapeKind::kAffine2 : TapeKind::kProduct}));
}

// Constants are folded: an operation with a constant operand records a unary node, and the
// exact identities x + 0 = x, x · 1 = x, x · 0 = 0 record none (the many zero entries of constant
// placements, zero vectors and axis columns would otherwise each cost a node). Which operands are
// constant, and their values, come from the model only, so the node count is the same at every state.
TRELLIS_TAPE_INLINE TapeVar operator+(const TapeVar& a, double b) { return b == 0.0 ? a : recordUnary(a, a.v + b, 1.0, 0.0); }
inline TapeVar operator+(double b, const TapeVar& a) { return a + b; }
TRELLIS_TAPE_INLINE TapeVar operator-(const TapeVar& a, double b) { return b == 0.0 ? a : recordUnary(a, a.v - b, 1.0, 0.0); }
inline TapeVar operator-(double b, const TapeVar& a) { return recordUnary(a, b - a.v, -1.0, 0.0); }
TRELLIS_TAPE_INLINE TapeVar operator*(const TapeVar& a, double b) {
  if (b == 0.0) return TapeVar(0.0);
  if (b == 1.0) return a;
  return recordUnary(a, a.v * b, b, 0.0);
}
inline TapeVar operator*(double b, const TapeVar& a) { return a * b; }
inline TapeVar operator-(const TapeVar& a) { return recordUnary(a, -a.v, -1.0, 0.0); }
TRELLIS_TAPE_INLINE TapeVar operator+(const TapeVar& a, const TapeVar& b) {
  if (a.idx == 0) return b + a.v;
  if (b.idx == 0) return a + b.v;
  return recordBinary(a, b, a.v + b.v, 1.0, 1.0, 0.0);
}
TRELLIS_TAPE_INLINE TapeVar operator-(const TapeVar& a, const TapeVar& b) {
  if (a.idx == 0) return a.v - b;
  if (b.idx == 0) return a - b.v;
  return recordBinary(a, b, a.v - b.v, 1.0, -1.0, 0.0);
}
TRELLIS_TAPE_INLINE TapeVar operator*(const TapeVar& a, const TapeVar& b) {
  if (a.idx == 0) return b * a.v;
  if (b.idx == 0) return a * b.v;
  return recordBinary(a, b, a.v * b.v, b.v, a.v, 1.0);
}
inline TapeVar& operator+=(TapeVar& a, const TapeVar& b) { return a = a + b; }
inline TapeVar& operator-=(TapeVar& a, const TapeVar& b) { return a = a - b; }
inline TapeVar inverse(const TapeVar& x) {
  const double i = 1.0 / x.v;
  return recordUnary(x, i, -i * i, 2.0 * i * i * i);
}
inline TapeVar operator/(const TapeVar& a, const TapeVar& b) { return a * inverse(b); }
inline TapeVar operator/(double a, const TapeVar& b) { return a * inverse(b); }
inline TapeVar operator/(const TapeVar& a, double b) { return a * (1.0 / b); }
inline TapeVar sqrt(const TapeVar& x) {
  const double r = std::sqrt(x.v);
  return recordUnary(x, r, 0.5 / r, -0.25 / (r * x.v));
}
inline TapeVar sin(const TapeVar& x) { return recordUnary(x, std::sin(x.v), std::cos(x.v), -std::sin(x.v)); }
inline TapeVar cos(const TapeVar& x) { return recordUnary(x, std::cos(x.v), -std::sin(x.v), -std::cos(x.v)); }

/// x̄ (size ≥ tape.size, seeded at the outputs, zero elsewhere) ← the adjoints of every node.
inline void reverseSweep(const Tape& tape, double* xbar) {
  const TapeNode* nodes = tape.nodes.data();
  for (int k = tape.size - 1; k >= 1; --k) {
    const TapeNode& nd = nodes[k];
    const double b = xbar[k];
    xbar[nd.i] += nd.di * b;
    xbar[nd.j] += nd.dj * b;
  }
}

// ---- L directions at once ------------------------------------------------------------------------
// ẋ and x̄̇ hold L entries per node, node-major (x[k L + l] for direction l), so that each node's
// partials are read once for L directions. The L entries are processed in chunks of W, each one
// vector value of the GCC/Clang vector extension: W = 2 fills an SSE2 register, W = 4 an AVX one
// (wider vectors than the machine's registers are lowered through the stack). A chunk is accessed
// through a type that assumes neither alignment (the rows are 8-byte aligned) nor the absence of
// aliasing (x̄̇_i and x̄̇_j may be the same row, as in x · x).

inline constexpr int kTapeLanesMax = 16;  ///< the widest block (L = 4, 8 or 16)

/// Whether the sweeps of the contraction run the AVX2+FMA build (second_order.cpp: chosen at run
/// time when the CPU has both); tests force the baseline build to check both.
bool secondOrderSweepsUseAvx2();
void secondOrderSweepsForceGeneric(bool force);

template <int W>
struct TapeChunk {
  typedef double type __attribute__((vector_size(sizeof(double) * W)));
  /// The access type, aligned as a double and exempt from type-based alias analysis (it reads and
  /// writes arrays of double). GCC honours an under-aligned may_alias vector typedef; Clang does
  /// not lower the alignment of a vector typedef (it emitted aligned moves, which fault on these
  /// 8-byte aligned rows), so there a packed may_alias struct holds the vector.
#if defined(__clang__)
  struct __attribute__((packed, may_alias)) Access {
    type v;
  };
#else
  typedef double Access __attribute__((vector_size(sizeof(double) * W), aligned(alignof(double)), may_alias));
#endif
};

/// Chunk c (W lanes) of row k of a node-major array of L lanes, as a vector lvalue.
#if defined(__clang__)
#define TRELLIS_TAPE_LANES(W, L, x, k, c) (lanesAccess<W, L>(x, k, c).v)
#else
#define TRELLIS_TAPE_LANES(W, L, x, k, c) (lanesAccess<W, L>(x, k, c))
#endif
template <int W, int L>
TRELLIS_TAPE_INLINE typename TapeChunk<W>::Access& lanesAccess(double* x, int k, int c) {
  return *reinterpret_cast<typename TapeChunk<W>::Access*>(x + static_cast<size_t>(k) * L + c * W);
}
template <int W, int L>
TRELLIS_TAPE_INLINE const typename TapeChunk<W>::Access& lanesAccess(const double* x, int k, int c) {
  return *reinterpret_cast<const typename TapeChunk<W>::Access*>(x + static_cast<size_t>(k) * L + c * W);
}

/// ẋ (rows 1 … inputs seeded, row 0 zero) ← the tangents of every node after the inputs.
template <int W, int L>
TRELLIS_TAPE_INLINE void tangentSweepLanesBody(const Tape& tape, int inputs, double* xdot) {
  const TapeNode* nodes = tape.nodes.data();
  for (int k = inputs + 1; k < tape.size; ++k) {
    const TapeNode& nd = nodes[k];
    // A unary node names row 0 (zero) with dj = 0: no branch.
    for (int c = 0; c < L / W; ++c)
      TRELLIS_TAPE_LANES(W, L, xdot, k, c) = nd.di * TRELLIS_TAPE_LANES(W, L, xdot, nd.i, c) + nd.dj * TRELLIS_TAPE_LANES(W, L, xdot, nd.j, c);
  }
}

/// x̄̇ (zero above row `inputs` on entry) ← the tangents of the adjoints, from x̄ of reverseSweep
/// and ẋ of tangentSweepLanesBody: x̄̇_i = Σ_k [∂g_k/∂x_i x̄̇_k + x̄_k (∂²g_k/∂x_i∂x_i ẋ_i +
/// ∂²g_k/∂x_i∂x_j ẋ_j)], summed by the node kinds (an affine node has no second partial, a product
/// only ∂²/∂x_i∂x_j, a unary only ∂²/∂x_i²). Each row above `inputs` is zeroed once read, so it is
/// zero again on return: only rows 0 … inputs need clearing before the next block. Row i is
/// updated before row j is read, so i == j (x ± x, x · x) adds both contributions.
template <int W, int L>
TRELLIS_TAPE_INLINE void secondOrderReverseSweepLanesBody(const Tape& tape, int inputs, const double* xbar,
                                                          const double* xdot, double* xdotbar) {
  using V = typename TapeChunk<W>::type;
  const TapeNode* nodes = tape.nodes.data();
  for (int k = tape.size - 1; k > inputs; --k) {
    const TapeNode& nd = nodes[k];
    switch (nd.kind) {
      case TapeKind::kAffine1:
        for (int c = 0; c < L / W; ++c) {
          const V db = TRELLIS_TAPE_LANES(W, L, xdotbar, k, c);
          TRELLIS_TAPE_LANES(W, L, xdotbar, k, c) = V{};
          TRELLIS_TAPE_LANES(W, L, xdotbar, nd.i, c) += nd.di * db;
        }
        break;
      case TapeKind::kAffine2:
        for (int c = 0; c < L / W; ++c) {
          const V db = TRELLIS_TAPE_LANES(W, L, xdotbar, k, c);
          TRELLIS_TAPE_LANES(W, L, xdotbar, k, c) = V{};
          TRELLIS_TAPE_LANES(W, L, xdotbar, nd.i, c) += nd.di * db;
          TRELLIS_TAPE_LANES(W, L, xdotbar, nd.j, c) += nd.dj * db;
        }
        break;
      case TapeKind::kProduct: {
        const double s = xbar[k] * nd.d2;
        for (int c = 0; c < L / W; ++c) {
          const V db = TRELLIS_TAPE_LANES(W, L, xdotbar, k, c);
          TRELLIS_TAPE_LANES(W, L, xdotbar, k, c) = V{};
          TRELLIS_TAPE_LANES(W, L, xdotbar, nd.i, c) += nd.di * db + s * TRELLIS_TAPE_LANES(W, L, xdot, nd.j, c);
          TRELLIS_TAPE_LANES(W, L, xdotbar, nd.j, c) += nd.dj * db + s * TRELLIS_TAPE_LANES(W, L, xdot, nd.i, c);
        }
        break;
      }
      case TapeKind::kNonlinear1: {
        const double s = xbar[k] * nd.d2;
        for (int c = 0; c < L / W; ++c) {
          const V db = TRELLIS_TAPE_LANES(W, L, xdotbar, k, c);
          TRELLIS_TAPE_LANES(W, L, xdotbar, k, c) = V{};
          TRELLIS_TAPE_LANES(W, L, xdotbar, nd.i, c) += nd.di * db + s * TRELLIS_TAPE_LANES(W, L, xdot, nd.i, c);
        }
        break;
      }
    }
  }
}

}  // namespace trellis::detail
