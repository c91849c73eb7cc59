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

// The workspace is private to the library; these tests read its factor (core/src on the path).
#include "data_workspace.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>

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
    TRELLIS_CHECK_MATRIX(Minv, detail::workspace(data).massInverse, tol, Scale::kMatrix);
    const Eigen::MatrixXd Bq = data.inputMatrix;
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(ldlt.solve(Bq)), Eigen::MatrixXd(data.B.bottomRows(n)), tol,
                         Scale::kColumn);
    if (n <= 13) checkLinearizationAgainstFd(model, s);
  }
}

namespace {
/// A branched tree: a root rz joint carrying three branches of three joints (rx, ry, tz, with
/// constant placements between them), full inertias everywhere, skewed gravity, a config spring
/// and damping.
TestSystem branchedTree() {
  std::mt19937 rng(31);
  SystemBuilder s;
  s.frame("root", "world", Transform::rz("r"), Mass{1.0, randomInertia(rng)});
  for (int b = 0; b < 3; ++b) {
    const std::string n = std::string("b").append(std::to_string(b));
    s.frame(n + "_base", "root", Transform::constSE3(se3(0.4 + b, {1.0, 0.3 * b, 0.2}, {0.2, 0.1 * b, -0.1})));
    s.frame(n + "_1", n + "_base", Transform::rx(n + "_1"), Mass{0.5, randomInertia(rng)});
    s.frame(n + "_1e", n + "_1", Transform::ty(0.3));
    s.frame(n + "_2", n + "_1e", Transform::ry(n + "_2"), Mass{0.3, randomInertia(rng)});
    s.frame(n + "_2e", n + "_2", Transform::tx(0.2));
    s.frame(n + "_3", n + "_2e", Transform::tz(n + "_3"), Mass{0.2, randomInertia(rng)});
  }
  s.b.addGravity(Eigen::Vector3d(0.5, -9.7, 1.2));
  s.b.addConfigSpring("b1_2", 2.0, 0.1);
  s.b.addDamping(0.05, {});
  s.b.addConfigForce("r", "tau_r");
  return std::move(s).finish();
}
/// planarChain(links) with its last bob held on the world origin's x and y (two point rows).
TestSystem closedPlanarChain(int links) {
  SystemBuilder s;
  std::string parent = "world";
  for (int k = 0; k < links; ++k) {
    const std::string index = std::to_string(k);
    const std::string joint = std::string("joint").append(index);
    const std::string bob = std::string("bob").append(index);
    s.frame(joint, parent, Transform::rz(std::string("q").append(index)));
    Eigen::Matrix3d I = Eigen::Matrix3d::Zero();
    I.diagonal() << 1e-5, 1e-5, 2e-5;
    s.frame(bob, joint, Transform::ty(-0.1), Mass{0.1, I});
    parent = bob;
  }
  s.b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
  s.b.addConfigForce("q0", "torque0");
  s.b.addPointConstraint(parent, "world", 0);
  s.b.addPointConstraint(parent, "world", 1);
  return std::move(s).finish();
}

}  // namespace

// computeDynamics takes the articulated factor for chains without constraints, and with
// constraints for chains of at least 8 joints (then also for M⁻¹Aᵀ, the rows of a group in one
// sweep), and the tree factor of M otherwise (the KKT path); the linearization forms M⁻¹ from the
// same factor. Both against
// Eigen's dense solves of the same M and b (an independent factorization) to κ·eps: q̈ (with
// constraints, of the dense KKT system [M Aᵀ; A 0]) and M⁻¹, on chains (tree and dense kernels'
// lengths), a branched tree, every transform type and every force element. Independently of any
// factor, the energy balance dE/dt = P_nc along (q̇, q̈) checks q̈ against central differences of E.
TEST_CASE("Articulated factor: q̈ and M⁻¹ equal dense solves and balance energy", "[mass_factor]") {
  struct Case {
    std::string name;
    TestSystem sys;
    bool articulated;  // the path computeDynamics is expected to take
  };
  std::vector<Case> cases;
  for (const int n : {1, 3, 7, 13, 40}) cases.push_back({std::string("planar chain ").append(std::to_string(n)), planarChain(n), true});
  cases.push_back({"double pendulum", paperPendulum(0), true});
  cases.push_back({"kitchen sink, unconstrained", kitchenSink(3, false), true});
  for (const TransformType t : {TransformType::kTx, TransformType::kRy, TransformType::kRotAxis,
                                TransformType::kTransAxis, TransformType::kConstSE3})
    cases.push_back({std::string("transform chain ").append(std::to_string(static_cast<int>(t))), transformChain(t), true});
  cases.push_back({"branched tree", branchedTree(), false});
  cases.push_back({"kitchen sink, constrained", kitchenSink(3, true), false});
  cases.push_back({"paper pendulum", paperPendulum(1), false});
  for (const int n : {7, 8, 13}) {
    // A planar chain closed at its tip: x, y on a world point (2 rows in one group). Below 8
    // joints the tree factor, from 8 the articulated one.
    cases.push_back({std::string("planar chain closed at its tip ").append(std::to_string(n)), closedPlanarChain(n), n >= 8});
  }
  for (const Case& c : cases) {
    const Model& model = c.sys.model;
    const int n = model.nq(), nc = model.nc();
    INFO(c.name);
    std::mt19937 rng(900 + static_cast<unsigned>(n));
    const State s = nc > 0 ? randomConsistentState(model, rng) : randomState(model, rng, 0.8, 1.0, 0.5);
    Data data(model);
    REQUIRE(computeDynamics(model, data, s.q, s.dq, s.u).ok());
    CHECK(detail::workspace(data).articulatedCurrent == c.articulated);
    const Eigen::MatrixXd M = data.M;
    const Eigen::VectorXd qdd = data.qdd;
    const DenseKkt kkt = denseKktSolve(data);  // the independent reference: dense KKT, full-pivoting LU
    const double tol = 100.0 * kkt.condition * std::numeric_limits<double>::epsilon();
    INFO("cond = " << kkt.condition);
    const Eigen::VectorXd& ref = kkt.solution;
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(ref.head(n)), Eigen::MatrixXd(qdd), tol, Scale::kMatrix);

    REQUIRE(computeLinearization(model, data, s.q, s.dq, s.u).ok());
    CHECK(detail::workspace(data).articulatedCurrent == c.articulated);
    const Eigen::MatrixXd Minv = M.ldlt().solve(Eigen::MatrixXd::Identity(n, n));
    TRELLIS_CHECK_MATRIX(Minv, detail::workspace(data).massInverse, tol, Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(qdd), Eigen::MatrixXd(data.qdd), 0.0, Scale::kAbsolute);

    if (nc > 0) continue;  // the constraint forces do work on a path off the manifold
    const double P = computeNonConservativePower(model, data, s.q, s.dq, s.u);
    const double h = 1e-5;
    const double Ep = computeEnergy(model, data, s.q + h * s.dq, s.dq + h * qdd).total();
    const double Em = computeEnergy(model, data, s.q - h * s.dq, s.dq - h * qdd).total();
    const double scale = computeEnergy(model, data, s.q, s.dq).kinetic + std::abs(P) + 1.0;
    CHECK(std::abs((Ep - Em) / (2.0 * h) - P) < 1e-6 * scale);
  }
}
