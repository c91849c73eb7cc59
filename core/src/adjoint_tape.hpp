// Internal: a recording of one residual pass as elementary operations, for the second-order
// adjoint of the contraction (second_order.cpp). Not installed.
//
// Running a computation on TapeVar (a value and the index of the node that produced it) records
// every elementary operation x_k = g(x_i, x_j) with its partials ∂g/∂x_i, ∂g/∂x_j and second
// partials. With the recording, for a scalar φ = Σ μ_k x_out(k):
//  - one reverse sweep gives the adjoints x̄ = ∂φ/∂x of every node (seeded with μ);
//  - per direction d, a forward sweep gives the tangents ẋ = ∂x/∂d, and a second reverse sweep
//    the tangents of the adjoints, x̄̇_i = Σ_k [∂g_k/∂x_i x̄̇_k + x̄_k (∂²g_k/∂x_i∂x_i ẋ_i + ∂²g_k/∂x_i∂x_j ẋ_j)],
//    whose entries at the inputs are the row ∇²φ d (forward-over-reverse: a Hessian-vector
//    product for the cost of a few passes, instead of one pass per pair of directions).
// Node 0 is the constant sink: constants have index 0, unary operations name it as their second
// operand with zero partials, so that the sweeps need no branch. Inputs are the first nodes.
#pragma once

#include <cmath>
#include <vector>

namespace trellis::detail {

struct TapeNode {
  int i = 0, j = 0;
  double di = 0.0, dj = 0.0, dii = 0.0, dij = 0.0, djj = 0.0;
};

struct Tape {
  std::vector<TapeNode> nodes = std::vector<TapeNode>(1);
  int size = 1;  ///< nodes in use (node 0 included)
  int push(const TapeNode& node) {
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

inline TapeVar recordUnary(const TapeVar& x, double g, double g1, double g2) {
  if (x.idx == 0) return TapeVar(g);
  return TapeVar(g, activeTape->push({x.idx, 0, g1, 0.0, g2, 0.0, 0.0}));
}
inline TapeVar recordBinary(const TapeVar& a, const TapeVar& b, double g, double da, double db, double dab) {
  if (a.idx == 0 && b.idx == 0) return TapeVar(g);
  return TapeVar(g, activeTape->push({a.idx, b.idx, da, db, 0.0, dab, 0.0}));
}

// Constants are folded: an operation with a constant operand records a unary node, and the
// exact identities x + 0 = x, x · 1 = x, x · 0 = 0 record none (the many zero entries of constant
// placements, zero vectors and axis columns would otherwise each cost a node). Which operands are
// constant, and their values, come from the model only, so the node count is the same at every state.
inline TapeVar operator+(const TapeVar& a, double b) { return b == 0.0 ? a : recordUnary(a, a.v + b, 1.0, 0.0); }
inline TapeVar operator+(double b, const TapeVar& a) { return a + b; }
inline TapeVar operator-(const TapeVar& a, double b) { return b == 0.0 ? a : recordUnary(a, a.v - b, 1.0, 0.0); }
inline TapeVar operator-(double b, const TapeVar& a) { return recordUnary(a, b - a.v, -1.0, 0.0); }
inline TapeVar operator*(const TapeVar& a, double b) {
  if (b == 0.0) return TapeVar(0.0);
  if (b == 1.0) return a;
  return recordUnary(a, a.v * b, b, 0.0);
}
inline TapeVar operator*(double b, const TapeVar& a) { return a * b; }
inline TapeVar operator-(const TapeVar& a) { return recordUnary(a, -a.v, -1.0, 0.0); }
inline TapeVar operator+(const TapeVar& a, const TapeVar& b) {
  if (a.idx == 0) return b + a.v;
  if (b.idx == 0) return a + b.v;
  return recordBinary(a, b, a.v + b.v, 1.0, 1.0, 0.0);
}
inline TapeVar operator-(const TapeVar& a, const TapeVar& b) {
  if (a.idx == 0) return a.v - b;
  if (b.idx == 0) return a - b.v;
  return recordBinary(a, b, a.v - b.v, 1.0, -1.0, 0.0);
}
inline TapeVar operator*(const TapeVar& a, const TapeVar& b) {
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

/// ẋ (inputs 1…inputs seeded) ← the tangents of every node after the inputs.
inline void tangentSweep(const Tape& tape, int inputs, double* xdot) {
  const TapeNode* nodes = tape.nodes.data();
  for (int k = inputs + 1; k < tape.size; ++k) {
    const TapeNode& nd = nodes[k];
    xdot[k] = nd.di * xdot[nd.i] + nd.dj * xdot[nd.j];
  }
}

/// x̄̇ (zeroed by the caller) ← the tangents of the adjoints, from x̄ and ẋ of the sweeps above.
inline void secondOrderReverseSweep(const Tape& tape, int inputs, const double* xbar, const double* xdot,
                                    double* xdotbar) {
  const TapeNode* nodes = tape.nodes.data();
  for (int k = tape.size - 1; k > inputs; --k) {
    const TapeNode& nd = nodes[k];
    const double b = xbar[k], db = xdotbar[k];
    const double ti = nd.dii * xdot[nd.i] + nd.dij * xdot[nd.j];
    const double tj = nd.dij * xdot[nd.i] + nd.djj * xdot[nd.j];
    xdotbar[nd.i] += nd.di * db + b * ti;
    xdotbar[nd.j] += nd.dj * db + b * tj;
  }
}

}  // namespace trellis::detail
