// lapack.cpp — the LAPACK calls of control/ (see lapack.hpp); the only file that declares them.
#include "lapack.hpp"

#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>

// Fortran LAPACK (LP64: INTEGER is int); hidden CHARACTER lengths last, as gfortran passes them.
extern "C" {
void dgetrf_(const int* m, const int* n, double* a, const int* lda, int* ipiv, int* info);
void dgetri_(const int* n, double* a, const int* lda, const int* ipiv, double* work,
             const int* lwork, int* info);
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

LuInverse::LuInverse(Eigen::Index n) : n_(checkedSize(n)), ipiv_(static_cast<std::size_t>(n_)) {
  double query = 0.0, unused = 0.0;
  const int lwork = -1;
  int info = 0;
  dgetri_(&n_, &unused, &n_, ipiv_.data(), &query, &lwork, &info);
  checkInfo(info, "dgetri (workspace query)");
  work_.resize(static_cast<std::size_t>(std::max(static_cast<double>(n_), query)));
}

int LuInverse::invert(Eigen::MatrixXd& Z, double& logAbsDet) {
  if (Z.rows() != n_ || Z.cols() != n_) throw std::logic_error("lapack: LuInverse size mismatch");
  int info = 0;
  dgetrf_(&n_, &n_, Z.data(), &n_, ipiv_.data(), &info);
  checkInfo(info, "dgetrf");
  logAbsDet = 0.0;
  for (int i = 0; i < n_; ++i) {
    const double u = std::abs(Z(i, i));
    if (!(u > 0.0) || !std::isfinite(u)) return info > 0 ? info : i + 1;
    logAbsDet += std::log(u);
  }
  if (info > 0) return info;
  const int lwork = static_cast<int>(work_.size());
  dgetri_(&n_, Z.data(), &n_, ipiv_.data(), work_.data(), &lwork, &info);
  return checkInfo(info, "dgetri");
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
