// trellis/control/lqr.hpp — linear-quadratic regulation of linear systems, one equation per header:
//   care.hpp                        continuous algebraic Riccati equation (CARE)
//   dare.hpp                        discrete algebraic Riccati equation (DARE)
//   algebraic_riccati.hpp           what both share: LqrCode, CareOptions, LqrResult, the method
//   lyapunov.hpp, stein.hpp         Lyapunov and Stein equations (matrix_equation.hpp: their result)
//   stabilizability.hpp             the PBH stabilizability test
//   zero_order_hold.hpp             exact ZOH discretization
//   discrete_riccati_recursion.hpp  the finite-horizon discrete Riccati recursion
#pragma once

#include "trellis/control/algebraic_riccati.hpp"
#include "trellis/control/care.hpp"
#include "trellis/control/dare.hpp"
#include "trellis/control/discrete_riccati_recursion.hpp"
#include "trellis/control/lyapunov.hpp"
#include "trellis/control/matrix_equation.hpp"
#include "trellis/control/stabilizability.hpp"
#include "trellis/control/stein.hpp"
#include "trellis/control/zero_order_hold.hpp"
