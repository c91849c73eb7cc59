// Tests for the LAPACK kernels of control/ (control/src/lapack.hpp, private) and the solvers built
// on them (solveLyapunov, solveStein, the CARE's sign iteration): each kernel against Eigen's
// counterpart on random and ill-conditioned matrices, the matrix equations against their Kronecker
// form (an independent reference), and every LAPACK failure INFO turned into a status.
#include "lapack.hpp"
#include "riccati_lyapunov.hpp"

#include <trellis/control.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <random>
#include <vector>

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;
namespace lapack = trellis::detail::lapack;

namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();

MatrixXd gaussian(std::mt19937& rng, Index rows, Index cols) {
  std::normal_distribution<double> nd(0.0, 1.0);
  return MatrixXd::NullaryExpr(rows, cols, [&] { return nd(rng); });
}

/// D M D⁻¹ with D = diag(10^k), k uniform in ±decades: the same eigenvalues, entries over
/// 4·decades orders of magnitude (what the balancing of the Riccati solvers meets).
MatrixXd badlyScaled(std::mt19937& rng, const MatrixXd& M, double decades) {
  std::uniform_real_distribution<double> ud(-decades, decades);
  const VectorXd d = VectorXd::NullaryExpr(M.rows(), [&](Index) { return std::pow(10.0, ud(rng)); });
  return d.asDiagonal() * M * d.cwiseInverse().asDiagonal();
}

/// vec(FᵀX + XF) = (I ⊗ Fᵀ + Fᵀ ⊗ I) vec(X) (column-major), or vec(FᵀXF − X) = (Fᵀ ⊗ Fᵀ − I) vec(X).
MatrixXd kroneckerSolve(const MatrixXd& F, const MatrixXd& C, bool stein) {
  const Index n = F.rows();
  MatrixXd L = MatrixXd::Zero(n * n, n * n);
  for (Index j = 0; j < n; ++j)
    for (Index i = 0; i < n; ++i)
      for (Index l = 0; l < n; ++l)
        for (Index k = 0; k < n; ++k) {
          // coefficient of X_kl in entry (i, j)
          double a = 0.0;
          if (stein) {
            a = F(k, i) * F(l, j) - (k == i && l == j ? 1.0 : 0.0);
          } else {
            if (l == j) a += F(k, i);
            if (k == i) a += F(l, j);
          }
          L(j * n + i, l * n + k) = a;
        }
  const VectorXd x = L.fullPivLu().solve(-Eigen::Map<const VectorXd>(C.data(), n * n));
  return Eigen::Map<const MatrixXd>(x.data(), n, n);
}

/// Sorted (by real part, then imaginary) eigenvalues.
std::vector<std::complex<double>> sorted(const Eigen::VectorXcd& v) {
  std::vector<std::complex<double>> s(v.data(), v.data() + v.size());
  std::sort(s.begin(), s.end(), [](auto a, auto b) {
    return a.real() != b.real() ? a.real() < b.real() : a.imag() < b.imag();
  });
  return s;
}

}  // namespace

TEST_CASE("LAPACK LU inverse against Eigen's", "[lqr][lapack]") {
  std::mt19937 rng(31);
  for (const double decades : {0.0, 3.0}) {
    for (const Index n : {1, 7, 60}) {
      const MatrixXd Z = badlyScaled(rng, gaussian(rng, n, n), decades);
      MatrixXd W = Z;
      lapack::LuInverse inverse(n);
      double logdet = std::numeric_limits<double>::quiet_NaN();
      REQUIRE(inverse.invert(W, logdet) == 0);
      const Eigen::PartialPivLU<MatrixXd> lu(Z);
      const MatrixXd ref = lu.inverse();
      // Both are backward stable: Z·W = I to cond·eps, and the two inverses agree to cond·eps.
      const double cond = Z.norm() * ref.norm();
      INFO("n = " << n << ", decades = " << decades << ", cond = " << cond);
      CHECK((Z * W - MatrixXd::Identity(n, n)).norm() <= 100 * cond * kEps);
      CHECK((W - ref).norm() <= 100 * cond * kEps * ref.norm());
      // log|det Z| = Σ log|U_ii| of either factorization.
      const double refLogdet = lu.matrixLU().diagonal().cwiseAbs().array().log().sum();
      CHECK(std::abs(logdet - refLogdet) <= 1e-12 * std::max(1.0, std::abs(refLogdet)) + 1e-12 * n);
      // The workspace is reused: a second inversion in the same object gives Z back.
      REQUIRE(inverse.invert(W, logdet) == 0);
      CHECK((W - Z).norm() <= 100 * cond * kEps * Z.norm());
    }
  }
  SECTION("an exactly singular matrix is reported with its zero pivot, not inverted") {
    MatrixXd Z = MatrixXd::Identity(3, 3);
    Z(2, 2) = 0.0;
    lapack::LuInverse inverse(3);
    double logdet = 0.0;
    CHECK(inverse.invert(Z, logdet) == 3);
    MatrixXd N = MatrixXd::Identity(2, 2);
    N(1, 1) = std::numeric_limits<double>::quiet_NaN();
    lapack::LuInverse inverse2(2);
    CHECK(inverse2.invert(N, logdet) == 2);
  }
}

TEST_CASE("LAPACK real Schur form against Eigen's eigenvalues", "[lqr][lapack]") {
  std::mt19937 rng(32);
  for (const double decades : {0.0, 4.0}) {
    for (const Index n : {1, 2, 9, 50}) {
      const MatrixXd F = badlyScaled(rng, gaussian(rng, n, n), decades);
      lapack::RealSchur schur(n, true);
      REQUIRE(schur.compute(F) == 0);
      const MatrixXd& T = schur.T();
      const MatrixXd& U = schur.U();
      INFO("n = " << n << ", decades = " << decades);
      CHECK((U.transpose() * U - MatrixXd::Identity(n, n)).norm() <= 100 * n * kEps);
      CHECK((U * T * U.transpose() - F).norm() <= 100 * n * kEps * F.norm());
      for (Index j = 0; j < n; ++j)
        for (Index i = j + 2; i < n; ++i) CHECK(T(i, j) == 0.0);  // quasi-triangular
      Eigen::VectorXcd mine(n);
      for (Index i = 0; i < n; ++i) mine(i) = {schur.wr()(i), schur.wi()(i)};
      const auto a = sorted(mine), b = sorted(Eigen::EigenSolver<MatrixXd>(F, false).eigenvalues());
      // Eigenvalues of a badly scaled (nonnormal) matrix are as accurate as their condition
      // allows; both solvers see the same data, so they agree far below ‖F‖.
      for (Index i = 0; i < n; ++i) CHECK(std::abs(a[i] - b[i]) <= 1e-8 * F.norm());
      lapack::RealSchur values(n, false);
      REQUIRE(values.compute(F) == 0);
      CHECK(values.U().size() == 0);
      CHECK((values.wr() - schur.wr()).norm() <= 1e-10 * F.norm());
    }
  }
  SECTION("a non-finite entry is INFO n + 1, not a QR iteration on NaN") {
    MatrixXd F = MatrixXd::Identity(4, 4);
    F(1, 2) = std::numeric_limits<double>::infinity();
    lapack::RealSchur schur(4, true);
    CHECK(schur.compute(F) == 5);
  }
}

TEST_CASE("LAPACK triangular Sylvester: a singular equation is INFO 1", "[lqr][lapack]") {
  // T = diag(1, −1): λ_1 + λ_2 = 0, the operator TᵀY + YT is singular; dtrsyl perturbs and says so.
  MatrixXd T = MatrixXd::Zero(2, 2);
  T(0, 0) = 1.0;
  T(1, 1) = -1.0;
  MatrixXd C = MatrixXd::Ones(2, 2);
  double scale = 0.0;
  CHECK(lapack::solveSchurLyapunov(T, C, scale) == 1);
  MatrixXd T2 = MatrixXd::Identity(2, 2);
  MatrixXd C2 = MatrixXd::Ones(2, 2);
  CHECK(lapack::solveSchurLyapunov(T2, C2, scale) == 0);
  CHECK(scale == 1.0);
  CHECK((C2 - 0.5 * MatrixXd::Ones(2, 2)).norm() <= 4 * kEps);
}

TEST_CASE("Lyapunov and Stein solves against the Kronecker form", "[lqr][lapack]") {
  std::mt19937 rng(33);
  for (const double decades : {0.0, 2.0}) {
    for (const Index n : {1, 2, 6, 15}) {
      INFO("n = " << n << ", decades = " << decades);
      const MatrixXd L = gaussian(rng, n, n);
      const MatrixXd C = L * L.transpose();
      // Lyapunov: F stable with complex pairs; Stein: F with spectral radius 0.9.
      MatrixXd F = gaussian(rng, n, n);
      F.diagonal().array() -= 1.0 + Eigen::EigenSolver<MatrixXd>(F, false).eigenvalues().real().maxCoeff();
      F = badlyScaled(rng, F, decades);
      const trellis::MatrixEquationSolution lyap = trellis::solveLyapunov(F, C);
      REQUIRE(lyap.ok());
      const MatrixXd Xl = kroneckerSolve(F, C, false);
      const double kl = (lyap.X - Xl).norm() / Xl.norm();
      CHECK(kl <= 1e-9);
      CHECK((F.transpose() * lyap.X + lyap.X * F + C).norm() <=
            1e-12 * (2 * F.norm() * lyap.X.norm() + C.norm()));

      MatrixXd G = gaussian(rng, n, n);
      G *= 0.9 / Eigen::EigenSolver<MatrixXd>(G, false).eigenvalues().cwiseAbs().maxCoeff();
      G = badlyScaled(rng, G, decades);
      const trellis::MatrixEquationSolution stein = trellis::solveStein(G, C);
      REQUIRE(stein.ok());
      const MatrixXd Xs = kroneckerSolve(G, C, true);
      CHECK((stein.X - Xs).norm() / Xs.norm() <= 1e-9);
      CHECK((G.transpose() * stein.X * G - stein.X + C).norm() <=
            1e-12 * (G.norm() * G.norm() * stein.X.norm() + stein.X.norm() + C.norm()));
    }
  }
  SECTION("the same solve as the Riccati integrator's (Eigen's real Schur, own substitution)") {
    // SchurLyapunov: X − γ(AᵀX + XA) = R, i.e. FᵀX + XF = −R with F = γA − I/2.
    const Index n = 40;
    const MatrixXd A = gaussian(rng, n, n) / std::sqrt(static_cast<double>(n));
    const MatrixXd L = gaussian(rng, n, n);
    const MatrixXd R = L * L.transpose();
    const double gamma = 0.3;
    trellis::detail::SchurLyapunov eigenPath(n);
    REQUIRE(eigenPath.factor(A));
    MatrixXd X = R;
    REQUIRE(eigenPath.solve(gamma, X));
    MatrixXd F = gamma * A;
    F.diagonal().array() -= 0.5;
    const trellis::MatrixEquationSolution lapackPath = trellis::solveLyapunov(F, R);
    REQUIRE(lapackPath.ok());
    CHECK((lapackPath.X - X).norm() <= 1e-12 * X.norm());
  }
}

TEST_CASE("Lyapunov and Stein: failures are statuses", "[lqr][lapack]") {
  SECTION("Lyapunov: λ_i + λ_j = 0 at the first Schur column that has a partner") {
    // Eigenvalues 2, 1, −1 (in some Schur order): 1 + (−1) = 0; the index is a column holding
    // one of them.
    MatrixXd F = MatrixXd::Zero(3, 3);
    F(0, 0) = 2.0;
    F(1, 1) = 1.0;
    F(2, 2) = -1.0;
    F(0, 1) = F(1, 2) = 0.5;
    const trellis::MatrixEquationSolution s = trellis::solveLyapunov(F, MatrixXd::Identity(3, 3));
    CHECK(s.status.code == trellis::MatrixEquationCode::kSingular);
    CHECK(s.status.index >= 1);
    CHECK(s.X.size() == 0);
  }
  SECTION("a non-finite F is a status that says so") {
    MatrixXd F = -MatrixXd::Identity(3, 3);
    F(0, 2) = std::numeric_limits<double>::quiet_NaN();
    const trellis::MatrixEquationSolution l = trellis::solveLyapunov(F, MatrixXd::Identity(3, 3));
    CHECK(l.status.code == trellis::MatrixEquationCode::kNoConvergence);
    CHECK_THAT(l.status.message, Catch::Matchers::Contains("non-finite"));
    const trellis::MatrixEquationSolution s = trellis::solveStein(F, MatrixXd::Identity(3, 3));
    CHECK(s.status.code == trellis::MatrixEquationCode::kNoConvergence);
    CHECK_THAT(s.json(), Catch::Matchers::Contains("\"status\":\"no_convergence\""));
  }
  SECTION("Stein: a pair λ_i conj(λ_j) = 1 inside a complex block") {
    // F = rotation by 0.3 rad: eigenvalues e^{±0.3i}, λ conj(λ) = 1.
    MatrixXd F(2, 2);
    F << std::cos(0.3), -std::sin(0.3), std::sin(0.3), std::cos(0.3);
    const trellis::MatrixEquationSolution s = trellis::solveStein(F, MatrixXd::Identity(2, 2));
    CHECK(s.status.code == trellis::MatrixEquationCode::kSingular);
  }
}
