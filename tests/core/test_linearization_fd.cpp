// tests/core/test_linearization_fd.cpp — leg 1 of the derivative tests: every analytic derivative
// trellis computes against central differences of the function it differentiates.
//
// For every element type a small 3D model that uses it is linearized at several seeded random
// states, and A, B (and ∂λ/∂x) are compared with central differences of computeDynamics
// (support/linearization_checks.hpp: 1e-6 relative to max(1, ‖FD column‖∞), four orders above the
// ~1e-10 error of the differences). Constrained systems are compared at arbitrary states, not only
// consistent ones: M q̈ = … + Aᵀλ with A q̈ + Ȧ q̇ = 0 defines q̈(q, q̇, u) everywhere A M⁻¹ Aᵀ is
// invertible, and that function is what computeLinearization differentiates.
//
// The kinematic derivatives the linearization rests on are checked the same way: constraint
// Jacobian A = ∂h/∂q, drift Ȧ q̇ (the derivative of A along q̇, applied to q̇), ∂(A q̇)/∂q, the input
// matrix ∂Q/∂u, and frame body velocities against differences of frame poses.
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/linearization_checks.hpp"
#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>

#include <string>
#include <vector>

using namespace trellis;
using namespace trellis::test;

namespace {

constexpr int kStatesPerModel = 3;

/// Linearizes `model` at kStatesPerModel random states drawn from `seed`.
void checkAtRandomStates(const Model& model, std::uint32_t seed, double qRange = 1.2) {
  std::mt19937 rng(seed);
  for (int k = 0; k < kStatesPerModel; ++k) {
    const State s = randomState(model, rng, qRange);
    INFO("random state #" << k << " (seed " << seed << ")");
    checkLinearizationAgainstFd(model, s);
  }
}

}  // namespace

TEST_CASE("Linearization matches central differences for every transform type",
          "[linearization][fd]") {
  const std::vector<TransformType> types = {
      TransformType::kTx, TransformType::kTy, TransformType::kTz,      TransformType::kRx,
      TransformType::kRy, TransformType::kRz, TransformType::kConstSE3,
      TransformType::kRotAxis, TransformType::kTransAxis};
  for (TransformType t : types) {
    // transformChain: the type appears once driven (except const_se3) and once constant, between
    // two other joints, with masses before, on and after it, in skewed gravity.
    SECTION(transformTypeName(t)) {
      const TestSystem sys = transformChain(t);
      CHECK(sys.model.nq() == (t == TransformType::kConstSE3 ? 2 : 3));
      checkAtRandomStates(sys.model, 100 + static_cast<std::uint32_t>(t));
    }
  }
}

TEST_CASE("Linearization matches central differences for masses with full inertia",
          "[linearization][fd]") {
  // armBase: four joints of four kinds, every body with a random, non-diagonal inertia tensor;
  // no force at all, so q̈ is pure Coriolis/centripetal and M(q) dependence.
  SECTION("inertia only") {
    const TestSystem sys = std::move(armBase()).finish();
    checkAtRandomStates(sys.model, 201);
  }
  SECTION("inertia only, large velocities") {
    const TestSystem sys = std::move(armBase(8)).finish();
    std::mt19937 rng(202);
    const State s = randomState(sys.model, rng, 1.2, 5.0);
    checkLinearizationAgainstFd(sys.model, s);
  }
}

TEST_CASE("Linearization matches central differences for every potential", "[linearization][fd]") {
  SECTION("gravity") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.3, -9.81, -1.2));
    checkAtRandomStates(std::move(s).finish().model, 301);
  }
  SECTION("linear_spring between a body and the world") {
    SystemBuilder s = armBase();
    s.b.addLinearSpring("l4", "w1", 5.0, 0.3);
    checkAtRandomStates(std::move(s).finish().model, 302);
  }
  SECTION("linear_spring between two bodies, zero rest length") {
    SystemBuilder s = armBase();
    s.b.addLinearSpring("j1", "l3", 4.0, 0.0);
    checkAtRandomStates(std::move(s).finish().model, 303);
  }
  SECTION("config_spring") {
    SystemBuilder s = armBase();
    s.b.addConfigSpring("b", 3.0, 0.4);
    s.b.addConfigSpring("d", 7.0, -0.1);
    checkAtRandomStates(std::move(s).finish().model, 304);
  }
}

TEST_CASE("Linearization matches central differences for every force", "[linearization][fd]") {
  SECTION("config_force") {
    SystemBuilder s = armBase();
    s.b.addConfigForce("a", "ua");
    s.b.addConfigForce("d", "ud");
    s.b.addConfigForce("b", "ua");  // one input driving two coordinates
    const TestSystem sys = std::move(s).finish();
    CHECK(sys.model.nu() == 2);
    checkAtRandomStates(sys.model, 401);
  }
  SECTION("damping with default and per-coordinate coefficients") {
    SystemBuilder s = armBase();
    s.b.addDamping(0.3, {{"c", 1.5}, {"d", 0.05}});
    checkAtRandomStates(std::move(s).finish().model, 402);
  }
  SECTION("body_wrench with constant entries") {
    SystemBuilder s = armBase();
    s.b.addBodyWrench("l3", {WrenchEntry{0.5}, WrenchEntry{-0.3}, WrenchEntry{0.8},
                             WrenchEntry{0.1}, WrenchEntry{-0.2}, WrenchEntry{0.15}});
    checkAtRandomStates(std::move(s).finish().model, 403);
  }
  SECTION("body_wrench with input and constant entries") {
    SystemBuilder s = armBase();
    s.b.addBodyWrench(
        "l4", {WrenchEntry{std::string("fx")}, WrenchEntry{0.2}, WrenchEntry{std::string("fz")},
               WrenchEntry{std::string("tx")}, WrenchEntry{-0.4}, WrenchEntry{std::string("tz")}});
    const TestSystem sys = std::move(s).finish();
    CHECK(sys.model.nu() == 4);
    checkAtRandomStates(sys.model, 404);
  }
  SECTION("tendon through four frames on three bodies and the world") {
    SystemBuilder s = armBase();
    s.b.addTendon({"w3", "l2", "l3", "l4"}, "tension");
    checkAtRandomStates(std::move(s).finish().model, 405);
  }
}

TEST_CASE("Linearization matches central differences for every holonomic constraint",
          "[linearization][fd][constraints]") {
  // Random, inconsistent states: the dynamics as written are differentiated (file comment).
  SECTION("distance between a body and the world") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addDistanceConstraint("l4", "w1", 0.9);
    checkAtRandomStates(std::move(s).finish().model, 501);
  }
  SECTION("distance between two bodies") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addConfigForce("a", "ua");
    s.b.addDistanceConstraint("l2", "l4", 0.5);
    checkAtRandomStates(std::move(s).finish().model, 502);
  }
  for (int axis = 0; axis < 3; ++axis) {
    SECTION("point along world axis " + std::to_string(axis)) {
      SystemBuilder s = armBase();
      s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
      s.b.addConfigForce("c", "uc");
      s.b.addPointConstraint("l4", "w3", axis);
      checkAtRandomStates(std::move(s).finish().model, 510 + static_cast<std::uint32_t>(axis));
    }
  }
  SECTION("point_on_plane, plane on a moving body") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addPointOnPlaneConstraint("l2", Eigen::Vector3d(0.3, -0.5, 1.0), "l4");
    checkAtRandomStates(std::move(s).finish().model, 520);
  }
  SECTION("point_on_plane, plane in the world") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addPointOnPlaneConstraint("w1", Eigen::Vector3d(0.0, 0.0, 1.0), "l3");
    checkAtRandomStates(std::move(s).finish().model, 521);
  }
  SECTION("two constraints at once (distance and point)") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addDistanceConstraint("l4", "w1", 0.9);
    s.b.addPointConstraint("l3", "w2", 1);
    checkAtRandomStates(std::move(s).finish().model, 530);
  }
}

TEST_CASE("Linearization matches central differences for the knife edge (nonholonomic)",
          "[linearization][fd][constraints]") {
  SECTION("planar skate, blade at the centre of mass") {
    checkAtRandomStates(planarSkate(0.0).model, 601);
  }
  SECTION("planar skate, blade offset from the centre of mass") {
    checkAtRandomStates(planarSkate(0.3).model, 602);
  }
  SECTION("3D arm, knife edge on the last body along a skewed axis") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addKnifeEdgeConstraint("l4", Eigen::Vector3d(1.0, 0.5, -0.2).normalized());
    checkAtRandomStates(std::move(s).finish().model, 603);
  }
}

TEST_CASE("Linearization matches central differences for a system with every element",
          "[linearization][fd][constraints]") {
  SECTION("unconstrained") { checkAtRandomStates(kitchenSink(3, false).model, 701); }
  SECTION("with knife edge, distance, point and point_on_plane constraints") {
    checkAtRandomStates(kitchenSink(3, true).model, 702);
  }
  SECTION("at a consistent state") {
    const TestSystem sys = kitchenSink(3, true);
    std::mt19937 rng(703);
    const State s = randomConsistentState(sys.model, rng);
    checkLinearizationAgainstFd(sys.model, s);
  }
}

namespace {

/// Checks A, Ȧ q̇ and ∂(A q̇)/∂q at s against central differences.
void checkConstraintDerivatives(const Model& model, const State& s) {
  const int n = model.nq(), nc = model.nc();
  Data data(model), work(model);
  computeConstraints(model, data, s.q, s.dq);
  REQUIRE(data.constraintValue.size() == nc);
  REQUIRE(data.constraintJacobian.rows() == nc);
  REQUIRE(data.constraintJacobian.cols() == n);
  REQUIRE(data.constraintDrift.size() == nc);

  // A = ∂h/∂q on holonomic rows; nonholonomic rows have h ≡ 0.
  const VectorFunction h = [&](const Eigen::VectorXd& q) {
    computeConstraints(model, work, q, s.dq);
    return Eigen::VectorXd(work.constraintValue);
  };
  const Eigen::MatrixXd dh = centralDifferenceJacobian(h, s.q);
  for (int i = 0; i < nc; ++i) {
    const Constraint& c = model.constraints()[static_cast<std::size_t>(i)];
    INFO("constraint row " << i << " (" << c.name << ")");
    if (c.holonomic()) {
      // FD tolerance: see support/linearization_checks.hpp (kFdTolerance).
      TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(dh.row(i)),
                           Eigen::MatrixXd(data.constraintJacobian.row(i)), kFdTolerance,
                           Scale::kMatrix);
    } else {
      CHECK(data.constraintValue[i] == 0.0);
    }
  }

  // Ȧ q̇ = (d/dε A(q + ε q̇)) q̇: for holonomic rows q̇ᵀ (∂²h/∂q²) q̇, for the knife edge the
  // time derivative of its A(q) along the motion.
  const VectorFunction Aqd = [&](const Eigen::VectorXd& q) {
    computeConstraints(model, work, q, s.dq);
    return Eigen::VectorXd(work.constraintJacobian * s.dq);
  };
  const Eigen::VectorXd drift = centralDifferenceDirectional(Aqd, s.q, s.dq);
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(drift), Eigen::MatrixXd(data.constraintDrift), kFdTolerance,
                       Scale::kMatrix);

  // ∂(A q̇)/∂q, filled by computeLinearization.
  Data lin(model);
  const DynamicsStatus status = computeLinearization(model, lin, s.q, s.dq, s.u);
  INFO(status.message);
  REQUIRE(status.ok());
  const Eigen::MatrixXd dAqd = centralDifferenceJacobian(Aqd, s.q);
  TRELLIS_CHECK_MATRIX(dAqd, lin.constraintVelocityJacobian, kFdTolerance, Scale::kColumn);
}

}  // namespace

TEST_CASE("Constraint Jacobian, drift and velocity Jacobian match central differences",
          "[kinematics][fd][constraints]") {
  SECTION("paper pendulum") {
    const TestSystem sys = paperPendulum();
    std::mt19937 rng(801);
    for (int k = 0; k < kStatesPerModel; ++k)
      checkConstraintDerivatives(sys.model, randomState(sys.model, rng));
  }
  SECTION("planar skate (knife edge)") {
    const TestSystem sys = planarSkate(0.3);
    std::mt19937 rng(802);
    for (int k = 0; k < kStatesPerModel; ++k)
      checkConstraintDerivatives(sys.model, randomState(sys.model, rng));
  }
  SECTION("every constraint type in 3D") {
    const TestSystem sys = kitchenSink();
    std::mt19937 rng(803);
    for (int k = 0; k < kStatesPerModel; ++k)
      checkConstraintDerivatives(sys.model, randomState(sys.model, rng));
  }
}

TEST_CASE("Input matrix matches the generalized force", "[forces][fd]") {
  const TestSystem sys = kitchenSink(3, false);
  const Model& model = sys.model;
  const int n = model.nq(), m = model.nu();
  std::mt19937 rng(901);
  const State s = randomState(model, rng);
  Data data(model), work(model);
  computeInputMatrix(model, data, s.q);
  REQUIRE(data.inputMatrix.rows() == n);
  REQUIRE(data.inputMatrix.cols() == m);

  SECTION("against central differences of −bias = Q − ID(q, q̇, 0) in u") {
    // bias = ID(q, q̇, 0) − Q(q, q̇, u): its u-dependence is −Q's. Q is affine in u, so the central
    // difference is exact up to rounding; the FD tolerance applies all the same.
    const VectorFunction minusBias = [&](const Eigen::VectorXd& u) {
      computeDynamics(model, work, s.q, s.dq, u);
      return Eigen::VectorXd(-work.bias);
    };
    const Eigen::MatrixXd fd = centralDifferenceJacobian(minusBias, s.u);
    TRELLIS_CHECK_MATRIX(fd, data.inputMatrix, kFdTolerance, Scale::kColumn);
  }
  SECTION("config_force columns are unit vectors") {
    const Eigen::MatrixXd expected = Eigen::VectorXd::Unit(n, model.configIndex("x"));
    TRELLIS_CHECK_MATRIX(expected, Eigen::MatrixXd(data.inputMatrix.col(model.inputIndex("push"))),
                         0.0, Scale::kAbsolute);
    const Eigen::MatrixXd expected2 = Eigen::VectorXd::Unit(n, model.configIndex("yaw"));
    TRELLIS_CHECK_MATRIX(expected2,
                         Eigen::MatrixXd(data.inputMatrix.col(model.inputIndex("steer"))), 0.0,
                         Scale::kAbsolute);
  }
  SECTION("tendon column is −∂l/∂q, l from the frame poses") {
    // Independent of the implementation's tendon code: l(q) = Σ ‖p_{i+1} − p_i‖ from framePose.
    const std::vector<std::string> path = {"pulley", "upper", "lower", "tip"};
    const VectorFunction length = [&](const Eigen::VectorXd& q) {
      computeKinematics(model, work, q, Eigen::VectorXd::Zero(n));
      double l = 0.0;
      for (std::size_t i = 0; i + 1 < path.size(); ++i) {
        const auto a = static_cast<std::size_t>(model.frameIndex(path[i]));
        const auto b = static_cast<std::size_t>(model.frameIndex(path[i + 1]));
        l += (work.framePose[b].translation() - work.framePose[a].translation()).norm();
      }
      return Eigen::VectorXd::Constant(1, l);
    };
    const Eigen::MatrixXd dl = centralDifferenceJacobian(length, s.q);  // 1×n
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(-dl.transpose()),
                         Eigen::MatrixXd(data.inputMatrix.col(model.inputIndex("tension"))),
                         kFdTolerance, Scale::kColumn);
  }
  SECTION("body_wrench columns are J_bᵀ e_i, J_b from the frame body velocities") {
    // Power balance: Qᵀ q̇ = wᵀ V_b for every q̇, so column j of J_b is V_b at q̇ = e_j and the
    // column of input entry i is row i of J_b. Both sides are exact; 1e-12 relative allows the
    // rounding of the two different evaluation orders.
    const int frame = model.frameIndex("lower");
    Eigen::MatrixXd Jb(6, n);
    for (int j = 0; j < n; ++j) {
      computeKinematics(model, work, s.q, Eigen::VectorXd::Unit(n, j));
      Jb.col(j) = work.frameVelocity[static_cast<std::size_t>(frame)];
    }
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(Jb.row(0).transpose()),
                         Eigen::MatrixXd(data.inputMatrix.col(model.inputIndex("fx_in"))), 1e-12,
                         Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(Jb.row(4).transpose()),
                         Eigen::MatrixXd(data.inputMatrix.col(model.inputIndex("tau_in"))), 1e-12,
                         Scale::kMatrix);
  }
}

TEST_CASE("Frame body velocities match central differences of frame poses", "[kinematics][fd]") {
  const auto checkAll = [](const Model& model, std::uint32_t seed) {
    std::mt19937 rng(seed);
    for (int k = 0; k < kStatesPerModel; ++k) {
      const State s = randomState(model, rng);
      Data data(model);
      computeKinematics(model, data, s.q, s.dq);
      REQUIRE(static_cast<int>(data.framePose.size()) == model.nframes());
      REQUIRE(static_cast<int>(data.frameVelocity.size()) == model.nframes());
      for (int f = 0; f < model.nframes(); ++f) {
        INFO("frame " << model.frames()[static_cast<std::size_t>(f)].name);
        const Vector6d fd = finiteDifferenceBodyVelocity(model, s.q, s.dq, f);
        // Directional central difference of poses: error ~1e-10 relative (finite_difference.hpp).
        TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(fd),
                             Eigen::MatrixXd(data.frameVelocity[static_cast<std::size_t>(f)]),
                             kFdTolerance, Scale::kMatrix);
      }
    }
  };
  SECTION("every transform type") {
    for (TransformType t :
         {TransformType::kTx, TransformType::kTy, TransformType::kTz, TransformType::kRx,
          TransformType::kRy, TransformType::kRz, TransformType::kConstSE3}) {
      INFO("transform " << transformTypeName(t));
      checkAll(transformChain(t).model, 1000 + static_cast<std::uint32_t>(t));
    }
  }
  SECTION("system with every element") { checkAll(kitchenSink().model, 1010); }
}
