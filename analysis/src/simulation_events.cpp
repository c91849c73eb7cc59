// simulation_events.cpp — the simulator's event list (see simulation_events.hpp).
#include "simulation_events.hpp"

#include "closed_loop_system.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace trellis::detail {

std::vector<SimulationEvent> simulationEvents(double t0, double t1,
                                              const SimulationOptions& options,
                                              const Trajectory* reference) {
  // Events closer than the rounding of t0 + k h merge: relative to the size of the times, with no
  // absolute floor (a floor of 1e-10 merged t0 into t1 on a horizon of 1e-300 and lost the first
  // row), and below a quarter of the span, so that t0 and t1 never merge unless equal.
  const double mergeTol = std::min(1e-10 * std::max(std::abs(t0), std::abs(t1)), 0.25 * (t1 - t0));
  // Event lists are materialized: refuse grids that would not fit in memory.
  constexpr double kMaxEvents = 1e7;
  if (options.outputStep > 0.0 && (t1 - t0) / options.outputStep > kMaxEvents) {
    throw std::invalid_argument("simulate: SimulationOptions.outputStep = " +
                                formatTime(options.outputStep) + " gives more than 1e7 outputs");
  }
  if (options.sampleRate > 0.0 && (t1 - t0) * options.sampleRate > kMaxEvents) {
    throw std::invalid_argument("simulate: SimulationOptions.sampleRate = " +
                                formatTime(options.sampleRate) + " gives more than 1e7 samples");
  }
  const bool sampled = options.sampleRate > 0.0;
  std::vector<SimulationEvent> events;
  auto inside = [&](double t) { return t > t0 + mergeTol && t < t1 - mergeTol; };
  events.push_back({t0, true, true, sampled});
  events.push_back({t1, true, true, false});
  if (options.outputStep > 0.0) {
    for (long k = 1;; ++k) {
      const double t = t0 + static_cast<double>(k) * options.outputStep;
      if (!inside(t)) break;
      events.push_back({t, true, false, false});
    }
  } else if (reference) {
    for (Eigen::Index k = 0; k < reference->size(); ++k) {
      const double t = reference->times()(k);
      if (inside(t)) events.push_back({t, true, false, false});
    }
  }
  for (double t : options.breakpoints) {
    if (inside(t)) events.push_back({t, false, true, false});
  }
  if (sampled) {
    const double h = 1.0 / options.sampleRate;
    for (long k = 1;; ++k) {
      const double t = t0 + static_cast<double>(k) * h;
      if (!inside(t)) break;
      events.push_back({t, false, true, true});
    }
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const SimulationEvent& a, const SimulationEvent& b) { return a.t < b.t; });
  std::vector<SimulationEvent> merged;
  merged.reserve(events.size());
  for (const SimulationEvent& e : events) {
    if (!merged.empty() && e.t - merged.back().t <= mergeTol) {
      SimulationEvent& last = merged.back();
      last.output |= e.output;
      last.stop |= e.stop;
      last.sample |= e.sample;
    } else {
      merged.push_back(e);
    }
  }
  merged.front().t = t0;
  merged.back().t = t1;  // t1 may have merged into an earlier time within the tolerance
  return merged;
}

}  // namespace trellis::detail
