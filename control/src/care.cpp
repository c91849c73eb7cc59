// care.cpp — the continuous algebraic Riccati equation: scaled sign function of the balanced
// Hamiltonian (in its symmetric form, on LAPACK's symmetric indefinite inverse), then
// Newton–Kleinman steps (Lyapunov solves on LAPACK's Schur form; see
// trellis/control/algebraic_riccati.hpp).
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

  // Sign iteration Z ← (Z/c + c Z⁻¹)/2, c = |det Z|^{1/2n}, until Z = sign(H), H balanced. Every
  // iterate is Hamiltonian, so it is carried as the symmetric W = J Z (J = [[0, I], [−I, 0]]):
  //   W ← (W/c + c J W⁻¹ J)/2,  J Y J = [[−Y22, Y21], [Y12, −Y11]],
  // since Z⁻¹ = (−J W)⁻¹ = W⁻¹ J (Byers' structured iteration). W⁻¹ is LAPACK's symmetric
  // indefinite inverse (Bunch–Kaufman, n³ flops for the 2n×2n matrix instead of 2n³ by LU), and
  // |det Z| = |det W|. W, its inverse Y and the pivots are allocated here, once per solve.
  MatrixXd W(2 * n, 2 * n), Y(2 * n, 2 * n);
  W << -p.Q, -p.A.transpose(), -p.A, p.G;
  detail::lapack::SymmetricInverse inverse(2 * n);
  bool scaling = true, converged = false;
  int stalled = 0;
  double prev = std::numeric_limits<double>::infinity();
  for (int it = 0; it < options.maxIterations; ++it) {
    res.iterations = it + 1;
    Y = W;
    double logdet = 0.0;
    if (inverse.invert(Y, logdet) != 0) {
      diagnoseFailure(res, p, false, options, "solveCare",
                      "the sign iteration met an exactly singular matrix at iteration " +
                          std::to_string(it + 1));
      return res;
    }
    const double c = scaling ? std::exp(logdet / static_cast<double>(2 * n)) : 1.0;
    // The next iterate, in place of W⁻¹: (W/c + c J Y J)/2, J Y J by swapping Y's blocks.
    Y.topLeftCorner(n, n).swap(Y.bottomRightCorner(n, n));
    Y.topRightCorner(n, n).swap(Y.bottomLeftCorner(n, n));
    Y.topLeftCorner(n, n) *= -1.0;
    Y.bottomRightCorner(n, n) *= -1.0;
    Y = 0.5 * (W / c + c * Y);
    if (!Y.allFinite()) {
      diagnoseFailure(res, p, false, options, "solveCare",
                      "the sign iteration overflowed at iteration " + std::to_string(it + 1));
      return res;
    }
    // ‖·‖₁ of J X equals that of X (J permutes rows and flips signs): the same test as on Z.
    const double rel = (Y - W).lpNorm<1>() / std::max(1.0, Y.lpNorm<1>());
    W.swap(Y);
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
  // Z = sign(H) = −J W = [[−W21, −W22], [W11, W12]].
  const MatrixXd Z = (MatrixXd(2 * n, 2 * n) << -W.bottomLeftCorner(n, n), -W.bottomRightCorner(n, n),
                      W.topLeftCorner(n, n), W.topRightCorner(n, n)).finished();
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
