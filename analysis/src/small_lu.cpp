// analysis/src/small_lu.cpp — trellis/analysis/detail/small_lu.hpp.
#include "trellis/analysis/detail/small_lu.hpp"

#include "trellis/analysis/detail/dense_kernels.hpp"

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <utility>

namespace trellis::detail {
namespace {

using Index = Eigen::Index;

// The kernels' bodies, inlined into a generic and an AVX2+FMA instance (the CPU picks one once,
// as matmul does). a: n×n row-major (lda = n); x: n×k row-major (ldx).

/// Right-looking elimination with partial pivoting; perm records the row order.
__attribute__((always_inline)) inline void factorBody(double* a, Index n, int* perm) {
  for (Index i = 0; i < n; ++i) perm[i] = static_cast<int>(i);
  for (Index k = 0; k < n; ++k) {
    Index p = k;
    double best = std::abs(a[k * n + k]);
    for (Index i = k + 1; i < n; ++i) {
      const double v = std::abs(a[i * n + k]);
      if (v > best) {
        best = v;
        p = i;
      }
    }
    if (p != k) {
      double* rk = a + k * n;
      double* rp = a + p * n;
      for (Index j = 0; j < n; ++j) std::swap(rk[j], rp[j]);
      std::swap(perm[k], perm[p]);
    }
    const double* rk = a + k * n;
    const double pivot = rk[k];
    for (Index i = k + 1; i < n; ++i) {
      double* ri = a + i * n;
      const double l = ri[k] / pivot;
      ri[k] = l;
      TRELLIS_IVDEP
      for (Index j = k + 1; j < n; ++j) ri[j] -= l * rk[j];
    }
  }
}

/// L y = x, then U z = y, on every column of x at once (row operations across the columns).
__attribute__((always_inline)) inline void substituteBody(const double* a, Index n, double* x, Index cols, Index ldx) {
  for (Index k = 0; k < n; ++k) {
    const double* xk = x + k * ldx;
    for (Index i = k + 1; i < n; ++i) {
      const double l = a[i * n + k];
      double* xi = x + i * ldx;
      TRELLIS_IVDEP
      for (Index j = 0; j < cols; ++j) xi[j] -= l * xk[j];
    }
  }
  for (Index k = n - 1; k >= 0; --k) {
    double* xk = x + k * ldx;
    const double u = a[k * n + k];
    TRELLIS_IVDEP
    for (Index j = 0; j < cols; ++j) xk[j] /= u;
    for (Index i = 0; i < k; ++i) {
      const double l = a[i * n + k];
      double* xi = x + i * ldx;
      TRELLIS_IVDEP
      for (Index j = 0; j < cols; ++j) xi[j] -= l * xk[j];
    }
  }
}

void factorGeneric(double* a, Index n, int* perm) { factorBody(a, n, perm); }
__attribute__((target("avx2,fma"))) void factorAvx2(double* a, Index n, int* perm) { factorBody(a, n, perm); }
void substituteGeneric(const double* a, Index n, double* x, Index cols, Index ldx) {
  substituteBody(a, n, x, cols, ldx);
}

/// The substitution on four columns at once (Full: all four, else the first `m` lanes): each
/// elimination one broadcast, load, FMA and store, the pivot row held in a register.
template <bool Full>
__attribute__((target("avx2,fma"))) inline __m256d loadChunk(const double* p, __m256i m) {
  return Full ? _mm256_loadu_pd(p) : _mm256_maskload_pd(p, m);
}
template <bool Full>
__attribute__((target("avx2,fma"))) inline void storeChunk(double* p, __m256i m, __m256d v) {
  if (Full) {
    _mm256_storeu_pd(p, v);
  } else {
    _mm256_maskstore_pd(p, m, v);
  }
}
template <bool Full>
__attribute__((target("avx2,fma"))) inline void substituteChunk(const double* a, Index n, double* xc, Index ldx,
                                                                __m256i m) {
  for (Index k = 0; k < n; ++k) {
    const __m256d xk = loadChunk<Full>(xc + k * ldx, m);
    for (Index i = k + 1; i < n; ++i) {
      double* xi = xc + i * ldx;
      storeChunk<Full>(xi, m, _mm256_fnmadd_pd(_mm256_broadcast_sd(a + i * n + k), xk, loadChunk<Full>(xi, m)));
    }
  }
  for (Index k = n - 1; k >= 0; --k) {
    double* xkp = xc + k * ldx;
    const __m256d xk = _mm256_div_pd(loadChunk<Full>(xkp, m), _mm256_broadcast_sd(a + k * n + k));
    storeChunk<Full>(xkp, m, xk);
    for (Index i = 0; i < k; ++i) {
      double* xi = xc + i * ldx;
      storeChunk<Full>(xi, m, _mm256_fnmadd_pd(_mm256_broadcast_sd(a + i * n + k), xk, loadChunk<Full>(xi, m)));
    }
  }
}

/// All the columns at once (NC chunks of four, the last one masked to `m` unless LastFull): the
/// pivot row held in NC registers, every elimination of one step k independent of the others
/// (the chunk-at-a-time version above waits on each pivot row's store).
/// Row ri −= l · (the pivot row held in xk), over the NC chunks.
template <int NC, bool LastFull>
__attribute__((target("avx2,fma"))) inline void eliminate(double* ri, const double* l, const __m256d* xk, __m256i m) {
  const __m256d lv = _mm256_broadcast_sd(l);
  for (int c = 0; c + 1 < NC; ++c) {
    _mm256_storeu_pd(ri + 4 * c, _mm256_fnmadd_pd(lv, xk[c], _mm256_loadu_pd(ri + 4 * c)));
  }
  storeChunk<LastFull>(ri + 4 * (NC - 1), m,
                       _mm256_fnmadd_pd(lv, xk[NC - 1], loadChunk<LastFull>(ri + 4 * (NC - 1), m)));
}

template <int NC, bool LastFull>
__attribute__((target("avx2,fma"))) inline void substituteRows(const double* a, Index n, double* x, Index ldx,
                                                               __m256i m) {
  __m256d xk[NC];
  for (Index k = 0; k < n; ++k) {
    const double* rk = x + k * ldx;
    for (int c = 0; c + 1 < NC; ++c) xk[c] = _mm256_loadu_pd(rk + 4 * c);
    xk[NC - 1] = loadChunk<LastFull>(rk + 4 * (NC - 1), m);
    for (Index i = k + 1; i < n; ++i) eliminate<NC, LastFull>(x + i * ldx, a + i * n + k, xk, m);
  }
  for (Index k = n - 1; k >= 0; --k) {
    double* rk = x + k * ldx;
    const __m256d u = _mm256_broadcast_sd(a + k * n + k);
    for (int c = 0; c + 1 < NC; ++c) {
      xk[c] = _mm256_div_pd(_mm256_loadu_pd(rk + 4 * c), u);
      _mm256_storeu_pd(rk + 4 * c, xk[c]);
    }
    xk[NC - 1] = _mm256_div_pd(loadChunk<LastFull>(rk + 4 * (NC - 1), m), u);
    storeChunk<LastFull>(rk + 4 * (NC - 1), m, xk[NC - 1]);
    for (Index i = 0; i < k; ++i) eliminate<NC, LastFull>(x + i * ldx, a + i * n + k, xk, m);
  }
}

template <int NC>
__attribute__((target("avx2,fma"))) inline void substituteRowsDispatch(const double* a, Index n, double* x, Index ldx,
                                                                       Index cols, __m256i m) {
  if (cols == 4 * NC) {
    substituteRows<NC, true>(a, n, x, ldx, m);
  } else {
    substituteRows<NC, false>(a, n, x, ldx, m);
  }
}

__attribute__((target("avx2,fma"))) void substituteAvx2(const double* a, Index n, double* x, Index cols, Index ldx) {
  const __m256i lane = _mm256_set_epi64x(3, 2, 1, 0);
  if (cols <= 32) {  // up to 8 chunks in registers
    const Index nc = (cols + 3) / 4;
    const __m256i m = _mm256_cmpgt_epi64(_mm256_set1_epi64x(cols - 4 * (nc - 1)), lane);
    switch (nc) {
      case 1: substituteRowsDispatch<1>(a, n, x, ldx, cols, m); return;
      case 2: substituteRowsDispatch<2>(a, n, x, ldx, cols, m); return;
      case 3: substituteRowsDispatch<3>(a, n, x, ldx, cols, m); return;
      case 4: substituteRowsDispatch<4>(a, n, x, ldx, cols, m); return;
      case 5: substituteRowsDispatch<5>(a, n, x, ldx, cols, m); return;
      case 6: substituteRowsDispatch<6>(a, n, x, ldx, cols, m); return;
      case 7: substituteRowsDispatch<7>(a, n, x, ldx, cols, m); return;
      default: substituteRowsDispatch<8>(a, n, x, ldx, cols, m); return;
    }
  }
  for (Index j0 = 0; j0 < cols; j0 += 4) {
    const Index w = std::min<Index>(4, cols - j0);
    const __m256i m = _mm256_cmpgt_epi64(_mm256_set1_epi64x(w), lane);
    if (w == 4) {
      substituteChunk<true>(a, n, x + j0, ldx, m);
    } else {
      substituteChunk<false>(a, n, x + j0, ldx, m);
    }
  }
}

}  // namespace

void SmallLu::resize(Index n, Index columns) {
  lu_.resize(n, n);
  perm_.resize(n);
  x_.resize(n, columns);
}

void SmallLu::factor(const Eigen::Ref<const Eigen::MatrixXd>& M, bool transposed) {
  const Index n = M.rows();
  if (lu_.rows() != n) resize(n, x_.cols() > 0 ? x_.cols() : 1);
  if (transposed) {
    lu_ = M.transpose();  // row-major copy of Mᵀ: M's columns become rows
  } else {
    lu_ = M;  // row-major copy
  }
  if (matmulUsesAvx2()) {
    factorAvx2(lu_.data(), n, perm_.data());
  } else {
    factorGeneric(lu_.data(), n, perm_.data());
  }
}

void SmallLu::solve(Eigen::Ref<Eigen::MatrixXd> X) {
  const Index n = lu_.rows(), cols = X.cols();
  if (x_.rows() != n || x_.cols() < cols) x_.resize(n, cols);
  const Index ldx = x_.cols();
  // Gather in pivoted order, transposed to row-major.
  for (Index i = 0; i < n; ++i) {
    const double* src = X.data() + perm_[i];
    double* dst = x_.data() + i * ldx;
    for (Index j = 0; j < cols; ++j) dst[j] = src[j * X.outerStride()];
  }
  if (matmulUsesAvx2()) {
    substituteAvx2(lu_.data(), n, x_.data(), cols, ldx);
  } else {
    substituteGeneric(lu_.data(), n, x_.data(), cols, ldx);
  }
  for (Index j = 0; j < cols; ++j) {
    double* dst = X.data() + j * X.outerStride();
    for (Index i = 0; i < n; ++i) dst[i] = x_(i, j);
  }
}

}  // namespace trellis::detail
