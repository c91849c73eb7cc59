// manifold_riccati.cpp — solveManifoldRiccati: the Riccati equation on the reduced system
// (Ar, Br, Qr) along the transported basis, and the held solution's full-state K(t), S(t).
#include "trellis/control/manifold_lqr.hpp"
#include "trellis/core/trajectory.hpp"

#include <memory>
#include <stdexcept>
#include <string>

namespace trellis {

const std::string& ManifoldRiccatiSolution::message() const {
  if (!basis.ok()) return basis.message();
  return reduced.message;
}

Eigen::MatrixXd ManifoldRiccatiSolution::K(double t) const {
  return reduced.K(t) * basis.basis(t).transpose();
}

Eigen::MatrixXd ManifoldRiccatiSolution::S(double t) const {
  const Eigen::MatrixXd T = basis.basis(t);
  Eigen::MatrixXd S = T * reduced.S(t) * T.transpose();
  return 0.5 * (S + S.transpose());
}

ManifoldRiccatiSolution solveManifoldRiccati(const Model& model, const Trajectory& reference,
                                             const LqrWeights& weights,
                                             const RiccatiOptions& options,
                                             const TangentTransportOptions& transport) {
  options.validate();
  const int nx = reference.nx(), nu = reference.nu();
  checkWeightMatrix(weights.Qf, "Qf", nx, false);
  if (!weights.Qfun) checkWeightMatrix(weights.Q, "Q", nx, false);
  if (!weights.Rfun) checkWeightMatrix(weights.R, "R", nu, true);

  ManifoldRiccatiSolution sol;
  sol.basis = transportTangentBasis(model, reference, transport);
  if (!sol.basis.ok()) return sol;

  // One evaluator serves the linearization and the Q callbacks (its cache gives one dynamics
  // evaluation per t). The callbacks, and with them the evaluator's reference to the model, live
  // only for the solve: solveRiccati's result keeps none of them.
  struct Shared {
    Shared(const Model& m, const TangentBasisTrajectory& b) : lin(m, b) {}
    ReducedLinearization lin;
    Eigen::MatrixXd Q, QT;
  };
  auto sh = std::make_shared<Shared>(model, sol.basis);
  const int d = sol.basis.dimension();

  LinearizationCallback lin = [sh](double t, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
    sh->lin.evaluate(t);
    A = sh->lin.Ar();
    B = sh->lin.Br();
  };
  LqrWeights reducedWeights;
  reducedWeights.R = weights.R;
  reducedWeights.Rfun = weights.Rfun;
  const Eigen::MatrixXd Qconst = weights.Q;
  const WeightCallback Qfull = weights.Qfun;
  reducedWeights.Qfun = [sh, Qconst, Qfull, nx](double t, Eigen::MatrixXd& Qr) {
    sh->lin.evaluate(t);
    const Eigen::MatrixXd& T = sh->lin.T();
    if (Qfull) {
      sh->Q.setZero(nx, nx);
      Qfull(t, sh->Q);
      if (sh->Q.rows() != nx || sh->Q.cols() != nx) {
        throw std::runtime_error("Q(t) callback returned " + std::to_string(sh->Q.rows()) + "x" +
                                 std::to_string(sh->Q.cols()) + ", expected " +
                                 std::to_string(nx) + "x" + std::to_string(nx));
      }
      sh->QT.noalias() = sh->Q * T;
    } else {
      sh->QT.noalias() = Qconst * T;
    }
    Qr.noalias() = T.transpose() * sh->QT;
    for (Eigen::Index j = 0; j < Qr.cols(); ++j) {  // exactly symmetric: upper triangle mirrored
      for (Eigen::Index i = j + 1; i < Qr.rows(); ++i) Qr(i, j) = Qr(j, i);
    }
  };
  try {
    sh->lin.evaluate(reference.endTime());
  } catch (const std::exception& e) {
    // The dynamics failed at tf: report it as a failed solve (nothing else can run).
    sol.reduced.status = RiccatiStatus::kCallbackFailure;
    sol.reduced.failureTime = reference.endTime();
    sol.reduced.message = std::string("manifold Riccati: basis at tf failed: ") + e.what();
    return sol;
  }
  const Eigen::MatrixXd& Tf = sh->lin.T();
  reducedWeights.Qf = Tf.transpose() * weights.Qf * Tf;
  reducedWeights.Qf = 0.5 * (reducedWeights.Qf + reducedWeights.Qf.transpose()).eval();

  sol.reduced = solveRiccati(reference.startTime(), reference.endTime(), d, nu, lin,
                             reducedWeights, options);
  sol.linearizations = sh->lin.evaluations();
  return sol;
}

}  // namespace trellis
