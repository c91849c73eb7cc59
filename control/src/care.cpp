// care.cpp — the continuous algebraic Riccati equation: scaled sign function of the balanced
// Hamiltonian (LAPACK's inverse), then Newton–Kleinman steps (Lyapunov solves on LAPACK's Schur
// form; see trellis/control/algebraic_riccati.hpp).
#include "trellis/control/care.hpp"

#include "algebraic_riccati_common.hpp"
#include "lapack.hpp"
#include "trellis/control/lyapunov.hpp"
#include "trellis/control/riccati.hpp"  // checkWeightMatrix

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

  // Sign iteration Z ← (Z/c + c Z⁻¹)/2, c = |det Z|^{1/2n}, until Z = sign(H), H balanced. The
  // inverse is LAPACK's (dgetrf + dgetri, blocked); Z, its inverse W and the pivots are allocated
  // here, once per solve.
  MatrixXd Z(2 * n, 2 * n), W(2 * n, 2 * n);
  Z << p.A, -p.G, -p.Q, -p.A.transpose();
  detail::lapack::LuInverse inverse(2 * n);
  bool scaling = true, converged = false;
  int stalled = 0;
  double prev = std::numeric_limits<double>::infinity();
  for (int it = 0; it < options.maxIterations; ++it) {
    res.iterations = it + 1;
    W = Z;
    double logdet = 0.0;
    if (inverse.invert(W, logdet) != 0) {
      diagnoseFailure(res, p, false, options, "solveCare",
                      "the sign iteration met an exactly singular matrix at iteration " +
                          std::to_string(it + 1));
      return res;
    }
    const double c = scaling ? std::exp(logdet / static_cast<double>(2 * n)) : 1.0;
    W = 0.5 * (Z / c + c * W);  // the next iterate, in place of Z⁻¹
    if (!W.allFinite()) {
      diagnoseFailure(res, p, false, options, "solveCare",
                      "the sign iteration overflowed at iteration " + std::to_string(it + 1));
      return res;
    }
    const double rel = (W - Z).lpNorm<1>() / std::max(1.0, W.lpNorm<1>());
    Z.swap(W);
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
    // A singular correction equation ends the refinement (X stays the last accepted iterate).
    const MatrixEquationSolution delta = solveLyapunov(p.A - p.G * X, Res);
    if (!delta.ok()) break;
    MatrixXd Xn = X + delta.X;
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

}  // namespace trellis
