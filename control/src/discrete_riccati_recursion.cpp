// discrete_riccati_recursion.cpp — the finite-horizon Riccati difference equation.
#include "trellis/control/discrete_riccati_recursion.hpp"

#include "algebraic_riccati_common.hpp"  // checkSystem
#include "trellis/control/riccati.hpp"   // checkWeightMatrix

#include <Eigen/Cholesky>

#include <stdexcept>
#include <string>

namespace trellis {

using Eigen::MatrixXd;

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
  detail::are::checkSystem(Ad, Bd, "solveDiscreteRiccatiRecursion");
  return solveDiscreteRiccatiRecursion(
      [&](int, MatrixXd& A, MatrixXd& B) {
        A = Ad;
        B = Bd;
      },
      static_cast<int>(Ad.rows()), static_cast<int>(Bd.cols()), Q, R, Qf, N);
}

}  // namespace trellis
