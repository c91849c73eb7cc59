// trellis/analysis.hpp — everything in trellis::analysis: the closed-loop simulation of the
// nonlinear plant, the consistency check of a trajectory, and the dense output of an integration.
#pragma once

#include "trellis/analysis/consistency.hpp"
#include "trellis/analysis/dense_output.hpp"
#include "trellis/analysis/simulation.hpp"
