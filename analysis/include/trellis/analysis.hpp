// trellis/analysis.hpp — everything in trellis::analysis: the closed-loop simulation of the
// nonlinear plant, the consistency check of a trajectory, the dense output of an integration, and funnel
// (region-of-attraction) estimates by sampling.
#pragma once

#include "trellis/analysis/consistency.hpp"
#include "trellis/analysis/cost_to_go.hpp"
#include "trellis/analysis/dense_output.hpp"
#include "trellis/analysis/funnel.hpp"
#include "trellis/analysis/simulation.hpp"
