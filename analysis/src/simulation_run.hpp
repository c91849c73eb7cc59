// simulation_run.hpp (private) — the pieces of simulate(): argument checks, the event loop that
// drives the integrator, and the assembly of the result from what the loop recorded.
#pragma once

#include "closed_loop_system.hpp"
#include "trellis/analysis/simulation.hpp"

#include <Eigen/Core>

#include <vector>

namespace trellis::detail {

/// Throws std::invalid_argument (or TrajectoryError) naming the offending argument. The reference
/// (optional) must match the model and cover [t0, t1].
void checkSimulationArguments(const Model& model, const Eigen::VectorXd& x0, double t0, double t1,
                              const SimulationOptions& options, const Trajectory* reference);

/// What the event loop recorded at the output times (columns 0 … count−1 are filled).
struct SimulationRecord {
  std::vector<double> times;
  Eigen::MatrixXd states, inputs;
  Eigen::VectorXd drift, tracking;
};

/// The event loop (simulation_loop.cpp) after checkSimulationArguments; `reference` (optional)
/// has state derivatives.
SimulationResult runSimulation(const Model& model, const Eigen::VectorXd& x0, double t0, double t1,
                               const InputLaw& law, const SimulationOptions& options,
                               const Trajectory* reference);

/// Fills result.trajectory (with the state derivatives at the recorded points), the drift, the
/// tracking error and the saturated fraction from the record.
void assembleResult(const Model& model, const SimulationRecord& record, bool haveReference,
                    SimulationResult& result);

}  // namespace trellis::detail
