// trellis/optimization.hpp — every public header of trellis::optimization.
#pragma once

#include "trellis/optimization/optimizer.hpp"
#include "trellis/optimization/nlp.hpp"
#include "trellis/optimization/problem.hpp"
#include "trellis/optimization/transcription.hpp"
