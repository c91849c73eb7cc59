// trellis/control.hpp — everything in trellis::control, and the analysis layer it builds on
// (simulation, consistency: trellis/analysis.hpp). Trajectory, GainSchedule and
// ReferenceEvaluator are nouns of trellis::core: trellis/core.hpp.
#pragma once

#include "trellis/analysis.hpp"
#include "trellis/control/controllability.hpp"
#include "trellis/control/lqr.hpp"
#include "trellis/control/manifold_lqr.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/control/sampled_lqr.hpp"
#include "trellis/control/tvlqr.hpp"
