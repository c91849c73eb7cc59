// tests/core/test_mass_factor.cpp — the mass-matrix factor and inverse (core/src/mass_factor.cpp)
// on chains of every length around the kernels' switches: the tree (LTDL) path below 6 joints, the
// dense path with two-column passes and 2×2 tiles from 6 on, odd lengths (the tails of the tiles)
// and even ones. Reference: Eigen's LDLᵀ of the mass matrix from computeMassMatrix, an independent
// factorization; tolerance from the condition number of M (errors of a solve grow like κ·eps).
#include <catch2/catch.hpp>

#include "support/linearization_checks.hpp"
#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <limits>

using namespace trellis;
using namespace trellis::test;

TEST_CASE("Mass factor: M⁻¹, q̈ and B on chains across the kernels' switches", "[mass_factor]") {
  for (const int n : {3, 5, 6, 7, 8, 12, 13, 21, 40}) {
    const TestSystem sys = planarChain(n);
    const Model& model = sys.model;
    std::mt19937 rng(700 + static_cast<unsigned>(n));
    const State s = randomState(model, rng, 0.5, 1.0, 0.1);
    INFO("chain of " << n << " joints");

    Data ref(model);
    computeMassMatrix(model, ref, s.q);
    const Eigen::MatrixXd M = ref.M;
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(M);
    REQUIRE(ldlt.info() == Eigen::Success);
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(M);
    const double kappa = eig.eigenvalues().maxCoeff() / eig.eigenvalues().minCoeff();
    const double tol = 100.0 * kappa * std::numeric_limits<double>::epsilon();
    INFO("cond(M) = " << kappa << ", tolerance " << tol);
    const Eigen::MatrixXd Minv = ldlt.solve(Eigen::MatrixXd::Identity(n, n));

    Data data(model);
    const DynamicsStatus st = computeDynamics(model, data, s.q, s.dq, s.u);
    REQUIRE(st.ok());
    const Eigen::VectorXd qdd = ldlt.solve(Eigen::VectorXd(-data.bias));
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(qdd), Eigen::MatrixXd(data.qdd), tol, Scale::kMatrix);

    REQUIRE(computeLinearization(model, data, s.q, s.dq, s.u).ok());
    // The explicit inverse the linearization forms, and B = M⁻¹ ∂Q/∂u.
    TRELLIS_CHECK_MATRIX(Minv, data.massInverse, tol, Scale::kMatrix);
    const Eigen::MatrixXd Bq = data.inputMatrix;
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(ldlt.solve(Bq)), Eigen::MatrixXd(data.B.bottomRows(n)), tol,
                         Scale::kColumn);
    if (n <= 13) checkLinearizationAgainstFd(model, s);
  }
}
