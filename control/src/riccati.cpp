// riccati.cpp — backward Riccati integration with CVODES (SUNDIALS stays in this file).
#include "trellis/control/riccati.hpp"

#include "sundials_raii.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <cvodes/cvodes_ls.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunlinsol/sunlinsol_spgmr.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <sstream>
#include <vector>

namespace trellis {

const char* toString(RiccatiStatus status) {
  switch (status) {
    case RiccatiStatus::kOk: return "ok";
    case RiccatiStatus::kIntegratorFailure: return "integrator failure";
    case RiccatiStatus::kNonFinite: return "non-finite";
    case RiccatiStatus::kBlowUp: return "blow-up";
    case RiccatiStatus::kCallbackFailure: return "callback failure";
  }
  return "unknown";
}

const char* toString(RiccatiMethod method) {
  switch (method) {
    case RiccatiMethod::kBDF: return "bdf";
    case RiccatiMethod::kAdams: return "adams";
    case RiccatiMethod::kFactored: return "factored";
  }
  return "unknown";
}

RiccatiMethod parseRiccatiMethod(const std::string& text) {
  for (RiccatiMethod m : {RiccatiMethod::kBDF, RiccatiMethod::kAdams, RiccatiMethod::kFactored}) {
    if (text == toString(m)) return m;
  }
  throw std::invalid_argument("'" + text + "' is not one of bdf, adams, factored");
}

void RiccatiOptions::validate() const {
  auto bad = [](const char* field, double v, const char* rule) {
    std::ostringstream m;
    m << "RiccatiOptions." << field << " = " << v << " must be " << rule;
    throw std::invalid_argument(m.str());
  };
  if (!(rtol > 0.0) || !std::isfinite(rtol)) bad("rtol", rtol, "> 0 and finite");
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol, "> 0 and finite");
  if (maxSteps <= 0) bad("maxSteps", static_cast<double>(maxSteps), "> 0");
  if (!(maxNorm > 0.0)) bad("maxNorm", maxNorm, "> 0");
  if (!(initialStep >= 0.0) || !std::isfinite(initialStep)) bad("initialStep", initialStep, ">= 0");
  if (!(maxStep >= 0.0) || !std::isfinite(maxStep)) bad("maxStep", maxStep, ">= 0");
  if (!(factoredSwitchCondition >= 0.0) || std::isnan(factoredSwitchCondition)) {
    bad("factoredSwitchCondition", factoredSwitchCondition, ">= 0");
  }
  if (!(factoredQfShift >= 0.0) || !std::isfinite(factoredQfShift)) {
    bad("factoredQfShift", factoredQfShift, ">= 0 and finite");
  }
}

void checkWeightMatrix(const Eigen::MatrixXd& W, const char* name, Eigen::Index size,
                       bool definite) {
  std::ostringstream m;
  if (W.rows() != size || W.cols() != size) {
    m << name << " must be " << size << "x" << size << ", got " << W.rows() << "x" << W.cols();
    throw std::invalid_argument(m.str());
  }
  if (size == 0) return;
  if (!W.allFinite()) {
    m << name << " has a non-finite entry";
    throw std::invalid_argument(m.str());
  }
  const double scale = std::max(1.0, W.cwiseAbs().maxCoeff());
  const double asym = (W - W.transpose()).cwiseAbs().maxCoeff();
  if (asym > 1e-10 * scale) {
    m << name << " is not symmetric: max |W - W^T| = " << asym;
    throw std::invalid_argument(m.str());
  }
  const Eigen::MatrixXd Ws = 0.5 * (W + W.transpose());
  const double lmin = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Ws, Eigen::EigenvaluesOnly)
                          .eigenvalues()(0);
  if (definite && !(lmin > 0.0)) {
    m << name << " is not positive definite: smallest eigenvalue " << lmin << " (must be > 0)";
    throw std::invalid_argument(m.str());
  }
  if (!definite && lmin < -1e-12 * scale) {
    m << name << " is not positive semidefinite: smallest eigenvalue " << lmin
      << " (must be >= 0)";
    throw std::invalid_argument(m.str());
  }
}

namespace {

inline Eigen::Index packedIndex(Eigen::Index i, Eigen::Index j) {  // i <= j
  return j * (j + 1) / 2 + i;
}

void unpack(const double* y, Eigen::Index n, Eigen::MatrixXd& S) {
  for (Eigen::Index j = 0; j < n; ++j) {
    const double* col = y + j * (j + 1) / 2;
    for (Eigen::Index i = 0; i <= j; ++i) S(i, j) = S(j, i) = col[i];
  }
}

void pack(const Eigen::MatrixXd& S, Eigen::Index n, double* y) {
  for (Eigen::Index j = 0; j < n; ++j) {
    double* col = y + j * (j + 1) / 2;
    for (Eigen::Index i = 0; i <= j; ++i) col[i] = S(i, j);
  }
}

// Upper triangle of U from the packed vector (the strict lower triangle of U is left alone: zero).
void unpackUpper(const double* y, Eigen::Index n, Eigen::MatrixXd& U) {
  for (Eigen::Index j = 0; j < n; ++j) {
    const double* col = y + j * (j + 1) / 2;
    for (Eigen::Index i = 0; i <= j; ++i) U(i, j) = col[i];
  }
}

// max |S_ij| of S = UᵀU is its largest diagonal entry max_j ‖U(:, j)‖² (Cauchy–Schwarz).
double factorNorm(const double* y, Eigen::Index n) {
  double m = 0.0;
  for (Eigen::Index j = 0; j < n; ++j) {
    const double* col = y + j * (j + 1) / 2;
    double d = 0.0;
    for (Eigen::Index i = 0; i <= j; ++i) d += col[i] * col[i];
    m = std::max(m, d);
  }
  return m;
}

double maxAbs(const double* y, Eigen::Index N) {
  double m = 0.0;
  for (Eigen::Index i = 0; i < N; ++i) m = std::max(m, std::abs(y[i]));
  return m;
}

}  // namespace

/// Everything the CVODES callbacks need; scratch memory is allocated once here.
struct RiccatiSolver {
  int nx, nu;
  double T;
  const LinearizationCallback& lin;
  const LqrWeights& w;
  Eigen::MatrixXd A, B, Q, R, S, P, K, F, Acl;
  Eigen::LLT<Eigen::MatrixXd> Rllt;
  // Factored form: U (upper triangular, zero below), Ṡ, M = U⁻ᵀṠU⁻¹ and dU/dτ.
  bool factored = false;
  Eigen::MatrixXd U, Sdot, M, Udot, Upre;
  // Preconditioner: real Schur form A_cl = Z T Zᵀ at the last Jacobian update (T quasi upper
  // triangular: 1×1 blocks and 2×2 blocks for complex pairs, starting at blockStart[b]).
  Eigen::RealSchur<Eigen::MatrixXd> schur;
  Eigen::MatrixXd Z, Tschur, TF, TFt, Cs, Ys, Xr;
  std::vector<Eigen::Index> blockStart;
  bool schurOk = false;  // Schur form of the current A_cl computed (lazily, for stiff steps)
  bool aclOk = false;    // A_cl and ‖A_cl‖_∞ set by the preconditioner set-up
  double aclNorm = 0.0;
  bool failed = false;
  double failTime = 0.0;  // t of the evaluation that failed
  RiccatiStatus failStatus = RiccatiStatus::kCallbackFailure;
  std::string callbackMessage, cvodeMessage;

  RiccatiSolver(int nx_, int nu_, double T_, const LinearizationCallback& l, const LqrWeights& w_)
      : nx(nx_), nu(nu_), T(T_), lin(l), w(w_),
        A(nx_, nx_), B(nx_, nu_), Q(nx_, nx_), R(nu_, nu_), S(nx_, nx_), P(nx_, nu_),
        K(nu_, nx_), F(nx_, nx_), Acl(nx_, nx_), Rllt(nu_),
        U(Eigen::MatrixXd::Zero(nx_, nx_)), Sdot(nx_, nx_), M(nx_, nx_), Udot(nx_, nx_),
        Upre(Eigen::MatrixXd::Zero(nx_, nx_)), schur(nx_), Z(nx_, nx_), Tschur(nx_, nx_),
        TF(nx_, nx_), TFt(nx_, nx_), Cs(nx_, nx_), Ys(nx_, nx_), Xr(nx_, nx_) {
    blockStart.reserve(static_cast<std::size_t>(nx_) + 1);
    if (!w.Qfun) Q = w.Q;
    if (!w.Rfun) {
      R = w.R;
      Rllt.compute(R);
    }
  }

  void fail(RiccatiStatus s, const std::string& msg) {
    if (!failed) {
      failed = true;
      failTime = currentTime;
      failStatus = s;
      callbackMessage = msg;
    }
  }

  template <class M>
  bool checkSize(const M& X, Eigen::Index r, Eigen::Index c, const char* name, double t) {
    if (X.rows() == r && X.cols() == c && X.allFinite()) return true;
    std::ostringstream m;
    if (X.rows() != r || X.cols() != c) {
      m << name << "(t) callback returned " << X.rows() << "x" << X.cols() << ", expected " << r
        << "x" << c << " at t = " << t;
    } else {
      m << name << "(t) has a non-finite entry at t = " << t;
    }
    fail(RiccatiStatus::kCallbackFailure, m.str());
    return false;
  }

  /// A, B, Q, R, S and K = R⁻¹BᵀS at τ; false (with the message kept) on any failure.
  double currentTime = 0.0;

  bool evaluate(double tau, const double* y) {
    const double t = T - tau;
    currentTime = t;
    try {
      lin(t, A, B);
      if (!checkSize(A, nx, nx, "A", t) || !checkSize(B, nx, nu, "B", t)) return false;
      if (w.Qfun) {
        w.Qfun(t, Q);
        if (!checkSize(Q, nx, nx, "Q", t)) return false;
      }
      if (w.Rfun) {
        w.Rfun(t, R);
        if (!checkSize(R, nu, nu, "R", t)) return false;
        Rllt.compute(R);
        if (Rllt.info() != Eigen::Success) {
          std::ostringstream m;
          m << "R(t) is not positive definite at t = " << t;
          fail(RiccatiStatus::kCallbackFailure, m.str());
          return false;
        }
      }
    } catch (const std::exception& e) {
      std::ostringstream m;
      m << "callback threw at t = " << t << ": " << e.what();
      fail(RiccatiStatus::kCallbackFailure, m.str());
      return false;
    } catch (...) {
      std::ostringstream m;
      m << "callback threw an unknown exception at t = " << t;
      fail(RiccatiStatus::kCallbackFailure, m.str());
      return false;
    }
    if (factored) {
      unpackUpper(y, nx, U);
      S.noalias() = U.transpose() * U;
    } else {
      unpack(y, nx, S);
    }
    if (!S.allFinite()) {
      std::ostringstream m;
      m << "S became non-finite at t = " << t;
      fail(RiccatiStatus::kNonFinite, m.str());
      return false;
    }
    P.noalias() = S * B;
    K.noalias() = P.transpose();
    Rllt.solveInPlace(K);
    return true;
  }

  // dS/dτ = AᵀS + SA − S B R⁻¹ Bᵀ S + Q = AᵀS + SA − P K + Q.
  static int rhs(double tau, N_Vector yv, N_Vector ydotv, void* user) {
    auto& s = *static_cast<RiccatiSolver*>(user);
    if (!s.evaluate(tau, N_VGetArrayPointer(yv))) return -1;
    s.F.noalias() = s.A.transpose() * s.S;
    s.Acl.noalias() = s.P * s.K;  // reuse Acl as scratch for P K
    double* out = N_VGetArrayPointer(ydotv);
    for (Eigen::Index j = 0; j < s.nx; ++j) {
      double* col = out + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) {
        col[i] = s.F(i, j) + s.F(j, i) - s.Acl(i, j) + s.Q(i, j);
      }
    }
    return 0;
  }

  // The plain or the factored form, whichever is current (the factored solve may switch).
  static int rhsDispatch(double tau, N_Vector yv, N_Vector ydotv, void* user) {
    return static_cast<RiccatiSolver*>(user)->factored ? rhsFactored(tau, yv, ydotv, user)
                                                       : rhs(tau, yv, ydotv, user);
  }

  // Factored: dU/dτ = Υ(U⁻ᵀ Ṡ U⁻¹) U (see the header). A zero on U's diagonal (a trial point
  // where the factor lost rank) or a non-finite result is a recoverable error: CVODES retries
  // with a smaller step, and reports a failure if that keeps happening.
  static int rhsFactored(double tau, N_Vector yv, N_Vector ydotv, void* user) {
    auto& s = *static_cast<RiccatiSolver*>(user);
    if (!s.evaluate(tau, N_VGetArrayPointer(yv))) return -1;
    s.F.noalias() = s.A.transpose() * s.S;
    s.Sdot.noalias() = s.F + s.F.transpose();
    s.Sdot.noalias() -= s.P * s.K;
    s.Sdot += s.Q;
    if ((s.U.diagonal().array() == 0.0).any()) return 1;
    s.M = s.Sdot;
    s.U.transpose().triangularView<Eigen::Lower>().solveInPlace(s.M);  // U⁻ᵀṠ
    s.M.transposeInPlace();                                               // Ṡ U⁻¹ (Ṡ symmetric)
    s.U.transpose().triangularView<Eigen::Lower>().solveInPlace(s.M);  // U⁻ᵀ Ṡ U⁻¹
    s.M.diagonal() *= 0.5;
    s.Udot.noalias() = s.M.triangularView<Eigen::Upper>() * s.U;
    double* out = N_VGetArrayPointer(ydotv);
    for (Eigen::Index j = 0; j < s.nx; ++j) {
      double* col = out + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = s.Udot(i, j);
    }
    return s.Udot.allFinite() ? 0 : 1;
  }

  // Preconditioner set-up: A_cl = A − BK at (τ, y) and its real Schur form A_cl = Z T Zᵀ,
  // recomputed only when CVODES asks for a fresh Jacobian (jok false); γ enters in the solve.
  static int precSetup(double tau, N_Vector yv, N_Vector, int jok, int* jcur, double, void* user) {
    auto& s = *static_cast<RiccatiSolver*>(user);
    if (jok && s.aclOk) {
      *jcur = 0;
      return 0;
    }
    if (!s.evaluate(tau, N_VGetArrayPointer(yv))) return -1;
    s.Acl = s.A;
    s.Acl.noalias() -= s.B * s.K;
    if (s.factored) s.Upre = s.U;
    // ‖E ↦ A_clᵀE + EA_cl‖ ≤ 2‖A_cl‖_∞ (in the ∞-norm on entries, up to symmetry): below
    // γ·2‖A_cl‖_∞ < ½ the Newton matrix is within ½ of the identity, GMRES converges in a few
    // iterations unpreconditioned, and the O(nx³) Schur form and solves are skipped.
    s.aclNorm = s.Acl.cwiseAbs().rowwise().sum().maxCoeff();
    s.aclOk = true;
    s.schurOk = false;
    *jcur = 1;
    return 0;
  }

  bool computeSchur() {
    auto& s = *this;
    s.schur.compute(s.Acl);
    if (s.schur.info() != Eigen::Success) return false;
    s.Z = s.schur.matrixU();
    s.Tschur = s.schur.matrixT();
    s.blockStart.clear();
    for (Eigen::Index k = 0; k < s.nx;) {
      s.blockStart.push_back(k);
      k += (k + 1 < s.nx && s.Tschur(k + 1, k) != 0.0) ? 2 : 1;
    }
    s.blockStart.push_back(s.nx);
    s.schurOk = true;
    return true;
  }

  // X solving (γA_cl − ½I)ᵀX + X(γA_cl − ½I) = −R, i.e. X − γ(A_clᵀX + X A_cl) = R, for symmetric
  // R (in Xr on entry, X on exit). With F = γA_cl − ½I = Z T_F Zᵀ (T_F = γT − ½I, quasi upper
  // triangular) and Y = ZᵀXZ: T_Fᵀ Y + Y T_F = C = −ZᵀRZ. Block (I, J) of Y (1×1 … 2×2) solves
  //   T_F(I,I)ᵀ Y_IJ + Y_IJ T_F(J,J) = C_IJ − Σ_{L<I} T_F(L,I)ᵀ Y_LJ − Σ_{K<J} Y_IK T_F(K,J),
  // a Kronecker system of at most 4 unknowns, taken in increasing I and J (Bartels–Stewart).
  // All real: O(nx³) per application, no heap allocation.
  bool lyapunovSolve(double gamma) {
    const Eigen::Index n = nx;
    TF = gamma * Tschur;
    TF.diagonal().array() -= 0.5;
    TFt = TF.transpose();
    Cs.noalias() = Z.transpose() * Xr;
    Ys.noalias() = -Cs * Z;  // C, overwritten by Y block by block
    const std::size_t nb = blockStart.size() - 1;
    for (std::size_t bj = 0; bj < nb; ++bj) {
      const Eigen::Index j0 = blockStart[bj], sj = blockStart[bj + 1] - j0;
      // − Σ_{K<J} Y_IK T_F(K,J) for every I at once.
      if (j0 > 0) Ys.middleCols(j0, sj).noalias() -= Ys.leftCols(j0) * TF.block(0, j0, j0, sj);
      for (std::size_t bi = 0; bi < nb; ++bi) {
        const Eigen::Index i0 = blockStart[bi], si = blockStart[bi + 1] - i0;
        // Ys(I, J) now holds the right-hand side (rows L < I were subtracted below).
        // vec(T_IIᵀ Y + Y T_JJ) = (I ⊗ T_IIᵀ + T_JJᵀ ⊗ I) vec(Y), column-major vec.
        const Eigen::Index m = si * sj;
        if (m == 1) {
          const double d = TF(i0, i0) + TF(j0, j0);
          if (d == 0.0) return false;
          Ys(i0, j0) /= d;
        } else {
          Eigen::Matrix4d K = Eigen::Matrix4d::Zero();
          Eigen::Vector4d v = Eigen::Vector4d::Zero();
          for (Eigen::Index c = 0; c < sj; ++c) {
            for (Eigen::Index r = 0; r < si; ++r) {
              const Eigen::Index row = c * si + r;
              v(row) = Ys(i0 + r, j0 + c);
              for (Eigen::Index l = 0; l < si; ++l) K(row, c * si + l) += TF(i0 + l, i0 + r);
              for (Eigen::Index k = 0; k < sj; ++k) K(row, k * si + r) += TF(j0 + k, j0 + c);
            }
          }
          if (m == 2) {
            const Eigen::Vector2d y = K.topLeftCorner<2, 2>().partialPivLu().solve(v.head<2>());
            v.head<2>() = y;
          } else {
            v = K.partialPivLu().solve(v);
          }
          if (!v.allFinite()) return false;
          for (Eigen::Index c = 0; c < sj; ++c) {
            for (Eigen::Index r = 0; r < si; ++r) Ys(i0 + r, j0 + c) = v(c * si + r);
          }
        }
        // Rows below I: Ys(r, J) −= Σ_{l ∈ I} T_F(l, r) Y(l, J)  (T_F(l, r) = TFt(r, l), contiguous).
        const Eigen::Index below = i0 + si;
        for (Eigen::Index c = 0; c < sj; ++c) {
          double* out = &Ys(0, j0 + c);
          for (Eigen::Index l = 0; l < si; ++l) {
            const double y = Ys(i0 + l, j0 + c);
            const double* t = &TFt(0, i0 + l);
            for (Eigen::Index r = below; r < n; ++r) out[r] -= t[r] * y;
          }
        }
      }
    }
    Cs.noalias() = Z * Ys;
    Xr.noalias() = Cs * Z.transpose();
    return Xr.allFinite();
  }

  static int precSolve(double, N_Vector, N_Vector, N_Vector rv, N_Vector zv, double gamma, double,
                       int, void* user) {
    auto& s = *static_cast<RiccatiSolver*>(user);
    const double* r = N_VGetArrayPointer(rv);
    double* z = N_VGetArrayPointer(zv);
    const Eigen::Index n = s.nx;
    if (2.0 * gamma * s.aclNorm < 0.5) {  // non-stiff step: identity preconditioner
      std::copy(r, r + N_VGetLength(rv), z);
      return 0;
    }
    if (!s.schurOk && !s.computeSchur()) return 1;
    if (!s.factored) {
      unpack(r, n, s.Xr);
      if (!s.lyapunovSolve(gamma)) return 1;
      pack(s.Xr, n, z);
      return 0;
    }
    // U coordinates: δS = UᵀδU + δUᵀU, Lyapunov solve in S, back by δU = Υ(U⁻ᵀ δS U⁻¹) U.
    s.M.setZero();
    unpackUpper(r, n, s.M);
    s.F.noalias() = s.Upre.transpose() * s.M;
    s.Xr = s.F + s.F.transpose();
    if (!s.lyapunovSolve(gamma)) return 1;
    s.M = s.Xr;
    s.Upre.transpose().triangularView<Eigen::Lower>().solveInPlace(s.M);
    s.M.transposeInPlace();
    s.Upre.transpose().triangularView<Eigen::Lower>().solveInPlace(s.M);
    s.M.diagonal() *= 0.5;
    s.Udot.noalias() = s.M.triangularView<Eigen::Upper>() * s.Upre;
    for (Eigen::Index j = 0; j < n; ++j) {
      double* col = z + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = s.Udot(i, j);
    }
    return s.Udot.allFinite() ? 0 : 1;
  }

  // ∂f/∂S · E = A_clᵀ E + E A_cl with A_cl = A − B K. For the packed unknown s_ij (i ≤ j) the
  // direction is E = e_i e_jᵀ + e_j e_iᵀ (i < j) or e_i e_iᵀ; the image F has nonzeros only in rows
  // and columns i, j: F(k, j) = Acl(i, k) + [k = i] Acl(j, j) + [k = j] Acl(i, j),
  // F(k, i) = Acl(j, k) + [k = i] Acl(j, i) + [k = j] Acl(i, i)   (i < j),
  // F(k, i) = Acl(i, k) + [k = i] Acl(i, i)                         (i = j).
  static int jac(double tau, N_Vector yv, N_Vector, SUNMatrix J, void* user, N_Vector, N_Vector,
                 N_Vector) {
    auto& s = *static_cast<RiccatiSolver*>(user);
    if (!s.evaluate(tau, N_VGetArrayPointer(yv))) return -1;
    s.Acl = s.A;
    s.Acl.noalias() -= s.B * s.K;
    SUNMatZero(J);
    const Eigen::Index n = s.nx;
    const auto& C = s.Acl;
    for (Eigen::Index j = 0; j < n; ++j) {
      for (Eigen::Index i = 0; i <= j; ++i) {
        double* col = SM_COLUMN_D(J, packedIndex(i, j));
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

  // Matrix-free Newton: A_cl at (τ, y) once per setup, then Jv = A_clᵀV + V A_cl per product.
  static int jtSetup(double tau, N_Vector yv, N_Vector, void* user) {
    auto& s = *static_cast<RiccatiSolver*>(user);
    if (!s.evaluate(tau, N_VGetArrayPointer(yv))) return -1;
    s.Acl = s.A;
    s.Acl.noalias() -= s.B * s.K;
    return 0;
  }
  static int jtimes(N_Vector v, N_Vector Jv, double, N_Vector, N_Vector, void* user, N_Vector) {
    auto& s = *static_cast<RiccatiSolver*>(user);
    unpack(N_VGetArrayPointer(v), s.nx, s.S);  // S is free between right-hand sides
    s.F.noalias() = s.Acl.transpose() * s.S;
    double* out = N_VGetArrayPointer(Jv);
    for (Eigen::Index j = 0; j < s.nx; ++j) {
      double* col = out + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = s.F(i, j) + s.F(j, i);
    }
    return 0;
  }

  static void errorHandler(int code, const char* module, const char* function, char* msg,
                           void* user) {
    auto& s = *static_cast<RiccatiSolver*>(user);
    if (code < 0) {  // warnings (code > 0) are dropped; the last error is kept
      s.cvodeMessage = std::string(module) + "::" + function + ": " + msg;
    }
  }
};

double RiccatiSolution::validFrom() const {
  return steps_.empty() ? tf_ : tf_ - steps_.back().tau;
}

std::vector<double> RiccatiSolution::stepTimes() const {
  std::vector<double> t;
  t.reserve(steps_.size());
  for (auto it = steps_.rbegin(); it != steps_.rend(); ++it) t.push_back(tf_ - it->tau);
  return t;
}

void RiccatiSolution::S(double t, Eigen::MatrixXd& out) const {
  if (steps_.empty()) throw std::out_of_range("RiccatiSolution: empty solution");
  const double tauMax = steps_.back().tau;
  double tau = tf_ - t;
  const double slack = 1e-12 * std::max({1.0, std::abs(t0_), std::abs(tf_)});
  if (!(tau >= -slack && tau <= tauMax + slack)) {
    std::ostringstream m;
    m << "RiccatiSolution: t = " << t << " is outside [" << tf_ - tauMax << ", " << tf_ << "]";
    throw std::out_of_range(m.str());
  }
  tau = std::clamp(tau, 0.0, tauMax);
  // First stored step with τ_k ≥ τ; its polynomial covers [τ_{k-1}, τ_k].
  const auto it = std::lower_bound(steps_.begin(), steps_.end(), tau,
                                   [](const Step& s, double v) { return s.tau < v; });
  const Step& st = *it;
  const double dt = tau - st.tau;
  const Eigen::Index q = st.D.cols() - 1;
  // Horner on Σ D_k dtᵏ / k!.
  Eigen::VectorXd y = st.D.col(q);
  for (Eigen::Index k = q; k-- > 0;) y = st.D.col(k) + (dt / static_cast<double>(k + 1)) * y;
  out.resize(nx_, nx_);
  if (st.factored) {
    Eigen::MatrixXd U = Eigen::MatrixXd::Zero(nx_, nx_);
    unpackUpper(y.data(), nx_, U);
    out.noalias() = U.transpose() * U;  // symmetric PSD by construction
  } else {
    unpack(y.data(), nx_, out);
  }
}

Eigen::MatrixXd RiccatiSolution::S(double t) const {
  Eigen::MatrixXd out;
  S(t, out);
  return out;
}

Eigen::MatrixXd RiccatiSolution::K(double t) const {
  const Eigen::MatrixXd St = S(t);  // checks the range
  const auto n = static_cast<std::ptrdiff_t>(gainTimes_.size());
  if (n == 0) throw std::out_of_range("RiccatiSolution::K: no stored gain nodes");
  if (n == 1) return gainNodes_[0] * St;
  // The four nearest nodes (fewer when there are fewer): Lagrange cubic in t.
  const auto it = std::lower_bound(gainTimes_.begin(), gainTimes_.end(), t);
  std::ptrdiff_t hi = std::clamp<std::ptrdiff_t>(it - gainTimes_.begin(), 1, n - 1);
  std::ptrdiff_t first = std::clamp<std::ptrdiff_t>(hi - 2, 0, std::max<std::ptrdiff_t>(0, n - 4));
  const std::ptrdiff_t last = std::min<std::ptrdiff_t>(first + 3, n - 1);
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(nu_, nx_);
  for (std::ptrdiff_t i = first; i <= last; ++i) {
    double w = 1.0;
    for (std::ptrdiff_t j = first; j <= last; ++j) {
      if (j != i) w *= (t - gainTimes_[static_cast<std::size_t>(j)]) /
                       (gainTimes_[static_cast<std::size_t>(i)] - gainTimes_[static_cast<std::size_t>(j)]);
    }
    if (t == gainTimes_[static_cast<std::size_t>(i)]) return gainNodes_[static_cast<std::size_t>(i)] * St;
    G += w * gainNodes_[static_cast<std::size_t>(i)];
  }
  return G * St;
}

RiccatiSolution solveRiccati(double t0, double T, int nx, int nu,
                             const LinearizationCallback& linearization, const LqrWeights& weights,
                             const RiccatiOptions& options) {
  options.validate();
  if (!(t0 < T) || !std::isfinite(t0) || !std::isfinite(T)) {
    std::ostringstream m;
    m << "solveRiccati: need finite t0 < T, got t0 = " << t0 << ", T = " << T;
    throw std::invalid_argument(m.str());
  }
  if (nx <= 0 || nu < 0) {
    throw std::invalid_argument("solveRiccati: need nx > 0 and nu >= 0, got nx = " +
                                std::to_string(nx) + ", nu = " + std::to_string(nu));
  }
  if (!linearization) throw std::invalid_argument("solveRiccati: empty linearization callback");
  checkWeightMatrix(weights.Qf, "Qf", nx, false);
  for (double t : {t0, 0.5 * (t0 + T), T}) {
    Eigen::MatrixXd Q = weights.Q, R = weights.R;
    if (weights.Qfun) {
      Q.setZero(nx, nx);
      weights.Qfun(t, Q);
    }
    if (weights.Rfun) {
      R.setZero(nu, nu);
      weights.Rfun(t, R);
    }
    checkWeightMatrix(Q, weights.Qfun ? "Q(t)" : "Q", nx, false);
    checkWeightMatrix(R, weights.Rfun ? "R(t)" : "R", nu, true);
    if (!weights.Qfun && !weights.Rfun) break;
  }

  RiccatiSolution sol;
  sol.nx_ = nx;
  sol.nu_ = nu;
  sol.t0_ = t0;
  sol.tf_ = T;

  const sunindextype N = static_cast<sunindextype>(nx) * (nx + 1) / 2;
  const double tauEnd = T - t0;
  RiccatiSolver solver(nx, nu, T, linearization, weights);

  detail::CvodeSession cv;
  cv.context.reset(detail::createContext());
  SUNContext ctx = cv.context.get();
  cv.y.reset(N_VNew_Serial(N, ctx));
  cv.dky.reset(N_VNew_Serial(N, ctx));
  if (!cv.y || !cv.dky) throw std::runtime_error("solveRiccati: N_VNew_Serial failed");
  double* y = N_VGetArrayPointer(cv.y.get());
  bool factored = options.method == RiccatiMethod::kFactored;
  solver.factored = factored;
  if (factored) {
    // U(T) = chol(Qf + shift·I), upper triangular.
    Eigen::MatrixXd Qf = 0.5 * (weights.Qf + weights.Qf.transpose());
    Qf.diagonal().array() += options.factoredQfShift;
    Eigen::LLT<Eigen::MatrixXd> llt(Qf);
    Eigen::MatrixXd U0 = llt.matrixU();
    if (llt.info() != Eigen::Success || !(U0.diagonal().array() > 0.0).all()) {
      const double lmin = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(
                              weights.Qf, Eigen::EigenvaluesOnly).eigenvalues()(0);
      std::ostringstream m;
      m << "solveRiccati: RiccatiMethod::kFactored needs Qf + factoredQfShift*I positive definite"
        << " (Qf's smallest eigenvalue is " << lmin << ", factoredQfShift = "
        << options.factoredQfShift << "); set RiccatiOptions.factoredQfShift > 0 to regularize";
      throw std::invalid_argument(m.str());
    }
    pack(U0, nx, y);  // pack reads the upper triangle
  } else {
    pack(weights.Qf, nx, y);
  }
  auto normOf = [&](const double* yk) { return factored ? factorNorm(yk, nx) : maxAbs(yk, N); };

  const bool bdf = options.method != RiccatiMethod::kAdams;
  cv.cvode.reset(CVodeCreate(bdf ? CV_BDF : CV_ADAMS, ctx));
  void* mem = cv.cvode.get();
  if (!mem) throw std::runtime_error("solveRiccati: CVodeCreate failed");
  auto check = [&](int flag, const char* call) {
    if (flag < 0) {
      throw std::runtime_error(std::string("solveRiccati: ") + call + " failed with flag " +
                               std::to_string(flag) + ": " + solver.cvodeMessage);
    }
  };
  check(CVodeSetErrHandlerFn(mem, &RiccatiSolver::errorHandler, &solver), "CVodeSetErrHandlerFn");
  check(CVodeInit(mem, &RiccatiSolver::rhsDispatch, 0.0, cv.y.get()),
        "CVodeInit");
  check(CVodeSStolerances(mem, options.rtol, options.atol), "CVodeSStolerances");
  check(CVodeSetUserData(mem, &solver), "CVodeSetUserData");
  check(CVodeSetMaxNumSteps(mem, options.maxSteps), "CVodeSetMaxNumSteps");
  check(CVodeSetStopTime(mem, tauEnd), "CVodeSetStopTime");
  if (options.initialStep > 0) check(CVodeSetInitStep(mem, options.initialStep), "CVodeSetInitStep");
  if (options.maxStep > 0) check(CVodeSetMaxStep(mem, options.maxStep), "CVodeSetMaxStep");
  const bool krylov =
      options.linearSolver == RiccatiLinearSolver::kKrylov ||
      (options.linearSolver == RiccatiLinearSolver::kAuto && nx > 10);
  if (bdf && krylov) {
    const bool prec = options.krylovPreconditioner;
    cv.linearSolver.reset(
        SUNLinSol_SPGMR(cv.y.get(), prec ? SUN_PREC_LEFT : SUN_PREC_NONE, 0, ctx));
    if (!cv.linearSolver) throw std::runtime_error("solveRiccati: SPGMR solver");
    check(CVodeSetLinearSolver(mem, cv.linearSolver.get(), nullptr), "CVodeSetLinearSolver");
    // Factored: CVODES' difference-quotient Jacobian-vector products (the default).
    if (!factored) {
      check(CVodeSetJacTimes(mem, &RiccatiSolver::jtSetup, &RiccatiSolver::jtimes),
            "CVodeSetJacTimes");
    }
    if (prec) {
      check(CVodeSetPreconditioner(mem, &RiccatiSolver::precSetup, &RiccatiSolver::precSolve),
            "CVodeSetPreconditioner");
    }
  } else if (bdf) {
    cv.jacobian.reset(SUNDenseMatrix(N, N, ctx));
    cv.linearSolver.reset(SUNLinSol_Dense(cv.y.get(), cv.jacobian.get(), ctx));
    if (!cv.jacobian || !cv.linearSolver) throw std::runtime_error("solveRiccati: dense solver");
    check(CVodeSetLinearSolver(mem, cv.linearSolver.get(), cv.jacobian.get()),
          "CVodeSetLinearSolver");
    if (options.exactJacobian && !factored) {
      check(CVodeSetJacFn(mem, &RiccatiSolver::jac), "CVodeSetJacFn");
    }
  } else {
    cv.nonlinearSolver.reset(SUNNonlinSol_FixedPoint(cv.y.get(), 0, ctx));
    if (!cv.nonlinearSolver) throw std::runtime_error("solveRiccati: fixed-point solver");
    check(CVodeSetNonlinearSolver(mem, cv.nonlinearSolver.get()), "CVodeSetNonlinearSolver");
  }

  // τ = 0: S = Qf (a constant "polynomial").
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(nx);
  sol.minEigenvalue = std::numeric_limits<double>::infinity();
  sol.maxEigenvalue = -std::numeric_limits<double>::infinity();
  Eigen::MatrixXd Sk(nx, nx);
  auto trackEigen = [&](const double* yk) {
    if (!options.trackEigenvalues) return;
    if (factored) {
      Eigen::MatrixXd Uk = Eigen::MatrixXd::Zero(nx, nx);
      unpackUpper(yk, nx, Uk);
      Sk.noalias() = Uk.transpose() * Uk;
    } else {
      unpack(yk, nx, Sk);
    }
    eig.compute(Sk, Eigen::EigenvaluesOnly);
    sol.minEigenvalue = std::min(sol.minEigenvalue, eig.eigenvalues()(0));
    sol.maxEigenvalue = std::max(sol.maxEigenvalue, eig.eigenvalues()(nx - 1));
  };
  sol.steps_.push_back({0.0, Eigen::Map<Eigen::VectorXd>(y, N), factored});
  trackEigen(y);
  // G = R⁻¹Bᵀ at a node, so that K(t) needs neither the model nor the callbacks later.
  Eigen::MatrixXd An(nx, nx), Bn(nx, nu), Rn = weights.R;
  std::string nodeError;
  auto storeGain = [&](double t) {
    try {
      linearization(t, An, Bn);
      if (weights.Rfun) {
        Rn.setZero(nu, nu);
        weights.Rfun(t, Rn);
      }
      Eigen::LLT<Eigen::MatrixXd> llt(Rn);
      if (An.rows() != nx || Bn.rows() != nx || Bn.cols() != nu || llt.info() != Eigen::Success ||
          !Bn.allFinite()) {
        nodeError = "B(t) or R(t) invalid (size, non-finite, R not positive definite) at t = " + std::to_string(t);
        return false;
      }
      sol.gainTimes_.push_back(t);
      sol.gainNodes_.push_back(llt.solve(Bn.transpose()));
      return true;
    } catch (const std::exception& e) {
      nodeError = std::string("callback threw at t = ") + std::to_string(t) + ": " + e.what();
      return false;
    }
  };
  if (!storeGain(T)) {
    sol.status = RiccatiStatus::kCallbackFailure;
    sol.failureTime = T;
    sol.message = "Riccati solve: " + nodeError;
    return sol;
  }

  double tau = 0.0;
  double lastNorm = normOf(y);
  long taken = 0;
  // CVODES' counters restart at CVodeReInit (the switch below): accumulate them.
  auto addCounters = [&] {
    long v = 0;
    if (CVodeGetNumSteps(mem, &v) >= 0) sol.steps += v;
    if (CVodeGetNumRhsEvals(mem, &v) >= 0) sol.rhsEvaluations += v;
    if (bdf && CVodeGetNumJacEvals(mem, &v) >= 0) sol.jacobianEvaluations += v;
    if (bdf && krylov && CVodeGetNumLinIters(mem, &v) >= 0) sol.linearIterations += v;
    if (bdf && krylov && CVodeGetNumPrecSolves(mem, &v) >= 0) sol.preconditionerSolves += v;
  };
  while (tau < tauEnd) {
    // CV_ONE_STEP applies CVodeSetMaxNumSteps per call, so the budget over the horizon is ours.
    if (++taken > options.maxSteps) {
      sol.status = RiccatiStatus::kIntegratorFailure;
      sol.failureTime = T - tau;
      sol.failureNorm = lastNorm;
      std::ostringstream m;
      m << "Riccati solve stopped at t = " << sol.failureTime << " (max |S_ij| = " << lastNorm
        << "): more than maxSteps = " << options.maxSteps << " steps (too much work)";
      sol.message = m.str();
      break;
    }
    const int flag = CVode(mem, tauEnd, cv.y.get(), &tau, CV_ONE_STEP);
    if (flag < 0) {
      double tcur = tau;
      CVodeGetCurrentTime(mem, &tcur);
      // A failed callback names its own time (a trial point inside the step that failed);
      // otherwise CVODES' current time, the last point it reached.
      sol.failureTime = solver.failed ? solver.failTime : T - tcur;
      sol.failureNorm = lastNorm;
      sol.status = solver.failed ? solver.failStatus : RiccatiStatus::kIntegratorFailure;
      char* name = CVodeGetReturnFlagName(flag);
      std::ostringstream m;
      m << "Riccati solve stopped at t = " << sol.failureTime << " (max |S_ij| = " << lastNorm
        << " at the last accepted step): ";
      if (solver.failed) m << solver.callbackMessage << "; ";
      m << "CVODES " << (name ? name : "error") << " (" << flag << ")";
      if (!solver.cvodeMessage.empty()) m << ": " << solver.cvodeMessage;
      std::free(name);
      sol.message = m.str();
      break;
    }
    int q = 0;
    CVodeGetLastOrder(mem, &q);
    RiccatiSolution::Step st{tau, Eigen::MatrixXd(N, q + 1), factored};
    for (int k = 0; k <= q; ++k) {
      if (CVodeGetDky(mem, tau, k, cv.dky.get()) < 0) {
        st.D.conservativeResize(N, k);
        break;
      }
      st.D.col(k) = Eigen::Map<Eigen::VectorXd>(N_VGetArrayPointer(cv.dky.get()), N);
    }
    const double norm = normOf(y);
    if (!std::isfinite(norm) || !st.D.allFinite()) {
      sol.status = RiccatiStatus::kNonFinite;
      sol.failureTime = T - tau;
      sol.failureNorm = lastNorm;
      std::ostringstream m;
      m << "S became non-finite at t = " << sol.failureTime << " (max |S_ij| = " << lastNorm
        << " at the previous step)";
      sol.message = m.str();
      break;
    }
    const double tauPrev = sol.steps_.back().tau;
    sol.steps_.push_back(std::move(st));
    trackEigen(y);
    if (!storeGain(T - 0.5 * (tauPrev + tau)) || !storeGain(T - tau)) {
      sol.steps_.pop_back();
      sol.status = RiccatiStatus::kCallbackFailure;
      sol.failureTime = T - tau;
      sol.failureNorm = lastNorm;
      sol.message = "Riccati solve stopped: " + nodeError;
      if (sol.gainTimes_.size() > 2 * sol.steps_.size() - 1) {
        sol.gainTimes_.resize(2 * sol.steps_.size() - 1);
        sol.gainNodes_.resize(2 * sol.steps_.size() - 1);
      }
      break;
    }
    if (norm > options.maxNorm) {
      sol.status = RiccatiStatus::kBlowUp;
      sol.failureTime = T - tau;
      sol.failureNorm = norm;
      std::ostringstream m;
      m << "S blew up at t = " << sol.failureTime << ": max |S_ij| = " << norm
        << " > maxNorm = " << options.maxNorm;
      sol.message = m.str();
      break;
    }
    lastNorm = norm;
    if (flag == CV_TSTOP_RETURN) break;
    // Factored form near a singular S: U⁻¹ amplifies the integration error of U's small diagonal
    // entries, the problem turns stiff in U although S itself is smooth (thousands of steps, or
    // too much work). Past cond(S) = (max U_ii / min U_ii)² > factoredSwitchCondition the rest of
    // the horizon is integrated in the plain form on S = UᵀU (see the header).
    if (factored && options.factoredSwitchCondition > 0.0) {
      Eigen::MatrixXd Uk = Eigen::MatrixXd::Zero(nx, nx);
      unpackUpper(y, nx, Uk);
      const Eigen::ArrayXd d = Uk.diagonal().array().abs();
      const double ratio = d.minCoeff() / d.maxCoeff();
      if (!(ratio * ratio * options.factoredSwitchCondition > 1.0)) {
        const Eigen::MatrixXd Sk2 = Uk.transpose() * Uk;
        pack(Sk2, nx, y);
        factored = false;
        solver.factored = false;
        solver.aclOk = false;
        sol.switchedToPlainAt = T - tau;
        addCounters();
        check(CVodeReInit(mem, tau, cv.y.get()), "CVodeReInit");  // rhsDispatch now takes the plain form
        check(CVodeSetStopTime(mem, tauEnd), "CVodeSetStopTime");
        if (bdf && krylov) {
          check(CVodeSetJacTimes(mem, &RiccatiSolver::jtSetup, &RiccatiSolver::jtimes), "CVodeSetJacTimes");
        } else if (bdf && options.exactJacobian) {
          check(CVodeSetJacFn(mem, &RiccatiSolver::jac), "CVodeSetJacFn");
        }
        lastNorm = normOf(y);
      }
    }
  }
  addCounters();
  if (!options.trackEigenvalues) sol.minEigenvalue = sol.maxEigenvalue = 0.0;
  std::reverse(sol.gainTimes_.begin(), sol.gainTimes_.end());
  std::reverse(sol.gainNodes_.begin(), sol.gainNodes_.end());
  return sol;
}

LinearizationCallback makeTrajectoryLinearization(const Model& model, const Trajectory& trajectory) {
  trajectory.checkCompatible(model);
  if (!trajectory.hasStateDerivatives()) {
    throw std::logic_error(
        "makeTrajectoryLinearization: the trajectory has no state derivatives "
        "(call computeStateDerivatives)");
  }
  struct State {
    const Model* model;
    Trajectory traj;
    Data data;
    Eigen::VectorXd x, u, q, dq;
  };
  auto st = std::make_shared<State>(State{&model, trajectory, Data(model), {}, {}, {}, {}});
  return [st](double t, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
    st->traj.evaluate(t, st->x, st->u);
    const int n = st->traj.nq();
    st->q = st->x.head(n);
    st->dq = st->x.tail(n);
    const DynamicsStatus s = computeLinearization(*st->model, st->data, st->q, st->dq, st->u);
    if (!s.ok()) {
      throw std::runtime_error("linearization failed at t = " + std::to_string(t) + ": " +
                               s.message);
    }
    A = st->data.A;
    B = st->data.B;
  };
}

RiccatiSolution solveRiccati(const Model& model, const Trajectory& trajectory,
                             const LqrWeights& weights, const RiccatiOptions& options) {
  return solveRiccati(trajectory.startTime(), trajectory.endTime(), trajectory.nx(),
                      trajectory.nu(), makeTrajectoryLinearization(model, trajectory), weights,
                      options);
}

}  // namespace trellis
