// manifold_riccati.cpp — solveManifoldRiccati: the Riccati equation on the reduced system
// (Ar, Br, Qr) along the transported basis, and the held solution's full-state K(t), S(t).
#include "trellis/control/manifold_lqr.hpp"

#include "reduced_problem.hpp"
#include "trellis/core/detail/report_json.hpp"
#include "trellis/core/trajectory.hpp"

#include <memory>
#include <stdexcept>
#include <string>

namespace trellis {

std::string ManifoldRiccatiSolution::describe() const {
  return status.describe() + " (tangent dimension " + std::to_string(dimension()) + " of " +
         std::to_string(nx()) + "; reduced Riccati: " + reduced.describe() + ")";
}

std::string ManifoldRiccatiSolution::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["nx"] = nx();
  j["tangent_dimension"] = dimension();
  j["transport_steps"] = basis.steps();
  j["max_basis_correction"] = detail::toJson(basis.maxCorrection());
  j["linearizations"] = linearizations;
  j["riccati"] = detail::ReportJson::parse(reduced.json());
  return j.dump();
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
  if (!sol.basis.ok()) {
    sol.status.set(ManifoldRiccatiCode::kTransportFailure, sol.basis.status().message,
                   sol.basis.status().t);
    return sol;
  }

  // The reduced problem's callbacks (and with them the model) live only for the solve:
  // solveRiccati's result keeps none of them (reduced_problem.hpp).
  const detail::ReducedProblem problem = detail::makeReducedProblem(model, sol.basis, weights);
  const int d = sol.basis.dimension();
  LqrWeights reducedWeights = problem.weights;
  const ReferenceStatus terminal = problem.reducedTerminal(weights.Qf, reference.endTime(), reducedWeights.Qf);
  if (!terminal.ok()) {
    // The dynamics failed at tf: nothing else can run.
    sol.status.set(ManifoldRiccatiCode::kTerminalFailure,
                   "manifold Riccati: the reduced linearization at tf failed: " + terminal.message,
                   reference.endTime());
    return sol;
  }

  sol.reduced = solveRiccati(reference.startTime(), reference.endTime(), d, nu, problem.linearization,
                             reducedWeights, options);
  sol.linearizations = problem.evaluator->evaluations();
  if (sol.reduced.ok()) {
    sol.status = {};
  } else {
    sol.status.set(ManifoldRiccatiCode::kRiccatiFailure, sol.reduced.status.describe(),
                   sol.reduced.status.t);
  }
  return sol;
}

}  // namespace trellis
