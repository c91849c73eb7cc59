// dense_kernels.cpp — matmul: Eigen's product, or an AVX2+FMA kernel chosen at run time.
#include "trellis/analysis/detail/dense_kernels.hpp"

#include <immintrin.h>

#include <algorithm>
#include <cmath>

namespace trellis::detail {

namespace {

using Index = Eigen::Index;

// C(i0:i0+8, j0:j0+NJ) for NJ ≤ 4 columns (columns of A contiguous, op(B) entries broadcast):
// 2·NJ accumulators, one FMA per 4 rows and column per k. rows < 8 (bottom edge): masked.
template <bool TransB, int NJ, bool Full>
__attribute__((target("avx2,fma"))) inline void block8(Index rows, Index k, double alpha,
                                                       const double* A, Index lda,
                                                       const double* B, Index ldb, Index j0,
                                                       double* C, Index ldc, bool accumulate) {
  const __m256i lane = _mm256_set_epi64x(3, 2, 1, 0);
  const __m256i m0 = _mm256_cmpgt_epi64(_mm256_set1_epi64x(rows), lane);
  const __m256i m1 = _mm256_cmpgt_epi64(_mm256_set1_epi64x(rows - 4), lane);
  __m256d c[NJ][2];
  for (int j = 0; j < NJ; ++j) c[j][0] = c[j][1] = _mm256_setzero_pd();
  // op(B)(p, j0 + j) = B(p, j0 + j) or B(j0 + j, p).
  const Index bStep = TransB ? ldb : 1, bCol = TransB ? 1 : ldb;
  const double* b = B + (TransB ? j0 : j0 * ldb);
  for (Index p = 0; p < k; ++p, b += bStep) {
    const double* a = A + p * lda;
    const __m256d a0 = Full ? _mm256_loadu_pd(a) : _mm256_maskload_pd(a, m0);
    const __m256d a1 = Full ? _mm256_loadu_pd(a + 4) : _mm256_maskload_pd(a + 4, m1);
    for (int j = 0; j < NJ; ++j) {
      const __m256d bj = _mm256_broadcast_sd(b + j * bCol);
      c[j][0] = _mm256_fmadd_pd(a0, bj, c[j][0]);
      c[j][1] = _mm256_fmadd_pd(a1, bj, c[j][1]);
    }
  }
  const __m256d s = _mm256_set1_pd(alpha);
  for (int j = 0; j < NJ; ++j) {
    double* out = C + (j0 + j) * ldc;
    __m256d lo = _mm256_mul_pd(c[j][0], s), hi = _mm256_mul_pd(c[j][1], s);
    if (Full) {
      if (accumulate) {
        lo = _mm256_add_pd(lo, _mm256_loadu_pd(out));
        hi = _mm256_add_pd(hi, _mm256_loadu_pd(out + 4));
      }
      _mm256_storeu_pd(out, lo);
      _mm256_storeu_pd(out + 4, hi);
    } else {
      if (accumulate) {
        lo = _mm256_add_pd(lo, _mm256_maskload_pd(out, m0));
        hi = _mm256_add_pd(hi, _mm256_maskload_pd(out + 4, m1));
      }
      _mm256_maskstore_pd(out, m0, lo);
      _mm256_maskstore_pd(out + 4, m1, hi);
    }
  }
}

template <bool TransB, bool Full>
__attribute__((target("avx2,fma"))) inline void block8Columns(Index rows, Index nj, Index k,
                                                              double alpha, const double* A,
                                                              Index lda, const double* B,
                                                              Index ldb, Index j0, double* C,
                                                              Index ldc, bool accumulate) {
  switch (nj) {
    case 4: block8<TransB, 4, Full>(rows, k, alpha, A, lda, B, ldb, j0, C, ldc, accumulate); break;
    case 3: block8<TransB, 3, Full>(rows, k, alpha, A, lda, B, ldb, j0, C, ldc, accumulate); break;
    case 2: block8<TransB, 2, Full>(rows, k, alpha, A, lda, B, ldb, j0, C, ldc, accumulate); break;
    default: block8<TransB, 1, Full>(rows, k, alpha, A, lda, B, ldb, j0, C, ldc, accumulate); break;
  }
}

template <bool TransB>
__attribute__((target("avx2,fma"))) void matmulAvx2(Index m, Index n, Index k, double alpha,
                                                    const double* A, Index lda, const double* B,
                                                    Index ldb, double* C, Index ldc,
                                                    bool upperOnly, bool accumulate) {
  for (Index j0 = 0; j0 < n; j0 += 4) {
    const Index nj = std::min<Index>(4, n - j0);
    const Index iEnd = upperOnly ? std::min(m, j0 + nj) : m;
    for (Index i0 = 0; i0 < iEnd; i0 += 8) {
      const Index rows = std::min<Index>(8, m - i0);
      if (rows == 8) {
        block8Columns<TransB, true>(8, nj, k, alpha, A + i0, lda, B, ldb, j0, C + i0, ldc,
                                    accumulate);
      } else {
        block8Columns<TransB, false>(rows, nj, k, alpha, A + i0, lda, B, ldb, j0, C + i0, ldc,
                                     accumulate);
      }
    }
  }
}

__attribute__((target("avx2,fma"))) double dotAvx2(const double* x, const double* y, Index n) {
  __m256d s0 = _mm256_setzero_pd(), s1 = s0;
  Index i = 0;
  for (; i + 8 <= n; i += 8) {
    s0 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i), _mm256_loadu_pd(y + i), s0);
    s1 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 4), _mm256_loadu_pd(y + i + 4), s1);
  }
  if (i < n) {  // 1…7 left: masked loads read nothing past the end
    const __m256i lane = _mm256_set_epi64x(3, 2, 1, 0);
    const __m256i m0 = _mm256_cmpgt_epi64(_mm256_set1_epi64x(n - i), lane);
    const __m256i m1 = _mm256_cmpgt_epi64(_mm256_set1_epi64x(n - i - 4), lane);
    s0 = _mm256_fmadd_pd(_mm256_maskload_pd(x + i, m0), _mm256_maskload_pd(y + i, m0), s0);
    s1 = _mm256_fmadd_pd(_mm256_maskload_pd(x + i + 4, m1), _mm256_maskload_pd(y + i + 4, m1), s1);
  }
  const __m256d s = _mm256_add_pd(s0, s1);
  const __m128d h = _mm_add_pd(_mm256_castpd256_pd128(s), _mm256_extractf128_pd(s, 1));
  return _mm_cvtsd_f64(_mm_add_sd(h, _mm_unpackhi_pd(h, h)));
}

// Four partial sums: independent chains (the reduction does not vectorize without reassociation).
double dotGeneric(const double* x, const double* y, Index n) {
  double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
  Index i = 0;
  for (; i + 4 <= n; i += 4) {
    s0 += x[i] * y[i];
    s1 += x[i + 1] * y[i + 1];
    s2 += x[i + 2] * y[i + 2];
    s3 += x[i + 3] * y[i + 3];
  }
  for (; i < n; ++i) s0 += x[i] * y[i];
  return (s0 + s1) + (s2 + s3);
}

void matmulEigen(Index m, Index n, Index k, double alpha, const double* A, Index lda,
                 const double* B, Index ldb, bool transB, double* C, Index ldc, bool upperOnly,
                 bool accumulate) {
  using Map = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
  using MutMap = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
  const Map a(A, m, k, Eigen::OuterStride<>(lda));
  MutMap c(C, m, n, Eigen::OuterStride<>(ldc));
  if (transB) {
    const Map b(B, n, k, Eigen::OuterStride<>(ldb));
    if (accumulate) {
      c.noalias() += alpha * (a * b.transpose());
    } else if (upperOnly) {
      c.triangularView<Eigen::Upper>() = alpha * (a * b.transpose());
    } else {
      c.noalias() = alpha * (a * b.transpose());
    }
  } else {
    const Map b(B, k, n, Eigen::OuterStride<>(ldb));
    if (accumulate) {
      c.noalias() += alpha * (a * b);
    } else if (upperOnly) {
      c.triangularView<Eigen::Upper>() = alpha * (a * b);
    } else {
      c.noalias() = alpha * (a * b);
    }
  }
}

bool cpuHasAvx2Fma() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}

const bool kHasAvx2 = cpuHasAvx2Fma();
bool forceGeneric = false;

}  // namespace

bool matmulUsesAvx2() { return kHasAvx2 && !forceGeneric; }
void matmulForceGeneric(bool force) { forceGeneric = force; }

double dotProduct(const double* x, const double* y, Index n) {
  if (n <= 0) return 0.0;
  return matmulUsesAvx2() ? dotAvx2(x, y, n) : dotGeneric(x, y, n);
}

// x − x is 0 for a finite x and NaN otherwise, and NaN survives the sums (four partial sums).
bool finiteEntries(const double* x, Index n) {
  double s[4] = {0.0, 0.0, 0.0, 0.0};
  Index i = 0;
  for (; i + 4 <= n; i += 4) {
    for (int k = 0; k < 4; ++k) s[k] += x[i + k] - x[i + k];
  }
  for (; i < n; ++i) s[0] += x[i] - x[i];
  return s[0] + s[1] + s[2] + s[3] == 0.0;
}

// Right-looking: row k of U is A(k, k:n)/√A(k, k) (copied to work, contiguous), then the
// trailing upper triangle loses its outer product, column by column (contiguous axpy).
inline __attribute__((always_inline)) bool choleskyLoop(double* A, Index n, Index lda,
                                                         double* work) {
  for (Index k = 0; k < n; ++k) {
    const double d = A[k + k * lda];
    if (!(d > 0.0) || !std::isfinite(d)) return false;
    const double r = std::sqrt(d);
    A[k + k * lda] = r;
    for (Index j = k + 1; j < n; ++j) work[j] = A[k + j * lda] /= r;
    for (Index j = k + 1; j < n; ++j) {
      const double ukj = work[j];
      double* cj = A + j * lda;
TRELLIS_IVDEP
      for (Index i = k + 1; i <= j; ++i) cj[i] -= work[i] * ukj;
    }
  }
  return true;
}

__attribute__((target("avx2,fma"))) bool choleskyAvx2(double* A, Index n, Index lda,
                                                      double* work) {
  return choleskyLoop(A, n, lda, work);
}

bool choleskyUpper(double* A, Index n, Index lda, double* work) {
  return matmulUsesAvx2() ? choleskyAvx2(A, n, lda, work) : choleskyLoop(A, n, lda, work);
}

void matmul(Index m, Index n, Index k, double alpha, const double* A, Index lda, const double* B,
            Index ldb, bool transB, double* C, Index ldc, bool upperOnly, bool accumulate) {
  if (m <= 0 || n <= 0) return;
  if (k <= 0) {
    if (!accumulate) {
      for (Index j = 0; j < n; ++j) std::fill(C + j * ldc, C + j * ldc + m, 0.0);
    }
    return;
  }
  if (!matmulUsesAvx2()) {
    matmulEigen(m, n, k, alpha, A, lda, B, ldb, transB, C, ldc, upperOnly, accumulate);
  } else if (transB) {
    matmulAvx2<true>(m, n, k, alpha, A, lda, B, ldb, C, ldc, upperOnly, accumulate);
  } else {
    matmulAvx2<false>(m, n, k, alpha, A, lda, B, ldb, C, ldc, upperOnly, accumulate);
  }
}

}  // namespace trellis::detail
