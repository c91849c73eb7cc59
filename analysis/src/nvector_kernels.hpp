// nvector_kernels.hpp (private) — compiled (-O3, vectorized) kernels for SUNDIALS serial vectors.
//
// Why: CVODES does a few dozen vector operations per step (prediction, Newton update, error
// test, Nordsieck rescale, dense output, GMRES Gram–Schmidt). The system's SUNDIALS library may
// be built without optimization (Debian's 6.4.1 is: ~20 instructions per element of
// N_VLinearSum, measured with callgrind), which made these operations a quarter of a Riccati
// solve with 820 unknowns. useKernels(v) replaces the hot operations of one serial vector by
// Eigen loops with the same semantics (SUNDIALS's N_Vector specification: aliasing of the
// output with an input allowed where the specification allows it). Clones (N_VClone, which
// CVODES uses for all its work vectors) copy the operation table, so setting it on the vector
// given to CVodeInit covers the integrator's whole workspace.
#pragma once

#include <nvector/nvector_serial.h>

namespace trellis::detail {

/// Installs the compiled kernels on a serial vector (and so on its future clones).
void useKernels(N_Vector v);

}  // namespace trellis::detail
