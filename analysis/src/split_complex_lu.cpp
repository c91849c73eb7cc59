// analysis/src/split_complex_lu.cpp — trellis/analysis/detail/split_complex_lu.hpp.
#include "trellis/analysis/detail/split_complex_lu.hpp"

#include <complex>
#include <utility>

namespace trellis::detail {

void SplitComplexLu::resize(Eigen::Index n) {
  re_.resize(n, n);
  im_.resize(n, n);
  pivot_.resize(n);
  xr_.resize(n);
  xi_.resize(n);
}

void SplitComplexLu::factor() {
  const Eigen::Index n = re_.rows();
  for (Eigen::Index k = 0; k < n; ++k) {
    Eigen::Index p = k;
    double best = re_(k, k) * re_(k, k) + im_(k, k) * im_(k, k);
    for (Eigen::Index i = k + 1; i < n; ++i) {
      const double v = re_(i, k) * re_(i, k) + im_(i, k) * im_(i, k);
      if (v > best) {
        best = v;
        p = i;
      }
    }
    pivot_[k] = static_cast<int>(p);
    if (p != k) {
      re_.row(k).swap(re_.row(p));
      im_.row(k).swap(im_.row(p));
    }
    // L's column: divided by the pivot, 1/u = conj(u)/|u|².
    const double inv = 1.0 / best, ur = re_(k, k) * inv, ui = -im_(k, k) * inv;
    for (Eigen::Index i = k + 1; i < n; ++i) {
      const double a = re_(i, k), b = im_(i, k);
      re_(i, k) = a * ur - b * ui;
      im_(i, k) = a * ui + b * ur;
    }
    // The trailing update, column by column: M_ij −= l_i u_kj.
    const double* lr = &re_(0, k);
    const double* li = &im_(0, k);
    for (Eigen::Index j = k + 1; j < n; ++j) {
      const double ar = re_(k, j), ai = im_(k, j);
      double* cr = &re_(0, j);
      double* ci = &im_(0, j);
      for (Eigen::Index i = k + 1; i < n; ++i) {
        cr[i] -= lr[i] * ar - li[i] * ai;
        ci[i] -= lr[i] * ai + li[i] * ar;
      }
    }
  }
}

void SplitComplexLu::substitute(double* xr, double* xi) const {
  const Eigen::Index n = re_.rows();
  for (Eigen::Index k = 0; k < n; ++k) {
    std::swap(xr[k], xr[pivot_[k]]);
    std::swap(xi[k], xi[pivot_[k]]);
  }
  // L y = P x (unit lower), column by column.
  for (Eigen::Index k = 0; k < n; ++k) {
    const double yr = xr[k], yi = xi[k];
    const double* lr = &re_(0, k);
    const double* li = &im_(0, k);
    for (Eigen::Index i = k + 1; i < n; ++i) {
      xr[i] -= lr[i] * yr - li[i] * yi;
      xi[i] -= lr[i] * yi + li[i] * yr;
    }
  }
  // U z = y, column by column from the last.
  for (Eigen::Index k = n - 1; k >= 0; --k) {
    const double ur = re_(k, k), ui = im_(k, k), inv = 1.0 / (ur * ur + ui * ui);
    const double a = xr[k], b = xi[k];
    const double zr = (a * ur + b * ui) * inv, zi = (b * ur - a * ui) * inv;
    xr[k] = zr;
    xi[k] = zi;
    const double* cr = &re_(0, k);
    const double* ci = &im_(0, k);
    for (Eigen::Index i = 0; i < k; ++i) {
      xr[i] -= cr[i] * zr - ci[i] * zi;
      xi[i] -= cr[i] * zi + ci[i] * zr;
    }
  }
}

void SplitComplexLu::solve(Eigen::VectorXcd& x) {
  const Eigen::Index n = re_.rows();
  for (Eigen::Index k = 0; k < n; ++k) {
    xr_[k] = x[k].real();
    xi_[k] = x[k].imag();
  }
  substitute(xr_.data(), xi_.data());
  for (Eigen::Index k = 0; k < n; ++k) x[k] = std::complex<double>(xr_[k], xi_[k]);
}

void SplitComplexLu::solve(Eigen::Ref<Eigen::MatrixXd> Xr, Eigen::Ref<Eigen::MatrixXd> Xi) const {
  for (Eigen::Index j = 0; j < Xr.cols(); ++j) substitute(Xr.col(j).data(), Xi.col(j).data());
}

}  // namespace trellis::detail
