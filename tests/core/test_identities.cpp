// tests/core/test_identities.cpp — leg 2 of the derivative tests: identities between independent
// paths through the equations of motion.
//
//  - M(q) is symmetric positive definite and ½ q̇ᵀ M q̇ is the kinetic energy of the frames'
//    body velocities with the masses as given (Σ ½ m |v_b|² + ½ ω_bᵀ I ω_b);
//  - the potential energy is −Σ m g·p + Σ ½ k (‖p1 − p2‖ − x0)² + Σ ½ k (q − q0)² from frame poses;
//  - B = [0; M⁻¹ ∂Q/∂u] without constraints, [0; (M⁻¹ − M⁻¹Aᵀ(AM⁻¹Aᵀ)⁻¹AM⁻¹) ∂Q/∂u] with them;
//  - energy balance dE/dt = Q_ncᵀ q̇ + λᵀ A q̇ (the last term vanishes at consistent states);
//  - A q̈ + Ȧ q̇ = 0 after computeDynamics, at any state;
//  - at a consistent state (h = 0, A q̇ = 0) the tangent basis T is orthonormal, of dimension
//    2n − 2·(holonomic rows) − (nonholonomic rows), and spans the null space of ∂Φ/∂x,
//    Φ = [h; A q̇];
//  - the linearization is compatible with the invariance of {Φ = 0}. Along the flow
//    dΦ/dt = L Φ (L: dh/dt = A_h q̇ is a row of Φ, d(A q̇)/dt = A q̈ + Ȧ q̇ = 0), at every state
//    and every u. Differentiating, with J = ∂Φ/∂x and f = [q̇; q̈]:
//        J B = 0,        J A + (∂J/∂x) f = L J.
//    So (I − T Tᵀ) B = 0 at a consistent state, but (I − T Tᵀ) A T = −J⁺ (∂J/∂x)[f] T is NOT
//    zero in general: the tangent space turns as the state moves. (A unit point mass on the unit
//    circle at x = (1, 0, 0, ω) in (x, y, ẋ, ẏ), q̈ = −|q̇|² q / |q|²: tangent vectors satisfy
//    δx = 0 and δẋ = −ω δy; (0, 0, 0, 1) is one, and A maps it to (0, 1, −2ω, 0), which is not.)
//    It is zero where f = 0, at an equilibrium, which is tested.
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>

#include <numbers>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>

using namespace trellis;
using namespace trellis::test;

namespace {

/// Kinetic energy from frame body velocities and the masses as given to the builder.
double kineticEnergyFromFrames(const TestSystem& sys, const Data& data) {
  double T = 0.0;
  for (const auto& [name, mass] : sys.masses) {
    const Vector6d& vb = data.frameVelocity[static_cast<std::size_t>(sys.model.frameIndex(name))];
    const Eigen::Vector3d v = vb.head<3>(), w = vb.tail<3>();
    T += 0.5 * mass.m * v.squaredNorm() + 0.5 * w.dot(mass.inertia * w);
  }
  return T;
}

std::vector<TestSystem> assortedSystems() {
  std::vector<TestSystem> out;
  out.push_back(paperPendulum());
  out.push_back(kitchenSink());
  out.push_back(planarSkate());
  out.push_back(planarChain(12));
  for (TransformType t :
       {TransformType::kTx, TransformType::kTy, TransformType::kTz, TransformType::kRx,
        TransformType::kRy, TransformType::kRz, TransformType::kConstSE3, TransformType::kRotAxis,
        TransformType::kTransAxis})
    out.push_back(transformChain(t));
  return out;
}

}  // namespace

TEST_CASE("Mass matrix is symmetric positive definite", "[identities][mass]") {
  const std::vector<TestSystem> systems = assortedSystems();
  std::mt19937 rng(1101);
  for (std::size_t k = 0; k < systems.size(); ++k) {
    const Model& model = systems[k].model;
    INFO("system #" << k);
    for (int trial = 0; trial < 3; ++trial) {
      const State s = randomState(model, rng);
      Data data(model);
      computeMassMatrix(model, data, s.q);
      REQUIRE(data.M.rows() == model.nq());
      REQUIRE(data.M.cols() == model.nq());
      // Symmetric up to rounding: the two triangles may be accumulated in different orders.
      // 1e-14 relative to ‖M‖max is ~50 eps.
      TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(data.M.transpose()), data.M, 1e-14, Scale::kMatrix);
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(data.M);
      CHECK(eig.eigenvalues().minCoeff() > 0.0);
      CHECK(Eigen::LLT<Eigen::MatrixXd>(data.M).info() == Eigen::Success);
    }
  }
}

TEST_CASE("Mass matrix reproduces the kinetic energy of the frame velocities",
          "[identities][mass][energy]") {
  const std::vector<TestSystem> systems = assortedSystems();
  std::mt19937 rng(1201);
  for (std::size_t k = 0; k < systems.size(); ++k) {
    const TestSystem& sys = systems[k];
    const Model& model = sys.model;
    INFO("system #" << k);
    for (int trial = 0; trial < 3; ++trial) {
      const State s = randomState(model, rng, 1.2, 2.0);
      Data data(model);
      computeKinematics(model, data, s.q, s.dq);
      const double Tframes = kineticEnergyFromFrames(sys, data);
      computeMassMatrix(model, data, s.q);
      const double Tmass = 0.5 * s.dq.dot(data.M * s.dq);
      const Energy E = computeEnergy(model, data, s.q, s.dq);
      // Two evaluations of one sum of ~10 products: rounding only, 1e-12 relative.
      CHECK(std::abs(Tmass - Tframes) <= 1e-12 * std::max(1.0, Tframes));
      CHECK(std::abs(E.kinetic - Tframes) <= 1e-12 * std::max(1.0, Tframes));
    }
  }
}

TEST_CASE("Potential energy equals gravity and spring energies from frame poses",
          "[identities][energy]") {
  const TestSystem sys = kitchenSink(3, false);
  const Model& model = sys.model;
  const Eigen::Vector3d g(0.4, -1.1, -9.7);  // as in kitchenSink
  std::mt19937 rng(1301);
  for (int trial = 0; trial < 3; ++trial) {
    const State s = randomState(model, rng);
    Data data(model);
    computeKinematics(model, data, s.q, s.dq);
    const auto p = [&](const char* name) {
      return Eigen::Vector3d(
          data.framePose[static_cast<std::size_t>(model.frameIndex(name))].translation());
    };
    double V = 0.0;
    for (const auto& [name, mass] : sys.masses) V -= mass.m * g.dot(p(name.c_str()));
    V += 0.5 * 3.0 * std::pow((p("tip") - p("pulley")).norm() - 0.4, 2);
    V += 0.5 * 2.0 * std::pow((p("upper") - p("cart_y")).norm() - 0.1, 2);
    V += 0.5 * 1.5 * std::pow(s.q[model.configIndex("pitch")] - 0.2, 2);
    const Energy E = computeEnergy(model, data, s.q, s.dq);
    // Sums of a dozen terms of size ≤ 20: 1e-12 relative covers rounding.
    CHECK(std::abs(E.potential - V) <= 1e-12 * std::max(1.0, std::abs(V)));
  }
}

TEST_CASE("B is M^-1 dQ/du projected by the constraints", "[identities][linearization]") {
  const auto check = [](const Model& model, std::uint32_t seed) {
    std::mt19937 rng(seed);
    const State s = randomState(model, rng);
    Data data(model);
    const DynamicsStatus status = computeLinearization(model, data, s.q, s.dq, s.u);
    INFO(status.message);
    REQUIRE(status.ok());
    Data aux(model);
    computeMassMatrix(model, aux, s.q);
    computeInputMatrix(model, aux, s.q);
    const int n = model.nq(), m = model.nu();
    const Eigen::MatrixXd Minv = aux.M.llt().solve(Eigen::MatrixXd::Identity(n, n));
    Eigen::MatrixXd P = Minv;  // M⁻¹ − M⁻¹Aᵀ(AM⁻¹Aᵀ)⁻¹AM⁻¹
    if (model.nc() > 0) {
      computeConstraints(model, aux, s.q, s.dq);
      const Eigen::MatrixXd& A = aux.constraintJacobian;
      const Eigen::MatrixXd S = A * Minv * A.transpose();
      P -= Minv * A.transpose() * S.ldlt().solve(A * Minv);
    }
    Eigen::MatrixXd expected(2 * n, m);
    expected << Eigen::MatrixXd::Zero(n, m), P * aux.inputMatrix;
    // Both are exact; the paths differ (explicit inverse vs the implementation's factorization),
    // so rounding differs by ~eps·cond(M)·cond(S) ≲ 1e-13 for these well-conditioned systems;
    // 1e-10 relative to ‖B‖max leaves margin.
    TRELLIS_CHECK_MATRIX(expected, data.B, 1e-10, Scale::kMatrix);
  };
  SECTION("unconstrained, every element") { check(kitchenSink(3, false).model, 1401); }
  SECTION("unconstrained double pendulum") { check(paperPendulum(0).model, 1402); }
  SECTION("constrained, every element") { check(kitchenSink(3, true).model, 1403); }
  SECTION("paper pendulum") { check(paperPendulum(1).model, 1404); }
  SECTION("planar skate") { check(planarSkate().model, 1405); }
}

namespace {

/// dE/dt along the motion by a central difference of computeEnergy in the direction (q̇, q̈), and
/// the powers: non-conservative Q_ncᵀ q̇ and constraint λᵀ A q̇.
struct PowerBalance {
  double dEdt, nonConservative, constraint, scale;
};

PowerBalance powerBalance(const Model& model, const State& s) {
  const int n = model.nq();
  Data data(model), work(model);
  const DynamicsStatus status = computeDynamics(model, data, s.q, s.dq, s.u);
  INFO(status.message);
  REQUIRE(status.ok());
  Eigen::VectorXd x(2 * n), xdot(2 * n);
  x << s.q, s.dq;
  xdot << s.dq, data.qdd;
  const VectorFunction energy = [&](const Eigen::VectorXd& xx) {
    return Eigen::VectorXd::Constant(1, computeEnergy(model, work, xx.head(n), xx.tail(n)).total());
  };
  PowerBalance pb{};
  pb.dEdt = centralDifferenceDirectional(energy, x, xdot)[0];
  pb.nonConservative = computeNonConservativePower(model, work, s.q, s.dq, s.u);
  computeConstraints(model, work, s.q, s.dq);
  pb.constraint = model.nc() > 0 ? data.lambda.dot(work.constraintJacobian * s.dq) : 0.0;
  const Energy E = computeEnergy(model, work, s.q, s.dq);
  pb.scale = std::max({1.0, std::abs(E.kinetic), std::abs(E.potential),
                       std::abs(pb.nonConservative), std::abs(pb.constraint)});
  return pb;
}

// The directional central difference of E is accurate to ~eps^(2/3) ≈ 4e-11 relative to the
// scale of E and its third derivative along the motion (finite_difference.hpp); 1e-7 relative to
// max(1, |T|, |V|, |powers|) leaves three orders of margin.
constexpr double kPowerTolerance = 1e-7;

}  // namespace

TEST_CASE("Energy balance: dE/dt equals the power of the non-conservative forces",
          "[identities][energy]") {
  SECTION("unconstrained, every force type") {
    const Model model = kitchenSink(3, false).model;
    std::mt19937 rng(1501);
    for (int k = 0; k < 3; ++k) {
      const PowerBalance pb = powerBalance(model, randomState(model, rng));
      INFO("dE/dt = " << pb.dEdt << ", Q_nc·dq = " << pb.nonConservative);
      CHECK(std::abs(pb.dEdt - pb.nonConservative) <= kPowerTolerance * pb.scale);
    }
  }
  SECTION("conservative system: energy is constant") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addLinearSpring("l4", "w1", 5.0, 0.3);
    s.b.addConfigSpring("b", 3.0, 0.4);
    const Model model = std::move(s).finish().model;
    std::mt19937 rng(1502);
    const PowerBalance pb = powerBalance(model, randomState(model, rng));
    INFO("dE/dt = " << pb.dEdt);
    CHECK(pb.nonConservative == 0.0);
    CHECK(std::abs(pb.dEdt) <= kPowerTolerance * pb.scale);
  }
  SECTION("constrained, every element, consistent state: constraint forces do no work") {
    const Model model = kitchenSink(3, true).model;
    std::mt19937 rng(1503);
    for (int k = 0; k < 3; ++k) {
      const PowerBalance pb = powerBalance(model, randomConsistentState(model, rng));
      INFO("dE/dt = " << pb.dEdt << ", Q_nc·dq = " << pb.nonConservative
                      << ", lambda·A dq = " << pb.constraint);
      CHECK(std::abs(pb.constraint) <= 1e-10 * pb.scale);
      CHECK(std::abs(pb.dEdt - pb.nonConservative) <= kPowerTolerance * pb.scale);
    }
  }
  SECTION("paper pendulum at (pi/6, pi/3), a consistent state") {
    const Model model = paperPendulum().model;
    State s{Eigen::Vector2d(std::numbers::pi / 6, std::numbers::pi / 3), Eigen::Vector2d(0.7, -1.4),
            Eigen::VectorXd::Constant(1, 2.0)};
    const PowerBalance pb = powerBalance(model, s);
    INFO("dE/dt = " << pb.dEdt << ", u·dq1 = " << pb.nonConservative);
    CHECK(pb.nonConservative == Approx(2.0 * 0.7).epsilon(1e-14));
    CHECK(std::abs(pb.dEdt - pb.nonConservative) <= kPowerTolerance * pb.scale);
  }
  SECTION("planar skate, consistent state") {
    const Model model = planarSkate().model;
    std::mt19937 rng(1505);
    const PowerBalance pb = powerBalance(model, randomConsistentState(model, rng));
    CHECK(std::abs(pb.dEdt - pb.nonConservative) <= kPowerTolerance * pb.scale);
  }
  SECTION("constrained, inconsistent state: constraint forces do work lambda·A dq") {
    const Model model = kitchenSink(3, true).model;
    std::mt19937 rng(1506);
    const PowerBalance pb = powerBalance(model, randomState(model, rng));
    INFO("dE/dt = " << pb.dEdt << ", Q_nc·dq = " << pb.nonConservative
                    << ", lambda·A dq = " << pb.constraint);
    CHECK(std::abs(pb.dEdt - pb.nonConservative - pb.constraint) <= kPowerTolerance * pb.scale);
  }
}

TEST_CASE("Constraint accelerations vanish: A qdd + Adot dq = 0", "[identities][constraints]") {
  const auto check = [](const Model& model, std::uint32_t seed) {
    std::mt19937 rng(seed);
    for (int k = 0; k < 3; ++k) {
      const State s = randomState(model, rng);  // any state: the equation holds everywhere
      Data data(model);
      const DynamicsStatus status = computeDynamics(model, data, s.q, s.dq, s.u);
      INFO(status.message);
      REQUIRE(status.ok());
      computeConstraints(model, data, s.q, s.dq);
      const Eigen::VectorXd residual = data.constraintJacobian * data.qdd + data.constraintDrift;
      const double scale = std::max(
          1.0, data.constraintJacobian.cwiseAbs().maxCoeff() * data.qdd.cwiseAbs().maxCoeff() +
                   data.constraintDrift.cwiseAbs().maxCoeff());
      // Backward error of the KKT solve, ~eps·cond(A M⁻¹ Aᵀ) ≲ 1e-13 here; 1e-10 leaves margin.
      INFO("residual " << residual.transpose() << ", scale " << scale);
      CHECK(residual.cwiseAbs().maxCoeff() <= 1e-10 * scale);
    }
  };
  SECTION("paper pendulum") { check(paperPendulum().model, 1601); }
  SECTION("planar skate") { check(planarSkate().model, 1602); }
  SECTION("every constraint type") { check(kitchenSink().model, 1603); }
}

namespace {

struct ConstraintCounts {
  int holonomic = 0, nonholonomic = 0;
};
ConstraintCounts countConstraints(const Model& model) {
  ConstraintCounts c;
  for (const Constraint& k : model.constraints()) (k.holonomic() ? c.holonomic : c.nonholonomic)++;
  return c;
}

/// J = ∂Φ/∂x, Φ = [h (holonomic rows); A q̇ (all rows)], from the implementation's A and
/// ∂(A q̇)/∂q (both checked against differences in test_linearization_fd).
Eigen::MatrixXd constraintStateJacobian(const Model& model, const Data& data) {
  const int n = model.nq(), nh = countConstraints(model).holonomic;
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(nh + model.nc(), 2 * n);
  int r = 0;
  for (int i = 0; i < model.nc(); ++i)
    if (model.constraints()[static_cast<std::size_t>(i)].holonomic())
      J.block(r++, 0, 1, n) = data.constraintJacobian.row(i);
  J.block(r, 0, model.nc(), n) = data.constraintVelocityJacobian;
  J.block(r, n, model.nc(), n) = data.constraintJacobian;
  return J;
}

/// L with dΦ/dt = L Φ: the h-rows' derivative A_h q̇ is the matching row of the A q̇ block.
Eigen::MatrixXd phiRateMatrix(const Model& model) {
  const int nh = countConstraints(model).holonomic, rows = nh + model.nc();
  Eigen::MatrixXd L = Eigen::MatrixXd::Zero(rows, rows);
  int r = 0;
  for (int i = 0; i < model.nc(); ++i)
    if (model.constraints()[static_cast<std::size_t>(i)].holonomic()) L(r++, nh + i) = 1.0;
  return L;
}

/// Orthonormality, dimension, tangency of T; reducedA/B; (I − T Tᵀ) B = 0. Returns T and leaves
/// the linearization in `data`.
void checkTangentSpace(const Model& model, const State& s, Data& data) {
  const int n = model.nq();
  const ConstraintCounts counts = countConstraints(model);
  const DynamicsStatus status = computeLinearization(model, data, s.q, s.dq, s.u);
  INFO(status.message);
  REQUIRE(status.ok());
  const int d = computeConstraintTangentBasis(model, data);
  CHECK(d == 2 * n - 2 * counts.holonomic - counts.nonholonomic);
  const Eigen::MatrixXd& T = data.tangentBasis;
  REQUIRE(T.rows() == 2 * n);
  REQUIRE(T.cols() == d);
  // Orthonormal: from a Householder QR, exact to a few eps.
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd::Identity(d, d), Eigen::MatrixXd(T.transpose() * T), 1e-12,
                       Scale::kAbsolute);
  // Tangent: J T = 0 up to rounding of entries of size ‖J‖ (≲ 10 here): 1e-12 relative.
  const Eigen::MatrixXd J = constraintStateJacobian(model, data);
  const double scaleJ = std::max(1.0, J.cwiseAbs().maxCoeff());
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd::Zero(J.rows(), d), Eigen::MatrixXd(J * T / scaleJ), 1e-12,
                       Scale::kAbsolute);
  // Inputs keep the state on the manifold: (I − T Tᵀ) B = 0. Exact at Φ = 0; the state has
  // ‖Φ‖ ≲ 1e-13 and the product rounds at ~eps·‖B‖: 1e-10 relative to max(1, ‖B‖max).
  const Eigen::MatrixXd P = Eigen::MatrixXd::Identity(2 * n, 2 * n) - T * T.transpose();
  const double scaleB = std::max(1.0, data.B.size() ? data.B.cwiseAbs().maxCoeff() : 0.0);
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd::Zero(2 * n, model.nu()),
                       Eigen::MatrixXd(P * data.B / scaleB), 1e-10, Scale::kAbsolute);
  // The reduced matrices are the projections they are documented to be (rounding only).
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(T.transpose() * data.A * T), data.reducedA, 1e-12,
                       Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(T.transpose() * data.B), data.reducedB, 1e-12,
                       Scale::kMatrix);
}

/// J B = 0 and J A + (∂J/∂x)[f] = L J at any state (file comment); ∂J/∂x along f by a central
/// difference of J.
void checkInvarianceIdentity(const Model& model, const State& s) {
  const int n = model.nq();
  Data data(model), work(model);
  const DynamicsStatus status = computeLinearization(model, data, s.q, s.dq, s.u);
  INFO(status.message);
  REQUIRE(status.ok());
  const Eigen::MatrixXd J = constraintStateJacobian(model, data);
  Eigen::VectorXd x(2 * n), f(2 * n);
  x << s.q, s.dq;
  f << s.dq, data.qdd;
  const VectorFunction vecJ = [&](const Eigen::VectorXd& xx) {
    computeLinearization(model, work, xx.head(n), xx.tail(n), s.u);
    const Eigen::MatrixXd Jx = constraintStateJacobian(model, work);
    return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(Jx.data(), Jx.size()));
  };
  const Eigen::VectorXd dJ = centralDifferenceDirectional(vecJ, x, f);
  const Eigen::MatrixXd Jdot = Eigen::Map<const Eigen::MatrixXd>(dJ.data(), J.rows(), J.cols());
  const Eigen::MatrixXd lhs = J * data.A + Jdot;
  const Eigen::MatrixXd rhs = phiRateMatrix(model) * J;
  // Jdot is a central difference (error ~1e-10 relative to the scale of J's derivatives times
  // ‖f‖); J·A is exact up to rounding. kFdTolerance (1e-6) relative to
  // max(1, ‖J‖max·‖A‖max) leaves four orders of margin.
  const double scale = std::max(1.0, J.cwiseAbs().maxCoeff() * data.A.cwiseAbs().maxCoeff());
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(rhs / scale), Eigen::MatrixXd(lhs / scale), 1e-6,
                       Scale::kAbsolute);
  const double scaleB =
      std::max(1.0, J.cwiseAbs().maxCoeff() * (data.B.size() ? data.B.cwiseAbs().maxCoeff() : 0.0));
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd::Zero(J.rows(), model.nu()),
                       Eigen::MatrixXd(J * data.B / scaleB), 1e-12, Scale::kAbsolute);
}

}  // namespace

TEST_CASE("Tangent basis of the constraint manifold at a consistent state",
          "[identities][constraints][tangent]") {
  SECTION("paper pendulum at (pi/6, pi/3), dq from the null space of A") {
    const Model model = paperPendulum().model;
    const Eigen::Vector2d q(std::numbers::pi / 6, std::numbers::pi / 3);
    Data data(model);
    computeConstraints(model, data, q, Eigen::Vector2d::Zero());
    // h(π/6, π/3) = ‖(1.5, −√3/2) − (2, 0)‖² − 1 = 0.25 + 0.75 − 1 = 0.
    CHECK(std::abs(data.constraintValue[0]) <= 1e-15);
    // A = 2 (p_B − p_C)ᵀ ∂p_B/∂q = [−2√3, −√3]: the null space is spanned by (1, −2).
    CHECK(std::abs(data.constraintJacobian(0, 0) + 2.0 * std::sqrt(3.0)) <= 1e-14);
    CHECK(std::abs(data.constraintJacobian(0, 1) + std::sqrt(3.0)) <= 1e-14);
    const Eigen::Vector2d dq = 0.8 * Eigen::Vector2d(1.0, -2.0);
    checkTangentSpace(model, State{q, dq, Eigen::VectorXd::Constant(1, 2.0)}, data);
  }
  SECTION("every constraint type (3 holonomic, 1 nonholonomic)") {
    const Model model = kitchenSink().model;
    std::mt19937 rng(1701);
    for (int k = 0; k < 2; ++k) {
      Data data(model);
      checkTangentSpace(model, randomConsistentState(model, rng), data);
    }
  }
  SECTION("planar skate (nonholonomic only)") {
    const Model model = planarSkate().model;
    std::mt19937 rng(1702);
    Data data(model);
    checkTangentSpace(model, randomConsistentState(model, rng), data);
  }
  SECTION("unconstrained: T = I") {
    const Model model = kitchenSink(3, false).model;
    std::mt19937 rng(1703);
    const State s = randomState(model, rng);
    Data data(model);
    REQUIRE(computeLinearization(model, data, s.q, s.dq, s.u).ok());
    CHECK(computeConstraintTangentBasis(model, data) == 2 * model.nq());
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd::Identity(2 * model.nq(), 2 * model.nq()),
                         data.tangentBasis, 0.0, Scale::kAbsolute);
  }
}

TEST_CASE("The linearized flow preserves the constraint manifold",
          "[identities][constraints][tangent]") {
  SECTION("at an equilibrium of the paper pendulum, (I - T T^T) A T = 0") {
    // At q = (π/6, π/3), q̇ = 0, q̈ = a + b u lies in the one-dimensional null space of A (A q̈ =
    // −Ȧ q̇ = 0), so the torque u* = −(b·a)/(b·b) makes q̈ = 0: f = 0 and the tangent space is
    // invariant under the linearized flow.
    const Model model = paperPendulum().model;
    const Eigen::Vector2d q(std::numbers::pi / 6, std::numbers::pi / 3),
        dq = Eigen::Vector2d::Zero();
    Data data(model);
    REQUIRE(computeDynamics(model, data, q, dq, Eigen::VectorXd::Zero(1)).ok());
    const Eigen::Vector2d a = data.qdd;
    REQUIRE(computeDynamics(model, data, q, dq, Eigen::VectorXd::Ones(1)).ok());
    const Eigen::Vector2d b = Eigen::Vector2d(data.qdd) - a;
    const Eigen::VectorXd uStar = Eigen::VectorXd::Constant(1, -b.dot(a) / b.dot(b));
    REQUIRE(computeDynamics(model, data, q, dq, uStar).ok());
    INFO("u* = " << uStar[0] << ", qdd(u*) = " << data.qdd.transpose());
    REQUIRE(data.qdd.cwiseAbs().maxCoeff() <= 1e-12);  // q̈ = 0 up to rounding
    checkTangentSpace(model, State{q, dq, uStar}, data);
    const Eigen::MatrixXd& T = data.tangentBasis;
    const Eigen::MatrixXd P = Eigen::MatrixXd::Identity(4, 4) - T * T.transpose();
    // Exact at f = 0; f ≲ 1e-12 and rounding ~eps·‖A‖: 1e-10 relative to max(1, ‖A‖max).
    const double scaleA = std::max(1.0, data.A.cwiseAbs().maxCoeff());
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd::Zero(4, T.cols()),
                         Eigen::MatrixXd(P * data.A * T / scaleA), 1e-10, Scale::kAbsolute);
  }
  SECTION("J A + (dJ/dx) f = L J and J B = 0 at consistent and inconsistent states") {
    const auto run = [](const Model& model, std::uint32_t seed) {
      std::mt19937 rng(seed);
      checkInvarianceIdentity(model, randomConsistentState(model, rng));
      checkInvarianceIdentity(model, randomState(model, rng));
    };
    run(paperPendulum().model, 1801);
    run(planarSkate().model, 1802);
    run(kitchenSink().model, 1803);
  }
}
