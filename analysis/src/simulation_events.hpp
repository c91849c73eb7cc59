// simulation_events.hpp (private) — the simulator's time grid: the output times, the sample
// times of sampled feedback and the breakpoints, merged into one increasing list of events.
#pragma once

#include "trellis/analysis/simulation.hpp"

#include <vector>

namespace trellis::detail {

struct SimulationEvent {
  double t = 0.0;
  bool output = false;  ///< record x, u here
  bool stop = false;    ///< the right-hand side jumps here: integrate exactly to t, then restart
  bool sample = false;  ///< a new held input is sampled here
};

/// Events on [t0, t1]: t0 and t1 (outputs, stops), the outputs (options.outputStep > 0: a uniform
/// grid; else the reference's knots), sample times (stops) and options.breakpoints inside (t0, t1)
/// (stops). Times closer than 1e-10·max(1, |t0|, |t1|) are merged. Throws std::invalid_argument for
/// a grid of more than 1e7 points.
std::vector<SimulationEvent> simulationEvents(double t0, double t1,
                                              const SimulationOptions& options,
                                              const Trajectory* reference);

}  // namespace trellis::detail
