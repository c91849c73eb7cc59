// riccati_packing.hpp (private) — the packed upper triangle the Riccati solver integrates.
//
// A symmetric S (or an upper-triangular factor U) of size n is stored column by column as its
// upper triangle: entry (i, j), i ≤ j, at j(j+1)/2 + i; N = n(n+1)/2 numbers in all.
#pragma once

#include <Eigen/Core>

#include <algorithm>
#include <cmath>

namespace trellis::detail {

inline Eigen::Index packedSize(Eigen::Index n) { return n * (n + 1) / 2; }

inline Eigen::Index packedIndex(Eigen::Index i, Eigen::Index j) {  // i <= j
  return j * (j + 1) / 2 + i;
}

/// S (both triangles) from the packed upper triangle.
template <class Matrix>
void unpackSymmetric(const double* y, Eigen::Index n, Matrix& S) {
  for (Eigen::Index j = 0; j < n; ++j) {
    const double* col = y + j * (j + 1) / 2;
    for (Eigen::Index i = 0; i <= j; ++i) S(i, j) = S(j, i) = col[i];
  }
}

/// The upper triangle of U; the strict lower triangle is left alone (keep it zero).
template <class Matrix>
void unpackUpper(const double* y, Eigen::Index n, Matrix& U) {
  for (Eigen::Index j = 0; j < n; ++j) {
    const double* col = y + j * (j + 1) / 2;
    for (Eigen::Index i = 0; i <= j; ++i) U(i, j) = col[i];
  }
}

/// Packs the upper triangle of S.
template <class Matrix>
void packUpper(const Matrix& S, Eigen::Index n, double* y) {
  for (Eigen::Index j = 0; j < n; ++j) {
    double* col = y + j * (j + 1) / 2;
    for (Eigen::Index i = 0; i <= j; ++i) col[i] = S(i, j);
  }
}

/// Packs the symmetric part F + Fᵀ (plus D when given) without forming it.
template <class Matrix>
void packSymmetrized(const Matrix& F, Eigen::Index n, double* y) {
  for (Eigen::Index j = 0; j < n; ++j) {
    double* col = y + j * (j + 1) / 2;
    for (Eigen::Index i = 0; i <= j; ++i) col[i] = F(i, j) + F(j, i);
  }
}

/// max |S_ij| of S = UᵀU: its largest diagonal entry max_j ‖U(:, j)‖² (Cauchy–Schwarz).
inline double factorNorm(const double* y, Eigen::Index n) {
  double m = 0.0;
  for (Eigen::Index j = 0; j < n; ++j) {
    const double* col = y + j * (j + 1) / 2;
    double d = 0.0;
    for (Eigen::Index i = 0; i <= j; ++i) d += col[i] * col[i];
    m = std::max(m, d);
  }
  return m;
}

inline double maxAbs(const double* y, Eigen::Index N) {
  double m = 0.0;
  for (Eigen::Index i = 0; i < N; ++i) m = std::max(m, std::abs(y[i]));
  return m;
}

}  // namespace trellis::detail
