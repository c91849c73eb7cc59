// lapack.cpp — the LAPACK calls of control/ (see lapack.hpp); the only file that declares them.
#include "lapack.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>

// Fortran LAPACK (LP64: INTEGER is int); hidden CHARACTER lengths last, as gfortran passes them.
extern "C" {
void dsytrf_(const char* uplo, const int* n, double* a, const int* lda, int* ipiv, double* work,
             const int* lwork, int* info, std::size_t uploLen);
void dsytri2_(const char* uplo, const int* n, double* a, const int* lda, const int* ipiv,
              double* work, const int* lwork, int* info, std::size_t uploLen);
void dgees_(const char* jobvs, const char* sort, int (*select)(const double*, const double*),
            const int* n, double* a, const int* lda, int* sdim, double* wr, double* wi, double* vs,
            const int* ldvs, double* work, const int* lwork, int* bwork, int* info,
            std::size_t jobvsLen, std::size_t sortLen);
void dtrsyl_(const char* trana, const char* tranb, const int* isgn, const int* m, const int* n,
             const double* a, const int* lda, const double* b, const int* ldb, double* c,
             const int* ldc, double* scale, int* info, std::size_t tranaLen, std::size_t tranbLen);
}

namespace trellis::detail::lapack {

namespace {

int checkedSize(Eigen::Index n) {
  if (n < 1 || n > 1 << 24) throw std::logic_error("lapack: size " + std::to_string(n) + " out of range");
  return static_cast<int>(n);
}

/// A negative INFO is an argument this file got wrong, never a property of the data.
int checkInfo(int info, const char* routine) {
  if (info < 0)
    throw std::logic_error(std::string("lapack: ") + routine + " rejected argument " +
                           std::to_string(-info));
  return info;
}

}  // namespace

SymmetricInverse::SymmetricInverse(Eigen::Index n) : n_(checkedSize(n)), ipiv_(static_cast<std::size_t>(n_)) {
  double qf = 0.0, qi = 0.0, unused = 0.0;
  const int lwork = -1;
  int info = 0;
  dsytrf_("L", &n_, &unused, &n_, ipiv_.data(), &qf, &lwork, &info, 1);
  checkInfo(info, "dsytrf (workspace query)");
  dsytri2_("L", &n_, &unused, &n_, ipiv_.data(), &qi, &lwork, &info, 1);
  checkInfo(info, "dsytri2 (workspace query)");
  work_.resize(static_cast<std::size_t>(std::max({static_cast<double>(n_), qf, qi})));
}

int SymmetricInverse::invert(Eigen::MatrixXd& W, double& logAbsDet) {
  if (W.rows() != n_ || W.cols() != n_) throw std::logic_error("lapack: SymmetricInverse size mismatch");
  const int lwork = static_cast<int>(work_.size());
  int info = 0;
  dsytrf_("L", &n_, W.data(), &n_, ipiv_.data(), work_.data(), &lwork, &info, 1);
  checkInfo(info, "dsytrf");
  // det W = Π det D_k: ipiv_k > 0 marks a 1×1 block D_kk; ipiv_k = ipiv_{k+1} < 0 a 2×2 block
  // [[D_kk, D_k+1,k], [D_k+1,k, D_k+1,k+1]] (lower storage, 1-based pivots).
  logAbsDet = 0.0;
  for (int k = 0; k < n_; ++k) {
    double logDet = 0.0;
    if (ipiv_[static_cast<std::size_t>(k)] < 0 && k + 1 < n_) {
      // ac − b² = b²((a/b)(c/b) − 1): Bunch–Kaufman takes a 2×2 block when |b| dominates, and the
      // logarithms of the two factors do not overflow where the product would.
      const double a = W(k, k), b = W(k + 1, k), c = W(k + 1, k + 1);
      logDet = b != 0.0 ? 2.0 * std::log(std::abs(b)) + std::log(std::abs((a / b) * (c / b) - 1.0))
                        : std::log(std::abs(a * c));
      ++k;
    } else {
      logDet = std::log(std::abs(W(k, k)));
    }
    if (!std::isfinite(logDet)) return info > 0 ? info : k + 1;  // an exactly singular or non-finite block
    logAbsDet += logDet;
  }
  if (info > 0) return info;
  dsytri2_("L", &n_, W.data(), &n_, ipiv_.data(), work_.data(), &lwork, &info, 1);
  checkInfo(info, "dsytri2");
  if (info > 0) return info;
  for (int j = 1; j < n_; ++j)
    for (int i = 0; i < j; ++i) W(i, j) = W(j, i);
  return 0;
}

RealSchur::RealSchur(Eigen::Index n, bool vectors)
    : n_(checkedSize(n)), vectors_(vectors), T_(n, n), U_(vectors ? n : 0, vectors ? n : 0),
      wr_(n), wi_(n) {
  double query = 0.0;
  const int lwork = -1, ldvs = vectors_ ? n_ : 1;
  int sdim = 0, info = 0;
  dgees_(vectors_ ? "V" : "N", "N", nullptr, &n_, T_.data(), &n_, &sdim, wr_.data(), wi_.data(),
         vectors_ ? U_.data() : nullptr, &ldvs, &query, &lwork, nullptr, &info, 1, 1);
  checkInfo(info, "dgees (workspace query)");
  work_.resize(static_cast<std::size_t>(std::max(3.0 * n_, query)));
}

int RealSchur::compute(const Eigen::MatrixXd& F) {
  if (F.rows() != n_ || F.cols() != n_) throw std::logic_error("lapack: RealSchur size mismatch");
  if (!F.allFinite()) return n_ + 1;  // dgees would iterate on NaN without a diagnosis
  T_ = F;
  const int lwork = static_cast<int>(work_.size()), ldvs = vectors_ ? n_ : 1;
  int sdim = 0, info = 0;
  dgees_(vectors_ ? "V" : "N", "N", nullptr, &n_, T_.data(), &n_, &sdim, wr_.data(), wi_.data(),
         vectors_ ? U_.data() : nullptr, &ldvs, work_.data(), &lwork, nullptr, &info, 1, 1);
  return checkInfo(info, "dgees");
}

int solveSchurLyapunov(const Eigen::MatrixXd& T, Eigen::MatrixXd& C, double& scale) {
  const int n = checkedSize(T.rows()), isgn = 1;
  if (T.cols() != n || C.rows() != n || C.cols() != n)
    throw std::logic_error("lapack: solveSchurLyapunov size mismatch");
  int info = 0;
  scale = 1.0;
  dtrsyl_("T", "N", &isgn, &n, &n, T.data(), &n, T.data(), &n, C.data(), &n, &scale, &info, 1, 1);
  return checkInfo(info, "dtrsyl");
}

}  // namespace trellis::detail::lapack
