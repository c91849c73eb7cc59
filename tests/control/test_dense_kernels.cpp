// Tests for control/src/dense_kernels.hpp (private): matmul against Eigen's product on both of
// its paths (the AVX2+FMA kernel when the CPU has it, and Eigen's product), every shape the
// kernel's edges handle (rows not a multiple of 8 or 4, 1…3 trailing columns, k = 0), op(B) = B
// and Bᵀ, the upper-triangle mode and accumulation, with leading dimensions larger than the
// blocks; and the Lyapunov solve on both paths.
#include "trellis/analysis/detail/dense_kernels.hpp"
#include "riccati_lyapunov.hpp"

#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cstdlib>
#include <limits>

using Eigen::MatrixXd;
using trellis::detail::matmul;

namespace {

struct ForceGeneric {  // restores the automatic choice even when a check fails
  explicit ForceGeneric(bool force) { trellis::detail::matmulForceGeneric(force); }
  ~ForceGeneric() { trellis::detail::matmulForceGeneric(false); }
};

void checkShapes() {
  std::srand(5);
  for (int m : {1, 3, 4, 7, 8, 9, 13, 16, 21, 40}) {
    for (int n : {1, 2, 3, 4, 5, 7, 9, 40}) {
      for (int k : {0, 1, 2, 5, 17}) {
        for (bool transB : {false, true}) {
          // Operands inside larger arrays: leading dimensions exceed the block sizes.
          const MatrixXd Abig = MatrixXd::Random(m + 3, k + 1);
          const MatrixXd Bbig = transB ? MatrixXd::Random(n + 2, k + 1) : MatrixXd::Random(k + 2, n + 1);
          const MatrixXd A = Abig.topLeftCorner(m, k);
          const MatrixXd opB = transB ? MatrixXd(Bbig.topLeftCorner(n, k).transpose())
                                      : MatrixXd(Bbig.topLeftCorner(k, n));
          const MatrixXd ref = -0.7 * A * opB;
          const MatrixXd C0 = MatrixXd::Random(m + 1, n);
          INFO("m = " << m << ", n = " << n << ", k = " << k << ", transB = " << transB);
          MatrixXd C = C0;  // overwrite: every entry of the m×n block, nothing below it
          matmul(m, n, k, -0.7, Abig.data(), Abig.rows(), Bbig.data(), Bbig.rows(), transB,
                 C.data(), C.rows(), false);
          CHECK((C.topRows(m) - ref).cwiseAbs().maxCoeff() <= 1e-13);
          CHECK(C.row(m) == C0.row(m));
          C = C0;  // accumulate
          matmul(m, n, k, -0.7, Abig.data(), Abig.rows(), Bbig.data(), Bbig.rows(), transB,
                 C.data(), C.rows(), false, true);
          CHECK((C.topRows(m) - C0.topRows(m) - ref).cwiseAbs().maxCoeff() <= 1e-13);
          CHECK(C.row(m) == C0.row(m));
          C = C0;  // upper triangle only
          matmul(m, n, k, -0.7, Abig.data(), Abig.rows(), Bbig.data(), Bbig.rows(), transB,
                 C.data(), C.rows(), true);
          double err = 0.0;
          for (int j = 0; j < n; ++j) {
            for (int i = 0; i <= std::min(j, m - 1); ++i) err = std::max(err, std::abs(C(i, j) - ref(i, j)));
          }
          CHECK(err <= 1e-13);
          CHECK(C.row(m) == C0.row(m));
        }
      }
    }
  }
}

}  // namespace

TEST_CASE("matmul equals Eigen's product on the automatic path", "[riccati]") {
  INFO("AVX2+FMA kernel in use: " << trellis::detail::matmulUsesAvx2());
  checkShapes();
}

TEST_CASE("matmul equals Eigen's product on the generic path", "[riccati]") {
  const ForceGeneric generic(true);
  CHECK_FALSE(trellis::detail::matmulUsesAvx2());
  checkShapes();
}

TEST_CASE("the Lyapunov solve agrees on both matmul paths", "[riccati]") {
  std::srand(9);
  for (int n : {5, 12, 40}) {
    const MatrixXd A = 3.0 * MatrixXd::Random(n, n);
    MatrixXd R = MatrixXd::Random(n, n);
    R = (R + R.transpose()).eval();
    trellis::detail::SchurLyapunov lyap(n);
    REQUIRE(lyap.factor(A));
    MatrixXd Xauto = R, Xgeneric = R;
    REQUIRE(lyap.solve(0.2, Xauto));
    {
      const ForceGeneric generic(true);
      REQUIRE(lyap.solve(0.2, Xgeneric));
    }
    INFO("n = " << n);
    const MatrixXd residual = Xauto - 0.2 * (A.transpose() * Xauto + Xauto * A) - R;
    CHECK(residual.cwiseAbs().maxCoeff() <= 1e-10 * (1.0 + R.cwiseAbs().maxCoeff()));
    CHECK((Xauto - Xgeneric).cwiseAbs().maxCoeff() <= 1e-11 * (1.0 + Xgeneric.cwiseAbs().maxCoeff()));
  }
}

TEST_CASE("dotProduct equals Eigen's dot on both paths, every tail length", "[riccati]") {
  std::srand(13);
  for (bool generic : {false, true}) {
    const ForceGeneric force(generic);
    for (int n : {0, 1, 3, 4, 5, 7, 8, 9, 15, 16, 17, 40, 83}) {
      const Eigen::VectorXd x = Eigen::VectorXd::Random(n + 1), y = Eigen::VectorXd::Random(n + 1);
      INFO("n = " << n << ", generic = " << generic);
      CHECK(std::abs(trellis::detail::dotProduct(x.data(), y.data(), n) - x.head(n).dot(y.head(n))) <= 1e-14 * (1 + n));
    }
  }
}

TEST_CASE("choleskyUpper: UᵀU = A for positive definite A, false otherwise, on both paths",
          "[riccati]") {
  std::srand(17);
  for (bool generic : {false, true}) {
    const ForceGeneric force(generic);
    for (int n : {1, 2, 5, 9, 40}) {
      INFO("n = " << n << ", generic = " << generic);
      const MatrixXd M = MatrixXd::Random(n, n);
      const MatrixXd A = M * M.transpose() + 0.1 * MatrixXd::Identity(n, n);
      MatrixXd U = A;
      Eigen::VectorXd work(n);
      REQUIRE(trellis::detail::choleskyUpper(U.data(), n, n, work.data()));
      const MatrixXd Ut = U.triangularView<Eigen::Upper>();
      CHECK((Ut.transpose() * Ut - A).cwiseAbs().maxCoeff() <= 1e-12 * A.cwiseAbs().maxCoeff());
      CHECK((U.triangularView<Eigen::StrictlyLower>().toDenseMatrix() -
             A.triangularView<Eigen::StrictlyLower>().toDenseMatrix())
                .cwiseAbs()
                .maxCoeff() == 0.0);  // the lower triangle is left alone
      // Indefinite (one negative eigenvalue), semidefinite (a zero pivot) and non-finite.
      Eigen::SelfAdjointEigenSolver<MatrixXd> es(A);
      Eigen::VectorXd lambda = es.eigenvalues();
      lambda(0) = -0.05;
      MatrixXd B = es.eigenvectors() * lambda.asDiagonal() * es.eigenvectors().transpose();
      CHECK_FALSE(trellis::detail::choleskyUpper(B.data(), n, n, work.data()));
      MatrixXd Z = MatrixXd::Zero(n, n);
      CHECK_FALSE(trellis::detail::choleskyUpper(Z.data(), n, n, work.data()));
      MatrixXd N = A;
      N(n - 1, n - 1) = std::numeric_limits<double>::quiet_NaN();
      CHECK_FALSE(trellis::detail::choleskyUpper(N.data(), n, n, work.data()));
    }
  }
}

TEST_CASE("finiteEntries finds a NaN or an infinity anywhere", "[riccati]") {
  for (int n : {0, 1, 3, 4, 9}) {
    Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(n, -1e300, 1e300);
    CHECK(trellis::detail::finiteEntries(x.data(), n));
    for (int k = 0; k < n; ++k) {
      for (double bad : {std::numeric_limits<double>::quiet_NaN(),
                         std::numeric_limits<double>::infinity(),
                         -std::numeric_limits<double>::infinity()}) {
        Eigen::VectorXd y = x;
        y(k) = bad;
        INFO("n = " << n << ", k = " << k << ", value " << bad);
        CHECK_FALSE(trellis::detail::finiteEntries(y.data(), n));
      }
    }
  }
}
