// algebraic_riccati_common.cpp — the parts CARE and DARE share (see algebraic_riccati_common.hpp).
#include "algebraic_riccati_common.hpp"

#include "lapack.hpp"

#include "trellis/core/detail/report_json.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/QR>
#include <Eigen/SVD>

#include <cmath>
#include <complex>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

std::string LqrResult::describe() const {
  return status.describe() + " (residual " + formatStatusNumber(residual) + ", " +
         std::to_string(iterations) + " iterations, " + std::to_string(refinementSteps) +
         " Newton steps)";
}

std::string LqrResult::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["nx"] = S.rows();
  j["nu"] = K.rows();
  j["residual"] = detail::toJson(residual);
  j["iterations"] = iterations;
  j["refinement_steps"] = refinementSteps;
  const bool have = closedLoopEigenvalues.size() > 0;
  j["max_real_closed_loop"] =
      have ? detail::toJson(closedLoopEigenvalues.real().maxCoeff()) : detail::ReportJson(nullptr);
  j["max_abs_closed_loop"] =
      have ? detail::toJson(closedLoopEigenvalues.cwiseAbs().maxCoeff()) : detail::ReportJson(nullptr);
  j["S"] = detail::toJson(S);
  j["K"] = detail::toJson(K);
  return j.dump();
}

namespace detail::are {

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
                    const MatrixXd& X, MatrixXd* Res, MatrixXd* Kv) {
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
                    const MatrixXd& X, MatrixXd* Res, MatrixXd* Kv) {
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
    res.status.code = LqrCode::kNotStabilizable;
    res.status.message = fn + ": " + st.message + " [" + why + "]";
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
    res.status.code = LqrCode::kNoStabilizingSolution;
    msg << "no stabilizing solution: the " << (discrete ? "symplectic pencil" : "Hamiltonian")
        << " has the eigenvalue " << formatComplex(nearest)
        << (discrete ? " on the unit circle (||lambda| - 1|/max(|lambda|, 1) = "
                     : " on the imaginary axis (|Re lambda|/|lambda| = ")
        << gap << " <= " << kBoundaryTolerance << ", rounding uncertainty " << relUnc
        << "): a mode of A there is unobservable in Q (not detectable), or the cost is not "
           "definite enough [" << why << "]";
  } else if (gap <= relUnc) {
    res.status.code = LqrCode::kNoConvergence;
    msg << "ill conditioned at working precision: the "
        << (discrete ? "symplectic pencil" : "Hamiltonian") << " eigenvalue nearest "
        << (discrete ? "the unit circle " : "the imaginary axis ") << formatComplex(nearest)
        << " has relative distance " << gap << " within its rounding uncertainty " << relUnc
        << " (first-order, from its condition number after balancing), so the data do not "
           "determine whether a stabilizing solution exists; a state basis in which the data are "
           "not mixed across scales may help (diagonal scalings are already undone) [" << why
        << "]";
  } else {
    res.status.code = LqrCode::kNoConvergence;
    msg << why << " ((A, B) is stabilizable: least margin " << st.margin << "; eigenvalue nearest "
        << (discrete ? "the unit circle " : "the imaginary axis ") << formatComplex(nearest)
        << ", relative distance " << gap << ", rounding uncertainty " << relUnc << ")";
  }
  res.status.message = msg.str();
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
  lapack::RealSchur schur(Acl.rows(), false);
  if (const int info = schur.compute(Acl); info != 0) {
    diagnoseFailure(res, p, discrete, options, fn,
                    info > Acl.rows() ? "the closed loop A - BK has a non-finite entry"
                                      : "the eigenvalues of the closed loop A - BK did not "
                                        "converge (LAPACK dgees INFO = " + std::to_string(info) + ")");
    return;
  }
  res.closedLoopEigenvalues.resize(Acl.rows());
  for (Index i = 0; i < Acl.rows(); ++i)
    res.closedLoopEigenvalues(i) = Complex(schur.wr()(i), schur.wi()(i));
  const double worst = discrete ? res.closedLoopEigenvalues.cwiseAbs().maxCoeff()
                                : res.closedLoopEigenvalues.real().maxCoeff();
  const bool stable = discrete ? worst < 1.0 : worst < 0.0;
  if (!stable || !res.K.allFinite()) {
    std::ostringstream why;
    why << "the computed solution does not stabilize: "
        << (discrete ? "spectral radius of Ad - Bd K = " : "max Re eig(A - BK) = ") << worst;
    diagnoseFailure(res, p, discrete, options, fn, why.str());
  } else if (!(res.residual <= options.residualTolerance)) {
    res.status.code = LqrCode::kNoConvergence;
    std::ostringstream m;
    m << fn << ": scale-invariant residual " << res.residual << " > " << options.residualTolerance
      << " (closed loop stable)";
    res.status.message = m.str();
  }
}


}  // namespace detail::are

}  // namespace trellis
