// trellis/control.hpp — everything in trellis::control.
#pragma once

#include "trellis/control/controllability.hpp"
#include "trellis/control/lqr.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/control/trajectory.hpp"
