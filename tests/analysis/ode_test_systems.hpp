// ode_test_systems.hpp — the linear test problem of the ODE driver's tests (test_ode_driver.cpp for
// CVODES, test_radau.cpp for the Radau engine): ẏ = A y, stiff, with eigenvalues −1, −10, −1000 and
// −2 ± 3i (exact solution exp(At) y0), and its start y0.
#pragma once

#include <Eigen/Core>

namespace trellis::test {

inline Eigen::MatrixXd stiffLinearMatrix() {
  Eigen::MatrixXd A(5, 5);
  A << -1, 0, 0, 0, 0,   //
      0.5, -10, 0, 0, 0,  //
      0, 1, -1000, 0, 0,  //
      0, 0, 0, -2, 3,     //
      0, 0, 0, -3, -2;
  return A;
}

inline Eigen::VectorXd stiffLinearStart() {
  Eigen::VectorXd y(5);
  y << 1, -1, 2, 1, 0.5;
  return y;
}

}  // namespace trellis::test
