// stabilizability.cpp — the PBH stabilizability test (see trellis/control/stabilizability.hpp).
#include "trellis/control/stabilizability.hpp"

#include "algebraic_riccati_common.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/QR>
#include <Eigen/SVD>

#include <cmath>
#include <complex>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

namespace detail::are {

StabilizabilityCheck stabilizabilityImpl(const MatrixXd& A, const MatrixXd& B, bool discrete,
                                         double tolerance) {
  const Index n = A.rows(), m = B.cols();
  StabilizabilityCheck out;
  Eigen::ComplexSchur<MatrixXcd> schur(A.cast<Complex>());
  const MatrixXcd& T = schur.matrixT();
  const MatrixXcd C = schur.matrixU().adjoint() * B.cast<Complex>();  // wᴴB = zᵀ C
  const double bNorm = B.norm();
  const double floor = kEps * std::max(T.norm(), std::numeric_limits<double>::min());
  Eigen::VectorXcd z(n);
  for (Index k = 0; k < n; ++k) {
    const Complex lambda = T(k, k);
    if (!outsideStabilityRegion(lambda, discrete)) continue;
    // Left eigenvector: Tᵀ z = λ z, z_j = 0 (j < k), z_k = 1.
    z.setZero();
    z(k) = 1.0;
    for (Index j = k + 1; j < n; ++j) {
      Complex s = 0.0;
      for (Index i = k; i < j; ++i) s += T(i, j) * z(i);
      Complex den = lambda - T(j, j);
      if (std::abs(den) < floor) den = den == 0.0 ? Complex(floor) : den / std::abs(den) * floor;
      z(j) = s / den;
      if (std::abs(z(j)) > 1e150) z /= 1e150;
    }
    double margin = bNorm > 0.0 ? (z.transpose() * C).norm() / (z.norm() * bNorm) : 0.0;
    // A repeated eigenvalue: one left eigenvector need not expose an uncontrollable direction of
    // its eigenspace; use the PBH singular value there.
    bool repeated = false;
    for (Index j = 0; j < n && !repeated; ++j)
      repeated = j != k && std::abs(T(j, j) - lambda) <= 1e-6 * std::max(1.0, std::abs(lambda));
    if (repeated) {
      MatrixXcd M(n, n + m);
      M.leftCols(n) = A.cast<Complex>();
      M.leftCols(n).diagonal().array() -= lambda;
      M.rightCols(m) = B.cast<Complex>();
      const double scale = std::max((MatrixXd(n, n + m) << A, B).finished().norm(),
                                    std::numeric_limits<double>::min());
      const double smin = Eigen::JacobiSVD<MatrixXcd>(M).singularValues()(n - 1) / scale;
      margin = std::min(margin, smin);
    }
    if (margin < out.margin) {
      out.margin = margin;
      out.eigenvalue = lambda;
    }
  }
  if (out.margin <= tolerance) {
    out.stabilizable = false;
    std::ostringstream msg;
    msg << "(A, B) is not stabilizable: the eigenvalue " << formatComplex(out.eigenvalue)
        << " of A";
    if (discrete) {
      msg << " (|lambda| = " << std::abs(out.eigenvalue)
          << (std::abs(out.eigenvalue) >= 1.0 ? " >= 1)" : ", within 1e-8 of the unit circle)");
    } else {
      msg << " (Re = " << out.eigenvalue.real()
          << (out.eigenvalue.real() >= 0.0 ? " >= 0)" : ", within 1e-8|lambda| of the imaginary axis)");
    }
    msg << " is uncontrollable: controllability margin |w^H B|/(|w||B|) = " << out.margin
        << " <= " << tolerance << " (w its left eigenvector"
        << (out.margin > 1e3 * kEps ? "; a margin above rounding means nearly, not exactly, "
                                      "uncontrollable: below the tolerance it is treated as "
                                      "uncontrollable, see CareOptions::stabilizabilityTolerance)"
                                    : ")");
    out.message = msg.str();
  }
  return out;
}

}  // namespace detail::are

using namespace detail::are;

StabilizabilityCheck checkStabilizability(const MatrixXd& A, const MatrixXd& B, bool discrete,
                                          double tolerance) {
  checkSystem(A, B, "checkStabilizability");
  return stabilizabilityImpl(A, B, discrete, tolerance);
}

}  // namespace trellis
