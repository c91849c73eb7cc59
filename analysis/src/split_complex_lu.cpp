// analysis/src/split_complex_lu.cpp — trellis/analysis/detail/split_complex_lu.hpp.
#include "trellis/analysis/detail/split_complex_lu.hpp"

#include "trellis/analysis/detail/dense_kernels.hpp"

#include <immintrin.h>

#include <algorithm>
#include <complex>
#include <utility>

namespace trellis::detail {

void SplitComplexLu::resize(Eigen::Index n) {
  re_.resize(n, n);
  im_.resize(n, n);
  pivot_.resize(n);
  perm_.resize(n);
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
  // The swaps' product: row i of P M is row perm_[i] of M.
  for (Eigen::Index i = 0; i < n; ++i) perm_[i] = static_cast<int>(i);
  for (Eigen::Index k = 0; k < n; ++k) std::swap(perm_[k], perm_[pivot_[k]]);
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

namespace {

using Index = Eigen::Index;

/// The pivoted substitution on all the columns at once, held row-major in (xr, xi) (ldx): NC
/// chunks of four columns, the last masked to `m` unless LastFull; the pivot row in registers, so
/// the eliminations of one step are independent (see small_lu.hpp). re, im: the factors, n×n
/// column-major.
template <int NC, bool LastFull>
__attribute__((target("avx2,fma"))) inline void substituteRows(const double* re, const double* im, Index n,
                                                               double* xr, double* xi, Index ldx, __m256i m) {
  __m256d ar[NC], ai[NC];
  auto update = [&](Index i, const double* lre, const double* lim) __attribute__((target("avx2,fma"))) {
    const __m256d lr = _mm256_broadcast_sd(lre), li = _mm256_broadcast_sd(lim);
    double* br = xr + i * ldx;
    double* bi = xi + i * ldx;
    for (int c = 0; c < NC; ++c) {
      const bool full = LastFull || c + 1 < NC;
      __m256d r = full ? _mm256_loadu_pd(br + 4 * c) : _mm256_maskload_pd(br + 4 * c, m);
      __m256d q = full ? _mm256_loadu_pd(bi + 4 * c) : _mm256_maskload_pd(bi + 4 * c, m);
      r = _mm256_fmadd_pd(li, ai[c], _mm256_fnmadd_pd(lr, ar[c], r));  // r − (lr ar − li ai)
      q = _mm256_fnmadd_pd(li, ar[c], _mm256_fnmadd_pd(lr, ai[c], q));  // q − (lr ai + li ar)
      if (full) {
        _mm256_storeu_pd(br + 4 * c, r);
        _mm256_storeu_pd(bi + 4 * c, q);
      } else {
        _mm256_maskstore_pd(br + 4 * c, m, r);
        _mm256_maskstore_pd(bi + 4 * c, m, q);
      }
    }
  };
  for (Index k = 0; k < n; ++k) {
    for (int c = 0; c < NC; ++c) {
      const bool full = LastFull || c + 1 < NC;
      ar[c] = full ? _mm256_loadu_pd(xr + k * ldx + 4 * c) : _mm256_maskload_pd(xr + k * ldx + 4 * c, m);
      ai[c] = full ? _mm256_loadu_pd(xi + k * ldx + 4 * c) : _mm256_maskload_pd(xi + k * ldx + 4 * c, m);
    }
    for (Index i = k + 1; i < n; ++i) update(i, re + i + k * n, im + i + k * n);
  }
  for (Index k = n - 1; k >= 0; --k) {
    // z = x ū / |u|², as substitute().
    const double ur = re[k + k * n], ui = im[k + k * n], inv = 1.0 / (ur * ur + ui * ui);
    const __m256d vr = _mm256_set1_pd(ur), vi = _mm256_set1_pd(ui), vinv = _mm256_set1_pd(inv);
    for (int c = 0; c < NC; ++c) {
      const bool full = LastFull || c + 1 < NC;
      double* pr = xr + k * ldx + 4 * c;
      double* pi = xi + k * ldx + 4 * c;
      const __m256d a = full ? _mm256_loadu_pd(pr) : _mm256_maskload_pd(pr, m);
      const __m256d b = full ? _mm256_loadu_pd(pi) : _mm256_maskload_pd(pi, m);
      ar[c] = _mm256_mul_pd(_mm256_fmadd_pd(b, vi, _mm256_mul_pd(a, vr)), vinv);
      ai[c] = _mm256_mul_pd(_mm256_fnmadd_pd(a, vi, _mm256_mul_pd(b, vr)), vinv);
      if (full) {
        _mm256_storeu_pd(pr, ar[c]);
        _mm256_storeu_pd(pi, ai[c]);
      } else {
        _mm256_maskstore_pd(pr, m, ar[c]);
        _mm256_maskstore_pd(pi, m, ai[c]);
      }
    }
    for (Index i = 0; i < k; ++i) update(i, re + i + k * n, im + i + k * n);
  }
}

template <int NC>
__attribute__((target("avx2,fma"))) void substituteRowsAvx2(const double* re, const double* im, Index n, double* xr,
                                                            double* xi, Index ldx, Index cols) {
  const __m256i lane = _mm256_set_epi64x(3, 2, 1, 0);
  const __m256i m = _mm256_cmpgt_epi64(_mm256_set1_epi64x(cols - 4 * (NC - 1)), lane);
  if (cols == 4 * NC) {
    substituteRows<NC, true>(re, im, n, xr, xi, ldx, m);
  } else {
    substituteRows<NC, false>(re, im, n, xr, xi, ldx, m);
  }
}

}  // namespace

void SplitComplexLu::solve(Eigen::Ref<Eigen::MatrixXd> Xr, Eigen::Ref<Eigen::MatrixXd> Xi) {
  const Index n = re_.rows(), cols = Xr.cols();
  if (cols < 2 || cols > 32 || !matmulUsesAvx2()) {
    for (Index j = 0; j < cols; ++j) substitute(Xr.col(j).data(), Xi.col(j).data());
    return;
  }
  if (rowsR_.rows() != n || rowsR_.cols() < cols) {
    rowsR_.resize(n, cols);
    rowsI_.resize(n, cols);
  }
  const Index ld = rowsR_.cols();
  // Gather in pivoted order, transposed to row-major.
  for (Index i = 0; i < n; ++i) {
    for (Index j = 0; j < cols; ++j) {
      rowsR_(i, j) = Xr(perm_[i], j);
      rowsI_(i, j) = Xi(perm_[i], j);
    }
  }
  double* r = rowsR_.data();
  double* q = rowsI_.data();
  switch ((cols + 3) / 4) {
    case 1: substituteRowsAvx2<1>(re_.data(), im_.data(), n, r, q, ld, cols); break;
    case 2: substituteRowsAvx2<2>(re_.data(), im_.data(), n, r, q, ld, cols); break;
    case 3: substituteRowsAvx2<3>(re_.data(), im_.data(), n, r, q, ld, cols); break;
    case 4: substituteRowsAvx2<4>(re_.data(), im_.data(), n, r, q, ld, cols); break;
    case 5: substituteRowsAvx2<5>(re_.data(), im_.data(), n, r, q, ld, cols); break;
    case 6: substituteRowsAvx2<6>(re_.data(), im_.data(), n, r, q, ld, cols); break;
    case 7: substituteRowsAvx2<7>(re_.data(), im_.data(), n, r, q, ld, cols); break;
    default: substituteRowsAvx2<8>(re_.data(), im_.data(), n, r, q, ld, cols); break;
  }
  for (Index j = 0; j < cols; ++j) {
    for (Index i = 0; i < n; ++i) {
      Xr(i, j) = rowsR_(i, j);
      Xi(i, j) = rowsI_(i, j);
    }
  }
}

}  // namespace trellis::detail
