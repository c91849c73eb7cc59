// riccati_lyapunov.cpp — Bartels–Stewart solve of the Riccati Newton matrix (see the header).
#include "riccati_lyapunov.hpp"

#include <Eigen/LU>

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

// With F = Z T_F Zᵀ (T_F = γT − ½I) and Y = ZᵀXZ: T_Fᵀ Y + Y T_F = C = −ZᵀRZ. Block (I, J) of Y
// (1×1 … 2×2) solves
//   T_F(I,I)ᵀ Y_IJ + Y_IJ T_F(J,J) = C_IJ − Σ_{L<I} T_F(L,I)ᵀ Y_LJ − Σ_{K<J} Y_IK T_F(K,J),
// a Kronecker system of at most 4 unknowns, taken in increasing I and J.
bool SchurLyapunov::solve(double gamma, Eigen::MatrixXd& X) {
  const Eigen::Index n = n_;
  TF_ = gamma * T_;
  TF_.diagonal().array() -= 0.5;
  TFt_ = TF_.transpose();
  C_.noalias() = Z_.transpose() * X;
  Y_.noalias() = -C_ * Z_;  // C, overwritten by Y block by block
  const std::size_t nb = blockStart_.size() - 1;
  for (std::size_t bj = 0; bj < nb; ++bj) {
    const Eigen::Index j0 = blockStart_[bj], sj = blockStart_[bj + 1] - j0;
    // − Σ_{K<J} Y_IK T_F(K,J) for every I at once.
    if (j0 > 0) Y_.middleCols(j0, sj).noalias() -= Y_.leftCols(j0) * TF_.block(0, j0, j0, sj);
    for (std::size_t bi = 0; bi < nb; ++bi) {
      const Eigen::Index i0 = blockStart_[bi], si = blockStart_[bi + 1] - i0;
      // vec(T_IIᵀ Y + Y T_JJ) = (I ⊗ T_IIᵀ + T_JJᵀ ⊗ I) vec(Y), column-major vec.
      const Eigen::Index m = si * sj;
      if (m == 1) {
        const double d = TF_(i0, i0) + TF_(j0, j0);
        if (d == 0.0) return false;
        Y_(i0, j0) /= d;
      } else {
        Eigen::Matrix4d K = Eigen::Matrix4d::Zero();
        Eigen::Vector4d v = Eigen::Vector4d::Zero();
        for (Eigen::Index c = 0; c < sj; ++c) {
          for (Eigen::Index r = 0; r < si; ++r) {
            const Eigen::Index row = c * si + r;
            v(row) = Y_(i0 + r, j0 + c);
            for (Eigen::Index l = 0; l < si; ++l) K(row, c * si + l) += TF_(i0 + l, i0 + r);
            for (Eigen::Index k = 0; k < sj; ++k) K(row, k * si + r) += TF_(j0 + k, j0 + c);
          }
        }
        if (m == 2) {
          const Eigen::Vector2d y = K.topLeftCorner<2, 2>().partialPivLu().solve(v.head<2>());
          v.head<2>() = y;
        } else {
          v = K.partialPivLu().solve(v);
        }
        if (!v.allFinite()) return false;
        for (Eigen::Index c = 0; c < sj; ++c) {
          for (Eigen::Index r = 0; r < si; ++r) Y_(i0 + r, j0 + c) = v(c * si + r);
        }
      }
      // Rows below I: Y(r, J) −= Σ_{l ∈ I} T_F(l, r) Y(l, J)  (T_F(l, r) = TFt(r, l), contiguous).
      const Eigen::Index below = i0 + si;
      for (Eigen::Index c = 0; c < sj; ++c) {
        double* out = &Y_(0, j0 + c);
        for (Eigen::Index l = 0; l < si; ++l) {
          const double y = Y_(i0 + l, j0 + c);
          const double* t = &TFt_(0, i0 + l);
          for (Eigen::Index r = below; r < n; ++r) out[r] -= t[r] * y;
        }
      }
    }
  }
  C_.noalias() = Z_ * Y_;
  X.noalias() = C_ * Z_.transpose();
  return X.allFinite();
}

}  // namespace trellis::detail
