// lqr.cpp — CARE (matrix sign function + Newton), DARE (doubling), Lyapunov, ZOH, discrete recursion.
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

using Eigen::MatrixXd;
using Eigen::MatrixXcd;

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

/// PBH test on the eigenvalues outside the stability region: continuous Re λ ≥ 0, discrete |λ| ≥ 1.
/// Returns an empty string when (A, B) is stabilizable, else a message naming the eigenvalue.
std::string stabilizabilityDefect(const MatrixXd& A, const MatrixXd& B, bool discrete, double tol) {
  const Eigen::Index n = A.rows(), m = B.cols();
  Eigen::EigenSolver<MatrixXd> es(A, false);
  const double scale = std::max(1.0, (MatrixXd(n, n + m) << A, B).finished().norm());
  const double margin = 1e-9 * std::max(1.0, A.norm());
  for (Eigen::Index i = 0; i < n; ++i) {
    const std::complex<double> lambda = es.eigenvalues()(i);
    const bool unstable = discrete ? std::abs(lambda) >= 1.0 - margin : lambda.real() >= -margin;
    if (!unstable) continue;
    MatrixXcd M(n, n + m);
    M.leftCols(n) = A.cast<std::complex<double>>();
    M.leftCols(n).diagonal().array() -= lambda;
    M.rightCols(m) = B.cast<std::complex<double>>();
    Eigen::JacobiSVD<MatrixXcd> svd(M);
    const double smin = svd.singularValues()(n - 1);
    if (smin <= tol * scale) {
      std::ostringstream msg;
      msg << "(A, B) is not stabilizable: the eigenvalue " << lambda.real()
          << (lambda.imag() >= 0 ? "+" : "") << lambda.imag() << "i of A"
          << (discrete ? " (|lambda| >= 1)" : " (Re >= 0)")
          << " is uncontrollable: smallest singular value of [A - lambda I, B] is " << smin;
      return msg.str();
    }
  }
  return {};
}

double careResidual(const MatrixXd& A, const MatrixXd& G, const MatrixXd& Q, const MatrixXd& X,
                    MatrixXd* Res = nullptr) {
  const MatrixXd AtX = A.transpose() * X;
  const MatrixXd XGX = X * G * X;
  const MatrixXd R = AtX + AtX.transpose() - XGX + Q;
  if (Res) *Res = 0.5 * (R + R.transpose());
  const double denom = Q.norm() + 2 * AtX.norm() + XGX.norm();
  return R.norm() / std::max(denom, std::numeric_limits<double>::min());
}

double dareResidual(const MatrixXd& A, const MatrixXd& B, const MatrixXd& Q, const MatrixXd& R,
                    const MatrixXd& X) {
  const MatrixXd BtXA = B.transpose() * X * A;
  const MatrixXd AtXA = A.transpose() * X * A;
  const MatrixXd corr = BtXA.transpose() * (R + B.transpose() * X * B).ldlt().solve(BtXA);
  const MatrixXd Res = AtXA - X - corr + Q;
  const double denom = AtXA.norm() + X.norm() + corr.norm() + Q.norm();
  return Res.norm() / std::max(denom, std::numeric_limits<double>::min());
}

}  // namespace

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

LqrResult solveCare(const MatrixXd& A, const MatrixXd& B, const MatrixXd& Q, const MatrixXd& R,
                    const CareOptions& options) {
  checkSystem(A, B, "solveCare");
  const Eigen::Index n = A.rows();
  checkWeightMatrix(Q, "Q", n, false);
  checkWeightMatrix(R, "R", B.cols(), true);
  LqrResult res;
  if (auto defect = stabilizabilityDefect(A, B, false, options.stabilizabilityTolerance);
      !defect.empty()) {
    res.status = LqrStatus::kNotStabilizable;
    res.message = "solveCare: " + defect;
    return res;
  }
  const Eigen::LLT<MatrixXd> Rllt(R);
  const MatrixXd G = B * Rllt.solve(B.transpose());
  const MatrixXd Qs = 0.5 * (Q + Q.transpose());

  // Sign iteration Z ← (Z/c + c Z⁻¹)/2, c = |det Z|^{1/2n}, until Z = sign(H).
  MatrixXd Z(2 * n, 2 * n);
  Z << A, -G, -Qs, -A.transpose();
  bool scaling = true, converged = false;
  double prev = std::numeric_limits<double>::infinity();
  for (int it = 0; it < options.maxIterations; ++it) {
    res.iterations = it + 1;
    Eigen::PartialPivLU<MatrixXd> lu(Z);
    if (!(lu.rcond() > 10 * std::numeric_limits<double>::epsilon())) {
      res.status = LqrStatus::kNoStabilizingSolution;
      res.message = "solveCare: the Hamiltonian is (nearly) singular: an eigenvalue on the "
                    "imaginary axis, so no stabilizing solution ((A, Q) not detectable?)";
      return res;
    }
    double c = 1.0;
    if (scaling) {
      double logdet = 0.0;
      for (Eigen::Index i = 0; i < 2 * n; ++i) logdet += std::log(std::abs(lu.matrixLU()(i, i)));
      c = std::exp(logdet / static_cast<double>(2 * n));
    }
    MatrixXd Zn = 0.5 * (Z / c + c * lu.inverse());
    const double rel = (Zn - Z).lpNorm<1>() / std::max(1.0, Zn.lpNorm<1>());
    Z = std::move(Zn);
    if (rel < 1e-2) scaling = false;  // quadratic convergence without scaling near the end
    if (rel <= options.tolerance || (!scaling && rel < 1e-8 && rel >= 0.5 * prev)) {
      converged = true;
      break;
    }
    prev = rel;
  }
  if (!converged) {
    res.status = LqrStatus::kNoStabilizingSolution;
    res.message = "solveCare: the sign iteration did not converge in " +
                  std::to_string(options.maxIterations) +
                  " iterations (Hamiltonian eigenvalues on or near the imaginary axis)";
    return res;
  }
  // [W12; W22 + I] X = −[W11 + I; W21].
  MatrixXd lhs(2 * n, n), rhs(2 * n, n);
  lhs << Z.topRightCorner(n, n), Z.bottomRightCorner(n, n) + MatrixXd::Identity(n, n);
  rhs << Z.topLeftCorner(n, n) + MatrixXd::Identity(n, n), Z.bottomLeftCorner(n, n);
  MatrixXd X = lhs.colPivHouseholderQr().solve(-rhs);
  X = (0.5 * (X + X.transpose())).eval();  // eval: transpose aliases X

  // Newton refinement: (A − GX)ᵀΔ + Δ(A − GX) + Res(X) = 0.
  MatrixXd Res;
  for (int k = 0; k < options.refinementSteps && X.allFinite(); ++k) {
    careResidual(A, G, Qs, X, &Res);
    const MatrixXd Acl = A - G * X;
    Eigen::EigenSolver<MatrixXd> es(Acl, false);
    if (es.eigenvalues().real().maxCoeff() >= 0.0) break;
    try {
      X += solveLyapunov(Acl, Res);
    } catch (const std::runtime_error&) {
      break;
    }
  }
  res.S = X;
  res.residual = careResidual(A, G, Qs, X);
  res.K = Rllt.solve(B.transpose() * X);
  res.closedLoopEigenvalues = Eigen::EigenSolver<MatrixXd>(A - B * res.K, false).eigenvalues();
  if (!X.allFinite() || res.closedLoopEigenvalues.real().maxCoeff() >= 0.0) {
    res.status = LqrStatus::kNoStabilizingSolution;
    std::ostringstream m;
    m << "solveCare: no stabilizing solution: max Re eig(A - BK) = "
      << res.closedLoopEigenvalues.real().maxCoeff();
    res.message = m.str();
  } else if (res.residual > options.residualTolerance) {
    res.status = LqrStatus::kNoConvergence;
    std::ostringstream m;
    m << "solveCare: relative residual " << res.residual << " > " << options.residualTolerance;
    res.message = m.str();
  }
  return res;
}

LqrResult solveDare(const MatrixXd& Ad, const MatrixXd& Bd, const MatrixXd& Q, const MatrixXd& R,
                    const CareOptions& options) {
  checkSystem(Ad, Bd, "solveDare");
  const Eigen::Index n = Ad.rows();
  checkWeightMatrix(Q, "Q", n, false);
  checkWeightMatrix(R, "R", Bd.cols(), true);
  LqrResult res;
  if (auto defect = stabilizabilityDefect(Ad, Bd, true, options.stabilizabilityTolerance);
      !defect.empty()) {
    res.status = LqrStatus::kNotStabilizable;
    res.message = "solveDare: " + defect;
    return res;
  }
  // Structure-preserving doubling: H_k → S.
  MatrixXd Ak = Ad, Gk = Bd * R.llt().solve(Bd.transpose()), Hk = 0.5 * (Q + Q.transpose());
  const MatrixXd I = MatrixXd::Identity(n, n);
  bool converged = false;
  for (int it = 0; it < options.maxIterations; ++it) {
    res.iterations = it + 1;
    Eigen::PartialPivLU<MatrixXd> lu(I + Gk * Hk);
    const MatrixXd WA = lu.solve(Ak), WG = lu.solve(Gk);
    MatrixXd Hn = Hk + Ak.transpose() * Hk * WA;
    Hn = (0.5 * (Hn + Hn.transpose())).eval();
    MatrixXd Gn = Gk + Ak * WG * Ak.transpose();
    Gk = 0.5 * (Gn + Gn.transpose());
    Ak = Ak * WA;
    const double rel = (Hn - Hk).norm() / std::max(1.0, Hn.norm());
    Hk = std::move(Hn);
    if (!Hk.allFinite()) break;
    if (rel <= options.tolerance) {
      converged = true;
      break;
    }
  }
  res.S = Hk;
  if (!converged || !Hk.allFinite()) {
    res.status = LqrStatus::kNoStabilizingSolution;
    res.message = "solveDare: the doubling iteration did not converge in " +
                  std::to_string(res.iterations) +
                  " iterations (closed-loop eigenvalues on the unit circle?)";
    return res;
  }
  res.K = (R + Bd.transpose() * Hk * Bd).ldlt().solve(Bd.transpose() * Hk * Ad);
  res.residual = dareResidual(Ad, Bd, Q, R, Hk);
  res.closedLoopEigenvalues = Eigen::EigenSolver<MatrixXd>(Ad - Bd * res.K, false).eigenvalues();
  const double rho = res.closedLoopEigenvalues.cwiseAbs().maxCoeff();
  if (rho >= 1.0) {
    res.status = LqrStatus::kNoStabilizingSolution;
    res.message = "solveDare: closed-loop spectral radius " + std::to_string(rho) + " >= 1";
  } else if (res.residual > options.residualTolerance) {
    res.status = LqrStatus::kNoConvergence;
    std::ostringstream m;
    m << "solveDare: relative residual " << res.residual << " > " << options.residualTolerance;
    res.message = m.str();
  }
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
