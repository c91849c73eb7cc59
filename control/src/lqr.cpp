// lqr.cpp — CARE (balanced sign function + Newton), DARE (doubling + Newton), stabilizability,
// Lyapunov and Stein equations, ZOH, discrete recursion. See lqr.hpp for the method and the tests.
#include "trellis/control/lqr.hpp"

#include "trellis/control/riccati.hpp"  // checkWeightMatrix

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <unsupported/Eigen/MatrixFunctions>

#include <cmath>
#include <complex>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

const char* toString(LqrStatus status) {
  switch (status) {
    case LqrStatus::kOk: return "ok";
    case LqrStatus::kNotStabilizable: return "not stabilizable";
    case LqrStatus::kNoStabilizingSolution: return "no stabilizing solution";
    case LqrStatus::kNoConvergence: return "no convergence";
  }
  return "unknown";
}

namespace {

using Eigen::Index;
using Eigen::MatrixXcd;
using Eigen::MatrixXd;
using Eigen::VectorXcd;
using Eigen::VectorXd;
using LongDouble = long double;
using MatrixXld = Eigen::Matrix<LongDouble, Eigen::Dynamic, Eigen::Dynamic>;
using Complex = std::complex<double>;

constexpr double kEps = std::numeric_limits<double>::epsilon();
/// A Hamiltonian eigenvalue with |Re λ| ≤ this·|λ| (a pencil eigenvalue with ||λ| − 1| ≤ this) is
/// reported as on the boundary: a defective boundary eigenvalue moves by O(√eps) under rounding.
constexpr double kBoundaryTolerance = 1e-6;
/// An eigenvalue of A with Re λ ≥ −this·|λ| (|λ| ≥ 1 − this) is treated as not strictly stable.
constexpr double kUnstableMargin = 1e-8;

void checkSystem(const MatrixXd& A, const MatrixXd& B, const char* fn) {
  std::ostringstream m;
  if (A.rows() != A.cols() || A.rows() == 0) {
    m << fn << ": A must be square and non-empty, got " << A.rows() << "x" << A.cols();
    throw std::invalid_argument(m.str());
  }
  if (B.rows() != A.rows() || B.cols() == 0) {
    m << fn << ": B must be " << A.rows() << "xm with m >= 1, got " << B.rows() << "x" << B.cols();
    throw std::invalid_argument(m.str());
  }
  if (!A.allFinite() || !B.allFinite()) {
    m << fn << ": A or B has a non-finite entry";
    throw std::invalid_argument(m.str());
  }
}

/// Q: symmetric (indefinite allowed); N: nx×m, finite (empty = no cross term).
void checkStateWeights(const MatrixXd& Q, const MatrixXd& N, Index n, Index m, const char* fn) {
  std::ostringstream msg;
  if (Q.rows() != n || Q.cols() != n) {
    msg << fn << ": Q must be " << n << "x" << n << ", got " << Q.rows() << "x" << Q.cols();
    throw std::invalid_argument(msg.str());
  }
  if (!Q.allFinite()) {
    msg << fn << ": Q has a non-finite entry";
    throw std::invalid_argument(msg.str());
  }
  const double scale = std::max(1.0, Q.cwiseAbs().maxCoeff());
  const double asym = (Q - Q.transpose()).cwiseAbs().maxCoeff();
  if (asym > 1e-10 * scale) {
    msg << fn << ": Q is not symmetric: max |Q - Q^T| = " << asym;
    throw std::invalid_argument(msg.str());
  }
  if (N.size() == 0) return;
  if (N.rows() != n || N.cols() != m) {
    msg << fn << ": N must be " << n << "x" << m << ", got " << N.rows() << "x" << N.cols();
    throw std::invalid_argument(msg.str());
  }
  if (!N.allFinite()) {
    msg << fn << ": N has a non-finite entry";
    throw std::invalid_argument(msg.str());
  }
}

double nearestPowerOfTwo(double x) { return std::ldexp(1.0, static_cast<int>(std::lround(std::log2(x)))); }

/// State scaling D (x = D z, powers of 2) balancing the Hamiltonian [[A, −G], [−Q, −Aᵀ]], which
/// becomes [[D⁻¹AD, −D⁻¹GD⁻¹], [−DQD, ...]]. Minimizes Σ_{i≠j} (D⁻¹AD)_ij² + ‖DQD‖² + ‖D⁻¹GD⁻¹‖²
/// + Σ_i μ_i (d_i² + d_i⁻²), μ_i = A_ii² + μ₀ (the pull keeps a decoupled mode with G_ii = 0 or
/// Q_ii = 0 bounded, near |A_ii|). The objective is convex in log d: coordinate descent, each
/// coordinate by bisection on the derivative in s = ln d_i².
VectorXd balancingScaling(const MatrixXd& A, const MatrixXd& G, const MatrixXd& Q) {
  const Index n = A.rows();
  double logSum = 0.0;
  int count = 0;
  for (const MatrixXd* M : {&A, &G, &Q}) {
    for (Index j = 0; j < n; ++j)
      for (Index i = 0; i < n; ++i)
        if ((*M)(i, j) != 0.0) {
          logSum += 2.0 * std::log(std::abs((*M)(i, j)));
          ++count;
        }
  }
  const double mu0 = count > 0 ? 1e-4 * std::exp(logSum / count) : 1.0;
  VectorXd dd = VectorXd::Ones(n);  // d_i²
  const double sMax = 200.0 * std::log(2.0);
  for (int sweep = 0; sweep < 30; ++sweep) {
    bool changed = false;
    for (Index i = 0; i < n; ++i) {
      double a = 0.0, b = 0.0;
      for (Index j = 0; j < n; ++j) {
        if (j == i) continue;
        a += A(j, i) * A(j, i) / dd(j) + 2.0 * Q(i, j) * Q(i, j) * dd(j);
        b += A(i, j) * A(i, j) * dd(j) + 2.0 * G(i, j) * G(i, j) / dd(j);
      }
      const double mu = A(i, i) * A(i, i) + mu0;
      const double c = Q(i, i) * Q(i, i), e = G(i, i) * G(i, i);
      a += mu;
      b += mu;
      // φ(s) = a e^s + b e^−s + c e^{2s} + e e^{−2s}; φ' is increasing.
      auto slope = [&](double s) {
        return a * std::exp(s) - b * std::exp(-s) + 2.0 * c * std::exp(2.0 * s) -
               2.0 * e * std::exp(-2.0 * s);
      };
      double lo = -sMax, hi = sMax;
      for (int k = 0; k < 64; ++k) {
        const double mid = 0.5 * (lo + hi);
        (slope(mid) > 0.0 ? hi : lo) = mid;
      }
      const double d = nearestPowerOfTwo(std::exp(0.25 * (lo + hi)));  // d = √u = e^{s/2}
      if (d * d != dd(i)) {
        dd(i) = d * d;
        changed = true;
      }
    }
    if (!changed) break;
  }
  return dd.cwiseSqrt();
}

/// The problem in whitened inputs (R → I), without cross term, and in balanced states.
struct Prepared {
  VectorXd e;          ///< input scaling, u = E ũ
  MatrixXld L;         ///< E R E = L Lᵀ (long double)
  MatrixXd Bh, Nh;     ///< B E L⁻ᵀ, N E L⁻ᵀ (original states; Nh empty without cross term)
  VectorXd d;          ///< state scaling, x = D z
  MatrixXd A, G, Q, B; ///< balanced reduced: D⁻¹(A − B̂N̂ᵀ)D, D⁻¹B̂B̂ᵀD⁻¹, D(Q − N̂N̂ᵀ)D, D⁻¹B̂
};

Prepared prepare(const MatrixXd& A, const MatrixXd& B, const MatrixXd& Q, const MatrixXd& R,
                 const MatrixXd& N, bool balance) {
  const Index n = A.rows(), m = B.cols();
  Prepared p;
  p.e.resize(m);
  for (Index j = 0; j < m; ++j) p.e(j) = nearestPowerOfTwo(1.0 / std::sqrt(R(j, j)));
  MatrixXld Rs(m, m);
  for (Index j = 0; j < m; ++j)
    for (Index i = 0; i < m; ++i)
      Rs(i, j) = 0.5L * (static_cast<LongDouble>(R(i, j)) + R(j, i)) * p.e(i) * p.e(j);
  Eigen::LLT<MatrixXld> llt(Rs);
  if (llt.info() != Eigen::Success) throw std::invalid_argument("R is not positive definite");
  p.L = llt.matrixL();
  // B̂ᵀ = L⁻¹ (B E)ᵀ, exactly scaled (E powers of 2), then solved in extended precision.
  const MatrixXld BsT = (B * p.e.asDiagonal()).transpose().cast<LongDouble>();
  const MatrixXld BhT = p.L.triangularView<Eigen::Lower>().solve(BsT);
  MatrixXld Gl = BhT.transpose() * BhT;
  MatrixXld Al = A.cast<LongDouble>();
  MatrixXld Ql = Q.cast<LongDouble>();
  Ql = (0.5L * (Ql + Ql.transpose())).eval();
  p.Bh = BhT.transpose().cast<double>();
  const bool cross = N.size() > 0 && !N.isZero(0.0);
  if (cross) {
    const MatrixXld NsT = (N * p.e.asDiagonal()).transpose().cast<LongDouble>();
    const MatrixXld NhT = p.L.triangularView<Eigen::Lower>().solve(NsT);
    Al -= BhT.transpose() * NhT;
    Ql -= NhT.transpose() * NhT;
    p.Nh = NhT.transpose().cast<double>();
  }
  MatrixXd Ar = Al.cast<double>(), Gr = Gl.cast<double>(), Qr = Ql.cast<double>();
  Gr = (0.5 * (Gr + Gr.transpose())).eval();
  Qr = (0.5 * (Qr + Qr.transpose())).eval();
  p.d = balance ? balancingScaling(Ar, Gr, Qr) : VectorXd::Ones(n);
  const VectorXd dinv = p.d.cwiseInverse();
  p.A = dinv.asDiagonal() * Ar * p.d.asDiagonal();
  p.G = dinv.asDiagonal() * Gr * dinv.asDiagonal();
  p.Q = p.d.asDiagonal() * Qr * p.d.asDiagonal();
  p.B = dinv.asDiagonal() * p.Bh;
  return p;
}

/// max_ij |Res_ij| / max(√(T_ii T_jj), T_ij), 0/0 = 0: invariant under Res, T → D·D.
double scaledResidual(const MatrixXd& Res, const MatrixXd& T) {
  double rho = 0.0;
  for (Index j = 0; j < Res.cols(); ++j)
    for (Index i = 0; i < Res.rows(); ++i) {
      const double r = std::abs(Res(i, j));
      if (r == 0.0) continue;
      const double den = std::max(std::sqrt(T(i, i) * T(j, j)), T(i, j));
      if (!(r <= den * 1e300)) return std::numeric_limits<double>::infinity();  // NaN, 0 den
      rho = std::max(rho, r / den);
    }
  return rho;
}

/// CARE in whitened inputs: Res = AᵀX + XA − F Fᵀ + Q, F = X B̂ + N̂; Kv = Fᵀ.
double careResidual(const MatrixXd& A, const MatrixXd& Bh, const MatrixXd& Nh, const MatrixXd& Q,
                    const MatrixXd& X, MatrixXd* Res = nullptr, MatrixXd* Kv = nullptr) {
  MatrixXd F = X * Bh;
  if (Nh.size() > 0) F += Nh;
  const MatrixXd AtX = A.transpose() * X;
  MatrixXd Rr = AtX + AtX.transpose() - F * F.transpose() + Q;
  Rr = (0.5 * (Rr + Rr.transpose())).eval();
  const MatrixXd Fa = F.cwiseAbs();
  const MatrixXd AtXa = A.cwiseAbs().transpose() * X.cwiseAbs();
  const MatrixXd T = AtXa + AtXa.transpose() + Fa * Fa.transpose() + Q.cwiseAbs();
  const double rho = scaledResidual(Rr, T);
  if (Res) *Res = std::move(Rr);
  if (Kv) *Kv = F.transpose();
  return rho;
}

/// DARE in whitened inputs: Res = AᵀXA − X − Fᵀ W⁻¹ F + Q, W = I + B̂ᵀXB̂, F = B̂ᵀXA + N̂ᵀ;
/// Kv = W⁻¹F.
double dareResidual(const MatrixXd& A, const MatrixXd& Bh, const MatrixXd& Nh, const MatrixXd& Q,
                    const MatrixXd& X, MatrixXd* Res = nullptr, MatrixXd* Kv = nullptr) {
  const Index m = Bh.cols();
  const MatrixXd XB = X * Bh;
  MatrixXd W = MatrixXd::Identity(m, m) + Bh.transpose() * XB;
  W = (0.5 * (W + W.transpose())).eval();
  MatrixXd F = XB.transpose() * A;
  if (Nh.size() > 0) F += Nh.transpose();
  const MatrixXd K = Eigen::PartialPivLU<MatrixXd>(W).solve(F);
  const MatrixXd XA = X * A;
  MatrixXd Rr = A.transpose() * XA - X - F.transpose() * K + Q;
  Rr = (0.5 * (Rr + Rr.transpose())).eval();
  const MatrixXd T = A.cwiseAbs().transpose() * (X.cwiseAbs() * A.cwiseAbs()) + X.cwiseAbs() +
                     F.cwiseAbs().transpose() * K.cwiseAbs() + Q.cwiseAbs();
  const double rho = scaledResidual(Rr, T);
  if (Res) *Res = std::move(Rr);
  if (Kv) *Kv = K;
  return rho;
}

std::string formatComplex(Complex z) {
  std::ostringstream s;
  s << z.real() << (z.imag() >= 0 ? "+" : "") << z.imag() << "i";
  return s.str();
}

bool outsideStabilityRegion(Complex lambda, bool discrete) {
  return discrete ? std::abs(lambda) >= 1.0 - kUnstableMargin
                  : lambda.real() >= -kUnstableMargin * std::abs(lambda);
}

StabilizabilityCheck stabilizabilityImpl(const MatrixXd& A, const MatrixXd& B, bool discrete,
                                         double tolerance) {
  const Index n = A.rows(), m = B.cols();
  StabilizabilityCheck out;
  Eigen::ComplexSchur<MatrixXcd> schur(A.cast<Complex>());
  const MatrixXcd& T = schur.matrixT();
  const MatrixXcd C = schur.matrixU().adjoint() * B.cast<Complex>();  // wᴴB = zᵀ C
  const double bNorm = B.norm();
  const double floor = kEps * std::max(T.norm(), std::numeric_limits<double>::min());
  Eigen::VectorXcd z(n);
  for (Index k = 0; k < n; ++k) {
    const Complex lambda = T(k, k);
    if (!outsideStabilityRegion(lambda, discrete)) continue;
    // Left eigenvector: Tᵀ z = λ z, z_j = 0 (j < k), z_k = 1.
    z.setZero();
    z(k) = 1.0;
    for (Index j = k + 1; j < n; ++j) {
      Complex s = 0.0;
      for (Index i = k; i < j; ++i) s += T(i, j) * z(i);
      Complex den = lambda - T(j, j);
      if (std::abs(den) < floor) den = den == 0.0 ? Complex(floor) : den / std::abs(den) * floor;
      z(j) = s / den;
      if (std::abs(z(j)) > 1e150) z /= 1e150;
    }
    double margin = bNorm > 0.0 ? (z.transpose() * C).norm() / (z.norm() * bNorm) : 0.0;
    // A repeated eigenvalue: one left eigenvector need not expose an uncontrollable direction of
    // its eigenspace; use the PBH singular value there.
    bool repeated = false;
    for (Index j = 0; j < n && !repeated; ++j)
      repeated = j != k && std::abs(T(j, j) - lambda) <= 1e-6 * std::max(1.0, std::abs(lambda));
    if (repeated) {
      MatrixXcd M(n, n + m);
      M.leftCols(n) = A.cast<Complex>();
      M.leftCols(n).diagonal().array() -= lambda;
      M.rightCols(m) = B.cast<Complex>();
      const double scale = std::max((MatrixXd(n, n + m) << A, B).finished().norm(),
                                    std::numeric_limits<double>::min());
      const double smin = Eigen::JacobiSVD<MatrixXcd>(M).singularValues()(n - 1) / scale;
      margin = std::min(margin, smin);
    }
    if (margin < out.margin) {
      out.margin = margin;
      out.eigenvalue = lambda;
    }
  }
  if (out.margin <= tolerance) {
    out.stabilizable = false;
    std::ostringstream msg;
    msg << "(A, B) is not stabilizable: the eigenvalue " << formatComplex(out.eigenvalue)
        << " of A";
    if (discrete) {
      msg << " (|lambda| = " << std::abs(out.eigenvalue)
          << (std::abs(out.eigenvalue) >= 1.0 ? " >= 1)" : ", within 1e-8 of the unit circle)");
    } else {
      msg << " (Re = " << out.eigenvalue.real()
          << (out.eigenvalue.real() >= 0.0 ? " >= 0)" : ", within 1e-8|lambda| of the imaginary axis)");
    }
    msg << " is uncontrollable: controllability margin |w^H B|/(|w||B|) = " << out.margin
        << " <= " << tolerance << " (w its left eigenvector"
        << (out.margin > 1e3 * kEps ? "; a margin above rounding means nearly, not exactly, "
                                      "uncontrollable: below the tolerance it is treated as "
                                      "uncontrollable, see CareOptions::stabilizabilityTolerance)"
                                    : ")");
    out.message = msg.str();
  }
  return out;
}

/// First-order rounding uncertainty of an eigenvalue λ of the pencil (M, L):
///   u = 4 eps (‖M‖ + |λ|‖L‖) ‖x‖‖y‖ / |yᴴLx|,
/// x, y its right and left eigenvectors (inverse iteration on M − λL, one complex LU, O(n³)). A
/// backward-stable eigensolver may move λ by about u; u ≥ |λ − λ_true| is the sign of an
/// eigenvalue that the data, at working precision, do not determine.
double eigenvalueUncertainty(const MatrixXd& M, const MatrixXd& L, Complex lambda) {
  const Index k = M.rows();
  const double scale = M.norm() + std::abs(lambda) * L.norm();
  MatrixXcd P = M.cast<Complex>() - lambda * L.cast<Complex>();
  P.diagonal().array() += Complex(kEps * scale, 0.0);  // keep an exact eigenvalue from a zero pivot
  const Eigen::PartialPivLU<MatrixXcd> lu(P);
  VectorXcd x(k), y(k);
  for (Index i = 0; i < k; ++i) x(i) = y(i) = Complex(1.0 + 0.37 * std::sin(1.0 + i), 0.1 * std::cos(2.0 * i));
  for (int it = 0; it < 3; ++it) {
    x = lu.solve(x);
    y = lu.adjoint().solve(y);
    if (!x.allFinite() || !y.allFinite() || x.norm() == 0.0 || y.norm() == 0.0)
      return std::numeric_limits<double>::infinity();
    x.normalize();
    y.normalize();
  }
  const double den = std::abs(y.dot(L.cast<Complex>() * x));  // |yᴴ L x|
  return den > 0.0 ? 4.0 * kEps * scale / den : std::numeric_limits<double>::infinity();
}

/// After a failed solve: the first true reason among (1) an uncontrollable unstable mode, (2) a
/// Hamiltonian / symplectic-pencil eigenvalue on the boundary; otherwise no convergence.
void diagnoseFailure(LqrResult& res, const Prepared& p, bool discrete, const CareOptions& options,
                     const std::string& fn, const std::string& why) {
  const auto st = stabilizabilityImpl(p.A, p.B, discrete, options.stabilizabilityTolerance);
  if (!st.stabilizable) {
    res.status = LqrStatus::kNotStabilizable;
    res.message = fn + ": " + st.message + " [" + why + "]";
    return;
  }
  const Index n = p.A.rows();
  Complex nearest(0.0, 0.0);
  double gap = std::numeric_limits<double>::infinity();
  MatrixXd H(2 * n, 2 * n), M, L;
  if (!discrete) {
    H << p.A, -p.G, -p.Q, -p.A.transpose();
    const VectorXcd ev = Eigen::EigenSolver<MatrixXd>(H, false).eigenvalues();
    for (Index i = 0; i < ev.size(); ++i) {
      const double g = std::abs(ev(i)) > 0.0 ? std::abs(ev(i).real()) / std::abs(ev(i)) : 0.0;
      if (g < gap) {
        gap = g;
        nearest = ev(i);
      }
    }
  } else {
    M = MatrixXd::Zero(2 * n, 2 * n);
    L = MatrixXd::Zero(2 * n, 2 * n);
    M << p.A, MatrixXd::Zero(n, n), -p.Q, MatrixXd::Identity(n, n);
    L << MatrixXd::Identity(n, n), p.G, MatrixXd::Zero(n, n), p.A.transpose();
    Eigen::GeneralizedEigenSolver<MatrixXd> ges(M, L, false);
    for (Index i = 0; i < 2 * n; ++i) {
      const Complex alpha = ges.alphas()(i);
      const double beta = ges.betas()(i);
      const double aa = std::abs(alpha), bb = std::abs(beta);
      if (std::max(aa, bb) == 0.0) continue;
      const double g = std::abs(aa - bb) / std::max(aa, bb);  // ||λ| − 1| / max(|λ|, 1)
      if (g < gap) {
        gap = g;
        nearest = alpha / beta;
      }
    }
  }
  // The eigenvalue's rounding uncertainty u (same relative measure as gap, on the balanced problem,
  // so diagonal scalings change neither). On the boundary: gap ≤ 1e-6 (u is not used there yet: an
  // exactly defective boundary eigenvalue has u = ∞). Otherwise gap ≤ u: undetermined, said so.
  double relUnc = std::numeric_limits<double>::infinity();
  if (std::isfinite(gap)) {
    const double u = discrete ? eigenvalueUncertainty(M, L, nearest)
                              : eigenvalueUncertainty(H, MatrixXd::Identity(2 * n, 2 * n), nearest);
    relUnc = u / (discrete ? std::max(std::abs(nearest), 1.0) : std::abs(nearest));
  }
  std::ostringstream msg;
  msg << fn << ": ";
  if (gap <= kBoundaryTolerance) {
    res.status = LqrStatus::kNoStabilizingSolution;
    msg << "no stabilizing solution: the " << (discrete ? "symplectic pencil" : "Hamiltonian")
        << " has the eigenvalue " << formatComplex(nearest)
        << (discrete ? " on the unit circle (||lambda| - 1|/max(|lambda|, 1) = "
                     : " on the imaginary axis (|Re lambda|/|lambda| = ")
        << gap << " <= " << kBoundaryTolerance << ", rounding uncertainty " << relUnc
        << "): a mode of A there is unobservable in Q (not detectable), or the cost is not "
           "definite enough [" << why << "]";
  } else if (gap <= relUnc) {
    res.status = LqrStatus::kNoConvergence;
    msg << "ill conditioned at working precision: the "
        << (discrete ? "symplectic pencil" : "Hamiltonian") << " eigenvalue nearest "
        << (discrete ? "the unit circle " : "the imaginary axis ") << formatComplex(nearest)
        << " has relative distance " << gap << " within its rounding uncertainty " << relUnc
        << " (first-order, from its condition number after balancing), so the data do not "
           "determine whether a stabilizing solution exists; a state basis in which the data are "
           "not mixed across scales may help (diagonal scalings are already undone) [" << why
        << "]";
  } else {
    res.status = LqrStatus::kNoConvergence;
    msg << why << " ((A, B) is stabilizable: least margin " << st.margin << "; eigenvalue nearest "
        << (discrete ? "the unit circle " : "the imaginary axis ") << formatComplex(nearest)
        << ", relative distance " << gap << ", rounding uncertainty " << relUnc << ")";
  }
  res.message = msg.str();
}

/// K = E L⁻ᵀ Kv (whitened-input gain back to u), in extended precision.
MatrixXd gainFromWhitened(const Prepared& p, const MatrixXd& Kv) {
  const MatrixXld K = p.L.transpose().triangularView<Eigen::Upper>().solve(Kv.cast<LongDouble>());
  return p.e.asDiagonal() * K.cast<double>();
}

/// Shared ending: S, K, residual on the original data, closed loop, status.
void finish(LqrResult& res, const Prepared& p, const MatrixXd& A, const MatrixXd& Q, bool discrete,
            const MatrixXd& Xb, const CareOptions& options, const std::string& fn) {
  const VectorXd dinv = p.d.cwiseInverse();
  MatrixXd X = dinv.asDiagonal() * Xb * dinv.asDiagonal();
  X = (0.5 * (X + X.transpose())).eval();
  res.S = X;
  res.stateScaling = p.d;
  if (!X.allFinite()) {
    diagnoseFailure(res, p, discrete, options, fn, "the solution has non-finite entries");
    return;
  }
  const MatrixXd Qs = 0.5 * (Q + Q.transpose());
  MatrixXd Kv;
  res.residual = discrete ? dareResidual(A, p.Bh, p.Nh, Qs, X, nullptr, &Kv)
                          : careResidual(A, p.Bh, p.Nh, Qs, X, nullptr, &Kv);
  res.K = gainFromWhitened(p, Kv);
  // Closed loop A − B̂Kv, in balanced coordinates for the eigenvalue solver.
  const MatrixXd Acl = dinv.asDiagonal() * (A - p.Bh * Kv) * p.d.asDiagonal();
  res.closedLoopEigenvalues = Eigen::EigenSolver<MatrixXd>(Acl, false).eigenvalues();
  const double worst = discrete ? res.closedLoopEigenvalues.cwiseAbs().maxCoeff()
                                : res.closedLoopEigenvalues.real().maxCoeff();
  const bool stable = discrete ? worst < 1.0 : worst < 0.0;
  if (!stable || !res.K.allFinite()) {
    std::ostringstream why;
    why << "the computed solution does not stabilize: "
        << (discrete ? "spectral radius of Ad - Bd K = " : "max Re eig(A - BK) = ") << worst;
    diagnoseFailure(res, p, discrete, options, fn, why.str());
  } else if (!(res.residual <= options.residualTolerance)) {
    res.status = LqrStatus::kNoConvergence;
    std::ostringstream m;
    m << fn << ": scale-invariant residual " << res.residual << " > " << options.residualTolerance
      << " (closed loop stable)";
    res.message = m.str();
  }
}

}  // namespace

StabilizabilityCheck checkStabilizability(const MatrixXd& A, const MatrixXd& B, bool discrete,
                                          double tolerance) {
  checkSystem(A, B, "checkStabilizability");
  return stabilizabilityImpl(A, B, discrete, tolerance);
}

MatrixXd solveLyapunov(const MatrixXd& F, const MatrixXd& C) {
  const Eigen::Index n = F.rows();
  if (F.cols() != n || C.rows() != n || C.cols() != n) {
    throw std::invalid_argument("solveLyapunov: F and C must be square and of the same size");
  }
  Eigen::ComplexSchur<MatrixXcd> schur(F.cast<std::complex<double>>());
  const MatrixXcd& T = schur.matrixT();
  const MatrixXcd& U = schur.matrixU();
  const MatrixXcd Ct = U.adjoint() * C.cast<std::complex<double>>() * U;
  MatrixXcd Y(n, n);
  const MatrixXcd Th = T.adjoint();  // lower triangular
  MatrixXcd L(n, n);
  const double tiny = 1e3 * std::numeric_limits<double>::epsilon() * std::max(1.0, T.norm());
  for (Eigen::Index j = 0; j < n; ++j) {
    Eigen::VectorXcd rhs = -Ct.col(j);
    for (Eigen::Index k = 0; k < j; ++k) rhs -= Y.col(k) * T(k, j);
    L = Th;
    L.diagonal().array() += T(j, j);
    for (Eigen::Index i = 0; i < n; ++i) {
      if (std::abs(L(i, i)) <= tiny) {
        throw std::runtime_error(
            "solveLyapunov: singular equation (eigenvalues of F with lambda_i + conj(lambda_j) = 0)");
      }
    }
    Y.col(j) = L.triangularView<Eigen::Lower>().solve(rhs);
  }
  const MatrixXd X = (U * Y * U.adjoint()).real();
  return 0.5 * (X + X.transpose());
}


MatrixXd solveStein(const MatrixXd& F, const MatrixXd& C) {
  const Index n = F.rows();
  if (F.cols() != n || C.rows() != n || C.cols() != n) {
    throw std::invalid_argument("solveStein: F and C must be square and of the same size");
  }
  // F = U T Uᴴ, X = U Y Uᴴ: Tᴴ Y T − Y + Uᴴ C U = 0, solved column by column:
  // (T_jj Tᴴ − I) Y_j = −C̃_j − Tᴴ Σ_{k<j} Y_k T_kj  (lower triangular).
  Eigen::ComplexSchur<MatrixXcd> schur(F.cast<Complex>());
  const MatrixXcd& T = schur.matrixT();
  const MatrixXcd& U = schur.matrixU();
  const MatrixXcd Ct = U.adjoint() * C.cast<Complex>() * U;
  const MatrixXcd Th = T.adjoint();
  MatrixXcd Y(n, n), L(n, n);
  Eigen::VectorXcd acc(n);
  const double tiny = 1e3 * kEps * std::max(1.0, T.norm() * T.norm());
  for (Index j = 0; j < n; ++j) {
    acc.setZero();
    for (Index k = 0; k < j; ++k) acc += Y.col(k) * T(k, j);
    const Eigen::VectorXcd rhs = -Ct.col(j) - Th.triangularView<Eigen::Lower>() * acc;
    L = T(j, j) * Th;
    L.diagonal().array() -= 1.0;
    for (Index i = 0; i < n; ++i) {
      if (std::abs(L(i, i)) <= tiny) {
        throw std::runtime_error(
            "solveStein: singular equation (eigenvalues of F with lambda_i conj(lambda_j) = 1)");
      }
    }
    Y.col(j) = L.triangularView<Eigen::Lower>().solve(rhs);
  }
  const MatrixXd X = (U * Y * U.adjoint()).real();
  return 0.5 * (X + X.transpose());
}

LqrResult solveCare(const MatrixXd& A, const MatrixXd& B, const MatrixXd& Q, const MatrixXd& R,
                    const CareOptions& options) {
  return solveCare(A, B, Q, R, MatrixXd(), options);
}

LqrResult solveCare(const MatrixXd& A, const MatrixXd& B, const MatrixXd& Q, const MatrixXd& R,
                    const MatrixXd& N, const CareOptions& options) {
  checkSystem(A, B, "solveCare");
  const Index n = A.rows();
  checkStateWeights(Q, N, n, B.cols(), "solveCare");
  checkWeightMatrix(R, "R", B.cols(), true);
  const Prepared p = prepare(A, B, Q, R, N, options.balance);
  LqrResult res;
  res.stateScaling = p.d;

  // Sign iteration Z ← (Z/c + c Z⁻¹)/2, c = |det Z|^{1/2n}, until Z = sign(H), H balanced.
  MatrixXd Z(2 * n, 2 * n);
  Z << p.A, -p.G, -p.Q, -p.A.transpose();
  bool scaling = true, converged = false;
  int stalled = 0;
  double prev = std::numeric_limits<double>::infinity();
  for (int it = 0; it < options.maxIterations; ++it) {
    res.iterations = it + 1;
    Eigen::PartialPivLU<MatrixXd> lu(Z);
    double logdet = 0.0;
    bool singular = false;
    for (Index i = 0; i < 2 * n; ++i) {
      const double u = std::abs(lu.matrixLU()(i, i));
      singular = singular || !(u > 0.0) || !std::isfinite(u);
      logdet += std::log(u);
    }
    if (singular) {
      diagnoseFailure(res, p, false, options, "solveCare",
                      "the sign iteration met an exactly singular matrix at iteration " +
                          std::to_string(it + 1));
      return res;
    }
    const double c = scaling ? std::exp(logdet / static_cast<double>(2 * n)) : 1.0;
    MatrixXd Zn = 0.5 * (Z / c + c * lu.inverse());
    if (!Zn.allFinite()) {
      diagnoseFailure(res, p, false, options, "solveCare",
                      "the sign iteration overflowed at iteration " + std::to_string(it + 1));
      return res;
    }
    const double rel = (Zn - Z).lpNorm<1>() / std::max(1.0, Zn.lpNorm<1>());
    Z = std::move(Zn);
    if (rel < 1e-2) scaling = false;  // quadratic convergence without scaling near the end
    if (rel <= options.tolerance || (!scaling && rel < 1e-8 && rel >= 0.5 * prev)) {
      converged = true;
      break;
    }
    // Stagnation above 1e-8: rounding in a badly conditioned H (entries that no diagonal scaling
    // equalizes) limits how far the iteration can go. The subspace it has reached is a starting
    // point for Newton; the residual test in finish() decides whether the result is right.
    stalled = !scaling && rel >= 0.5 * prev ? stalled + 1 : 0;
    if (stalled >= 3) {
      converged = true;
      break;
    }
    prev = rel;
  }
  if (!converged) {
    diagnoseFailure(res, p, false, options, "solveCare",
                    "the sign iteration did not converge in " +
                        std::to_string(options.maxIterations) + " iterations");
    return res;
  }
  // The stable invariant subspace: [W12; W22 + I] X = −[W11 + I; W21].
  MatrixXd lhs(2 * n, n), rhs(2 * n, n);
  lhs << Z.topRightCorner(n, n), Z.bottomRightCorner(n, n) + MatrixXd::Identity(n, n);
  rhs << Z.topLeftCorner(n, n) + MatrixXd::Identity(n, n), Z.bottomLeftCorner(n, n);
  MatrixXd X = lhs.colPivHouseholderQr().solve(-rhs);
  X = (0.5 * (X + X.transpose())).eval();  // eval: transpose aliases X

  // Newton–Kleinman: (A − GX)ᵀΔ + Δ(A − GX) + Res(X) = 0; a step is kept only if it lowers the
  // scale-invariant residual.
  MatrixXd Res, ResNew;
  double rho = careResidual(p.A, p.B, MatrixXd(), p.Q, X, &Res);
  for (int k = 0; k < options.refinementSteps && std::isfinite(rho) && rho > kEps; ++k) {
    MatrixXd Xn;
    try {
      Xn = X + solveLyapunov(p.A - p.G * X, Res);
    } catch (const std::runtime_error&) {
      break;
    }
    Xn = (0.5 * (Xn + Xn.transpose())).eval();
    const double rhoNew = careResidual(p.A, p.B, MatrixXd(), p.Q, Xn, &ResNew);
    if (!(rhoNew < rho)) break;
    X = std::move(Xn);
    Res.swap(ResNew);
    rho = rhoNew;
    ++res.refinementSteps;
  }
  finish(res, p, A, Q, false, X, options, "solveCare");
  return res;
}

namespace {

/// max_ij |Hn_ij − H_ij| / max(√|Hn_ii Hn_jj|, |Hn_ij|): per-entry change, invariant under H → DHD.
double entrywiseChange(const MatrixXd& Hn, const MatrixXd& H) {
  double worst = 0.0;
  for (Index j = 0; j < H.cols(); ++j)
    for (Index i = 0; i < H.rows(); ++i) {
      const double diff = std::abs(Hn(i, j) - H(i, j));
      if (diff == 0.0) continue;
      const double den = std::max(std::sqrt(std::abs(Hn(i, i) * Hn(j, j))), std::abs(Hn(i, j)));
      if (!(diff <= den * 1e300)) return std::numeric_limits<double>::infinity();
      worst = std::max(worst, diff / den);
    }
  return worst;
}

/// Structure-preserving doubling for X = Aᵀ X (I + G X)⁻¹ A + H (G, H symmetric): H_k → X. A_k
/// behaves like (A − B K)^{2^k}, and what H_k still lacks is about A_kᵀ X A_k. Two tests must both
/// pass: the change per entry, relative to √|X_ii X_jj| (a large block cannot hide a small one in
/// the same coordinates), and ‖A_k‖_F ≤ √tol ‖A_0‖_F (in a basis that mixes modes of very
/// different sizes a slow mode adds only a masked amount to every entry, and the first test alone
/// stops with that mode unconverged).
MatrixXd doubling(const MatrixXd& A, const MatrixXd& G, const MatrixXd& H, const CareOptions& options,
                  int& iterations, bool& converged) {
  const Index n = A.rows();
  MatrixXd Ak = A, Gk = G, Hk = H;
  const MatrixXd I = MatrixXd::Identity(n, n);
  const double a0 = std::max(A.norm(), std::numeric_limits<double>::min());
  converged = false;
  iterations = 0;
  for (int it = 0; it < options.maxIterations; ++it) {
    iterations = it + 1;
    Eigen::PartialPivLU<MatrixXd> lu(I + Gk * Hk);
    const MatrixXd WA = lu.solve(Ak), WG = lu.solve(Gk);
    MatrixXd Hn = Hk + Ak.transpose() * Hk * WA;
    Hn = (0.5 * (Hn + Hn.transpose())).eval();
    MatrixXd Gn = Gk + Ak * WG * Ak.transpose();
    Gk = 0.5 * (Gn + Gn.transpose());
    Ak = Ak * WA;
    const double change = entrywiseChange(Hn, Hk);
    Hk = std::move(Hn);
    if (!Hk.allFinite() || !Gk.allFinite() || !Ak.allFinite()) break;
    if (change <= options.tolerance && Ak.norm() <= std::sqrt(options.tolerance) * a0) {
      converged = true;
      break;
    }
  }
  return Hk;
}

}  // namespace

LqrResult solveDare(const MatrixXd& Ad, const MatrixXd& Bd, const MatrixXd& Q, const MatrixXd& R,
                    const CareOptions& options) {
  return solveDare(Ad, Bd, Q, R, MatrixXd(), options);
}

LqrResult solveDare(const MatrixXd& Ad, const MatrixXd& Bd, const MatrixXd& Q, const MatrixXd& R,
                    const MatrixXd& N, const CareOptions& options) {
  checkSystem(Ad, Bd, "solveDare");
  const Index n = Ad.rows();
  checkStateWeights(Q, N, n, Bd.cols(), "solveDare");
  checkWeightMatrix(R, "R", Bd.cols(), true);
  const Prepared p = prepare(Ad, Bd, Q, R, N, options.balance);
  LqrResult res;
  res.stateScaling = p.d;

  // Structure-preserving doubling on the balanced problem (see doubling()).
  bool converged = false;
  MatrixXd X = doubling(p.A, p.G, p.Q, options, res.iterations, converged);
  if (!converged) {
    diagnoseFailure(res, p, true, options, "solveDare",
                    X.allFinite() ? "the doubling iteration did not converge in " +
                                        std::to_string(res.iterations) + " iterations"
                                  : "the doubling iteration overflowed at iteration " +
                                        std::to_string(res.iterations));
    return res;
  }
  // Newton (Hewer): Aclᵀ Δ Acl − Δ + Res(X) = 0, Acl = A − B̂ Kv; kept only if it lowers the residual.
  MatrixXd Res, ResNew, Kv, KvNew;
  double rho = dareResidual(p.A, p.B, MatrixXd(), p.Q, X, &Res, &Kv);
  for (int k = 0; k < options.refinementSteps && std::isfinite(rho) && rho > kEps; ++k) {
    MatrixXd Xn;
    try {
      Xn = X + solveStein(p.A - p.B * Kv, Res);
    } catch (const std::runtime_error&) {
      break;
    }
    Xn = (0.5 * (Xn + Xn.transpose())).eval();
    const double rhoNew = dareResidual(p.A, p.B, MatrixXd(), p.Q, Xn, &ResNew, &KvNew);
    if (!(rhoNew < rho)) break;
    X = std::move(Xn);
    Res.swap(ResNew);
    Kv.swap(KvNew);
    rho = rhoNew;
    ++res.refinementSteps;
  }
  finish(res, p, Ad, Q, true, X, options, "solveDare");
  return res;
}

DiscreteSystem discretizeZeroOrderHold(const MatrixXd& A, const MatrixXd& B, double h) {
  if (A.rows() != A.cols() || B.rows() != A.rows()) {
    throw std::invalid_argument("discretizeZeroOrderHold: A must be nxn and B nxm");
  }
  if (!(h > 0.0) || !std::isfinite(h)) {
    throw std::invalid_argument("discretizeZeroOrderHold: step h = " + std::to_string(h) +
                                " must be > 0 and finite");
  }
  const Eigen::Index n = A.rows(), m = B.cols();
  MatrixXd M = MatrixXd::Zero(n + m, n + m);
  M.topLeftCorner(n, n) = A * h;
  M.topRightCorner(n, m) = B * h;
  const MatrixXd E = M.exp();
  return {E.topLeftCorner(n, n), E.topRightCorner(n, m)};
}

DiscreteRiccatiRecursion solveDiscreteRiccatiRecursion(
    const std::function<void(int, MatrixXd&, MatrixXd&)>& system, int nx, int nu,
    const MatrixXd& Q, const MatrixXd& R, const MatrixXd& Qf, int N) {
  if (N < 0) throw std::invalid_argument("solveDiscreteRiccatiRecursion: N must be >= 0");
  checkWeightMatrix(Q, "Q", nx, false);
  checkWeightMatrix(R, "R", nu, true);
  checkWeightMatrix(Qf, "Qf", nx, false);
  DiscreteRiccatiRecursion out;
  out.S.resize(N + 1);
  out.K.resize(N);
  out.S[N] = 0.5 * (Qf + Qf.transpose());
  MatrixXd Ad(nx, nx), Bd(nx, nu);
  for (int k = N - 1; k >= 0; --k) {
    system(k, Ad, Bd);
    if (Ad.rows() != nx || Ad.cols() != nx || Bd.rows() != nx || Bd.cols() != nu) {
      throw std::invalid_argument("solveDiscreteRiccatiRecursion: system callback returned wrong "
                                  "sizes at step " + std::to_string(k));
    }
    const MatrixXd& Sn = out.S[k + 1];
    const MatrixXd SB = Sn * Bd;
    out.K[k] = (R + Bd.transpose() * SB).ldlt().solve(SB.transpose() * Ad);
    MatrixXd S = Q + Ad.transpose() * Sn * (Ad - Bd * out.K[k]);
    out.S[k] = 0.5 * (S + S.transpose());
  }
  return out;
}

DiscreteRiccatiRecursion solveDiscreteRiccatiRecursion(const MatrixXd& Ad, const MatrixXd& Bd,
                                                       const MatrixXd& Q, const MatrixXd& R,
                                                       const MatrixXd& Qf, int N) {
  checkSystem(Ad, Bd, "solveDiscreteRiccatiRecursion");
  return solveDiscreteRiccatiRecursion(
      [&](int, MatrixXd& A, MatrixXd& B) {
        A = Ad;
        B = Bd;
      },
      static_cast<int>(Ad.rows()), static_cast<int>(Bd.cols()), Q, R, Qf, N);
}

}  // namespace trellis
