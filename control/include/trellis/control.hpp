// trellis/control.hpp — everything in trellis::control. (Trajectory, GainSchedule and
// ReferenceEvaluator are nouns of trellis::core: trellis/core.hpp.)
#pragma once

#include "trellis/control/consistency.hpp"
#include "trellis/control/controllability.hpp"
#include "trellis/control/lqr.hpp"
#include "trellis/control/manifold_lqr.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/control/sampled_lqr.hpp"
#include "trellis/control/simulation.hpp"
#include "trellis/control/tvlqr.hpp"
