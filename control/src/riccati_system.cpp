// riccati_system.cpp — right-hand sides, Jacobian and preconditioner of the Riccati equation.
#include "riccati_system.hpp"

#include "trellis/analysis/detail/dense_kernels.hpp"
#include "riccati_packing.hpp"

#include <sstream>

namespace trellis::detail {

RiccatiSystem::RiccatiSystem(int nx, int nu, double T, const LinearizationCallback& linearization,
                             const LqrWeights& weights)
    : nx_(nx), nu_(nu), T_(T), lin_(linearization), w_(weights),
      A_(nx, nx), B_(nx, nu), Q_(nx, nx), R_(nu, nu), G_(nu, nx), S_(nx, nx), P_(nx, nu), Pt_(nu, nx),
      K_(nu, nx), F_(nx, nx), Acl_(nx, nx), PK_(nx, nx), Rllt_(nu),
      U_(Eigen::MatrixXd::Zero(nx, nx)), Sdot_(nx, nx), M_(nx, nx), Udot_(nx, nx),
      Upre_(Eigen::MatrixXd::Zero(nx, nx)), lyap_(nx), Xr_(nx, nx) {
  if (!w_.Qfun) Q_ = w_.Q;
  if (!w_.Rfun) {
    R_ = w_.R;
    Rllt_.compute(R_);
    // Constant R: R⁻¹ once, so that G = R⁻¹Bᵀ is one m×m×nx product per linearization instead
    // of two triangular solves.
    if (Rllt_.info() == Eigen::Success) Rinv_ = Rllt_.solve(Eigen::MatrixXd::Identity(nu, nu));
  }
}

void RiccatiSystem::fail(RiccatiCode status, double t, const std::string& message) {
  if (!failed) {
    failed = true;
    failTime = t;
    failStatus = status;
    failMessage = message;
  }
}

template <class M>
bool RiccatiSystem::checkSize(const M& X, Eigen::Index r, Eigen::Index c, const char* name,
                              double t) {
  if (X.rows() == r && X.cols() == c && finiteEntries(X.data(), X.size())) return true;
  std::ostringstream m;
  if (X.rows() != r || X.cols() != c) {
    m << name << "(t) callback returned " << X.rows() << "x" << X.cols() << ", expected " << r
      << "x" << c << " at t = " << t;
  } else {
    m << name << "(t) has a non-finite entry at t = " << t;
  }
  fail(RiccatiCode::kCallbackFailure, t, m.str());
  return false;
}

bool RiccatiSystem::coefficientsAt(double t) {
  if (cacheValid_ && t == cachedT_) return true;
  cacheValid_ = false;
  // A user's callback may throw: caught here, at the integrator's C boundary (the library's own
  // callbacks return their failure as the status).
  try {
    const ReferenceStatus st = lin_(t, A_, B_);
    ++linearizations_;
    if (!st.ok()) {
      fail(RiccatiCode::kCallbackFailure, t, st.message);
      return false;
    }
    if (!checkSize(A_, nx_, nx_, "A", t) || !checkSize(B_, nx_, nu_, "B", t)) return false;
    if (w_.Qfun) {
      w_.Qfun(t, Q_);
      if (!checkSize(Q_, nx_, nx_, "Q", t)) return false;
    }
    if (w_.Rfun) {
      w_.Rfun(t, R_);
      if (!checkSize(R_, nu_, nu_, "R", t)) return false;
      Rllt_.compute(R_);
    }
    if (Rllt_.info() != Eigen::Success) {
      std::ostringstream m;
      m << "R(t) is not positive definite at t = " << t;
      fail(RiccatiCode::kCallbackFailure, t, m.str());
      return false;
    }
  } catch (const std::exception& e) {
    std::ostringstream m;
    m << "callback threw at t = " << t << ": " << e.what();
    fail(RiccatiCode::kCallbackFailure, t, m.str());
    return false;
  } catch (...) {
    std::ostringstream m;
    m << "callback threw an unknown exception at t = " << t;
    fail(RiccatiCode::kCallbackFailure, t, m.str());
    return false;
  }
  // Mechanical structure (x = [q; v], q̇ = v, inputs act on v̇): A = [0 I; Aq Av], B = [0; Bv]
  // exactly, as an exact linearization in generalized coordinates gives it. Then G = [0 Gv] and
  // the products below need only the v rows of S (half of AᵀS and of G S).
  const Eigen::Index h = nx_ / 2;
  mechanical_ = nx_ % 2 == 0 && h > 0 && A_.topLeftCorner(h, h).isZero(0.0) &&
                A_.topRightCorner(h, h).isIdentity(0.0) && B_.topRows(h).isZero(0.0);
  if (w_.Rfun) {
    G_ = B_.transpose();
    Rllt_.solveInPlace(G_);
  } else if (mechanical_) {  // G = R⁻¹ Bᵀ = [0, R⁻¹ Bvᵀ]
    G_.leftCols(h).setZero();
    if (nu_ > 0) {
      matmul(nu_, h, nu_, 1.0, Rinv_.data(), nu_, B_.data() + h, nx_, true, G_.data() + h * nu_,
             nu_, false);
    }
  } else {
    matmul(nu_, nx_, nu_, 1.0, Rinv_.data(), nu_, B_.data(), nx_, true, G_.data(), nu_, false);
  }
  cachedT_ = t;
  cacheValid_ = true;
  return true;
}

bool RiccatiSystem::evaluate(double tau, const double* y) {
  const double t = T_ - tau;
  if (!coefficientsAt(t)) return false;
  if (factored) {
    unpackUpper(y, nx_, U_);
    S_.noalias() = U_.transpose() * U_;
  } else {
    unpackSymmetric(y, nx_, S_);
  }
  if (!S_.allFinite()) {
    std::ostringstream m;
    m << "S became non-finite at t = " << t;
    fail(RiccatiCode::kNonFinite, t, m.str());
    return false;
  }
  if (mechanical_) {  // K = G_v S_v (the v columns of G, the v rows of S)
    const Eigen::Index h = nx_ / 2;
    matmul(nu_, nx_, h, 1.0, G_.data() + h * nu_, nu_, &S_(h, 0), nx_, false, K_.data(), nu_, false);
  } else {
    matmul(nu_, nx_, nx_, 1.0, G_.data(), nu_, S_.data(), nx_, false, K_.data(), nu_, false);
  }
  return true;
}

void RiccatiSystem::closedLoop() {
  Acl_ = A_;
  Acl_.noalias() -= B_ * K_;
}

// dS/dτ = AᵀS + SA − S B R⁻¹ Bᵀ S + Q = F + Fᵀ − P K + Q with F = AᵀS, K = G S and
// P = S B = Kᵀ R (R K = BᵀS): nx·m² flops for P instead of nx²·m, and only the upper triangle
// of the symmetric P K (half its nx²·m) in the plain form.
int RiccatiSystem::rhs(double tau, ConstVectorMap y, VectorMap ydot) {
  if (!evaluate(tau, y.data())) return -1;
  // F = S A = (AᵀS)ᵀ: only F + Fᵀ enters. Mechanical A: S A = [S_v Aq, S_q + S_v Av] with S_q,
  // S_v the q and v columns of S.
  const Eigen::Index n = nx_;
  if (mechanical_) {
    const Eigen::Index h = n / 2;
    matmul(n, h, h, 1.0, &S_(0, h), n, &A_(h, 0), n, false, F_.data(), n, false);
    F_.rightCols(h) = S_.leftCols(h);
    matmul(n, h, h, 1.0, &S_(0, h), n, &A_(h, h), n, false, &F_(0, h), n, false, true);
  } else {
    matmul(n, n, n, 1.0, S_.data(), n, A_.data(), n, false, F_.data(), n, false);
  }
  // P = Kᵀ R = (R K)ᵀ (R symmetric): the product on contiguous operands, then a transposed copy.
  matmul(nu_, n, nu_, 1.0, R_.data(), nu_, K_.data(), nu_, false, Pt_.data(), nu_, false);
  P_ = Pt_.transpose();
  double* out = ydot.data();
  if (!factored) {
    matmul(n, n, nu_, 1.0, P_.data(), n, K_.data(), nu_, false, PK_.data(), n, true);
    for (Eigen::Index j = 0; j < nx_; ++j) {
      double* col = out + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = F_(i, j) + F_(j, i) - PK_(i, j) + Q_(i, j);
    }
    return 0;
  }
  matmul(n, n, nu_, 1.0, P_.data(), n, K_.data(), nu_, false, PK_.data(), n, false);
  // Factored: dU/dτ = Υ(U⁻ᵀ Ṡ U⁻¹) U. A zero on U's diagonal (a trial point where the factor
  // lost rank) or a non-finite result is recoverable: CVODES retries with a smaller step.
  Sdot_.noalias() = F_ + F_.transpose();
  Sdot_ -= PK_;
  Sdot_ += Q_;
  if ((U_.diagonal().array() == 0.0).any()) return 1;
  M_ = Sdot_;
  U_.transpose().triangularView<Eigen::Lower>().solveInPlace(M_);  // U⁻ᵀṠ
  M_.transposeInPlace();                                             // Ṡ U⁻¹ (Ṡ symmetric)
  U_.transpose().triangularView<Eigen::Lower>().solveInPlace(M_);  // U⁻ᵀ Ṡ U⁻¹
  M_.diagonal() *= 0.5;
  Udot_.noalias() = M_.triangularView<Eigen::Upper>() * U_;
  packUpper(Udot_, nx_, out);
  return Udot_.allFinite() ? 0 : 1;
}

// ∂f/∂S · E = A_clᵀ E + E A_cl. For the packed unknown s_ij (i ≤ j) the direction is
// E = e_i e_jᵀ + e_j e_iᵀ (i < j) or e_i e_iᵀ; the image has nonzeros only in rows and columns
// i, j: F(k, j) = Acl(i, k) + [k = i] Acl(j, j) + [k = j] Acl(i, j),
// F(k, i) = Acl(j, k) + [k = i] Acl(j, i) + [k = j] Acl(i, i)   (i < j),
// F(k, i) = Acl(i, k) + [k = i] Acl(i, i)                         (i = j).
int RiccatiSystem::jacobian(double tau, ConstVectorMap y, ConstVectorMap, MatrixMap J) {
  if (!evaluate(tau, y.data())) return -1;
  closedLoop();
  J.setZero();
  const Eigen::Index n = nx_;
  const auto& C = Acl_;
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index i = 0; i <= j; ++i) {
      double* col = J.data() + packedIndex(i, j) * J.rows();
      if (i == j) {
        for (Eigen::Index k = 0; k < n; ++k) {
          col[packedIndex(std::min(k, i), std::max(k, i))] = C(i, k) + (k == i ? C(i, i) : 0.0);
        }
      } else {
        for (Eigen::Index k = 0; k < n; ++k) {
          col[packedIndex(std::min(k, j), std::max(k, j))] =
              C(i, k) + (k == i ? C(j, j) : 0.0) + (k == j ? C(i, j) : 0.0);
        }
        for (Eigen::Index k = 0; k < n; ++k) {
          if (k == j) continue;  // entry (i, j) already written (same value)
          col[packedIndex(std::min(k, i), std::max(k, i))] =
              C(j, k) + (k == i ? C(j, i) : 0.0) + (k == j ? C(i, i) : 0.0);
        }
      }
    }
  }
  return 0;
}

// Matrix-free Newton: A_cl at (τ, y) once per set-up, then J·V = A_clᵀV + V A_cl per product
// (V symmetric, so the image is F + Fᵀ with F = A_clᵀV: one nx³ product).
int RiccatiSystem::jacTimesSetup(double tau, ConstVectorMap y, ConstVectorMap) {
  if (!evaluate(tau, y.data())) return -1;
  closedLoop();
  return 0;
}

int RiccatiSystem::jacTimes(double, ConstVectorMap, ConstVectorMap, ConstVectorMap v,
                            VectorMap Jv) {
  unpackSymmetric(v.data(), nx_, Xr_);
  F_.noalias() = Acl_.transpose() * Xr_;
  packSymmetrized(F_, nx_, Jv.data());
  return 0;
}

// A_cl = A − BK at (τ, y), recomputed only when CVODES asks for a fresh Jacobian (jacOk false);
// γ enters in the solve. The Schur form is computed lazily by the first stiff solve.
int RiccatiSystem::preconditionerSetup(double tau, ConstVectorMap y, ConstVectorMap, bool jacOk,
                                       bool* jacUpdated, double) {
  if (jacOk && aclOk_) {
    *jacUpdated = false;
    return 0;
  }
  if (!evaluate(tau, y.data())) return -1;
  closedLoop();
  if (factored) Upre_ = U_;
  // ‖E ↦ A_clᵀE + EA_cl‖ ≤ 2‖A_cl‖_∞: below 2γ‖A_cl‖_∞ < ½ the Newton matrix is within ½ of
  // the identity, GMRES converges in a few iterations unpreconditioned, and the O(nx³) Schur
  // form and solves are skipped.
  aclNorm_ = Acl_.cwiseAbs().rowwise().sum().maxCoeff();
  aclOk_ = true;
  schurOk_ = false;
  *jacUpdated = true;
  return 0;
}

int RiccatiSystem::preconditionerSolve(double, ConstVectorMap, ConstVectorMap, ConstVectorMap r,
                                       VectorMap z, double gamma) {
  const Eigen::Index n = nx_;
  if (!exactSolve && 2.0 * gamma * aclNorm_ < 0.5) {  // non-stiff step: identity preconditioner
    z = r;
    return 0;
  }
  if (!schurOk_) {
    // Acl_ is the set-up's A_cl unless a Jacobian-product set-up replaced it since; the Schur
    // form is taken of the set-up's matrix either way (re-evaluated here would cost the same).
    ++schurFactorizations_;
    if (!lyap_.factor(Acl_)) return 1;
    schurOk_ = true;
  }
  if (!factored) {
    unpackSymmetric(r.data(), n, Xr_);
    if (!lyap_.solve(gamma, Xr_)) return 1;
    packUpper(Xr_, n, z.data());
    return 0;
  }
  // U coordinates: δS = UᵀδU + δUᵀU, Lyapunov solve in S, back by δU = Υ(U⁻ᵀ δS U⁻¹) U.
  M_.setZero();
  unpackUpper(r.data(), n, M_);
  F_.noalias() = Upre_.transpose() * M_;
  Xr_ = F_ + F_.transpose();
  if (!lyap_.solve(gamma, Xr_)) return 1;
  M_ = Xr_;
  Upre_.transpose().triangularView<Eigen::Lower>().solveInPlace(M_);
  M_.transposeInPlace();
  Upre_.transpose().triangularView<Eigen::Lower>().solveInPlace(M_);
  M_.diagonal() *= 0.5;
  Udot_.noalias() = M_.triangularView<Eigen::Upper>() * Upre_;
  packUpper(Udot_, n, z.data());
  return Udot_.allFinite() ? 0 : 1;
}

}  // namespace trellis::detail
