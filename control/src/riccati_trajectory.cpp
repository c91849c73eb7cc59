// riccati_trajectory.cpp — the Riccati solve along a trajectory: A(t), B(t) from the exact
// linearization at the trajectory's interpolated state and input.
#include "trellis/control/riccati.hpp"
#include "trellis/core/reference.hpp"
#include "trellis/core/trajectory.hpp"

#include <memory>
#include <stdexcept>
#include <string>

namespace trellis {

LinearizationCallback makeTrajectoryLinearization(const Model& model, const Trajectory& trajectory) {
  // The one evaluator along a reference: it checks the names and the supplied state derivatives
  // once and owns its copy of the trajectory and its Data.
  ReferenceOptions checks;
  checks.stateDerivatives = ReferenceOptions::StateDerivatives::kRequireSupplied;
  checks.caller = "makeTrajectoryLinearization";
  auto reference = std::make_shared<ReferenceEvaluator>(model, trajectory, checks);
  return [reference](double t, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
    // The Riccati solver's callback contract: a failure is the returned status (kCallbackFailure).
    const ReferenceStatus status = reference->linearize(t);
    if (status.ok()) {
      A = reference->A();
      B = reference->B();
    }
    return status;
  };
}

RiccatiSolution solveRiccati(const Model& model, const Trajectory& trajectory,
                             const LqrWeights& weights, const RiccatiOptions& options) {
  return solveRiccati(trajectory.startTime(), trajectory.endTime(), trajectory.nx(),
                      trajectory.nu(), makeTrajectoryLinearization(model, trajectory), weights,
                      options);
}

}  // namespace trellis
