// simulation_result.cpp — argument checks of simulate() and the result built from the event
// loop's record (see simulation_run.hpp).
#include "simulation_run.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/model.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace trellis::detail {

void checkSimulationArguments(const Model& model, const Eigen::VectorXd& x0, double t0, double t1,
                              const SimulationOptions& options, const Trajectory* reference) {
  options.validate();
  const int m = model.nu(), nx = 2 * model.nq();
  if (!std::isfinite(t0) || !std::isfinite(t1) || !(t0 < t1)) {
    throw std::invalid_argument("simulate: need finite t0 < t1, got t0 = " + formatTime(t0) +
                                ", t1 = " + formatTime(t1));
  }
  if (x0.size() != nx) {
    throw std::invalid_argument("simulate: x0 has size " + std::to_string(x0.size()) +
                                ", expected 2n = " + std::to_string(nx));
  }
  for (Eigen::Index i = 0; i < nx; ++i) {
    if (!std::isfinite(x0(i))) {
      throw std::invalid_argument("simulate: x0[" + std::to_string(i) +
                                  "] = " + std::to_string(x0(i)) + " is not finite");
    }
  }
  for (const auto* bound : {&options.inputLower, &options.inputUpper}) {
    if (bound->size() != 0 && bound->size() != m) {
      throw std::invalid_argument(std::string("simulate: SimulationOptions.") +
                                  (bound == &options.inputLower ? "inputLower" : "inputUpper") +
                                  " has size " + std::to_string(bound->size()) +
                                  ", expected the model's " + std::to_string(m) +
                                  " inputs (or empty)");
    }
  }
  const double scale = std::max({1.0, std::abs(t0), std::abs(t1)});
  if (reference) {
    reference->checkCompatible(model);
    if (reference->startTime() > t0 + 1e-12 * scale || reference->endTime() < t1 - 1e-12 * scale) {
      throw std::invalid_argument("simulate: the reference covers [" +
                                  formatTime(reference->startTime()) + ", " +
                                  formatTime(reference->endTime()) + "], which does not contain [" +
                                  formatTime(t0) + ", " + formatTime(t1) + "]");
    }
  } else if (options.outputStep == 0.0) {
    throw std::invalid_argument(
        "simulate: SimulationOptions.outputStep = 0 (output at the reference's knots) needs a "
        "reference; give outputStep > 0");
  }
}

void assembleResult(const Model& model, const SimulationRecord& record, bool haveReference,
                    SimulationResult& result) {
  const int n = model.nq(), nx = 2 * n;
  const auto recorded = static_cast<Eigen::Index>(record.times.size());
  if (recorded > 0) {
    const Eigen::VectorXd times = Eigen::Map<const Eigen::VectorXd>(record.times.data(), recorded);
    result.trajectory = Trajectory(model.configNames(), model.inputNames(), times,
                                   record.states.leftCols(recorded),
                                   record.inputs.leftCols(recorded));
    // ẋ = [q̇; q̈(q, q̇, u)] at the recorded points, so that the result can serve as a reference.
    Data data(model);
    Eigen::VectorXd q(n), dq(n), u(model.nu());
    Eigen::MatrixXd xdot(nx, recorded);
    bool derivativesOk = true;
    for (Eigen::Index k = 0; k < recorded && derivativesOk; ++k) {
      q = record.states.col(k).head(n);
      dq = record.states.col(k).tail(n);
      u = record.inputs.col(k);
      derivativesOk = computeDynamics(model, data, q, dq, u).ok();
      xdot.col(k).head(n) = dq;
      xdot.col(k).tail(n) = data.qdd;
    }
    if (derivativesOk && xdot.allFinite()) result.trajectory.setStateDerivatives(std::move(xdot));
  }
  result.constraintDrift = record.drift.head(recorded);
  result.trackingError = record.tracking.head(haveReference ? recorded : 0);
  result.saturatedFraction =
      result.controlSamples > 0
          ? static_cast<double>(result.saturatedSamples) / result.controlSamples
          : 0.0;
}

}  // namespace trellis::detail
