// riccati_trajectory.cpp — the Riccati solve along a trajectory: A(t), B(t) from the exact
// linearization at the trajectory's interpolated state and input.
#include "trellis/control/riccati.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <memory>
#include <stdexcept>
#include <string>

namespace trellis {

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
  const int n = trajectory.nq();
  st->q.resize(n);
  st->dq.resize(n);
  return [st](double t, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
    st->traj.evaluate(t, st->x, st->u);
    const Eigen::Index n = st->q.size();
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
