// manifold_riccati.cpp — solveManifoldRiccati: the Riccati equation on the reduced system
// (Ar, Br, Qr) along the transported basis, and the held solution's full-state K(t), S(t).
#include "trellis/control/manifold_lqr.hpp"

#include "reduced_problem.hpp"
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

  // The reduced problem's callbacks (and with them the model) live only for the solve:
  // solveRiccati's result keeps none of them (reduced_problem.hpp).
  const detail::ReducedProblem problem = detail::makeReducedProblem(model, sol.basis, weights);
  const int d = sol.basis.dimension();
  LqrWeights reducedWeights = problem.weights;
  try {
    reducedWeights.Qf = problem.reducedTerminal(weights.Qf, reference.endTime());
  } catch (const std::exception& e) {
    // The dynamics failed at tf: report it as a failed solve (nothing else can run).
    sol.reduced.status = RiccatiStatus::kCallbackFailure;
    sol.reduced.failureTime = reference.endTime();
    sol.reduced.message = std::string("manifold Riccati: basis at tf failed: ") + e.what();
    return sol;
  }

  sol.reduced = solveRiccati(reference.startTime(), reference.endTime(), d, nu, problem.linearization,
                             reducedWeights, options);
  sol.linearizations = problem.evaluator->evaluations();
  return sol;
}

}  // namespace trellis
