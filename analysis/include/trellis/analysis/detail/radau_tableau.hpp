// trellis/analysis/detail/radau_tableau.hpp (internal: for trellis's own libraries, not an API) —
// the three-stage Radau IIA method (order 5, L-stable, stiffly accurate; Hairer & Wanner, Solving
// ODEs II, §IV.5 and §IV.8), written once for its two users: the simulator's nonlinear stepper
// (analysis/src/radau_stepper.cpp) and the sampled-data discretization of the variational
// equation (control/src/sampled_lqr.cpp).
//
// Nodes c = ((4 − √6)/10, (4 + √6)/10, 1); a the collocation matrix (its last row the weights b).
// a has one real eigenvalue γ0 (1/γ0 = 30/(6 + 81^{1/3} − 9^{1/3})) and a complex pair μ, μ̄:
// a = T diag(γ0, μ, μ̄) T⁻¹ with T's first column real and its third the second's conjugate, so a
// stage system (I − h a⊗J) decouples into one real and one complex system in J's size.
// The embedded estimate (RADAU5): with the stage increments Z_i,
//   err = (I − γ0 h J)⁻¹ (γ0 h f(t_n, y_n) + Σ e_i Z_i),  e = γ0 d,  d = (−13 − 7√6, −13 + 7√6, −1)/3,
// the difference to a third-order companion, filtered so that damped stiff components do not count.
#pragma once

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include <cmath>
#include <complex>

namespace trellis::detail {

struct RadauTableau {
  double a[3][3] = {};
  double c[3] = {};
  double d[3] = {};  ///< the estimate's weights before the factor γ0
  double e[3] = {};  ///< γ0 d
  double gamma0 = 0.0;
  std::complex<double> mu;  ///< the eigenvalue of a with positive imaginary part
  Eigen::Matrix3cd T, Tinv;

  /// The one instance (computed once, thread-safe).
  static const RadauTableau& get() {
    static const RadauTableau t;
    return t;
  }

 private:
  RadauTableau() {
    const double r6 = std::sqrt(6.0);
    const double m[3][3] = {{(88.0 - 7.0 * r6) / 360.0, (296.0 - 169.0 * r6) / 1800.0, (-2.0 + 3.0 * r6) / 225.0},
                            {(296.0 + 169.0 * r6) / 1800.0, (88.0 + 7.0 * r6) / 360.0, (-2.0 - 3.0 * r6) / 225.0},
                            {(16.0 - r6) / 36.0, (16.0 + r6) / 36.0, 1.0 / 9.0}};
    Eigen::Matrix3d am;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) am(i, j) = a[i][j] = m[i][j];
    c[0] = (4.0 - r6) / 10.0;
    c[1] = (4.0 + r6) / 10.0;
    c[2] = 1.0;
    gamma0 = (6.0 + std::cbrt(81.0) - std::cbrt(9.0)) / 30.0;
    d[0] = (-13.0 - 7.0 * r6) / 3.0;
    d[1] = (-13.0 + 7.0 * r6) / 3.0;
    d[2] = -1.0 / 3.0;
    for (int i = 0; i < 3; ++i) e[i] = gamma0 * d[i];
    const Eigen::EigenSolver<Eigen::Matrix3d> eig(am);
    int real = 0;
    for (int k = 1; k < 3; ++k)
      if (std::abs(eig.eigenvalues()(k).imag()) < std::abs(eig.eigenvalues()(real).imag())) real = k;
    const int pos = eig.eigenvalues()((real + 1) % 3).imag() > 0.0 ? (real + 1) % 3 : (real + 2) % 3;
    mu = eig.eigenvalues()(pos);
    T.col(0) = eig.eigenvectors().col(real).real().cast<std::complex<double>>();
    T.col(1) = eig.eigenvectors().col(pos);
    T.col(2) = eig.eigenvectors().col(pos).conjugate();
    Tinv = T.inverse();
  }
};

}  // namespace trellis::detail
