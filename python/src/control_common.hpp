// python/src/control_common.hpp — helpers shared by the control and simulation binding files:
// weights from Python values, gain arrays, running a solve without the GIL.
#pragma once

#include "common.hpp"

#include "trellis/control/riccati.hpp"

#include <vector>

namespace trellis::python {

/// Q (nx×nx), R (nu×nu), Qf (nx×nx, default Q) from a number (w·I), a 1-D diagonal or a matrix;
/// a complex array is a TypeError naming the weight.
LqrWeights makeWeights(const py::object& Q, const py::object& R, const py::object& Qf,
                       Eigen::Index nx, Eigen::Index nu);

/// Gains as one (N, nu, nx) array (time first) → the vector the C++ takes; complex is refused.
std::vector<Eigen::MatrixXd> gainsFromArray(const py::object& gains);

/// Runs f with the GIL released (the long solves).
template <class F>
auto withoutGil(F&& f) {
  py::gil_scoped_release release;
  return f();
}

}  // namespace trellis::python
