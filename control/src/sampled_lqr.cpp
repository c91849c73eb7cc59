// sampled_lqr.cpp — exact discretization of a time-varying linearization over sample intervals
// (variational equation + cost quadrature, integrated by OdeDriver) and the discrete Riccati recursion with the
// cross term. See sampled_lqr.hpp for the math.
#include "trellis/control/sampled_lqr.hpp"

#include "trellis/analysis/detail/dense_kernels.hpp"
#include "trellis/analysis/detail/ode_driver.hpp"
#include "trellis/analysis/detail/radau_tableau.hpp"
#include "trellis/analysis/detail/shifted_solve.hpp"
#include "trellis/analysis/detail/small_lu.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdlib>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

namespace trellis {

void SampledDiscretizationOptions::validate() const {
  auto bad = [](const char* field, double v) {
    std::ostringstream m;
    m << "SampledDiscretizationOptions." << field << " = " << v << " is invalid (must be > 0)";
    throw std::invalid_argument(m.str());
  };
  if (!(rtol >= 0.0) || !std::isfinite(rtol)) {
    std::ostringstream m;
    m << "SampledDiscretizationOptions.rtol = " << rtol << " is invalid (must be >= 0; 0: the integrator's default)";
    throw std::invalid_argument(m.str());
  }
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol);
  if (maxSteps <= 0) bad("maxSteps", static_cast<double>(maxSteps));
}

double SampledDiscretizationOptions::relativeTolerance() const {
  if (rtol > 0.0) return rtol;
  return integrator == SampledIntegrator::kRadau ? kRadauRtol : kRtol;
}

Eigen::VectorXd sampleTimes(double t0, double T, double rate) {
  if (!(rate > 0.0) || !std::isfinite(rate)) {
    throw std::invalid_argument("sampleTimes: the rate must be finite and > 0, got " + std::to_string(rate));
  }
  if (!(t0 < T) || !std::isfinite(t0) || !std::isfinite(T)) {
    throw std::invalid_argument("sampleTimes: need finite t0 < T");
  }
  const double h = 1.0 / rate;
  std::vector<double> t;
  for (long k = 0;; ++k) {
    const double tk = t0 + static_cast<double>(k) * h;  // k·h from t0: no accumulated round-off
    if (tk >= T - 1e-9 * h) break;
    t.push_back(tk);
  }
  t.push_back(T);
  return Eigen::Map<Eigen::VectorXd>(t.data(), static_cast<Eigen::Index>(t.size()));
}

namespace {

/// Every entry finite (one branch-free pass: dense_kernels.hpp).
bool finite(const Eigen::MatrixXd& X) { return detail::finiteEntries(X.data(), X.size()); }

/// W ← (W + Wᵀ)/2 in place, without a temporary (W = 0.5 (W + Wᵀ) needs one: assigned lazily, it
/// would read entries it has already overwritten).
void symmetrize(Eigen::MatrixXd& W) {
  for (Eigen::Index j = 1; j < W.cols(); ++j)
    for (Eigen::Index i = 0; i < j; ++i) W(i, j) = W(j, i) = 0.5 * (W(i, j) + W(j, i));
}

/// The block exponential of a constant system over one unit of its own time: for Z (c×c, its last
/// nu rows zero: the held input) and a symmetric P (c×c),
///   E = e^{Z},  W = ∫₀¹ e^{Zᵀs} P e^{Zs} ds,
/// i.e. E = e^{Mh}, W = ∫₀ʰ e^{Mᵀs} Q̃ e^{Ms} ds for Z = Mh, P = Q̃h. Van Loan's exponential of
/// X = [[−Zᵀ, P], [0, Z]] holds e^{−Zᵀ}·W in its corner: for a stiff Z (|λ| ≫ 1) e^{−Zᵀ} and e^{Z}
/// differ by e^{2|λ|}, and W = e^{Zᵀ}·(that corner) loses every digit. So Van Loan is used only on
/// z = Z/2^s with max(‖z‖₁, ‖z‖∞) ≤ 1/8 (where both factors are O(1): W to a few ulps of ‖W‖), and
/// the doubling formulas, exact for a constant system,
///   E(2δ) = E(δ)²,  W(2δ) = W(δ) + E(δ)ᵀ W(δ) E(δ),
/// take it to 1 in s steps: W stays a sum of positive semidefinite terms when P is (no cancellation).
/// The small exponential is the [5/5] Padé approximant r = q(X)⁻¹p(X) (backward error below the
/// unit roundoff for ‖X‖₁ ≤ 0.2539, Higham 2005; here ‖X‖₁ ≤ max(‖z‖∞, ‖p‖₁ + ‖z‖₁) ≤ ¼ with P
/// scaled to ‖p‖₁ = 1/8) on the block structure, never forming the 2c×2c matrix: every power X^k is block
/// upper triangular with corners (±(z^k)ᵀ, U_k, z^k) — the even powers' U_k antisymmetric —, so
/// p(X) = V + U, q(X) = V − U need eight c×c products, and q F = p is solved for the two corners
/// used, F₂₂ = R_q⁻¹R_p and F₁₂ = (R_pᵀ)⁻¹(U_p − U_q F₂₂) (q's top-left corner is R_pᵀ, as
/// q(−zᵀ) = p(z)ᵀ). A workspace: its buffers are kept from call to call (the symmetrizations work
/// in place).
class BlockExponential {
 public:
  void operator()(const Eigen::MatrixXd& Z, const Eigen::MatrixXd& P, Eigen::Index nu, Eigen::MatrixXd& E,
                  Eigen::MatrixXd& W) {
    const Eigen::Index c = Z.rows();
    const double zNorm = std::max(Z.cwiseAbs().colwise().sum().maxCoeff(), Z.cwiseAbs().rowwise().sum().maxCoeff());
    int s = 0;
    if (zNorm > 0.125) {
      int e = 0;
      std::frexp(zNorm / 0.125, &e);  // zNorm/0.125 < 2^e
      s = e;
    }
    const double scale = std::ldexp(1.0, -s);
    // P enters the corner linearly: scaled to ‖p‖₁ = 1/8 like z, so that its size (unrelated to
    // Z's) does not raise the degree or the doublings; W is scaled back below.
    const double pScale =
        std::max(8.0 * scale * P.cwiseAbs().colwise().sum().maxCoeff(), std::numeric_limits<double>::min());
    z_ = scale * Z;
    p_ = (scale / pScale) * P;
    constexpr double b0 = 30240.0, b1 = 15120.0, b2 = 3360.0, b3 = 420.0, b4 = 30.0, b5 = 1.0;
    // The c×c products through matmul (dense_kernels.hpp): C = α X Y (+ C when accumulating).
    const auto mm = [c](Eigen::MatrixXd& C, const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, double alpha,
                        bool accumulate) {
      C.resize(c, c);
      detail::matmul(c, c, c, alpha, X.data(), c, Y.data(), c, false, C.data(), c, false, accumulate);
    };
    // X²: (z²)ᵀ, U₂ = p z − zᵀp, z²;  X⁴: U₄ = U₂z² + (z²)ᵀU₂ = U₂z² − (U₂z²)ᵀ.
    mm(r2_, z_, z_, 1.0, false);
    mm(t_, p_, z_, 1.0, false);
    u2_ = t_ - t_.transpose();
    mm(r4_, r2_, r2_, 1.0, false);
    mm(t_, u2_, r2_, 1.0, false);
    u4_ = t_ - t_.transpose();
    // Y = b5X⁴ + b3X² + b1I; the odd part U = X Y: corners (−R_Uᵀ, −zᵀU_Y + pR_Y, zR_Y).
    rY_ = b5 * r4_ + b3 * r2_;
    rY_.diagonal().array() += b1;
    uY_ = b5 * u4_ + b3 * u2_;
    mm(rU_, z_, rY_, 1.0, false);
    mm(uU_, p_, rY_, 1.0, false);
    eT_ = z_.transpose();
    mm(uU_, eT_, uY_, -1.0, true);
    // The even part V = b4X⁴ + b2X² + b0I; p = V + U, q = V − U.
    rp_ = b4 * r4_ + b2 * r2_;
    rp_.diagonal().array() += b0;
    rq_ = rp_ - rU_;
    rp_ += rU_;
    up_ = b4 * u4_ + b2 * u2_;
    uq_ = up_ - uU_;
    up_ += uU_;
    luq_.factor(rq_);
    E = rp_;
    luq_.solve(E);
    // The held input's rows are exactly [0 I] (u̇ = 0); the approximant returns them to rounding.
    E.bottomRows(nu).setZero();
    E.bottomRightCorner(nu, nu).setIdentity();
    mm(up_, uq_, E, -1.0, true);
    lup_.factor(rp_, true);  // p(X)'s corner: rp_ᵀ
    t_ = up_;
    lup_.solve(t_);  // F₁₂ = e^{−zᵀ}·W(z)/pScale
    eT_ = E.transpose();
    mm(W, eT_, t_, pScale, false);
    symmetrize(W);
    // The doublings on E = [[Φ, Γ], [0, I]]: W ← W + EᵀWE, E ← E² = [[Φ², ΦΓ + Γ], [0, I]].
    const Eigen::Index nx = c - nu;
    // The products through matmul (dense_kernels.hpp; column-major, leading dimension c; the
    // transposed factors copied): at these sizes Eigen's general product spends ~2× the
    // instructions on packing. t = W E, W += Eᵀ t (only E's top rows [Φ Γ] are not [0 I]).
    const auto Gamma = E.topRightCorner(nx, nu);
    for (int i = 0; i < s; ++i) {
      detail::matmul(c, nx, nx, 1.0, W.data(), c, E.data(), c, false, t_.data(), c, false);
      t_.rightCols(nu) = W.rightCols(nu);
      detail::matmul(c, nu, nx, 1.0, W.data(), c, E.data() + nx * c, c, false, t_.data() + nx * c, c, false, true);
      eT_ = E.topRows(nx).transpose();  // [Φ Γ]ᵀ, c×nx
      detail::matmul(c, c, nx, 1.0, eT_.data(), c, t_.data(), c, false, W.data(), c, false, true);
      W.bottomRows(nu) += t_.bottomRows(nu);
      symmetrize(W);
      detail::matmul(nx, c, nx, 1.0, E.data(), c, E.data(), c, false, r2_.data(), c, false);
      r2_.topRightCorner(nx, nu) += Gamma;
      E.topRows(nx) = r2_.topRows(nx);
    }
  }

 private:
  Eigen::MatrixXd z_, p_, r2_, u2_, r4_, u4_, rY_, uY_, rU_, uU_, rp_, rq_, up_, uq_, t_, eT_;
  detail::SmallLu luq_, lup_;
};

}  // namespace

void discretizeConstantInterval(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
                                const Eigen::MatrixXd& R, double h, SampledInterval& out) {
  const Eigen::Index nx = A.rows(), nu = B.cols(), c = nx + nu;
  if (A.cols() != nx || B.rows() != nx || Q.rows() != nx || Q.cols() != nx || R.rows() != nu || R.cols() != nu ||
      nx == 0 || nu == 0) {
    std::ostringstream m;
    m << "discretizeConstantInterval: need A nx×nx, B nx×m, Q nx×nx, R m×m with nx, m > 0; got A " << A.rows()
      << "x" << A.cols() << ", B " << B.rows() << "x" << B.cols() << ", Q " << Q.rows() << "x" << Q.cols()
      << ", R " << R.rows() << "x" << R.cols();
    throw std::invalid_argument(m.str());
  }
  if (!(h > 0.0) || !std::isfinite(h)) {
    throw std::invalid_argument("discretizeConstantInterval: the length h = " + std::to_string(h) +
                                " must be finite and > 0");
  }
  if (!A.allFinite() || !B.allFinite() || !Q.allFinite() || !R.allFinite()) {
    throw std::invalid_argument("discretizeConstantInterval: A, B, Q or R has a non-finite entry");
  }
  // Z = Mh with M = [[A, B], [0, 0]] (the held input is a state with u̇ = 0), P = Q̃h.
  Eigen::MatrixXd Z = Eigen::MatrixXd::Zero(c, c), P = Eigen::MatrixXd::Zero(c, c), E, W;
  BlockExponential blockExponential;
  Z.topLeftCorner(nx, nx) = h * A;
  Z.topRightCorner(nx, nu) = h * B;
  P.topLeftCorner(nx, nx) = (0.5 * h) * (Q + Q.transpose());
  P.bottomRightCorner(nu, nu) = (0.5 * h) * (R + R.transpose());
  blockExponential(Z, P, nu, E, W);
  out.Phi = E.topLeftCorner(nx, nx);
  out.Gamma = E.topRightCorner(nx, nu);
  out.Q = W.topLeftCorner(nx, nx);
  out.N = W.topRightCorner(nx, nu);
  out.R = W.bottomRightCorner(nu, nu);
}

namespace {

class ChebyshevLinearization;

/// The variational equation Y = [Φ Γ] (nx × (nx+m), column-major) and the cost quadrature
/// W = ∫ [Φ Γ]ᵀ Q [Φ Γ] + blkdiag(0, R) ((nx+m)² entries), for OdeDriver.
class Discretizer final : public detail::LinearOdeSystem {
 public:
  int nx, nu, cols;
  const LinearizationCallback& lin;
  const LqrWeights& w;
  Eigen::MatrixXd A, B, Q, R, QY, LUmat;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu;
  double cachedT = std::numeric_limits<double>::quiet_NaN();
  bool cacheValid = false;
  double luGamma = std::numeric_limits<double>::quiet_NaN();
  double precT = std::numeric_limits<double>::quiet_NaN();
  Eigen::MatrixXd Aprec;
  long linearizations = 0;
  bool failed = false;
  double failTime = 0.0;
  std::string failMessage;

  Discretizer(int nx_, int nu_, const LinearizationCallback& l, const LqrWeights& w_)
      : nx(nx_), nu(nu_), cols(nx_ + nu_), lin(l), w(w_), A(nx_, nx_), B(nx_, nu_), Q(nx_, nx_),
        R(nu_, nu_), QY(nx_, nx_ + nu_), LUmat(nx_, nx_), lu(nx_), Aprec(nx_, nx_) {
    if (!w.Qfun) Q = w.Q;
    if (!w.Rfun) R = w.R;
    // A constant diagonal Q (the usual weights): Q Y is a row scaling (RadauIntegrator::stageCost).
    qDiagonal = !w.Qfun && Q.isDiagonal(0.0);
    if (qDiagonal) qd = Q.diagonal();
  }

  bool qDiagonal = false;  ///< Q constant and diagonal (exactly): qd holds it
  Eigen::VectorXd qd;

  void fail(double t, const std::string& m) {
    if (!failed) {
      failed = true;
      failTime = t;
      failMessage = m;
    }
  }

  /// The exact A(t), B(t) from the callback into (Ax, Bx): sizes and finiteness checked, a failure
  /// recorded (fail) with the time. Counts the linearizations.
  bool linearizeExact(double t, Eigen::MatrixXd& Ax, Eigen::MatrixXd& Bx) {
    // A user's callback may throw: caught here, at the integrator's C boundary (the library's
    // own callbacks return their failure as the status).
    try {
      const ReferenceStatus st = lin(t, Ax, Bx);
      ++linearizations;
      if (!st.ok()) {
        fail(t, st.message);
        return false;
      }
      if (Ax.rows() != nx || Ax.cols() != nx || Bx.rows() != nx || Bx.cols() != nu) {
        std::ostringstream m;
        m << "linearization callback returned A " << Ax.rows() << "x" << Ax.cols() << ", B " << Bx.rows()
          << "x" << Bx.cols() << " at t = " << t << " (expected " << nx << "x" << nx << ", " << nx
          << "x" << nu << ")";
        fail(t, m.str());
        return false;
      }
    } catch (const std::exception& e) {
      fail(t, std::string("callback threw at t = ") + std::to_string(t) + ": " + e.what());
      return false;
    }
    if (!finite(Ax) || !finite(Bx)) {
      fail(t, "A or B has a non-finite entry at t = " + std::to_string(t));
      return false;
    }
    return true;
  }

  /// A, B (and Q, R if callbacks) at t, cached on t: A, B from the interpolant where the
  /// discretization made one (ChebyshevLinearization) and `interpolated` allows it, else exact.
  bool evaluate(double t, bool interpolated = true);
  bool cachedCheb = false;  ///< the cached A, B came from the interpolant

  std::unique_ptr<ChebyshevLinearization> cheb;  ///< A(t), B(t) between breakpoints (kRadau)

  // Ẏ = A Y + [0 B]: a linear ODE (detail::LinearOdeSystem), J V = A V (one A per column).
  bool prepareAt(double t) override { return evaluate(t); }
  void applyJacobian(detail::ConstVectorMap v, detail::VectorMap Jv) override {
    Eigen::Map<Eigen::MatrixXd>(Jv.data(), nx, cols).noalias() =
        A * Eigen::Map<const Eigen::MatrixXd>(v.data(), nx, cols);
  }
  void addForcing(detail::VectorMap ydot) override {
    Eigen::Map<Eigen::MatrixXd>(ydot.data(), nx, cols).rightCols(nu) += B;
  }

  // Ẇ = Yᵀ Q Y + blkdiag(0, R).
  int quadrature(double t, detail::ConstVectorMap y, detail::VectorMap qdot) override {
    if (!evaluate(t)) return -1;
    Eigen::Map<const Eigen::MatrixXd> Y(y.data(), nx, cols);
    Eigen::Map<Eigen::MatrixXd> Wd(qdot.data(), cols, cols);
    QY.noalias() = Q * Y;
    Wd.noalias() = Y.transpose() * QY;
    Wd.bottomRightCorner(nu, nu) += R;
    return 0;
  }

  // Exact preconditioner: the Newton matrix is blkdiag(I − γA), solved column by column with one
  // LU of I − γA (refactored when γ or the set-up time changes).
  bool hasPreconditioner() const override { return true; }
  int preconditionerSetup(double t, detail::ConstVectorMap, detail::ConstVectorMap, bool jacOk,
                          bool* jacUpdated, double gamma) override {
    if (!jacOk || !(t == precT)) {
      if (!evaluate(t)) return -1;
      Aprec = A;
      precT = t;
      *jacUpdated = true;
    } else {
      *jacUpdated = false;
    }
    factor(gamma);
    return 0;
  }
  void factor(double gamma) {
    LUmat = -gamma * Aprec;
    LUmat.diagonal().array() += 1.0;
    lu.compute(LUmat);
    luGamma = gamma;
  }
  int preconditionerSolve(double, detail::ConstVectorMap, detail::ConstVectorMap,
                          detail::ConstVectorMap r, detail::VectorMap z, double gamma) override {
    if (gamma != luGamma) factor(gamma);
    Eigen::Map<const Eigen::MatrixXd> Rm(r.data(), nx, cols);
    Eigen::Map<Eigen::MatrixXd> Z(z.data(), nx, cols);
    Z = lu.solve(Rm);
    return Z.allFinite() ? 0 : 1;
  }
};

/// A(t), B(t) between consecutive stops (the breakpoints: the reference's knots, where A may have
/// a kink) by barycentric interpolation of exact linearizations at Chebyshev–Lobatto nodes, for
/// a caller that says they are analytic there (SampledStructure::smoothBetweenBreakpoints: a
/// reference interpolated by polynomials between its knots, linearized exactly). Why: Radau takes
/// three linearizations per step, ~9 steps per 10 ms interval on the stiff chain (~28 % of the
/// integration), while A(t) along a swing is reproduced to rounding (~2e-14 of max |A|) by 9
/// nodes per 20 ms knot span. The check, per piece: the Chebyshev coefficients' tail
/// |c_{n−2}| + |c_{n−1}| of every entry (the interpolation error's estimate) against kTol times
/// the entries' scale, in the coordinates that balance A at the piece's middle (Osborne: D A D⁻¹
/// with rows and columns of equal norm, D in powers of 2) — so the verdict does not depend on the
/// states' units: A's entries against the largest balanced |A_ij|, B's columns each against its
/// own largest balanced entry (nor on the inputs' units); then one verification against the exact
/// linearization at a point that is not a node. 9 nodes, else 17 (the 9 are among them), else the
/// piece is halved (to kMaxDepth), else it is evaluated exactly at every t (a fallback, counted).
/// A piece holds its values (nx² + nx·m) × n, a query costs one product with n columns.
class ChebyshevLinearization {
 public:
  static constexpr int kMaxNodes = 17, kMaxDepth = 3, kCache = 4;
  static constexpr double kTol = 1e-12;

  ChebyshevLinearization(int nx, int nu, std::vector<double> stops);

  /// A, B at t (the interpolant of the piece holding t, built on first use, or the exact ones);
  /// false when a callback failed (s.failed, with its message and time).
  bool at(double t, Discretizer& s, Eigen::MatrixXd& A, Eigen::MatrixXd& B);

  long pieces = 0;     ///< pieces interpolated (built)
  long fallbacks = 0;  ///< pieces whose check failed at the deepest split: evaluated exactly

 private:
  /// One piece [lo, hi]: its n nodes, weights and values (direct: none, A and B exact at every t).
  struct Piece {
    double lo = std::numeric_limits<double>::quiet_NaN(), hi = lo;
    int n = 0;
    bool direct = false;
    double x[kMaxNodes] = {}, w[kMaxNodes] = {};
    Eigen::MatrixXd Pv;                 ///< the varying entries' values (first varying.size() rows)
    Eigen::VectorXd base;               ///< every entry at the first node (the constant ones' value)
    std::vector<Eigen::Index> varying;  ///< the entries that vary over the nodes
  };
  /// Builds the piece [lo, hi] into p; false when its check fails (or a callback failed: s.failed).
  bool build(double lo, double hi, Discretizer& s, Piece& p);
  /// The n-node candidate (in P_) passes the tail check.
  bool tailsPass(int n);
  /// The scaled size of `err` (an e-vector like a column of P_) against the candidate's scales:
  /// max over entries of |err| / (kTol · scale); ≤ 1 passes.
  double scaledError(const Eigen::VectorXd& err) const;
  /// v_ = the piece's interpolant at t (A's entries, then B's).
  void interpolate(const Piece& p, double t);
  void unpack(Eigen::MatrixXd& A, Eigen::MatrixXd& B) const;

  int nx_, nu_;
  Eigen::Index e_;
  std::vector<double> stops_;
  double spanLo_ = std::numeric_limits<double>::quiet_NaN();
  std::vector<std::pair<double, double>> failed_;  ///< pieces of the current span whose check failed
  Piece cache_[kCache];  ///< the pieces last used (a step may straddle two; rejections step back)
  int current_ = 0, next_ = 0;
  // Scratch of build(): the 17-node grid's values, the candidate's columns, the balancing D of A
  // at the middle node and the scales.
  Eigen::MatrixXd V_, P_;
  Eigen::VectorXd d_, scaleB_;
  double scaleA_ = 0.0;
  Eigen::MatrixXd Ax_, Bx_;
  Eigen::VectorXd tail_, v_, cb_, exact_, pv_;
};

bool Discretizer::evaluate(double t, bool interpolated) {
  const bool useCheb = interpolated && cheb;
  if (cacheValid && t == cachedT && cachedCheb == useCheb) return true;
  cacheValid = false;
  if (!(useCheb ? cheb->at(t, *this, A, B) : linearizeExact(t, A, B))) return false;
  cachedCheb = useCheb;
  try {
    if (w.Qfun) w.Qfun(t, Q);
    if (w.Rfun) w.Rfun(t, R);
  } catch (const std::exception& e) {
    fail(t, std::string("callback threw at t = ") + std::to_string(t) + ": " + e.what());
    return false;
  }
  if (Q.rows() != nx || Q.cols() != nx || R.rows() != nu || R.cols() != nu) {
    fail(t, "Q(t)/R(t) callback returned a wrong size at t = " + std::to_string(t));
    return false;
  }
  if (!finite(Q) || !finite(R)) {
    fail(t, "A, B, Q or R has a non-finite entry at t = " + std::to_string(t));
    return false;
  }
  cachedT = t;
  cacheValid = true;
  return true;
}

ChebyshevLinearization::ChebyshevLinearization(int nx, int nu, std::vector<double> stops)
    : nx_(nx), nu_(nu), e_(static_cast<Eigen::Index>(nx) * (nx + nu)), stops_(std::move(stops)),
      V_(e_, kMaxNodes), P_(e_, kMaxNodes), d_(nx), scaleB_(nu), Ax_(nx, nx), Bx_(nx, nu), tail_(e_), v_(e_),
      cb_(kMaxNodes), exact_(e_), pv_(e_) {
  for (Piece& p : cache_) {
    p.Pv.resize(e_, kMaxNodes);
    p.base.resize(e_);
    p.varying.reserve(static_cast<std::size_t>(e_));
  }
}

bool ChebyshevLinearization::at(double t, Discretizer& s, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
  if (!(t >= stops_.front() && t <= stops_.back())) return s.linearizeExact(t, A, B);
  const Piece* piece = nullptr;
  for (int i = 0; i < kCache && !piece; ++i) {
    const int j = (current_ + i) % kCache;
    if (t >= cache_[j].lo && t <= cache_[j].hi) {
      piece = &cache_[j];
      current_ = j;
    }
  }
  if (!piece) {
    // The span stops_[i] ≤ t ≤ stops_[i+1], then its pieces down to the one that holds t.
    const auto it = std::upper_bound(stops_.begin(), stops_.end(), t);
    std::size_t i = static_cast<std::size_t>(it - stops_.begin());
    i = i == 0 ? 0 : std::min(i - 1, stops_.size() - 2);
    double lo = stops_[i], hi = stops_[i + 1];
    if (!(lo == spanLo_)) {
      failed_.clear();
      spanLo_ = lo;
    }
    Piece& slot = cache_[next_];
    current_ = next_;
    next_ = (next_ + 1) % kCache;
    for (int depth = 0;; ++depth) {
      const bool knownBad = std::find(failed_.begin(), failed_.end(), std::make_pair(lo, hi)) != failed_.end();
      if (!knownBad) {
        if (build(lo, hi, s, slot)) {
          ++pieces;
          break;
        }
        if (s.failed) return false;
        failed_.emplace_back(lo, hi);
      }
      if (depth == kMaxDepth) {
        slot.lo = lo;
        slot.hi = hi;
        slot.direct = true;
        if (!knownBad) ++fallbacks;
        break;
      }
      const double mid = 0.5 * (lo + hi);
      (t <= mid ? hi : lo) = mid;
    }
    piece = &slot;
  }
  if (piece->direct) return s.linearizeExact(t, A, B);
  interpolate(*piece, t);
  unpack(A, B);
  return true;
}

bool ChebyshevLinearization::build(double lo, double hi, Discretizer& s, Piece& p) {
  p.lo = p.hi = std::numeric_limits<double>::quiet_NaN();  // no piece until this one passes
  p.direct = false;
  const double mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
  const int last = kMaxNodes - 1;
  double grid[kMaxNodes];
  for (int k = 0; k < kMaxNodes; ++k) grid[k] = mid + half * std::cos(std::numbers::pi * k / last);
  grid[0] = hi;
  grid[last] = lo;
  grid[last / 2] = mid;
  auto node = [&](int k) {
    if (!s.linearizeExact(grid[k], Ax_, Bx_)) return false;
    V_.col(k).head(static_cast<Eigen::Index>(nx_) * nx_) = Eigen::Map<const Eigen::VectorXd>(Ax_.data(), Ax_.size());
    V_.col(k).tail(static_cast<Eigen::Index>(nx_) * nu_) = Eigen::Map<const Eigen::VectorXd>(Bx_.data(), Bx_.size());
    return true;
  };
  // The balancing of A at the middle node (Osborne's iteration on the off-diagonal 1-norms).
  if (!node(last / 2)) return false;
  d_.setOnes();
  for (int sweep = 0; sweep < 30; ++sweep) {
    bool moved = false;
    for (int i = 0; i < nx_; ++i) {
      double c = 0.0, r = 0.0;
      for (int j = 0; j < nx_; ++j) {
        if (j == i) continue;
        c += std::abs(Ax_(j, i)) * d_(j) / d_(i);
        r += std::abs(Ax_(i, j)) * d_(i) / d_(j);
      }
      if (!(c > 0.0) || !(r > 0.0)) continue;
      int ex = 0;
      std::frexp(std::sqrt(c / r), &ex);  // f = 2^(ex−1) ≈ √(c/r): row i × f, column i ÷ f
      const double f = std::ldexp(1.0, ex - 1);
      if (c / f + r * f < 0.95 * (c + r)) {
        d_(i) *= f;
        moved = true;
      }
    }
    if (!moved) break;
  }
  for (int n : {9, kMaxNodes}) {
    const int stride = last / (n - 1);
    for (int k = 0; k < n; ++k) {
      const int g = k * stride;
      if (n == 9 || k % 2 == 1) {  // the 17-node grid's odd nodes are new
        if (g != last / 2 && !node(g)) return false;
      }
      P_.col(k) = V_.col(g);
      p.x[k] = grid[g];
      p.w[k] = (k % 2 == 0 ? 1.0 : -1.0) * (k == 0 || k == n - 1 ? 0.5 : 1.0);
    }
    p.n = n;
    // The scales: the largest balanced |A_ij| and each column's largest balanced |B_ij| over the nodes.
    scaleA_ = 0.0;
    scaleB_.setZero();
    for (int k = 0; k < n; ++k) {
      for (int j = 0; j < nx_; ++j) {
        for (int i = 0; i < nx_; ++i) scaleA_ = std::max(scaleA_, std::abs(P_(i + j * nx_, k)) * d_(i) / d_(j));
      }
      for (int j = 0; j < nu_; ++j) {
        for (int i = 0; i < nx_; ++i) {
          scaleB_(j) = std::max(scaleB_(j), std::abs(P_(static_cast<Eigen::Index>(nx_) * nx_ + i + j * nx_, k)) * d_(i));
        }
      }
    }
    if (!tailsPass(n)) continue;
    // The entries that vary over the nodes; the others keep the nodes' common value exactly (A's
    // [0 I] rows, B's zeros: the structure the integrator detects, mechanicalPair, survives).
    p.varying.clear();
    for (Eigen::Index r = 0; r < e_; ++r) {
      for (int k = 1; k < n; ++k) {
        if (P_(r, k) != P_(r, 0)) {
          p.varying.push_back(r);
          break;
        }
      }
    }
    p.base = P_.col(0);
    for (int k = 0; k < n; ++k) {
      for (std::size_t r = 0; r < p.varying.size(); ++r) p.Pv(static_cast<Eigen::Index>(r), k) = P_(p.varying[r], k);
    }
    // One verification where no node is (a fraction of the piece between the 17-node grid's).
    const double tv = lo + 0.2718281828459045 * (hi - lo);
    if (!s.linearizeExact(tv, Ax_, Bx_)) return false;
    exact_.head(static_cast<Eigen::Index>(nx_) * nx_) = Eigen::Map<const Eigen::VectorXd>(Ax_.data(), Ax_.size());
    exact_.tail(static_cast<Eigen::Index>(nx_) * nu_) = Eigen::Map<const Eigen::VectorXd>(Bx_.data(), Bx_.size());
    interpolate(p, tv);
    tail_ = v_ - exact_;
    if (scaledError(tail_) <= 10.0) {
      p.lo = lo;
      p.hi = hi;
      return true;
    }
  }
  return false;
}

bool ChebyshevLinearization::tailsPass(int n) {
  // c_j = (2/(n−1)) Σ'' f_k cos(πjk/(n−1)) (Σ'': the end terms halved; c_{n−1} halved again).
  cb_.setZero(kMaxNodes);
  tail_.setZero();
  for (int j : {n - 2, n - 1}) {
    for (int k = 0; k < n; ++k) {
      double c = (2.0 / (n - 1)) * std::cos(std::numbers::pi * j * k / (n - 1));
      if (k == 0 || k == n - 1) c *= 0.5;
      if (j == n - 1) c *= 0.5;
      cb_(k) = c;
    }
    v_.noalias() = P_.leftCols(n) * cb_.head(n);
    tail_ += v_.cwiseAbs();
  }
  return scaledError(tail_) <= 1.0;
}

double ChebyshevLinearization::scaledError(const Eigen::VectorXd& err) const {
  double worst = 0.0;
  const double floorA = kTol * scaleA_;
  for (int j = 0; j < nx_; ++j) {
    for (int i = 0; i < nx_; ++i) {
      const double e = std::abs(err(i + j * nx_)) * d_(i) / d_(j);
      if (e > 0.0) worst = std::max(worst, floorA > 0.0 ? e / floorA : std::numeric_limits<double>::infinity());
    }
  }
  for (int j = 0; j < nu_; ++j) {
    const double floorB = kTol * scaleB_(j);
    for (int i = 0; i < nx_; ++i) {
      const double e = std::abs(err(static_cast<Eigen::Index>(nx_) * nx_ + i + j * nx_)) * d_(i);
      if (e > 0.0) worst = std::max(worst, floorB > 0.0 ? e / floorB : std::numeric_limits<double>::infinity());
    }
  }
  return std::isfinite(worst) ? worst : std::numeric_limits<double>::infinity();
}

void ChebyshevLinearization::interpolate(const Piece& p, double t) {
  v_ = p.base;
  const Eigen::Index nv = static_cast<Eigen::Index>(p.varying.size());
  int at = -1;
  double sum = 0.0;
  for (int k = 0; k < p.n; ++k) {
    if (t == p.x[k]) {
      at = k;
      break;
    }
    cb_(k) = p.w[k] / (t - p.x[k]);
    sum += cb_(k);
  }
  if (nv == 0) return;
  if (at >= 0) {
    for (Eigen::Index r = 0; r < nv; ++r) v_(p.varying[r]) = p.Pv(r, at);
    return;
  }
  // v = P c / Σc (the barycentric formula) on the entries that vary: one product through matmul
  // (dense_kernels.hpp).
  detail::matmul(nv, 1, p.n, 1.0 / sum, p.Pv.data(), e_, cb_.data(), p.n, false, pv_.data(), nv, false);
  for (Eigen::Index r = 0; r < nv; ++r) v_(p.varying[r]) = pv_(r);
}

void ChebyshevLinearization::unpack(Eigen::MatrixXd& A, Eigen::MatrixXd& B) const {
  A.resize(nx_, nx_);
  B.resize(nx_, nu_);
  A = Eigen::Map<const Eigen::MatrixXd>(v_.data(), nx_, nx_);
  B = Eigen::Map<const Eigen::MatrixXd>(v_.data() + static_cast<Eigen::Index>(nx_) * nx_, nx_, nu_);
}

/// The adaptive step control both integrators share: steps from a to b that end on every
/// breakpoint inside (a knot: A(t) may have a kink there) and on b, at most maxSteps of them, none
/// below rounding. tryStep(t, d, factor) attempts a step of d from t and returns kAccepted (it
/// kept the step), kRejected (error test failed) or kFailed (failMessage set), with `factor` the
/// next step's scale. `next` carries the step size across intervals; a step cut short by a stop
/// says nothing about the next one's size, so it keeps `next` unless it shrinks.
enum class StepOutcome { kAccepted, kRejected, kFailed };
struct StepControl {
  long maxSteps = 0;
  const char* method = "";
  double next = 0.0;
  long steps = 0, rejected = 0;
  std::string failMessage;
  double failTime = 0.0;

  template <class TryStep>
  bool run(double a, double b, const std::vector<double>& breakpoints, TryStep&& tryStep) {
    auto nextBreak = std::upper_bound(breakpoints.begin(), breakpoints.end(), a);
    double t = a;
    long taken = 0;
    if (!(next > 0.0)) next = b - a;
    while (t < b) {
      // A breakpoint within rounding of t or b (a knot and a sample time that differ in the last
      // bits) is that point: no sliver step.
      const double round = 8.0 * std::numeric_limits<double>::epsilon() * std::max({std::abs(t), std::abs(b), b - a});
      while (nextBreak != breakpoints.end() && *nextBreak <= t + round) ++nextBreak;
      const double stop = (nextBreak != breakpoints.end() && *nextBreak < b - round) ? *nextBreak : b;
      double d = std::min(next, stop - t);
      if (t + 1.1 * d >= stop) d = stop - t;  // no sliver before the stop
      for (;;) {
        if (++taken > maxSteps) {
          failTime = t;
          failMessage = "more than maxSteps = " + std::to_string(maxSteps) + " " + method + " steps in the interval";
          return false;
        }
        if (!(d > 8.0 * std::numeric_limits<double>::epsilon() * std::max(std::abs(t), b - a))) {
          failTime = t;
          failMessage = std::string("the ") + method + " step size fell to " + std::to_string(d) + " s (A(t) not resolved)";
          return false;
        }
        double factor = 1.0;
        const StepOutcome outcome = tryStep(t, d, factor);
        if (outcome == StepOutcome::kFailed) return false;
        if (outcome == StepOutcome::kAccepted) {
          ++steps;
          const bool atStop = (t + d == stop) || d == stop - t;
          t = atStop ? stop : t + d;
          if (!atStop || factor < 1.0) next = d * factor;
          break;
        }
        ++rejected;
        d *= factor;
      }
    }
    return true;
  }
};

/// The sixth-order Magnus exponential of the Van Loan system of an interval (sampled_lqr.hpp),
/// over the whole interval at once and bisected only where a check asks for it.
/// With M(t) = [[A, B], [0, 0]] and Q̃(t) = blkdiag(Q, R), the block-triangular linear system
///   Ẋ = V(t) X,  V = [[−Mᵀ, Q̃], [0, M]],  X(a) = I
/// has X = [[Φ_M⁻ᵀ, Φ_M⁻ᵀ W], [0, Φ_M]] with Φ_M = [[Φ, Γ], [0, I]] and W the interval's cost
/// blocks. Matrices of this form are closed under sums and commutators, so a Magnus step's
/// generator Ω is again [[−Zᵀ, P], [0, Z]]: its exponential is blockExponential(Z, P) — exact to
/// rounding however stiff Z is (|λ|h ≈ 140 on the 6-link chain at 10 Hz). Ω from three
/// Gauss–Legendre nodes (Blanes, Casas & Ros' sixth-order scheme): with V_i at
/// t + d(½ − √15/10), t + d/2, t + d(½ + √15/10),
///   α1 = d V_2,  α2 = (√15 d/3)(V_3 − V_1),  α3 = (10d/3)(V_3 − 2V_2 + V_1),
///   C1 = [α1, α2],  C2 = −(1/60)[α1, 2α3 + C1],
///   Ω6 = α1 + α3/12 + (1/240)[−20α1 − α3 + C1, α2 + C2]   (local error O(d⁷) for smooth A).
/// For a constant A, B, Q, R the step is exact at any length; its error comes from their change
/// over the step, and for a stiff A the truncated series' error terms (nested commutators with
/// the stiff part) are damped by the fast modes rather than bounded by the series — which no
/// a-priori bound says, so a check decides: each piece's single step (E_f, W_f) against the
/// composition of its two halves (E_h = E₂E₁, W_h = W₁ + E₁ᵀW₂E₁). Where they agree to rtol
/// (stepError: relative, unit-invariant) the halves are kept; elsewhere each half is checked the
/// same way against its own halves (its single step is already computed). A piece starts as all
/// of [a, b] between stops (the breakpoints: the reference's knots, where A(t) may have a kink and
/// a step across would lose the order). An interval where A(t) is smooth on the scale of h thus
/// costs 9 linearizations and 3 exponentials of size 2(nx+m); no step size is carried from one
/// interval to the next and nothing restarts inside one (the fast modes' transient is inside
/// the exponential).
class MagnusIntegrator {
 public:
  MagnusIntegrator(Discretizer& s, double rtol, long maxSteps)
      : s_(s), nx_(s.nx), nu_(s.nu), c_(s.nx + s.nu), rtol_(rtol), maxSteps_(maxSteps) {
  }

  long steps = 0;            ///< accepted steps (two per accepted piece: its halves)
  long bisections = 0;       ///< pieces whose check failed (each then split in two)
  double failTime = 0.0;     ///< where integrate() stopped, when it returned false
  std::string failMessage;   ///< why (when not a callback failure: s.failed)

  /// E = [[Φ, Γ], [0, I]] and W (the cost blocks) over [a, b]. False on a callback failure
  /// (s.failed), a non-finite step, or when the pieces would exceed maxSteps or fall below
  /// rounding (failMessage).
  bool integrate(double a, double b, const std::vector<double>& breakpoints, Eigen::MatrixXd& E, Eigen::MatrixXd& W) {
    E = Eigen::MatrixXd::Identity(c_, c_);
    W = Eigen::MatrixXd::Zero(c_, c_);
    long taken = 0;
    auto nextBreak = std::upper_bound(breakpoints.begin(), breakpoints.end(), a);
    double t = a;
    while (t < b) {
      // A breakpoint within rounding of t or b (a knot and a sample time that differ in the last
      // bits) is that point: no sliver piece.
      const double round = 8.0 * std::numeric_limits<double>::epsilon() * std::max({std::abs(t), std::abs(b), b - a});
      while (nextBreak != breakpoints.end() && *nextBreak <= t + round) ++nextBreak;
      const double stop = (nextBreak != breakpoints.end() && *nextBreak < b - round) ? *nextBreak : b;
      // The piece stack: the last entry is the next piece (left to right), its single step done.
      std::size_t top = 0;
      Piece& first = slot(top++);
      first.t = t;
      first.d = stop - t;
      if (!step(first.t, first.d, first.E, first.W)) return false;
      bool segmentCheck = true;
      while (top > 0) {
        Piece& p = slot(top - 1);
        const double half = 0.5 * p.d;
        if (!(half > 8.0 * std::numeric_limits<double>::epsilon() * std::max(std::abs(p.t), b - a))) {
          failTime = p.t;
          failMessage = "the Magnus piece fell to " + std::to_string(p.d) + " s (A(t) not resolved)";
          return false;
        }
        if ((taken += 2) > maxSteps_) {
          failTime = p.t;
          failMessage = "more than maxSteps = " + std::to_string(maxSteps_) + " Magnus steps in the interval";
          return false;
        }
        // The second half ends exactly on the piece's end (no drift from t + d/2 + d/2).
        if (!step(p.t, half, E1_, W1_) || !step(p.t + half, (p.t + p.d) - (p.t + half), E2_, W2_)) return false;
        Eh_.noalias() = E2_ * E1_;
        tmp_.noalias() = W2_ * E1_;
        Wh_ = W1_;
        Wh_.noalias() += E1_.transpose() * tmp_;
        symmetrize(Wh_);
        if (segmentCheck) {
          // The stretch's cost scale: the smaller of its two first estimates (if they disagree,
          // the smaller is the stricter).
          wScale_ = p.W.diagonal().cwiseMin(Wh_.diagonal()).cwiseMax(0.0);
          segmentCheck = false;
        }
        if (stepError(p.E, p.W) <= 1.0) {
          // Accepted: the halves, composed onto the interval so far.
          tmp_.noalias() = Wh_ * E;
          W.noalias() += E.transpose() * tmp_;
          symmetrize(W);
          tmp_.noalias() = Eh_ * E;
          E.swap(tmp_);
          steps += 2;
          --top;
          continue;
        }
        // Bisect: the right half replaces p, the left half goes on top (next).
        ++bisections;
        const double pt = p.t, pd = p.d;
        p.t = pt + half;
        p.d = (pt + pd) - (pt + half);
        p.E.swap(E2_);
        p.W.swap(W2_);
        Piece& left = slot(top++);
        left.t = pt;
        left.d = half;
        left.E.swap(E1_);
        left.W.swap(W1_);
      }
      t = stop;
    }
    return true;
  }

 private:
  struct Piece {
    double t = 0.0, d = 0.0;
    Eigen::MatrixXd E, W;  // its single step
  };
  /// Stack entry i (grown on first use; the matrices keep their storage afterwards).
  Piece& slot(std::size_t i) {
    while (stack_.size() <= i) stack_.emplace_back();
    return stack_[i];
  }

  /// A generator [[−Zᵀ, P], [0, Z]] (P symmetric) held as its two corners: sums and commutators of
  /// such matrices keep the form, and a commutator costs four c×c products instead of two
  /// 2c×2c ones (sixteen c×c).
  struct Generator {
    Eigen::MatrixXd Z, P;
  };
  /// V(t) = [[−Mᵀ, Q̃], [0, M]]: Z = M = [[A, B], [0, 0]], P = Q̃ = blkdiag(Q, R) (symmetrized).
  bool vanLoanAt(double t, Generator& V) {
    if (!s_.evaluate(t)) return false;
    V.Z.setZero(c_, c_);
    V.Z.topLeftCorner(nx_, nx_) = s_.A;
    V.Z.topRightCorner(nx_, nu_) = s_.B;
    V.P.setZero(c_, c_);
    V.P.topLeftCorner(nx_, nx_) = 0.5 * (s_.Q + s_.Q.transpose());
    V.P.bottomRightCorner(nu_, nu_) = 0.5 * (s_.R + s_.R.transpose());
    return true;
  }
  /// [X, Y] = [[−Zᵀ, G + Gᵀ], [0, Z]] with Z = Z_x Z_y − Z_y Z_x, G = P_x Z_y − P_y Z_x (the
  /// top-right corner of XY − YX is −Z_xᵀP_y + P_xZ_y + Z_yᵀP_x − P_yZ_x).
  void commutator(const Generator& x, const Generator& y, Generator& out) {
    out.Z.noalias() = x.Z * y.Z;
    out.Z.noalias() -= y.Z * x.Z;
    g_.noalias() = x.P * y.Z;
    g_.noalias() -= y.P * x.Z;
    out.P = g_ + g_.transpose();
  }
  /// The single step's (Ef, Wf) difference from the halves' (Eh_, Wh_) in units of rtol: E's
  /// entries relative to max |E_h| (≥ 1: E holds the identity of the held input), W's relative
  /// to √(D_i D_j), D = max(diag W_h, the smaller diagonal of the first single step and halves
  /// over the whole stretch between stops) — the bound on |W_ij| of a positive semidefinite
  /// matrix, so the measure is the same in any units of the states and inputs, and a small piece
  /// is measured against the cost of the stretch it belongs to (floored at √ε·max D for a
  /// weight that vanishes).
  double stepError(const Eigen::MatrixXd& Ef, const Eigen::MatrixXd& Wf) const {
    if (!Eh_.allFinite() || !Wh_.allFinite() || !Ef.allFinite() || !Wf.allFinite()) {
      return std::numeric_limits<double>::infinity();
    }
    const double eScale = Eh_.cwiseAbs().maxCoeff();
    double err = (Eh_ - Ef).cwiseAbs().maxCoeff() / (rtol_ * eScale);
    const Eigen::VectorXd d = Wh_.diagonal().cwiseMax(wScale_).cwiseMax(0.0).cwiseSqrt();
    const double floor = std::sqrt(std::numeric_limits<double>::epsilon()) * d.maxCoeff() + std::numeric_limits<double>::min();
    for (Eigen::Index j = 0; j < c_; ++j) {
      for (Eigen::Index i = 0; i <= j; ++i) {
        const double diff = std::abs(Wh_(i, j) - Wf(i, j));
        if (diff > 0.0) err = std::max(err, diff / (rtol_ * std::max(d(i) * d(j), floor * floor)));
      }
    }
    return err;
  }
  /// One Magnus step from t of length d: E = e^{Z}, W (blockExponential of Ω6's corners).
  bool step(double t, double d, Eigen::MatrixXd& E, Eigen::MatrixXd& W) {
    const double r15 = std::sqrt(15.0);
    const double nodes[3] = {0.5 - r15 / 10.0, 0.5, 0.5 + r15 / 10.0};
    for (int i = 0; i < 3; ++i) {
      if (!vanLoanAt(t + nodes[i] * d, V_[i])) {
        failTime = s_.failTime;
        return false;
      }
    }
    a1_.Z = d * V_[1].Z;
    a1_.P = d * V_[1].P;
    a2_.Z = (r15 * d / 3.0) * (V_[2].Z - V_[0].Z);
    a2_.P = (r15 * d / 3.0) * (V_[2].P - V_[0].P);
    a3_.Z = (10.0 * d / 3.0) * (V_[2].Z - 2.0 * V_[1].Z + V_[0].Z);
    a3_.P = (10.0 * d / 3.0) * (V_[2].P - 2.0 * V_[1].P + V_[0].P);
    commutator(a1_, a2_, c1_);
    x_.Z = 2.0 * a3_.Z + c1_.Z;
    x_.P = 2.0 * a3_.P + c1_.P;
    commutator(a1_, x_, c2_);
    x_.Z = -20.0 * a1_.Z - a3_.Z + c1_.Z;
    x_.P = -20.0 * a1_.P - a3_.P + c1_.P;
    y_.Z = a2_.Z - c2_.Z / 60.0;
    y_.P = a2_.P - c2_.P / 60.0;
    commutator(x_, y_, om6_);
    // Ω6's corners: Z (its input rows exactly zero: every term has them zero) and P (symmetric
    // by construction).
    om6_.Z = om6_.Z / 240.0 + a1_.Z + a3_.Z / 12.0;
    om6_.P = om6_.P / 240.0 + a1_.P + a3_.P / 12.0;
    blockExponential(om6_.Z, om6_.P, nu_, E, W);
    return true;
  }

  Discretizer& s_;
  Eigen::Index nx_, nu_, c_;
  double rtol_;
  long maxSteps_;
  std::vector<Piece> stack_;
  Eigen::VectorXd wScale_;
  Generator V_[3], a1_, a2_, a3_, c1_, c2_, x_, y_, om6_;
  Eigen::MatrixXd g_, E1_, W1_, E2_, W2_, Eh_, Wh_, tmp_;
  BlockExponential blockExponential;
};

/// Whether x = [q; v] has the mechanical structure q̇ = v with the inputs on v̇, exactly:
/// A = [[0, I], [Aq, Av]], B = [0; Bv] (p = nx/2 rows each). The shifted solves then halve
/// (shifted_solve.hpp).
bool mechanicalPair(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B) {
  const Eigen::Index nx = A.rows(), p = nx / 2;
  if (p == 0 || 2 * p != nx) return false;
  for (Eigen::Index j = 0; j < nx; ++j) {
    for (Eigen::Index i = 0; i < p; ++i) {
      if (A(i, j) != (j == i + p ? 1.0 : 0.0)) return false;
    }
  }
  for (Eigen::Index j = 0; j < B.cols(); ++j) {
    for (Eigen::Index i = 0; i < p; ++i) {
      if (B(i, j) != 0.0) return false;
    }
  }
  return true;
}

/// The three-stage Radau IIA collocation (order 5, L-stable, stiffly accurate) of the variational
/// equation Ẏ = A(t)Y + [0 B(t)], Y = [Φ Γ] (nx×c) from [I 0] at the interval's start, and the cost
/// W = ∫ YᵀQY + blkdiag(0, R) by the method's own quadrature on its stages (W is one more
/// component of the same Runge–Kutta system: exact for polynomials of degree 4). The problem is
/// linear, so each step is one linear solve: with A_j = A(t + c_j δ), c = ((4−√6)/10, (4+√6)/10, 1),
/// the stages solve
///   Y_i − δ Σ_j a_ij A_j Y_j = Y_n + δ Σ_j a_ij [0 B_j]     (3nx unknowns per column, one LU),
/// and Y_{n+1} = Y_3 (3 linearizations per step; the start's f_n is the previous step's last node).
/// L-stability is what a stiff A needs (e^{λδ} → 0 is reproduced as R(λδ) → 0; Magnus' series and
/// explicit schemes need |λ|δ ≲ 1 there). Error estimate: Hairer & Wanner's embedded one (RADAU5,
/// Solving ODEs II §IV.8): with the stage increments Z_i = Y_i − Y_n, γ0 the real eigenvalue of
/// the method's matrix a (1/γ0 = 30/(6 + 81^{1/3} − 9^{1/3})) and e = γ0·(−13 − 7√6, −13 + 7√6, −1)/3,
///   err_Y = (I − γ0δA_n)⁻¹ (γ0δ f(t_n, Y_n) + Σ e_i Z_i),
/// the difference to an embedded third-order solution, filtered by (I − γ0δA_n)⁻¹ so that the
/// stiff components (which Radau damps correctly) do not count as error; the cost's row of the
/// same system (J = [[A, 0], [∂g/∂Y, 0]], g = YᵀQY + blkdiag(0, R)) gives
///   err_W = γ0δ g(t_n, Y_n) + Σ e_i Z^W_i + γ0δ (err_Yᵀ Q_n Y_n + Y_nᵀ Q_n err_Y).
/// The estimate is O(δ⁴): the step factor is err^{−1/4}. Where the first estimate of a first or
/// rejected step fails, it is refined once as RADAU5 does (f at Y_n + err_Y, one more nx×nx solve):
/// the unfiltered part is what a stiff transient inflates. One 3nx LU and one nx×nx LU per step
/// (the step-doubling estimate it replaces cost three of the first and 8 linearizations). Steps
/// are carried across intervals (a one-step method restarts for free) and end on the breakpoints.
///
/// The restart transient, split off exactly: Y restarts from [I 0] in every interval, which
/// brings the fast modes of a stiff A back in full (|λ| ~ 1.4e3 on the 6-link chain: steps of
/// ~2e-5 s growing ~13 % per step, ~40 per 10 ms interval). The twin Ẏ_f = A_f Y_f + [0 B_f],
/// frozen at the interval's start (A_f = A(t_k), and Q_f, R_f for its cost), has the same
/// transient and exact blocks E_f = e^{M_f h}, W_f (BlockExponential, once per interval). The
/// same steps integrate both systems; the result is
///   Y = E_f [I 0] + (Y_Radau − Y_f,Radau),  W = W_f + (W_Radau − W_f,Radau),
/// and the step control measures the error of the difference (the embedded estimate of the pair,
/// linear in the stages: err_Y − err_Y,f with their own filters (I − γ0δA_n)⁻¹, (I − γ0δA_f)⁻¹).
/// Near t_k, where the transient lives, A − A_f = O(τ): the two solutions' errors cancel to that
/// order and the difference is smooth, so the first steps may be long; where A(t) does not move,
/// the difference is zero and one step per interval is exact. The twin's step costs no
/// linearization: with its constant A_f the stage system decouples on a = T diag(γ0, μ, μ̄) T⁻¹
/// into one real and one complex nx×nx solve (the real one is the estimate's I − γ0δA_f).
/// A mechanical system (x = [q; v], A = [[0, I], [Aq, Av]], B = [0; Bv] exactly, checked per
/// step) halves every solve: the stage system to 3p×3p (p = nx/2, mechanicalStages), the filters
/// and the twin's real and complex solves to p×p (ShiftedSolve, ComplexShiftedSolve); any other
/// A takes the full ones. The stage cost, the estimate's products and the exponential's doublings
/// run through matmul (dense_kernels.hpp).
/// Where the time goes (callgrind, the 6-link swing at 100 Hz, docs/performance.md 2026-12-05,
/// fourth session): of the integration's ~0.51 G instructions (0.86 G before the interpolated
/// linearization and the small-LU kernels) ~14 % A, B (1 080 exact linearizations for 5 254 node
/// evaluations, ChebyshevLinearization), ~40 % the rest of the step (stage solve, quadrature,
/// estimate), ~28 % the twin, ~13 % the block exponentials; the step size is set by the embedded
/// estimate (mostly its cost row), not by the growth limit. The stage cost's Q Y is a row scaling
/// for a constant diagonal Q.
/// Q Y and g = YᵀQY + blkdiag(0, R) at a step's last stage are the next step's start's: kept.
class RadauIntegrator {
 public:
  RadauIntegrator(Discretizer& s, double rtol, long maxSteps)
      : s_(s), nx_(s.nx), nu_(s.nu), c_(s.nx + s.nu), rtol_(rtol),
        M_(3 * s.nx, 3 * s.nx), rhs_(3 * s.nx, s.nx + s.nu) {
    control.maxSteps = maxSteps;
    control.method = "Radau";
    // The method's constants, written once (radau_tableau.hpp).
    const detail::RadauTableau& tab = detail::RadauTableau::get();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) a_[i][j] = tab.a[i][j];
      nodes_[i] = tab.c[i];
      e_[i] = tab.e[i];
    }
    gamma0_ = tab.gamma0;
    mu_ = tab.mu;
    T_ = tab.T;
    Tinv_ = tab.Tinv;
    stagesF_.resize(3 * nx_, c_);
    stages_.resize(3 * nx_, c_);
    const Eigen::Index p = nx_ / 2;
    MM_.resize(3 * p, 3 * p);
    rhsM_.resize(3 * p, c_);
    vM_.resize(3 * p, c_);  // swapped with rhsM_ by every solve
    cVr_.resize(nx_, c_);
    cVi_.resize(nx_, c_);
    for (auto& x : A_) x.resize(nx_, nx_);
    for (auto& x : B_) x.resize(nx_, nu_);
    for (auto& x : Q_) x.resize(nx_, nx_);
    for (auto& x : R_) x.resize(nu_, nu_);
  }

  StepControl control;  ///< the step sizes, the counts and the failure's message and time

  /// Y = [Φ Γ], W over [a, b] (stops: the breakpoints inside); false as MagnusIntegrator's.
  bool integrate(double a, double b, const std::vector<double>& breakpoints, Eigen::MatrixXd& Y, Eigen::MatrixXd& W) {
    Y = Eigen::MatrixXd::Zero(nx_, c_);
    Y.leftCols(nx_).setIdentity();
    W = Eigen::MatrixXd::Zero(c_, c_);
    // Every interval restarts from [I 0]: its fast modes are back in full, and the step they allow
    // at the start is the previous interval's first step, not the long one carried from its end
    // (which would be rejected twice per interval).
    if (firstStep_ > 0.0) control.next = firstStep_;
    bool first = true;
    // W's error scale: at least half the interval's predicted cost diagonal, not only the partial
    // sum so far, which starts at zero in every interval — the recursion uses the interval's total.
    // The prediction is the smaller of two rates × the length: the previous interval's average
    // W_ii per unit time (only if it ends at a: a neighbour on the same reference) and the cost
    // rate (YᵀQY + blkdiag(0, R))_ii at the step's end — so a cost that drops (a jump in Q(t), a
    // gap) lowers the scale at once.
    if (wRate_.size() != c_ || !(a == prevEnd_)) wRate_ = Eigen::VectorXd::Zero(c_);
    halfLength_ = 0.5 * (b - a);
    wPred_.resize(c_);
    // The twin: the system frozen at the interval's start, its exact blocks by the exponential and
    // its Radau solution on the same steps (class comment).
    if (!start(a)) {
      control.failTime = a;
      return false;
    }
    Af_ = A0_;
    Bf_ = B0_;
    mechF_ = mechanicalPair(Af_, Bf_);
    Qf_ = Q0_;
    Rf_ = R0_;
    Y0_ = Y;
    W0_ = W;
    startCached_ = startCachedF_ = false;  // Y restarted at [I 0]
    ++exponentials;
    zf_.setZero(c_, c_);
    zf_.topLeftCorner(nx_, nx_) = (b - a) * Af_;
    zf_.topRightCorner(nx_, nu_) = (b - a) * Bf_;
    pf_.setZero(c_, c_);
    pf_.topLeftCorner(nx_, nx_) = (0.5 * (b - a)) * (Qf_ + Qf_.transpose());
    pf_.bottomRightCorner(nu_, nu_) = (0.5 * (b - a)) * (Rf_ + Rf_.transpose());
    blockExponential_(zf_, pf_, nu_, Ef_, Wf_);
    bool rejected = false;
    const bool ok = control.run(a, b, breakpoints, [&](double t, double d, double& factor) {
      if (!start(t)) return StepOutcome::kFailed;
      if (!step(t, d, Y, W)) return StepOutcome::kFailed;
      twinStep(d);
      double err = stepError();
      if (err > 1.0 && (first || rejected)) {
        // RADAU5's second estimate: f at Y_n + err_Y instead of Y_n (the filter applied twice),
        // for both systems (f0_, f0f_ are not read again this step).
        rY_ = e_[0] * stages_.topRows(nx_) + e_[1] * stages_.middleRows(nx_, nx_) + e_[2] * stages_.bottomRows(nx_);
        rY_ -= (e_[0] + e_[1] + e_[2]) * Y;
        f0_.noalias() += A0_ * errY_;
        rY_ += (gamma0_ * d) * f0_;
        errY_ = rY_;
        errSolve_.solve(errY_);
        rY_ = e_[0] * stagesF_.topRows(nx_) + e_[1] * stagesF_.middleRows(nx_, nx_) + e_[2] * stagesF_.bottomRows(nx_);
        rY_ -= (e_[0] + e_[1] + e_[2]) * Y0_;
        f0f_.noalias() += Af_ * errYf_;
        rY_ += (gamma0_ * d) * f0f_;
        errYf_ = rY_;
        errSolveF_.solve(errYf_);
        err = stepError();
      }
      factor = std::isfinite(err) ? std::clamp(0.9 * std::pow(std::max(err, 1e-30), -0.25), 0.2, 6.0) : 0.2;
      if (!(err <= 1.0 && finite(Yn_) && finite(Wn_) && finite(YnF_) && finite(WnF_))) {
        rejected = true;
          return StepOutcome::kRejected;
      }
      rejected = false;
      Y.swap(Yn_);
      W.swap(Wn_);
      Y0_.swap(YnF_);
      W0_.swap(WnF_);
      // The last stage's Q Y and g are the next step's start's (both systems).
      QY0_.swap(QYn_);
      g0_.swap(gn_);
      QY0F_.swap(QYnF_);
      g0F_.swap(gnF_);
      startCached_ = startCachedF_ = true;
      // The step's last node is the next step's start: its A, B, Q, R are kept.
      t0_ = t + d;
      A0_.swap(A_[2]);
      B0_.swap(B_[2]);
      Q0_.swap(Q_[2]);
      R0_.swap(R_[2]);
      if (first) firstStep_ = d * factor;  // the size its estimate asks for
      first = false;
      return StepOutcome::kAccepted;
    });
    if (ok) {
      // The exact frozen blocks plus the integrated difference: Y = E_f [I 0] + (Y − Y_f),
      // W = W_f + (W − W_f,Radau).
      Y -= Y0_;
      Y += Ef_.topRows(nx_);
      W -= W0_;
      W += Wf_;
    }
    symmetrize(W);
    if (ok) wRate_ = W.diagonal().cwiseMax(0.0) / (b - a);
    prevEnd_ = ok ? b : std::numeric_limits<double>::quiet_NaN();
    return ok;
  }

  long exponentials = 0;  ///< the frozen systems' block exponentials (one per interval)

 private:
  /// A, B, Q, R at the step's start t (kept from the previous step when it ended at t).
  bool start(double t) {
    if (t == t0_ && A0_.size() > 0) return true;
    if (!s_.evaluate(t)) return false;
    startCached_ = false;  // Q_n Y_n, g_n: of another start
    A0_ = s_.A;
    B0_ = s_.B;
    Q0_ = s_.Q;
    R0_ = s_.R;
    t0_ = t;
    return true;
  }

  /// The embedded estimate (errY_, errW_) relative to rtol: Y's against max |Y_{n+1}|, W's against
  /// √(D_ii D_jj), D_ii = max(W_ii at the step's end, half the interval's predicted W_ii) — the
  /// bound on |W_ij| of a PSD matrix, unit-invariant as stepError of the Magnus integrator.
  double stepError() {
    // The cost's row: the embedded difference of its quadrature, and err_Y through ∂g/∂Y at t_n.
    // The twin's estimate, subtracted: what is estimated is the error of the difference Y − Y_f
    // (the estimate is linear in the stages: that of the pair, its Jacobian blkdiag(A_n, A_f)).
    // eW = err_Yᵀ Q_n Y_n − err_Y,fᵀ Q_f Y_f,n (Q Y at the start: step(), twinStep()).
    transposedProduct(errY_.data(), nx_, QY0_, 1.0, false, false, eW_);
    transposedProduct(errYf_.data(), nx_, QY0F_, -1.0, false, true, eW_);
    errW_ = rW_;
    errW_ -= rWf_;
    errW_ += (gamma0_ * d_) * (eW_ + eW_.transpose());
    errYd_ = errY_ - errYf_;
    const double yScale = std::max(Yn_.cwiseAbs().maxCoeff(), std::numeric_limits<double>::min());
    double err = errYd_.cwiseAbs().maxCoeff() / (rtol_ * yScale);
    // The cost rate at t + d: g at the step's last node (Y_{n+1}ᵀ Q Y_{n+1} + blkdiag(0, R)).
    for (Eigen::Index j = 0; j < c_; ++j) wPred_(j) = halfLength_ * std::min(wRate_(j), gn_(j, j));
    dd_ = Wn_.diagonal().cwiseMax(wPred_).cwiseMax(0.0).cwiseSqrt();
    const double floor = std::sqrt(std::numeric_limits<double>::epsilon()) * dd_.maxCoeff() + std::numeric_limits<double>::min();
    for (Eigen::Index j = 0; j < c_; ++j) {
      for (Eigen::Index i = 0; i <= j; ++i) {
        const double diff = std::abs(errW_(i, j));
        if (diff > 0.0) err = std::max(err, diff / (rtol_ * std::max(dd_(i) * dd_(j), floor * floor)));
      }
    }
    return std::isfinite(err) ? err : std::numeric_limits<double>::infinity();
  }

  /// One collocation step from t of length d (its last node, c₃ = 1, at exactly t + d) from
  /// (Y, W): the result in (Yn_, Wn_), the embedded estimate's parts in errY_ and rW_.
  bool step(double t, double d, const Eigen::MatrixXd& Y, const Eigen::MatrixXd& W) {
    const Eigen::Index n = nx_;
    for (int j = 0; j < 3; ++j) {
      if (!s_.evaluate(j == 2 ? t + d : t + nodes_[j] * d)) return false;
      A_[j] = s_.A;
      B_[j] = s_.B;
      Q_[j] = s_.Q;
      R_[j] = s_.R;
    }
    mech0_ = mechanicalPair(A0_, B0_);
    if (mech0_ && mechanicalPair(A_[0], B_[0]) && mechanicalPair(A_[1], B_[1]) && mechanicalPair(A_[2], B_[2])) {
      mechanicalStages(d, Y);
    } else {
      for (int i = 0; i < 3; ++i) {
        rhs_.middleRows(i * n, n) = Y;
        for (int j = 0; j < 3; ++j) {
          M_.block(i * n, j * n, n, n) = (-d * a_[i][j]) * A_[j];
          if (i == j) M_.block(i * n, j * n, n, n).diagonal().array() += 1.0;
          rhs_.block(i * n, n, n, nu_) += (d * a_[i][j]) * B_[j];
        }
      }
      lu_.factor(M_);
      lu_.solve(rhs_);
      stages_.swap(rhs_);  // rhs_ is rewritten whole at the next step
    }
    // g_i = Y_iᵀ Q_i Y_i + blkdiag(0, R_i) at the stages; W_{n+1} = W_n + d Σ b_i g_i (b = a's last
    // row), and the cost's stage increments Z^W_i = d Σ_j a_ij g_j for the estimate.
    rW_.setZero(c_, c_);
    Wn_ = W;
    for (int j = 0; j < 3; ++j) {
      const auto Yj = stages_.middleRows(j * n, n);
      // The last stage is Y_{n+1}: its Q Y and g are kept (stepError's cost rate; the next
      // step's start when this one is accepted).
      Eigen::MatrixXd& qy = j == 2 ? QYn_ : QY_;
      Eigen::MatrixXd& gj = j == 2 ? gn_ : g_;
      stageCost(Q_[j], R_[j], Yj.data(), 3 * n, qy, gj);
      const double wj = d * (e_[0] * a_[0][j] + e_[1] * a_[1][j] + e_[2] * a_[2][j]);
      rW_ += wj * gj;
      Wn_ += (d * a_[2][j]) * gj;
    }
    // The start's rate: f_n = A_n Y_n + [0 B_n], g_n = Y_nᵀ Q_n Y_n + blkdiag(0, R_n) (Q_n Y_n and
    // g_n: the previous step's last stage's, or computed once for all attempts from Y_n).
    f0_.resize(n, c_);
    detail::matmul(n, c_, n, 1.0, A0_.data(), n, Y.data(), n, false, f0_.data(), n, false);
    f0_.rightCols(nu_) += B0_;
    if (!startCached_) {
      stageCost(Q0_, R0_, Y.data(), n, QY0_, g0_);
      startCached_ = true;
    }
    rW_ += (gamma0_ * d) * g0_;
    // err_Y = (I − γ0 d A_n)⁻¹ (γ0 d f_n + Σ e_i (Y_i − Y_n)).
    rY_ = e_[0] * stages_.topRows(n) + e_[1] * stages_.middleRows(n, n) + e_[2] * stages_.bottomRows(n);
    rY_ -= (e_[0] + e_[1] + e_[2]) * Y;
    rY_ += (gamma0_ * d) * f0_;
    errSolve_.factor(A0_, gamma0_ * d, mech0_);
    errY_ = rY_;
    errSolve_.solve(errY_);
    Yn_ = stages_.bottomRows(n);
    d_ = d;
    return true;
  }

  /// C = α XᵀZ (accumulate: C += α XᵀZ; upperOnly as matmul's) for X nx×c (column stride ldx)
  /// and Z nx×c, through the blocked matmul of dense_kernels.hpp with Xᵀ copied (yt_): at these
  /// sizes Eigen's general product spends ~2× the instructions on its packing.
  void transposedProduct(const double* X, Eigen::Index ldx, const Eigen::MatrixXd& Z, double alpha, bool upperOnly,
                         bool accumulate, Eigen::MatrixXd& C) {
    const Eigen::Index n = nx_, c = c_;
    yt_.resize(c, n);
    for (Eigen::Index j = 0; j < c; ++j) {
      for (Eigen::Index i = 0; i < n; ++i) yt_(j, i) = X[i + j * ldx];
    }
    C.resize(c, c);
    detail::matmul(c, c, n, alpha, yt_.data(), c, Z.data(), n, false, C.data(), c, upperOnly, accumulate);
  }

  /// At a stage Y (nx×c, column stride ld): QY = Q Y and g = Yᵀ Q Y + blkdiag(0, R) (symmetric:
  /// its upper triangle, then mirrored).
  void stageCost(const Eigen::MatrixXd& Q, const Eigen::MatrixXd& R, const double* Y, Eigen::Index ld,
                 Eigen::MatrixXd& qy, Eigen::MatrixXd& g) {
    const Eigen::Index n = nx_, c = c_;
    qy.resize(n, c);
    if (s_.qDiagonal) {  // Q = diag(q) (constant): Q Y scales Y's rows
      for (Eigen::Index j = 0; j < c; ++j) {
        for (Eigen::Index i = 0; i < n; ++i) qy(i, j) = s_.qd(i) * Y[i + j * ld];
      }
    } else {
      detail::matmul(n, c, n, 1.0, Q.data(), n, Y, ld, false, qy.data(), n, false);
    }
    transposedProduct(Y, ld, qy, 1.0, true, false, g);
    for (Eigen::Index j = 0; j < c; ++j) {
      for (Eigen::Index i = 0; i < j; ++i) g(j, i) = g(i, j);
    }
    g.bottomRightCorner(nu_, nu_) += R;
  }

  /// The stage system for mechanical A_j = [[0, I], [Aq_j, Av_j]], B_j = [0; Bv_j] (p = nx/2):
  /// the position rows Yq_i = Yq_n + δ Σ_l a_il Yv_l substituted into the velocity rows leave
  ///   Yv_i − δ Σ_l a_il Av_l Yv_l − δ² Σ_l (Σ_j a_ij a_jl Aq_j) Yv_l
  ///     = Yv_n + δ Σ_j a_ij (Aq_j Yq_n + [0 Bv_j]),
  /// one 3p×3p LU instead of 3nx×3nx (8× fewer flops to factor, 4× to solve); then the Yq_i.
  void mechanicalStages(double d, const Eigen::MatrixXd& Y) {
    const Eigen::Index p = nx_ / 2, n = nx_, c = c_, m3 = 3 * p;
    // A_q Y_q for the three nodes (A_q: rows p.. and columns ..p of A_j; Y_q: Y's first p rows).
    for (int j = 0; j < 3; ++j) {
      aqY_[j].resize(p, c);
      detail::matmul(p, c, p, 1.0, A_[j].data() + p, n, Y.data(), n, false, aqY_[j].data(), p, false);
    }
    // The 3p×3p matrix, column by column of each block (l, col): −δ a_il Av_l − δ² Σ_j a_ij a_jl Aq_j.
    for (int l = 0; l < 3; ++l) {
      for (Eigen::Index col = 0; col < p; ++col) {
        const double* av = A_[l].data() + (p + col) * n + p;
        const double* aq0 = A_[0].data() + col * n + p;
        const double* aq1 = A_[1].data() + col * n + p;
        const double* aq2 = A_[2].data() + col * n + p;
        for (int i = 0; i < 3; ++i) {
          const double cv = -d * a_[i][l];
          const double c0 = -d * d * a_[i][0] * a_[0][l], c1 = -d * d * a_[i][1] * a_[1][l],
                       c2 = -d * d * a_[i][2] * a_[2][l];
          double* dst = MM_.data() + (l * p + col) * m3 + i * p;
          for (Eigen::Index r = 0; r < p; ++r) dst[r] = cv * av[r] + c0 * aq0[r] + c1 * aq1[r] + c2 * aq2[r];
          if (i == l) dst[col] += 1.0;
        }
      }
    }
    // Right-hand side: Yv_n + δ Σ_j a_ij (Aq_j Yq_n + [0 Bv_j]).
    for (int i = 0; i < 3; ++i) {
      const double w0 = d * a_[i][0], w1 = d * a_[i][1], w2 = d * a_[i][2];
      for (Eigen::Index col = 0; col < c; ++col) {
        const double* yv = Y.data() + col * n + p;
        const double* q0 = aqY_[0].data() + col * p;
        const double* q1 = aqY_[1].data() + col * p;
        const double* q2 = aqY_[2].data() + col * p;
        double* dst = rhsM_.data() + col * m3 + i * p;
        for (Eigen::Index r = 0; r < p; ++r) dst[r] = yv[r] + w0 * q0[r] + w1 * q1[r] + w2 * q2[r];
        if (col >= n) {
          const double* b0 = B_[0].data() + (col - n) * n + p;
          const double* b1 = B_[1].data() + (col - n) * n + p;
          const double* b2 = B_[2].data() + (col - n) * n + p;
          for (Eigen::Index r = 0; r < p; ++r) dst[r] += w0 * b0[r] + w1 * b1[r] + w2 * b2[r];
        }
      }
    }
    luM_.factor(MM_);
    luM_.solve(rhsM_);
    vM_.swap(rhsM_);  // the velocity stages (rhsM_ is rewritten whole at the next step)
    // The stages: Yq_i = Yq_n + δ Σ_l a_il Yv_l, Yv_i (rows i·nx … of stages_, column stride 3nx).
    for (int i = 0; i < 3; ++i) {
      const double w0 = d * a_[i][0], w1 = d * a_[i][1], w2 = d * a_[i][2];
      for (Eigen::Index col = 0; col < c; ++col) {
        const double* yq = Y.data() + col * n;
        const double* v = vM_.data() + col * m3;
        double* dst = stages_.data() + col * 3 * n + i * n;
        for (Eigen::Index r = 0; r < p; ++r) dst[r] = yq[r] + w0 * v[r] + w1 * v[p + r] + w2 * v[2 * p + r];
        for (Eigen::Index r = 0; r < p; ++r) dst[p + r] = v[i * p + r];
      }
    }
  }

  /// The same step of the frozen twin Ẏ_f = A_f Y_f + [0 B_f] (from Y0_, W0_ with Q_f, R_f): its
  /// result in (YnF_, WnF_), its estimate's parts in errYf_ and rWf_. A_f is constant, so the
  /// stage matrix is I − δ (a ⊗ A_f) and the forcing's stage sums are δ c_i [0 B_f].
  void twinStep(double d) {
    const Eigen::Index n = nx_;
    // (I − δ a⊗A_f) U = r with a = T Λ T⁻¹: V = (T⁻¹⊗I) U solves (I − δλ_k A_f) V_k = Σ_i T⁻¹_ki r_i,
    // one real nx×nx system (λ = γ0: the estimate's matrix, factored here for both) and one
    // complex (μ; μ̄'s solution is its conjugate), U_i = T_i0 V_0 + 2 Re(T_i1 V_1). The stage
    // right-hand sides are r_i = Y_f + δ c_i [0 B_f], so Σ_i T⁻¹_ki r_i = (Σ_i T⁻¹_ki) Y_f +
    // δ (Σ_i T⁻¹_ki c_i) [0 B_f]: scaled copies, no stacked right-hand side.
    errSolveF_.factor(Af_, gamma0_ * d, mechF_);  // γ0: a's real eigenvalue
    // I − δμ A_f in split storage (shifted_solve.hpp).
    complexSolveF_.factor(Af_, mu_ * d, mechF_);
    std::complex<double> sum[2], sumC[2];
    for (int k = 0; k < 2; ++k) {
      sum[k] = Tinv_(k, 0) + Tinv_(k, 1) + Tinv_(k, 2);
      sumC[k] = d * (Tinv_(k, 0) * nodes_[0] + Tinv_(k, 1) * nodes_[1] + Tinv_(k, 2) * nodes_[2]);
    }
    v0_ = sum[0].real() * Y0_;
    v0_.rightCols(nu_) += sumC[0].real() * Bf_;
    errSolveF_.solve(v0_);
    cVr_ = sum[1].real() * Y0_;
    cVr_.rightCols(nu_) += sumC[1].real() * Bf_;
    cVi_ = sum[1].imag() * Y0_;
    cVi_.rightCols(nu_) += sumC[1].imag() * Bf_;
    complexSolveF_.solve(cVr_, cVi_);
    for (int i = 0; i < 3; ++i) {  // 2 Re(T_i1 V_1)
      stagesF_.middleRows(i * n, n) =
          T_(i, 0).real() * v0_ + (2.0 * T_(i, 1).real()) * cVr_ - (2.0 * T_(i, 1).imag()) * cVi_;
    }
    rWf_.setZero(c_, c_);
    WnF_ = W0_;
    for (int j = 0; j < 3; ++j) {
      const auto Yj = stagesF_.middleRows(j * n, n);
      Eigen::MatrixXd& qy = j == 2 ? QYnF_ : QY_;
      Eigen::MatrixXd& gj = j == 2 ? gnF_ : g_;
      stageCost(Qf_, Rf_, Yj.data(), 3 * n, qy, gj);
      rWf_ += (d * (e_[0] * a_[0][j] + e_[1] * a_[1][j] + e_[2] * a_[2][j])) * gj;
      WnF_ += (d * a_[2][j]) * gj;
    }
    f0f_.resize(n, c_);
    detail::matmul(n, c_, n, 1.0, Af_.data(), n, Y0_.data(), n, false, f0f_.data(), n, false);
    f0f_.rightCols(nu_) += Bf_;
    if (!startCachedF_) {
      stageCost(Qf_, Rf_, Y0_.data(), n, QY0F_, g0F_);
      startCachedF_ = true;
    }
    rWf_ += (gamma0_ * d) * g0F_;
    rY_ = e_[0] * stagesF_.topRows(n) + e_[1] * stagesF_.middleRows(n, n) + e_[2] * stagesF_.bottomRows(n);
    rY_ -= (e_[0] + e_[1] + e_[2]) * Y0_;
    rY_ += (gamma0_ * d) * f0f_;
    errYf_ = rY_;
    errSolveF_.solve(errYf_);  // I − γ0δA_f, factored above
    YnF_ = stagesF_.bottomRows(n);
  }

  Discretizer& s_;
  Eigen::Index nx_, nu_, c_;
  double rtol_;
  double a_[3][3] = {}, nodes_[3] = {}, e_[3] = {}, gamma0_ = 0.0, d_ = 0.0;
  double firstStep_ = 0.0;        ///< the previous interval's first accepted step (0: none yet)
  Eigen::VectorXd wRate_, wPred_;  ///< its W_ii per unit time; this interval's W scale floor
  Eigen::VectorXd dd_;             ///< √ of the W scale (stepError's buffer)
  double prevEnd_ = std::numeric_limits<double>::quiet_NaN(), halfLength_ = 0.0;
  double t0_ = std::numeric_limits<double>::quiet_NaN();  ///< where A0_.. were evaluated
  Eigen::MatrixXd A_[3], B_[3], Q_[3], R_[3], A0_, B0_, Q0_, R0_;
  Eigen::MatrixXd M_, rhs_, stages_, QY_, Yn_, Wn_, g_, f0_, rY_, rW_, errY_, errW_, eW_;
  detail::SmallLu lu_;
  detail::ShiftedSolve errSolve_;  ///< the estimate's filter I − γ0δA_n
  // The halved stage system of a mechanical step (mechanicalStages).
  bool mech0_ = false;  ///< A_n, B_n mechanical (the filter halves)
  Eigen::MatrixXd MM_, rhsM_, vM_, aqY_[3];
  Eigen::MatrixXd yt_;  ///< stageCost's Yᵀ
  detail::SmallLu luM_;
  // The frozen twin: A, B, Q, R at the interval's start, its exact blocks (Ef_, Wf_), its Radau
  // state and step (as above).
  Eigen::MatrixXd Af_, Bf_, Qf_, Rf_, zf_, pf_, Ef_, Wf_, Y0_, W0_, YnF_, WnF_, stagesF_, f0f_, errYf_,
      rWf_, errYd_;
  // Q Y and g = YᵀQY + blkdiag(0, R) at the step's start (…0_) and end (…n_), both systems.
  Eigen::MatrixXd QY0_, g0_, QYn_, gn_, QY0F_, g0F_, QYnF_, gnF_;
  bool startCached_ = false, startCachedF_ = false;
  bool mechF_ = false;  ///< A_f, B_f mechanical (the twin's solves halve)
  detail::ShiftedSolve errSolveF_;  ///< I − γ0δA_f: the twin's real stage solve and its filter
  Eigen::Matrix3cd T_, Tinv_;  ///< a's eigenvectors (columns: γ0, μ, μ̄) and their inverse
  std::complex<double> mu_;
  Eigen::MatrixXd v0_;
  Eigen::MatrixXd cVr_, cVi_;  // the complex stage system's right-hand side and solution, split
  detail::ComplexShiftedSolve complexSolveF_;  ///< I − δμA_f
  BlockExponential blockExponential_;
};

}  // namespace

std::string SampledDiscretization::describe() const {
  return status.describe() + " (" + std::to_string(intervals.size()) + " intervals, " +
         std::to_string(constantIntervals) + " by the exact exponential, " + std::to_string(steps) + " steps, " +
         std::to_string(linearizations) + " linearizations)";
}

std::string SampledDiscretization::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["intervals"] = intervals.size();
  j["steps"] = steps;
  j["rhs_evaluations"] = rhsEvaluations;
  j["linearizations"] = linearizations;
  j["constant_intervals"] = constantIntervals;
  j["exponentials"] = exponentials;
  j["bisections"] = bisections;
  j["interpolation_pieces"] = interpolationPieces;
  j["interpolation_fallbacks"] = interpolationFallbacks;
  return j.dump();
}

std::string SampledRiccatiRecursion::describe() const {
  return status.describe() + " (" + std::to_string(K.size()) + " steps)";
}

std::string SampledRiccatiRecursion::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["steps"] = K.size();
  return j.dump();
}

SampledDiscretization discretizeSampledData(const Eigen::VectorXd& times, int nx, int nu,
                                            const LinearizationCallback& linearization,
                                            const LqrWeights& weights,
                                            const SampledDiscretizationOptions& options,
                                            const SampledStructure& structure) {
  options.validate();
  if (nx <= 0 || nu <= 0) {
    throw std::invalid_argument("discretizeSampledData: need nx > 0 and m > 0, got nx = " +
                                std::to_string(nx) + ", m = " + std::to_string(nu));
  }
  if (times.size() < 2) throw std::invalid_argument("discretizeSampledData: need at least 2 times");
  for (Eigen::Index k = 0; k < times.size(); ++k) {
    if (!std::isfinite(times(k)) || (k > 0 && !(times(k) > times(k - 1)))) {
      throw std::invalid_argument("discretizeSampledData: times must be finite and increase strictly (entry " +
                                  std::to_string(k) + ")");
    }
  }
  if (!linearization) throw std::invalid_argument("discretizeSampledData: empty linearization callback");
  for (std::size_t i = 0; i < structure.breakpoints.size(); ++i) {
    const double t = structure.breakpoints[i];
    if (!std::isfinite(t) || (i > 0 && !(t > structure.breakpoints[i - 1]))) {
      throw std::invalid_argument("discretizeSampledData: structure.breakpoints must be finite and increase strictly (entry " +
                                  std::to_string(i) + " = " + std::to_string(t) + ")");
    }
  }
  if (!weights.Qfun) checkWeightMatrix(weights.Q, "Q", nx, false);
  if (!weights.Rfun) checkWeightMatrix(weights.R, "R", nu, true);

  SampledDiscretization out;
  Discretizer s(nx, nu, linearization, weights);
  const int cols = nx + nu;

  const Eigen::Index N = static_cast<Eigen::Index>(nx) * cols;
  const Eigen::Index NQ = static_cast<Eigen::Index>(cols) * cols;
  Eigen::VectorXd y0 = Eigen::VectorXd::Zero(N);  // Y(a) = [I 0]
  Eigen::Map<Eigen::MatrixXd>(y0.data(), nx, cols).leftCols(nx).setIdentity();
  Eigen::VectorXd wq(NQ);

  const double rtol = options.relativeTolerance();
  detail::OdeOptions o = detail::makeOdeOptions(
      "sampled-data discretization", detail::OdeMethod::Bdf, detail::OdeLinearSolver::Gmres,
      rtol, options.atol, options.maxSteps);
  o.quadratureSize = static_cast<int>(NQ);
  o.quadratureErrorControl = true;
  o.quadratureRtol = rtol;
  o.quadratureAtol = options.atol;
  // Made at the first interval that needs the integration (none on a held pose).
  std::optional<detail::OdeDriver> driver;
  std::optional<MagnusIntegrator> magnus;
  std::optional<RadauIntegrator> radau;
  Eigen::MatrixXd magnusE, magnusW;

  // Scale of the cost entries per unit time, for the quadrature's absolute tolerance.
  double costScale = 1.0;
  if (!weights.Qfun) costScale = std::max(costScale, weights.Q.cwiseAbs().maxCoeff());
  if (!weights.Rfun) costScale = std::max(costScale, weights.R.cwiseAbs().maxCoeff());

  // The last constant interval's blocks and what they were computed from.
  SampledInterval shared;
  Eigen::MatrixXd sharedA, sharedB, sharedQ, sharedR;
  double sharedC = std::numeric_limits<double>::quiet_NaN(), sharedH = 0.0;
  constexpr double kEps = std::numeric_limits<double>::epsilon();

  out.intervals.reserve(static_cast<std::size_t>(times.size() - 1));
  for (Eigen::Index k = 0; k + 1 < times.size(); ++k) {
    const double a = times(k), b = times(k + 1);
    double c = std::numeric_limits<double>::quiet_NaN();
    if (options.exactConstantIntervals && structure.constantOn) {
      try {
        c = structure.constantOn(a, b);
      } catch (const std::exception& e) {
        out.status.set(SampledCode::kCallbackFailure,
                       "sampled-data discretization: the constant-span callback threw for interval " +
                           std::to_string(k) + " [" + std::to_string(a) + ", " + std::to_string(b) + "]: " + e.what(),
                       a, static_cast<long>(k));
        break;
      }
    }
    if (std::isfinite(c)) {
      // Constant on [a, b]: the exact exponential of its A, B, Q, R (no integration).
      if (!s.evaluate(c, false)) {  // exact: the sharing below compares A, B
        out.status.set(SampledCode::kCallbackFailure,
                       "sampled-data discretization: interval " + std::to_string(k) + " [" + std::to_string(a) +
                           ", " + std::to_string(b) + "], constant, evaluated at t = " + std::to_string(c) + ": " +
                           s.failMessage,
                       c, static_cast<long>(k));
        break;
      }
      const double h = b - a;
      // The lengths of the sample intervals t0 + k/f differ by the rounding of the times
      // themselves (a few ulps of |t|, not of h): lengths that close are one length, as the grid
      // cannot tell them apart (Φ moves by ‖A‖·ulp(t), e.g. 1e-12 relative for ‖A‖ = 1e3, t = 5).
      const double grid = 8.0 * kEps * std::max({std::abs(a), std::abs(b), h});
      const bool same = c == sharedC && std::abs(h - sharedH) <= grid && s.A == sharedA &&
                        s.B == sharedB && s.Q == sharedQ && s.R == sharedR;
      if (!same) {
        discretizeConstantInterval(s.A, s.B, s.Q, s.R, h, shared);
        ++out.exponentials;
        sharedA = s.A;
        sharedB = s.B;
        sharedQ = s.Q;
        sharedR = s.R;
        sharedC = c;
        sharedH = h;
        if (!shared.Phi.allFinite() || !shared.Gamma.allFinite() || !shared.Q.allFinite() ||
            !shared.N.allFinite() || !shared.R.allFinite()) {
          out.status.set(SampledCode::kNonFinite,
                         "sampled-data discretization: the exponential of constant interval " + std::to_string(k) +
                             " [" + std::to_string(a) + ", " + std::to_string(b) + "] is not finite",
                         a, static_cast<long>(k));
          break;
        }
      }
      SampledInterval iv = shared;
      iv.t0 = a;
      iv.t1 = b;
      out.intervals.push_back(std::move(iv));
      ++out.constantIntervals;
      continue;
    }
    if (options.integrator == SampledIntegrator::kMagnus || options.integrator == SampledIntegrator::kRadau) {
      bool done = false;
      const bool byMagnus = options.integrator == SampledIntegrator::kMagnus;
      if (byMagnus) {
        if (!magnus) magnus.emplace(s, rtol, options.maxSteps);
        done = magnus->integrate(a, b, structure.breakpoints, magnusE, magnusW);
      } else {
        if (!radau) {
          radau.emplace(s, rtol, options.maxSteps);
          if (options.interpolateLinearization && structure.smoothBetweenBreakpoints) {
            // The pieces end on the breakpoints inside [t_0, t_N] (ChebyshevLinearization).
            std::vector<double> stops{times(0)};
            for (const double t : structure.breakpoints) {
              if (t > stops.back() && t < times(times.size() - 1)) stops.push_back(t);
            }
            stops.push_back(times(times.size() - 1));
            s.cheb = std::make_unique<ChebyshevLinearization>(nx, nu, std::move(stops));
          }
        }
        done = radau->integrate(a, b, structure.breakpoints, magnusE, magnusW);
        magnusE.conservativeResize(nx + nu, nx + nu);  // [[Φ, Γ], [0, I]] from Y = [Φ Γ]
        magnusE.bottomRows(nu).setZero();
        magnusE.bottomRightCorner(nu, nu).setIdentity();
      }
      if (!done) {
        const double at = s.failed ? s.failTime : (byMagnus ? magnus->failTime : radau->control.failTime);
        std::ostringstream m;
        m << "sampled-data discretization stopped in interval " << k << " [" << a << ", " << b << "] at t = " << at
          << ": " << (s.failed ? s.failMessage : (byMagnus ? magnus->failMessage : radau->control.failMessage));
        out.status.set(s.failed ? SampledCode::kCallbackFailure : SampledCode::kIntegratorFailure, m.str(), at,
                       static_cast<long>(k));
        break;
      }
      SampledInterval iv;
      iv.t0 = a;
      iv.t1 = b;
      iv.Phi = magnusE.topLeftCorner(nx, nx);
      iv.Gamma = magnusE.topRightCorner(nx, nu);
      iv.Q = magnusW.topLeftCorner(nx, nx);
      iv.N = magnusW.topRightCorner(nx, nu);
      iv.R = magnusW.bottomRightCorner(nu, nu);
      if (!magnusE.allFinite() || !magnusW.allFinite()) {
        out.status.set(SampledCode::kNonFinite,
                       "sampled-data discretization: non-finite Phi, Gamma or cost in interval " + std::to_string(k) +
                           " ending at t = " + std::to_string(b),
                       b, static_cast<long>(k));
        break;
      }
      out.intervals.push_back(std::move(iv));
      continue;
    }
    if (!driver) driver.emplace(s, N, o);
    // Every interval starts from Y = [I 0], W = 0 (a restart: Φ, Γ are per interval).
    driver->start(a, y0);
    driver->setQuadratureTolerances(rtol, options.atol * (b - a) * costScale);
    const detail::OdeStatus st = driver->advanceTo(b);
    if (!st.ok()) {
      const double at = s.failed ? s.failTime : st.t;
      std::ostringstream m;
      m << "sampled-data discretization stopped in interval " << k << " [" << a << ", " << b
        << "] at t = " << at << ": ";
      if (s.failed) m << s.failMessage << "; ";
      m << st.message;
      out.status.set(s.failed ? SampledCode::kCallbackFailure : SampledCode::kIntegratorFailure,
                     m.str(), at, static_cast<long>(k));
      break;
    }
    driver->quadrature(wq);
    Eigen::Map<const Eigen::MatrixXd> Y(driver->state().data(), nx, cols);
    Eigen::Map<const Eigen::MatrixXd> W(wq.data(), cols, cols);
    SampledInterval iv;
    iv.t0 = a;
    iv.t1 = b;
    iv.Phi = Y.leftCols(nx);
    iv.Gamma = Y.rightCols(nu);
    const Eigen::MatrixXd Ws = 0.5 * (W + W.transpose());
    iv.Q = Ws.topLeftCorner(nx, nx);
    iv.N = Ws.topRightCorner(nx, nu);
    iv.R = Ws.bottomRightCorner(nu, nu);
    if (!iv.Phi.allFinite() || !iv.Gamma.allFinite() || !Ws.allFinite()) {
      out.status.set(SampledCode::kNonFinite,
                     "sampled-data discretization: non-finite Phi, Gamma or cost in interval " +
                         std::to_string(k) + " ending at t = " + std::to_string(b),
                     b, static_cast<long>(k));
      break;
    }
    out.intervals.push_back(std::move(iv));
  }
  if (driver) {
    const detail::OdeStats stats = driver->stats();
    out.steps = stats.steps;
    out.rhsEvaluations = stats.rhsEvaluations;
  }
  if (magnus) {
    out.steps += magnus->steps;
    out.bisections = magnus->bisections;
  }
  if (radau) {
    out.steps += radau->control.steps;
    out.exponentials += radau->exponentials;
  }
  if (s.cheb) {
    out.interpolationPieces = s.cheb->pieces;
    out.interpolationFallbacks = s.cheb->fallbacks;
  }
  out.linearizations = s.linearizations;
  return out;
}

SampledRiccatiRecursion solveSampledRiccatiRecursion(const std::vector<SampledInterval>& intervals,
                                                     const Eigen::MatrixXd& Qf) {
  SampledRiccatiRecursion rec;
  const std::size_t N = intervals.size();
  if (N == 0) throw std::invalid_argument("solveSampledRiccatiRecursion: no intervals");
  const Eigen::Index nx = intervals[0].Phi.rows(), nu = intervals[0].Gamma.cols();
  checkWeightMatrix(Qf, "Qf", nx, false);
  rec.S.assign(N + 1, Eigen::MatrixXd());
  rec.K.assign(N, Eigen::MatrixXd());
  rec.S[N] = 0.5 * (Qf + Qf.transpose());
  Eigen::MatrixXd SPhi(nx, nx), SGamma(nx, nu), G(nu, nu), H(nu, nx);
  Eigen::LLT<Eigen::MatrixXd> llt(nu);
  for (std::size_t k = N; k-- > 0;) {
    const SampledInterval& iv = intervals[k];
    if (iv.Phi.rows() != nx || iv.Phi.cols() != nx || iv.Gamma.rows() != nx || iv.Gamma.cols() != nu ||
        iv.Q.rows() != nx || iv.Q.cols() != nx || iv.N.rows() != nx || iv.N.cols() != nu ||
        iv.R.rows() != nu || iv.R.cols() != nu) {
      throw std::invalid_argument("solveSampledRiccatiRecursion: interval " + std::to_string(k) +
                                  " has inconsistent sizes");
    }
    const Eigen::MatrixXd& S1 = rec.S[k + 1];
    SPhi.noalias() = S1 * iv.Phi;
    SGamma.noalias() = S1 * iv.Gamma;
    G = iv.R;
    G.noalias() += iv.Gamma.transpose() * SGamma;
    H = iv.N.transpose();
    H.noalias() += iv.Gamma.transpose() * SPhi;
    llt.compute(0.5 * (G + G.transpose()));
    if (llt.info() != Eigen::Success) {
      std::ostringstream m;
      m << "sampled Riccati recursion: R_k + Gamma_k^T S_{k+1} Gamma_k is not positive definite at step " << k
        << " (t = " << iv.t0 << ")";
      rec.status.set(SampledCode::kNotPositiveDefinite, m.str(), iv.t0, static_cast<long>(k));
      return rec;
    }
    rec.K[k] = llt.solve(H);
    Eigen::MatrixXd Sk = iv.Q;
    Sk.noalias() += iv.Phi.transpose() * SPhi;
    Sk.noalias() -= H.transpose() * rec.K[k];
    rec.S[k] = 0.5 * (Sk + Sk.transpose());
    if (!rec.S[k].allFinite() || !rec.K[k].allFinite()) {
      std::ostringstream m;
      m << "sampled Riccati recursion: S or K became non-finite at step " << k << " (t = " << iv.t0 << ")";
      rec.status.set(SampledCode::kNonFinite, m.str(), iv.t0, static_cast<long>(k));
      return rec;
    }
  }
  return rec;
}

}  // namespace trellis
