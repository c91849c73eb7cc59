// python/src/control_common.hpp — helpers shared by bind_control.cpp and bind_tvlqr.cpp.
#pragma once

#include "common.hpp"

#include "trellis/control/riccati.hpp"

namespace trellis::python {

/// Q (nx×nx), R (nu×nu), Qf (nx×nx, default Q) from a number (w·I), a 1-D diagonal or a matrix.
LqrWeights makeWeights(const py::object& Q, const py::object& R, const py::object& Qf,
                       Eigen::Index nx, Eigen::Index nu);

}  // namespace trellis::python
