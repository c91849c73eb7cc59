// dare.cpp — the discrete algebraic Riccati equation: structure-preserving doubling, then Newton
// (Hewer) steps (see trellis/control/algebraic_riccati.hpp).
#include "trellis/control/dare.hpp"

#include "algebraic_riccati_common.hpp"
#include "trellis/control/riccati.hpp"  // checkWeightMatrix
#include "trellis/control/stein.hpp"

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

using namespace detail::are;

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
    // A singular correction equation ends the refinement (X stays the last accepted iterate).
    const MatrixEquationSolution delta = solveStein(p.A - p.B * Kv, Res);
    if (!delta.ok()) break;
    MatrixXd Xn = X + delta.X;
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

}  // namespace trellis
