// riccati_lyapunov.cpp — Bartels–Stewart solve of the Riccati Newton matrix (see the header).
#include "riccati_lyapunov.hpp"

#include <cmath>
#include <utility>

namespace trellis::detail {

SchurLyapunov::SchurLyapunov(Eigen::Index n)
    : n_(n), schur_(n), Z_(n, n), T_(n, n), TF_(n, n), TFt_(n, n), C_(n, n), Y_(n, n) {
  blockStart_.reserve(static_cast<std::size_t>(n) + 1);
}

bool SchurLyapunov::factor(const Eigen::MatrixXd& Acl) {
  schur_.compute(Acl);
  if (schur_.info() != Eigen::Success) return false;
  Z_ = schur_.matrixU();
  T_ = schur_.matrixT();
  blockStart_.clear();
  for (Eigen::Index k = 0; k < n_;) {
    blockStart_.push_back(k);
    k += (k + 1 < n_ && T_(k + 1, k) != 0.0) ? 2 : 1;
  }
  blockStart_.push_back(n_);
  return true;
}

namespace {

// K v = v in place for m ≤ 4 unknowns (Gaussian elimination with partial pivoting); false if K
// is singular.
bool smallSolve(int m, double (&K)[4][4], double (&v)[4]) {
  for (int c = 0; c < m; ++c) {
    int p = c;
    for (int r = c + 1; r < m; ++r) {
      if (std::abs(K[r][c]) > std::abs(K[p][c])) p = r;
    }
    if (K[p][c] == 0.0) return false;
    if (p != c) {
      for (int k = 0; k < m; ++k) std::swap(K[p][k], K[c][k]);
      std::swap(v[p], v[c]);
    }
    for (int r = c + 1; r < m; ++r) {
      const double f = K[r][c] / K[c][c];
      for (int k = c + 1; k < m; ++k) K[r][k] -= f * K[c][k];
      v[r] -= f * v[c];
    }
  }
  for (int c = m - 1; c >= 0; --c) {
    double x = v[c];
    for (int k = c + 1; k < m; ++k) x -= K[c][k] * v[k];
    v[c] = x / K[c][c];
  }
  return true;
}

}  // namespace

// With F = Z T_F Zᵀ (T_F = γT − ½I) and Y = ZᵀXZ: T_Fᵀ Y + Y T_F = C = −ZᵀRZ. Block (I, J) of Y
// (1×1 … 2×2) solves
//   T_F(I,I)ᵀ Y_IJ + Y_IJ T_F(J,J) = C_IJ − Σ_{L<I} T_F(L,I)ᵀ Y_LJ − Σ_{K<J} Y_IK T_F(K,J),
// a Kronecker system of at most 4 unknowns. Y is symmetric: only the blocks I ≤ J are solved,
// column block by column block, and each finished column is mirrored into its row, so that every
// Y_IK the sums need is known (K < I: the mirror of Y_KI; I ≤ K < J: an earlier column). For the
// diagonal block the Σ_{K<J} term is (Y_{<J,J})ᵀ T_F(<J,J), once the rows above it are solved.
// Cost: ~6 nx³ flops for the two congruences (half of each second product, the result being
// symmetric) and ~nx³ for the substitution, against ~10 nx³ without symmetry.
bool SchurLyapunov::solve(double gamma, Eigen::MatrixXd& X) {
  TF_ = gamma * T_;
  TF_.diagonal().array() -= 0.5;
  TFt_ = TF_.transpose();
  // Y ← ZᵀXZ (upper triangle; the triangular product kernel computes only that half). The
  // substitution below solves with C = +ZᵀXZ and the sign of −C enters the back transform.
  C_.noalias() = X * Z_;
  Y_.triangularView<Eigen::Upper>() = Z_.transpose() * C_;
  const std::size_t nb = blockStart_.size() - 1;
  for (std::size_t bj = 0; bj < nb; ++bj) {
    const Eigen::Index j0 = blockStart_[bj], sj = blockStart_[bj + 1] - j0, jEnd = j0 + sj;
    if (sj == 2) Y_(j0 + 1, j0) = Y_(j0, j0 + 1);  // C's lower entry of the diagonal block
    // Rows above the diagonal block: − Σ_{K<J} Y_IK T_F(K,J) for every I < J at once.
    if (j0 > 0) {
      Y_.block(0, j0, j0, sj).noalias() -= Y_.topLeftCorner(j0, j0) * TF_.block(0, j0, j0, sj);
    }
    for (std::size_t bi = 0; bi <= bj; ++bi) {
      const Eigen::Index i0 = blockStart_[bi], si = blockStart_[bi + 1] - i0;
      if (bi == bj && j0 > 0) {
        Y_.block(j0, j0, sj, sj).noalias() -=
            Y_.block(0, j0, j0, sj).transpose() * TF_.block(0, j0, j0, sj);
      }
      // vec(T_IIᵀ Y + Y T_JJ) = (I ⊗ T_IIᵀ + T_JJᵀ ⊗ I) vec(Y), column-major vec.
      const int m = static_cast<int>(si * sj);
      if (m == 1) {
        const double d = TF_(i0, i0) + TF_(j0, j0);
        if (d == 0.0) return false;
        Y_(i0, j0) /= d;
      } else {
        double K[4][4] = {};
        double v[4] = {};
        for (Eigen::Index c = 0; c < sj; ++c) {
          for (Eigen::Index r = 0; r < si; ++r) {
            const Eigen::Index row = c * si + r;
            v[row] = Y_(i0 + r, j0 + c);
            for (Eigen::Index l = 0; l < si; ++l) K[row][c * si + l] += TF_(i0 + l, i0 + r);
            for (Eigen::Index k = 0; k < sj; ++k) K[row][k * si + r] += TF_(j0 + k, j0 + c);
          }
        }
        if (!smallSolve(m, K, v)) return false;
        for (Eigen::Index c = 0; c < sj; ++c) {
          for (Eigen::Index r = 0; r < si; ++r) Y_(i0 + r, j0 + c) = v[c * si + r];
        }
      }
      // Rows below I up to the end of J: Y(r, J) −= Σ_{l ∈ I} T_F(l, r) Y(l, J)
      // (T_F(l, r) = TFt(r, l), contiguous).
      const Eigen::Index below = i0 + si;
      for (Eigen::Index c = 0; c < sj; ++c) {
        double* out = &Y_(0, j0 + c);
        for (Eigen::Index l = 0; l < si; ++l) {
          const double y = Y_(i0 + l, j0 + c);
          const double* t = &TFt_(0, i0 + l);
          for (Eigen::Index r = below; r < jEnd; ++r) out[r] -= t[r] * y;
        }
      }
    }
    // Mirror the finished column block into its row block (the diagonal block symmetrized).
    if (j0 > 0) Y_.block(j0, 0, sj, j0) = Y_.block(0, j0, j0, sj).transpose();
    if (sj == 2) Y_(j0 + 1, j0) = Y_(j0, j0 + 1) = 0.5 * (Y_(j0 + 1, j0) + Y_(j0, j0 + 1));
  }
  C_.noalias() = -Z_ * Y_;
  X.triangularView<Eigen::Upper>() = C_ * Z_.transpose();
  X.triangularView<Eigen::StrictlyLower>() = X.transpose();
  return X.allFinite();
}

}  // namespace trellis::detail
