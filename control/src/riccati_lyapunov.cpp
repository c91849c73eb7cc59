// riccati_lyapunov.cpp — Bartels–Stewart solve of the Riccati Newton matrix (see the header).
#include "riccati_lyapunov.hpp"

#include "trellis/analysis/detail/dense_kernels.hpp"

#include <cmath>
#include <utility>

namespace trellis::detail {

SchurLyapunov::SchurLyapunov(Eigen::Index n)
    : n_(n), schur_(n), Z_(n, n), Zt_(n, n), T_(n, n), TF_(n, n), C_(n, n), Y_(n, n) {
  blockStart_.reserve(static_cast<std::size_t>(n) + 1);
}

bool SchurLyapunov::factor(const Eigen::MatrixXd& Acl) {
  schur_.compute(Acl);
  if (schur_.info() != Eigen::Success) return false;
  Z_ = schur_.matrixU();
  Zt_ = Z_.transpose();
  T_ = schur_.matrixT();
  tfValid_ = false;
  blockStart_.clear();
  for (Eigen::Index k = 0; k < n_;) {
    blockStart_.push_back(k);
    k += (k + 1 < n_ && T_(k + 1, k) != 0.0) ? 2 : 1;
  }
  blockStart_.push_back(n_);
  return true;
}

namespace {

// K v = v in place for M ≤ 4 unknowns (Gaussian elimination with partial pivoting; sizes fixed
// at compile time so that the loops unroll); false if K is singular.
template <int M>
bool smallSolve(double (&K)[4][4], double (&v)[4]) {
  for (int c = 0; c < M; ++c) {
    int p = c;
    for (int r = c + 1; r < M; ++r) {
      if (std::abs(K[r][c]) > std::abs(K[p][c])) p = r;
    }
    if (K[p][c] == 0.0) return false;
    if (p != c) {
      for (int k = 0; k < M; ++k) std::swap(K[p][k], K[c][k]);
      std::swap(v[p], v[c]);
    }
    for (int r = c + 1; r < M; ++r) {
      const double f = K[r][c] / K[c][c];
      for (int k = c + 1; k < M; ++k) K[r][k] -= f * K[c][k];
      v[r] -= f * v[c];
    }
  }
  for (int c = M - 1; c >= 0; --c) {
    double x = v[c];
    for (int k = c + 1; k < M; ++k) x -= K[c][k] * v[k];
    v[c] = x / K[c][c];
  }
  return true;
}

// Block (I, J) of T_F(I,I)ᵀ Y + Y T_F(J,J) = Y(I, J) in place, SI×SJ ∈ {1, 2}²:
// vec(T_IIᵀ Y + Y T_JJ) = (I ⊗ T_IIᵀ + T_JJᵀ ⊗ I) vec(Y), column-major vec.
template <int SI, int SJ>
bool blockSolve(const Eigen::MatrixXd& TF, Eigen::MatrixXd& Y, Eigen::Index i0, Eigen::Index j0) {
  double K[4][4] = {};
  double v[4] = {};
  for (int c = 0; c < SJ; ++c) {
    for (int r = 0; r < SI; ++r) {
      const int row = c * SI + r;
      v[row] = Y(i0 + r, j0 + c);
      for (int l = 0; l < SI; ++l) K[row][c * SI + l] += TF(i0 + l, i0 + r);
      for (int k = 0; k < SJ; ++k) K[row][k * SI + r] += TF(j0 + k, j0 + c);
    }
  }
  if (!smallSolve<SI * SJ>(K, v)) return false;
  for (int c = 0; c < SJ; ++c) {
    for (int r = 0; r < SI; ++r) Y(i0 + r, j0 + c) = v[c * SI + r];
  }
  return true;
}

}  // namespace

// With F = Z T_F Zᵀ (T_F = γT − ½I) and Y = ZᵀXZ: T_Fᵀ Y + Y T_F = C = −ZᵀRZ. Block (I, J) of Y
// (1×1 … 2×2) solves
//   T_F(I,I)ᵀ Y_IJ + Y_IJ T_F(J,J) = C_IJ − Σ_{L<I} T_F(L,I)ᵀ Y_LJ − Σ_{K<J} Y_IK T_F(K,J),
// a Kronecker system of at most 4 unknowns. Y is symmetric: only the blocks I ≤ J are solved,
// column block by column block, and each finished column is mirrored into its row, so that every
// Y_IK the sums need is known (K < I: the mirror of Y_KI; I ≤ K < J: an earlier column). Per
// column block J, the Σ_{K<J} terms of all rows above J are one product Y(0:j0, 0:j0)·T_F(0:j0, J);
// then, row block by row block, the Σ_{L<I} terms are dot products of a column of T_F with one of
// Y (both contiguous). For the diagonal block the Σ_{K<J} term is (Y_{<J,J})ᵀ T_F(<J,J), once the
// rows above it are solved.
// Cost: ~6 nx³ flops for the two congruences (half of each second product, the result being
// symmetric) and ~nx³ for the substitution, against ~10 nx³ without symmetry.
bool SchurLyapunov::solve(double gamma, Eigen::MatrixXd& X) {
  const Eigen::Index n = n_;
  if (!tfValid_ || gamma != gammaTF_) {  // γ is the same for all iterations of a step
    TF_ = gamma * T_;
    TF_.diagonal().array() -= 0.5;
    gammaTF_ = gamma;
    tfValid_ = true;
  }
  // Y ← ZᵀXZ (upper triangle). The substitution below solves with C = +ZᵀXZ and the sign of −C
  // enters the back transform.
  matmul(n, n, n, 1.0, X.data(), n, Z_.data(), n, false, C_.data(), n, false);
  matmul(n, n, n, 1.0, Zt_.data(), n, C_.data(), n, false, Y_.data(), n, true);
  const std::size_t nb = blockStart_.size() - 1;
  for (std::size_t bj = 0; bj < nb; ++bj) {
    const Eigen::Index j0 = blockStart_[bj], sj = blockStart_[bj + 1] - j0;
    if (sj == 2) Y_(j0 + 1, j0) = Y_(j0, j0 + 1);  // C's lower entry of the diagonal block
    // Rows above the diagonal block: Y(0:j0, J) −= Y(0:j0, 0:j0) T_F(0:j0, J), column by column
    // of Y (contiguous; Y(0:j0, 0:j0) is complete: earlier columns and their mirrors).
    matmul(j0, sj, j0, -1.0, Y_.data(), n, &TF_(0, j0), n, false, &Y_(0, j0), n, false, true);
    for (std::size_t bi = 0; bi <= bj; ++bi) {
      const Eigen::Index i0 = blockStart_[bi], si = blockStart_[bi + 1] - i0;
      // − Σ_{L<I} T_F(L,I)ᵀ Y_LJ: dot products of columns of T_F and Y over rows 0…i0 (the
      // rows above I in column block J are final). The diagonal block also takes
      // − Σ_{K<J} Y_JK T_F(K,J) = −(Y(0:j0, J))ᵀ T_F(0:j0, J), which the rows-above product
      // left out.
      if (i0 > 0) {
        for (Eigen::Index c = 0; c < sj; ++c) {
          const double* y = &Y_(0, j0 + c);
          for (Eigen::Index r = 0; r < si; ++r) {
            double d = dotProduct(&TF_(0, i0 + r), y, i0);
            if (bi == bj) d += dotProduct(&Y_(0, j0 + r), &TF_(0, j0 + c), j0);
            Y_(i0 + r, j0 + c) -= d;
          }
        }
      }
      bool ok = true;
      if (si == 1 && sj == 1) {
        const double d = TF_(i0, i0) + TF_(j0, j0);
        if (d == 0.0) return false;
        Y_(i0, j0) /= d;
      } else if (si == 1) {
        ok = blockSolve<1, 2>(TF_, Y_, i0, j0);
      } else if (sj == 1) {
        ok = blockSolve<2, 1>(TF_, Y_, i0, j0);
      } else {
        ok = blockSolve<2, 2>(TF_, Y_, i0, j0);
      }
      if (!ok) return false;
    }
    // Mirror the finished column block into its row block (the diagonal block symmetrized).
    for (Eigen::Index c = 0; c < sj; ++c) {
      const double* col = &Y_(0, j0 + c);
      for (Eigen::Index r = 0; r < j0; ++r) Y_(j0 + c, r) = col[r];
    }
    if (sj == 2) Y_(j0 + 1, j0) = Y_(j0, j0 + 1) = 0.5 * (Y_(j0 + 1, j0) + Y_(j0, j0 + 1));
  }
  // X = −Z Y Zᵀ (upper triangle, then mirrored).
  matmul(n, n, n, -1.0, Z_.data(), n, Y_.data(), n, false, C_.data(), n, false);
  matmul(n, n, n, 1.0, C_.data(), n, Z_.data(), n, true, X.data(), n, true);
  for (Eigen::Index j = 0; j < n; ++j) {
    const double* col = &X(0, j);
    for (Eigen::Index i = 0; i < j; ++i) X(j, i) = col[i];
  }
  return finiteEntries(X.data(), n * n);
}

}  // namespace trellis::detail
