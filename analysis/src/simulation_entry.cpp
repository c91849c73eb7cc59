// simulation_entry.cpp — the public simulate functions: a user policy, the open loop, the closed
// loop, and the batch of closed loops on threads. Each checks its arguments, sets up the input law
// and calls the event loop (simulation_loop.cpp).
#include "simulation_run.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/model.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace trellis {

namespace {

/// The reference itself when it has state derivatives (x_ref's Hermite spline needs them), else
/// a copy with them computed into `storage`.
const Trajectory& withStateDerivatives(const Model& model, const Trajectory& reference,
                                       Trajectory& storage) {
  if (reference.hasStateDerivatives()) return reference;
  storage = reference;
  Data data(model);
  storage.computeStateDerivatives(model, data);
  return storage;
}

void checkGainsCover(const Trajectory& reference, const GainSchedule& gains) {
  if (gains.size() == 0) throw std::invalid_argument("simulateClosedLoop: empty gain schedule");
  if (gains.nu() != reference.nu() || gains.nx() != reference.nx()) {
    std::ostringstream m;
    m << "simulateClosedLoop: gains are " << gains.nu() << "x" << gains.nx()
      << ", expected m x 2n = " << reference.nu() << "x" << reference.nx();
    throw std::invalid_argument(m.str());
  }
  const double slack =
      1e-12 * std::max({1.0, std::abs(reference.startTime()), std::abs(reference.endTime())});
  if (gains.startTime() > reference.startTime() + slack ||
      gains.endTime() < reference.endTime() - slack) {
    throw std::invalid_argument("simulateClosedLoop: the gain schedule covers [" +
                                detail::formatTime(gains.startTime()) + ", " +
                                detail::formatTime(gains.endTime()) + "], the reference needs [" +
                                detail::formatTime(reference.startTime()) + ", " +
                                detail::formatTime(reference.endTime()) + "]");
  }
}

/// The open loop (gains == nullptr) or the closed loop about `reference`; `storage` holds the
/// reference with state derivatives when it has none.
detail::InputLaw referenceLaw(const Model& model, const Trajectory& reference,
                              const GainSchedule* gains, Trajectory& storage) {
  detail::InputLaw law;
  law.kind = gains ? detail::InputLaw::Kind::kFeedback : detail::InputLaw::Kind::kOpenLoop;
  law.reference = &withStateDerivatives(model, reference, storage);
  law.gains = gains;
  return law;
}

/// Checks the reference (and the gains) against the model.
void checkReference(const Model& model, const Trajectory& reference, const GainSchedule* gains) {
  reference.checkCompatible(model);
  if (gains) checkGainsCover(reference, *gains);
}

SimulationResult simulateAboutReference(const Model& model, const Trajectory& reference,
                                        const GainSchedule* gains, const Eigen::VectorXd& x0,
                                        const SimulationOptions& options) {
  checkReference(model, reference, gains);
  const double t0 = reference.startTime(), t1 = reference.endTime();
  detail::checkSimulationArguments(model, x0, t0, t1, options, &reference);
  Trajectory storage;
  const detail::InputLaw law = referenceLaw(model, reference, gains, storage);
  return detail::runSimulation(model, x0, t0, t1, law, options, law.reference);
}

}  // namespace

SimulationResult simulate(const Model& model, const Eigen::VectorXd& x0, double t0, double t1,
                          const Policy& policy, const SimulationOptions& options,
                          const Trajectory* reference) {
  if (!policy) throw std::invalid_argument("simulate: empty policy");
  detail::checkSimulationArguments(model, x0, t0, t1, options, reference);
  Trajectory storage;
  const Trajectory* ref = reference ? &withStateDerivatives(model, *reference, storage) : nullptr;
  detail::InputLaw law;
  law.kind = detail::InputLaw::Kind::kPolicy;
  law.policy = &policy;
  return detail::runSimulation(model, x0, t0, t1, law, options, ref);
}

SimulationResult simulateOpenLoop(const Model& model, const Trajectory& reference,
                                  const Eigen::VectorXd& x0, const SimulationOptions& options) {
  return simulateAboutReference(model, reference, nullptr, x0, options);
}

SimulationResult simulateClosedLoop(const Model& model, const Trajectory& reference,
                                    const GainSchedule& gains, const Eigen::VectorXd& x0,
                                    const SimulationOptions& options) {
  return simulateAboutReference(model, reference, &gains, x0, options);
}

std::vector<SimulationResult> simulateBatch(const Model& model, const Trajectory& reference,
                                            const GainSchedule& gains,
                                            const std::vector<Eigen::VectorXd>& initialStates,
                                            const SimulationOptions& options, int threads) {
  if (threads < 0) {
    throw std::invalid_argument("simulateBatch: threads = " + std::to_string(threads) +
                                " must be >= 0");
  }
  // Every check on the calling thread, before any worker starts.
  checkReference(model, reference, &gains);
  const double t0 = reference.startTime(), t1 = reference.endTime();
  for (std::size_t k = 0; k < initialStates.size(); ++k) {
    try {
      detail::checkSimulationArguments(model, initialStates[k], t0, t1, options, &reference);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("simulateBatch: initial state " + std::to_string(k) + ": " +
                                  e.what());
    }
  }
  // Shared read-only by the workers: model, ref, gains (see "Threads" in simulation.hpp).
  Trajectory storage;
  const detail::InputLaw law = referenceLaw(model, reference, &gains, storage);

  const auto count = static_cast<int>(initialStates.size());
  std::vector<SimulationResult> results(initialStates.size());
  const int hardware = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int workers = std::min(threads > 0 ? threads : hardware, std::max(count, 1));
  std::atomic<int> next{0};
  std::vector<std::exception_ptr> errors(static_cast<std::size_t>(workers));
  auto work = [&](int w) {
    try {
      for (int k = next++; k < count; k = next++) {
        results[static_cast<std::size_t>(k)] = detail::runSimulation(
            model, initialStates[static_cast<std::size_t>(k)], t0, t1, law, options, law.reference);
      }
    } catch (...) {  // e.g. std::bad_alloc, or SUNDIALS failing to create an object
      errors[static_cast<std::size_t>(w)] = std::current_exception();
      next = count;  // the others stop at their next run
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(static_cast<std::size_t>(workers));
  for (int w = 1; w < workers; ++w) pool.emplace_back(work, w);
  work(0);
  for (std::thread& t : pool) t.join();
  for (const std::exception_ptr& e : errors) {
    if (e) std::rethrow_exception(e);
  }
  return results;
}

}  // namespace trellis
