// Tests for trellis/analysis/detail/small_lu.hpp: the row-major LU with partial pivoting of the
// Radau stage systems, against Eigen's PartialPivLU and as a residual, on both kernels (AVX2+FMA
// where the CPU has it, and the generic one), many columns in a view with an outer stride.
#include "trellis/analysis/detail/dense_kernels.hpp"
#include "trellis/analysis/detail/small_lu.hpp"

#include <Eigen/LU>

#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

namespace {

struct ForceGeneric {
  explicit ForceGeneric(bool force) { trellis::detail::matmulForceGeneric(force); }
  ~ForceGeneric() { trellis::detail::matmulForceGeneric(false); }
};

}  // namespace

TEST_CASE("small LU: solves as Eigen's PartialPivLU, pivoting where it must, every column of a view", "[small_lu]") {
  // A diagonally dominant matrix, one whose first pivot is zero (a row swap is required), one with
  // rows scaled over 12 orders and one with columns so scaled; sizes of the stage systems (the
  // halved 6, the full 18, the hand's 3·26).
  for (const bool generic : {false, true}) {
    ForceGeneric force(generic);
    for (const int n : {1, 6, 18, 78}) {
      std::vector<Eigen::MatrixXd> cases;
      cases.push_back(Eigen::MatrixXd::Random(n, n) + 8.0 * Eigen::MatrixXd::Identity(n, n));
      Eigen::MatrixXd swap = Eigen::MatrixXd::Random(n, n);
      swap(0, 0) = 0.0;
      if (n > 1) cases.push_back(swap);
      Eigen::MatrixXd rows = Eigen::MatrixXd::Random(n, n), cols = Eigen::MatrixXd::Random(n, n);
      for (int i = 0; i < n; ++i) {
        const double s = std::pow(10.0, n > 1 ? 12.0 * i / (n - 1) - 6.0 : 0.0);
        rows.row(i) *= s;
        cols.col(i) *= s;
      }
      cases.push_back(rows);
      cases.push_back(cols);
      for (std::size_t c = 0; c < cases.size(); ++c) {
        CAPTURE(generic, n, c);
        const Eigen::MatrixXd& M = cases[c];
        trellis::detail::SmallLu lu;
        lu.resize(n, 3);
        lu.factor(M);
        // 19 columns (more than resize asked: the buffer grows), inside a larger matrix.
        const int m = 19;
        const Eigen::MatrixXd B = Eigen::MatrixXd::Random(n, m);
        Eigen::MatrixXd X = Eigen::MatrixXd::Constant(n + 2, m + 1, 7.0);
        X.block(1, 0, n, m) = B;
        lu.solve(X.block(1, 0, n, m));
        const Eigen::MatrixXd x = X.block(1, 0, n, m);
        const Eigen::MatrixXd ref = Eigen::PartialPivLU<Eigen::MatrixXd>(M).solve(B);
        for (int j = 0; j < m; ++j) {
          const double residual = ((M * x.col(j) - B.col(j)).cwiseAbs().array() /
                                   (M.cwiseAbs() * x.col(j).cwiseAbs() + B.col(j).cwiseAbs()).array())
                                      .maxCoeff();
          CHECK(residual < 1e-14 * n);
          CHECK((x.col(j) - ref.col(j)).cwiseAbs().maxCoeff() <= 1e-11 * ref.col(j).cwiseAbs().maxCoeff());
        }
        // Nothing outside the view touched.
        CHECK((X.row(0).array() == 7.0).all());
        CHECK((X.row(n + 1).array() == 7.0).all());
        CHECK((X.col(m).array() == 7.0).all());
        // One column: the simulator's use; the same as the column of the block solve up to rounding.
        Eigen::MatrixXd one = B.col(3);
        lu.solve(one);
        CHECK((one - x.col(3)).cwiseAbs().maxCoeff() <= 1e-13 * x.col(3).cwiseAbs().maxCoeff());
      }
    }
  }
}

TEST_CASE("small LU: a singular matrix gives non-finite entries, not a silent answer", "[small_lu]") {
  Eigen::MatrixXd M = Eigen::MatrixXd::Random(5, 5);
  M.col(2).setZero();  // singular: the third pivot is zero
  trellis::detail::SmallLu lu;
  lu.factor(M);
  Eigen::MatrixXd X = Eigen::MatrixXd::Random(5, 3);
  lu.solve(X);
  CHECK_FALSE(X.allFinite());
  // Refactoring a regular matrix afterwards solves again.
  lu.factor(Eigen::MatrixXd::Identity(5, 5) * 2.0);
  X.setOnes();
  lu.solve(X);
  CHECK((X.array() == 0.5).all());
}
