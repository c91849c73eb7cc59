// trellis/core.hpp — everything of trellis::core.
#pragma once
#include "trellis/core/model.hpp"
#include "trellis/core/model_builder.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/kinematics.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/scene.hpp"
#include "trellis/core/state.hpp"
#include "trellis/core/projection.hpp"
#include "trellis/core/inverse_dynamics.hpp"
#include "trellis/core/equilibrium.hpp"
#include "trellis/core/io.hpp"
