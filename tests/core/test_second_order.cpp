// tests/core/test_second_order.cpp — the exact second derivatives (second_order.hpp) on the three
// legs of the derivative tests.
//
// Leg 1: for every transform kind, mass, potential, force and constraint kind (each in a small 3D
// model, at seeded random states — constrained ones off the manifold too, where q̈(z) is still
// defined), the tensors ∂²q̈ᵢ/∂z_a∂z_b and ∂²λ_r/∂z_a∂z_b against central differences of the
// EXACT first derivatives (computeLinearization), step h = eps^(1/3)·max(1, |z_a|) (numdiff.hpp).
// Tolerance: the difference of an exact Jacobian J has truncation error h²/6·|J'''| ≈ 6e-12·|J'''|
// and rounding error ≈ eps·κ·|J|/h ≈ 4e-11·κ·|J| (κ: the amplification of the KKT solve, 1–100
// on these models), so ≈ 1e-9 of the column's scale; 1e-6 (relative to max(1, ‖column‖∞)) leaves
// three orders for the rounding of J itself on the constrained models, and is still six orders
// below an error of a wrong term (which shows as O(1) of the column).
// Identities: the (u, u) block of the differences is ~0 (q̈ is affine in u for every element
// kind: inputs are configuration forces, body wrench entries, tendon tensions); the pure blocks
// of the differences are symmetric (a test of the differences; the exact tensors are symmetric by
// construction, each pair being evaluated once); the contraction Σ wᵢ ∇²q̈ᵢ + Σ ρ_r ∇²λ_r equals
// the same sum of the tensors.
// Leg 3: closed forms derived by hand (pendulum, cart-pole; below) to 1e-12.
#include <catch2/catch.hpp>

#include "support/cart_pole_model.hpp"
#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>
#include <trellis/core/second_order.hpp>
#include <trellis/core/numdiff.hpp>

#include "adjoint_tape.hpp"        // core/src: the sweeps' build switch
#include "second_order_tree.hpp"  // core/src: the tree pass's switch

#include <array>
#include <cmath>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <vector>

using namespace trellis;
using namespace trellis::test;

namespace {

constexpr double kFdTolerance = 1e-6;  // file comment

struct Tensors {
  std::vector<Eigen::MatrixXd> qdd, lambda;  ///< [i](a, b): ∂²/∂z_a∂z_b
};

/// Central differences of the exact Jacobians: out[i](b, a) = ∂/∂z_a of ∂yᵢ/∂z_b. The matrices
/// are not symmetrized (their symmetry is checked). stepScale multiplies the step.
Tensors differenceOfJacobians(const Model& model, const State& s, double stepScale = 1.0) {
  const int n = model.nq(), m = model.nu(), nc = model.nc(), N = 2 * n + m;
  Data data(model);
  Tensors out;
  out.qdd.assign(n, Eigen::MatrixXd::Zero(N, N));
  out.lambda.assign(nc, Eigen::MatrixXd::Zero(N, N));
  Eigen::VectorXd z(N);
  z << s.q, s.dq, s.u;
  Eigen::MatrixXd Jp(n + nc, N), Jm(n + nc, N);
  const NumDiffOptions options;  // central, h = eps^(1/3) max(1, |z|)
  for (int a = 0; a < N; ++a) {
    const double h = stepScale * options.step(z[a]);
    for (int sign = 0; sign < 2; ++sign) {
      Eigen::VectorXd zz = z;
      zz[a] += sign == 0 ? h : -h;
      const DynamicsStatus st = computeLinearization(model, data, zz.head(n), zz.segment(n, n), zz.tail(m));
      REQUIRE(st.code == DynamicsStatus::Code::kOk);
      Eigen::MatrixXd& J = sign == 0 ? Jp : Jm;
      J.topRows(n) << data.dqdd_dq, data.dqdd_ddq, data.dqdd_du;
      if (nc > 0) J.bottomRows(nc) = data.dlambda_dx;
    }
    const double step = (z[a] + h) - (z[a] - h);
    for (int i = 0; i < n; ++i) out.qdd[i].col(a) = (Jp.row(i) - Jm.row(i)).transpose() / step;
    for (int r = 0; r < nc; ++r) out.lambda[r].col(a) = (Jp.row(n + r) - Jm.row(n + r)).transpose() / step;
  }
  return out;
}

void checkSecondOrderAt(const Model& model, const State& s, std::uint32_t seed) {
  const int n = model.nq(), m = model.nu(), nc = model.nc(), N = 2 * n + m;
  Data data(model);
  SecondOrderWorkspace ws(model);
  const DynamicsStatus st = computeSecondOrderTensors(model, data, ws, s.q, s.dq, s.u);
  REQUIRE(st.code == DynamicsStatus::Code::kOk);
  const Tensors fd = differenceOfJacobians(model, s);
  for (int i = 0; i < n; ++i) {
    INFO("q̈ output " << i << " (" << model.configNames()[i] << ")");
    TRELLIS_CHECK_MATRIX(fd.qdd[i], ws.qddHessian[i], kFdTolerance, Scale::kColumn);
    // Symmetry of the differences' pure blocks (q, q), (q̇, q̇) and of the mixed entries.
    const double scale = std::max(1.0, fd.qdd[i].cwiseAbs().maxCoeff());
    CHECK((fd.qdd[i] - fd.qdd[i].transpose()).cwiseAbs().maxCoeff() <= 2 * kFdTolerance * scale);
    // q̈ is affine in u: the differences of ∂q̈/∂u in u vanish to their error.
    if (m > 0) CHECK(fd.qdd[i].bottomRightCorner(m, m).cwiseAbs().maxCoeff() <= kFdTolerance * scale);
    if (m > 0) CHECK(ws.qddHessian[i].bottomRightCorner(m, m).isZero(0.0));
  }
  for (int r = 0; r < nc; ++r) {
    INFO("λ output " << r << " (" << model.constraints()[r].name << ")");
    TRELLIS_CHECK_MATRIX(fd.lambda[r], ws.lambdaHessian[r], kFdTolerance, Scale::kColumn);
  }
  // The contraction against the same sum of the tensors (two computations that share only the
  // hyper-dual residual pass: one KKT solve per pair against one adjoint solve).
  std::mt19937 rng(seed);
  const Eigen::VectorXd w = uniformVector(rng, n, -1.0, 1.0), rho = uniformVector(rng, nc, -1.0, 1.0);
  Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(N, N);
  for (int i = 0; i < n; ++i) expected += w[i] * ws.qddHessian[i];
  for (int r = 0; r < nc; ++r) expected += rho[r] * ws.lambdaHessian[r];
  Eigen::MatrixXd H(N, N);
  Data data2(model);
  SecondOrderWorkspace ws2(model, false);
  REQUIRE(computeSecondOrderContraction(model, data2, ws2, s.q, s.dq, s.u, w, rho, H).code ==
          DynamicsStatus::Code::kOk);
  // Both are O(1)·eps·κ apart: 1e-10 of the largest entry.
  TRELLIS_CHECK_MATRIX(expected, H, 1e-10, Scale::kMatrix);
  if (nc > 0) {  // without ρ: the q̈ part alone
    Eigen::MatrixXd Hw(N, N), expectedW = Eigen::MatrixXd::Zero(N, N);
    for (int i = 0; i < n; ++i) expectedW += w[i] * ws.qddHessian[i];
    REQUIRE(computeSecondOrderContraction(model, data2, ws2, s.q, s.dq, s.u, w, Eigen::VectorXd(), Hw).ok());
    TRELLIS_CHECK_MATRIX(expectedW, Hw, 1e-10, Scale::kMatrix);
  }
}

constexpr int kStatesPerModel = 2;

void checkAtRandomStates(const Model& model, std::uint32_t seed) {
  std::mt19937 rng(seed);
  for (int k = 0; k < kStatesPerModel; ++k) {
    const State s = randomState(model, rng);
    INFO("random state #" << k << " (seed " << seed << ")");
    checkSecondOrderAt(model, s, seed + 1000u * static_cast<std::uint32_t>(k));
  }
}

}  // namespace

TEST_CASE("Second derivatives match differences of the exact Jacobians for every transform type",
          "[second_order][fd]") {
  const std::vector<TransformType> types = {
      TransformType::kTx, TransformType::kTy, TransformType::kTz,      TransformType::kRx,
      TransformType::kRy, TransformType::kRz, TransformType::kConstSE3,
      TransformType::kRotAxis, TransformType::kTransAxis};
  for (TransformType t : types) {
    SECTION(transformTypeName(t)) { checkAtRandomStates(transformChain(t).model, 100 + static_cast<std::uint32_t>(t)); }
  }
}

TEST_CASE("Second derivatives for masses with full inertia, potentials and forces", "[second_order][fd]") {
  SECTION("inertia only, large velocities") {
    const TestSystem sys = std::move(armBase(8)).finish();
    std::mt19937 rng(202);
    checkSecondOrderAt(sys.model, randomState(sys.model, rng, 1.2, 5.0), 202);
  }
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
  SECTION("config_force") {
    SystemBuilder s = armBase();
    s.b.addConfigForce("a", "ua");
    s.b.addConfigForce("d", "ud");
    s.b.addConfigForce("b", "ua");
    checkAtRandomStates(std::move(s).finish().model, 401);
  }
  SECTION("damping") {
    SystemBuilder s = armBase();
    s.b.addDamping(0.3, {{"c", 1.5}, {"d", 0.05}});
    checkAtRandomStates(std::move(s).finish().model, 402);
  }
  SECTION("body_wrench with input and constant entries") {
    SystemBuilder s = armBase();
    s.b.addBodyWrench(
        "l4", {WrenchEntry{std::string("fx")}, WrenchEntry{0.2}, WrenchEntry{std::string("fz")},
               WrenchEntry{std::string("tx")}, WrenchEntry{-0.4}, WrenchEntry{std::string("tz")}});
    checkAtRandomStates(std::move(s).finish().model, 404);
  }
  SECTION("tendon through four frames on three bodies and the world") {
    SystemBuilder s = armBase();
    s.b.addTendon({"w3", "l2", "l3", "l4"}, "tension");
    checkAtRandomStates(std::move(s).finish().model, 405);
  }
}

TEST_CASE("Second derivatives for every constraint kind", "[second_order][fd][constraints]") {
  SECTION("distance between two bodies") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addConfigForce("a", "ua");
    s.b.addDistanceConstraint("l2", "l4", 0.5);
    checkAtRandomStates(std::move(s).finish().model, 502);
  }
  SECTION("distance between a body and the world") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addDistanceConstraint("l4", "w1", 0.9);
    checkAtRandomStates(std::move(s).finish().model, 501);
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
  SECTION("knife edge (nonholonomic), planar skate") { checkAtRandomStates(planarSkate(0.3).model, 602); }
  SECTION("knife edge on a 3D arm along a skewed axis") {
    SystemBuilder s = armBase();
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addKnifeEdgeConstraint("l4", Eigen::Vector3d(1.0, 0.5, -0.2).normalized());
    checkAtRandomStates(std::move(s).finish().model, 603);
  }
  SECTION("paper example (Sec. IV)") { checkAtRandomStates(paperPendulum().model, 604); }
  SECTION("10-joint 3D chain with its tip pinned (the articulated factor, one group of three rows)") {
    // The solves share computeLinearization's factorization, which takes the articulated factor
    // for constrained chains of 8 joints or more (mass_factor.cpp).
    SystemBuilder s;
    std::string parent = "world";
    for (int k = 0; k < 10; ++k) {
      const std::string index = std::to_string(k), q = std::string("q").append(index);
      const std::string joint = std::string("j").append(index), body = std::string("b").append(index);
      s.frame(joint, parent, k % 3 == 0 ? Transform::rx(q) : k % 3 == 1 ? Transform::ry(q) : Transform::rz(q));
      s.frame(body, joint, Transform::ty(-0.3), Mass{0.4, Eigen::Vector3d(2e-3, 1e-3, 3e-3).asDiagonal()});
      parent = body;
    }
    s.frame("anchor", "world", Transform::ty(-1.5));
    s.b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    s.b.addConfigForce("q0", "u0");
    for (int axis = 0; axis < 3; ++axis) s.b.addPointConstraint(parent, "anchor", axis);
    checkAtRandomStates(std::move(s).finish().model, 605);
  }
}

TEST_CASE("Second derivatives for a system with every element", "[second_order][fd][constraints]") {
  SECTION("unconstrained") { checkAtRandomStates(kitchenSink(3, false).model, 701); }
  SECTION("with knife edge, distance, point and point_on_plane constraints") {
    checkAtRandomStates(kitchenSink(3, true).model, 702);
  }
  SECTION("at a consistent state") {
    const TestSystem sys = kitchenSink(3, true);
    std::mt19937 rng(703);
    checkSecondOrderAt(sys.model, randomConsistentState(sys.model, rng), 703);
  }
}

TEST_CASE("Second derivatives with redundant constraints equal those without the copies",
          "[second_order][constraints]") {
  // The paper's pendulum with its distance constraint written twice: A has a dependent row and
  // the solve takes the pseudo-inverse path (status kRedundantConstraints), but q̈(z) is the same
  // function as with one copy, so its second derivatives must agree (the duplicated λ splits the
  // force: each copy carries half of the single λ, and so do its derivatives).
  const Model one = paperPendulum(1).model, two = paperPendulum(2).model;
  Data d1(one), d2(two);
  SecondOrderWorkspace w1(one), w2(two, true), c2(two, false);
  std::mt19937 rng(880);
  for (int k = 0; k < 3; ++k) {
    const State s = randomState(one, rng);
    REQUIRE(computeSecondOrderTensors(one, d1, w1, s.q, s.dq, s.u).ok());
    REQUIRE(computeSecondOrderTensors(two, d2, w2, s.q, s.dq, s.u).code == DynamicsStatus::Code::kRedundantConstraints);
    for (int i = 0; i < one.nq(); ++i) TRELLIS_CHECK_MATRIX(w1.qddHessian[i], w2.qddHessian[i], 1e-9, Scale::kMatrix);
    for (int r = 0; r < 2; ++r)
      TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(0.5 * w1.lambdaHessian[0]), w2.lambdaHessian[r], 1e-9, Scale::kMatrix);
    const Eigen::VectorXd w = uniformVector(rng, one.nq(), -1.0, 1.0);
    const int N = 2 * one.nq() + one.nu();
    Eigen::MatrixXd H(N, N), expected = Eigen::MatrixXd::Zero(N, N);
    for (int i = 0; i < one.nq(); ++i) expected += w[i] * w1.qddHessian[i];
    computeSecondOrderContraction(two, d2, c2, s.q, s.dq, s.u, w, Eigen::VectorXd(), H);
    TRELLIS_CHECK_MATRIX(expected, H, 1e-9, Scale::kMatrix);
  }
}

namespace {

/// Forces the recording (the tape) instead of the tree pass while alive; restores the automatic
/// choice even when a check fails.
struct ForceTape {
  explicit ForceTape(bool force) { detail::secondOrderForceTape(force); }
  ~ForceTape() { detail::secondOrderForceTape(false); }
};
/// Forces the generic (non-AVX2) sweeps of the tree pass while alive.
struct ForceGeneric {
  explicit ForceGeneric(bool force) { detail::secondOrderSweepsForceGeneric(force); }
  ~ForceGeneric() { detail::secondOrderSweepsForceGeneric(false); }
};
/// One model's second-order workspaces both ways: `fast` by the automatic choice, `tape` with the
/// recording forced.
struct TreeAndTape {
  SecondOrderWorkspace fast;
  std::optional<SecondOrderWorkspace> tape;
  explicit TreeAndTape(const Model& model) : fast(model, true) {
    const ForceTape force(true);
    tape.emplace(model, false);
  }
};

}  // namespace

TEST_CASE("The contraction in blocks of directions, in both builds of its sweeps", "[second_order]") {
  // The sweeps run the 2n q and q̇ directions in blocks of 16 (the last one of 4, 8 or 16, partly
  // unused), in the baseline build or, when the CPU has AVX2 and FMA, in that one. Every block
  // shape (2n = 4, 6, 12, 20 = 16 + 4, 26 = 16 + 10) and both builds against the sum of the
  // tensors: 1e-10 of the largest entry, as in checkSecondOrderAt.
  std::vector<TestSystem> systems;
  for (const int links : {2, 3, 10, 13}) systems.push_back(planarChain(links, 0.5, 1.0));
  systems.push_back(kitchenSink(3, true));
  for (const bool generic : {false, true}) {
    const ForceGeneric force(generic);
    INFO((detail::secondOrderSweepsUseAvx2() ? "AVX2+FMA sweeps" : "baseline sweeps"));
    if (generic) CHECK_FALSE(detail::secondOrderSweepsUseAvx2());
    std::mt19937 rng(910);
    for (const TestSystem& sys : systems) {
      const Model& model = sys.model;
      const int n = model.nq(), nc = model.nc(), N = 2 * n + model.nu();
      INFO("n = " << n << ", nc = " << nc);
      const State s = randomState(model, rng);
      Data data(model);
      SecondOrderWorkspace ws(model);
      REQUIRE(computeSecondOrderTensors(model, data, ws, s.q, s.dq, s.u).ok());
      const Eigen::VectorXd w = uniformVector(rng, n, -1.0, 1.0), rho = uniformVector(rng, nc, -1.0, 1.0);
      Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(N, N), H(N, N);
      for (int i = 0; i < n; ++i) expected += w[i] * ws.qddHessian[i];
      for (int r = 0; r < nc; ++r) expected += rho[r] * ws.lambdaHessian[r];
      REQUIRE(computeSecondOrderContraction(model, data, ws, s.q, s.dq, s.u, w, rho, H).ok());
      TRELLIS_CHECK_MATRIX(expected, H, 1e-10, Scale::kMatrix);
      // A second call on the same workspace (the sweeps leave their arrays cleared) agrees.
      Eigen::MatrixXd again(N, N);
      REQUIRE(computeSecondOrderContraction(model, data, ws, s.q, s.dq, s.u, w, rho, again).ok());
      CHECK(again == H);
    }
  }
}

/// A branched 3D tree of every joint kind that the tree pass covers, with full inertias, skewed
/// gravity, a configuration spring, damping and configuration forces (no point-force element, no
/// constraint): root rz → {arm: ry, tx (prismatic), r_axis; leg: rx, t_axis}, plus a second root tz;
/// With `copies` > 1, that many such trees (8 coordinates each) hang from a hub of two joints
/// (rz, then rx): 3 copies need two blocks of each kind, and a block of q directions holds whole
/// subtrees that do not move with it but are coupled to it through the hub, below a hub joint
/// that does not move with it either but is not a root.
/// `extra` adds elements (constraint rows) before the model is finished.
using Extra = std::function<void(SystemBuilder&)>;

TestSystem branchedTree(std::uint32_t seed, int copies = 1, const Extra& extra = {}) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  std::string base = "world";
  if (copies > 1) {
    s.frame("hub", "world", Transform::rz("hub"), Mass{2.0, randomInertia(rng)});
    s.frame("hub_offset", "hub", Transform::constSE3(se3(0.7, {0.3, 0.4, 1.0}, {0.2, 0.3, -0.1})));
    s.frame("hub2", "hub_offset", Transform::rx("hub2"), Mass{1.5, randomInertia(rng)});
    base = "hub2";
  }
  for (int k = 0; k < copies; ++k) {
    const std::string x = k == 0 ? std::string() : std::string("_").append(std::to_string(k));
    auto name = [&](const char* base) { return std::string(base).append(x); };
    s.frame(name("hip"), base, Transform::rz(name("yaw")), Mass{1.2, randomInertia(rng)});
    s.frame(name("arm_base"), name("hip"), Transform::constSE3(se3(0.4, {1.0, 0.5, 0.2}, {0.3, 0.1, 0.2})));
    s.frame(name("shoulder"), name("arm_base"), Transform::ry(name("pitch")), Mass{0.7, randomInertia(rng)});
    s.frame(name("upper"), name("shoulder"), Transform::tz(0.5), Mass{0.4, randomInertia(rng)});
    s.frame(name("slide"), name("upper"), Transform::tx(name("ext")), Mass{0.3, randomInertia(rng)});
    s.frame(name("wrist"), name("slide"), Transform::rotAxis(Eigen::Vector3d(0.3, -0.5, 0.8).normalized(), name("twist")),
            Mass{0.2, randomInertia(rng)});
    s.frame(name("hand"), name("wrist"), Transform::ty(0.2), Mass{0.15, randomInertia(rng)});
    s.frame(name("leg"), name("hip"), Transform::rx(name("knee")), Mass{0.6, randomInertia(rng)});
    s.frame(name("shin"), name("leg"), Transform::ty(-0.6), Mass{0.5, randomInertia(rng)});
    s.frame(name("foot"), name("shin"), Transform::transAxis(Eigen::Vector3d(0.2, 0.9, -0.4).normalized(), name("reach")),
            Mass{0.25, randomInertia(rng)});
    s.frame(name("other"), base, Transform::constSE3(se3(-0.3, {0.0, 1.0, 0.0}, {1.0, 0.0, 0.5})));
    s.frame(name("lift"), name("other"), Transform::tz(name("lift")), Mass{0.9, randomInertia(rng)});
    s.frame(name("lift_arm"), name("lift"), Transform::ry(name("tilt")), Mass{0.35, randomInertia(rng)});
    s.frame(name("lift_tip"), name("lift_arm"), Transform::tx(0.4), Mass{0.1, randomInertia(rng)});
    s.b.addConfigSpring(name("knee"), 2.5, 0.3);
    s.b.addDamping(0.05, {{name("ext"), 0.4}});
    s.b.addConfigForce(name("yaw"), name("u_yaw"));
    s.b.addConfigForce(name("ext"), name("u_ext"));
    s.b.addConfigForce(name("tilt"), name("u_tilt"));
  }
  s.b.addGravity(Eigen::Vector3d(0.6, -1.3, -9.5));
  if (extra) extra(s);
  return std::move(s).finish();
}

/// A 3D chain of `links` joints cycling through every driven kind (rz, ry, tx, r_axis, rx, t_axis),
/// each body offset from its joint, with full inertias: past 16 joints, a block of q directions
/// holds moving joints below ones that do not move with it.
/// The driven joint kinds in turn: rz, ry, tx, r_axis, rx, t_axis (k mod 6) on coordinate q.
Transform drivenKind(int k, const std::string& q) {
  switch (k % 6) {
    case 1: return Transform::ry(q);
    case 2: return Transform::tx(q);
    case 3: return Transform::rotAxis(Eigen::Vector3d(0.3, -0.5, 0.8).normalized(), q);
    case 4: return Transform::rx(q);
    case 5: return Transform::transAxis(Eigen::Vector3d(0.2, 0.9, -0.4).normalized(), q);
    default: return Transform::rz(q);
  }
}

TestSystem spatialChain(int links, std::uint32_t seed, const Extra& extra = {}) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  std::string parent = "world";
  for (int k = 0; k < links; ++k) {
    const std::string index = std::to_string(k);
    const std::string joint = std::string("joint").append(index), body = std::string("body").append(index);
    const std::string q = std::string("q").append(index);
    s.frame(joint, parent, drivenKind(k, q));
    s.frame(body, joint, Transform::constSE3(se3(0.3, {0.2, 1.0, 0.4}, {0.1, -0.25, 0.2})), Mass{0.3, randomInertia(rng)});
    parent = body;
  }
  s.b.addGravity(Eigen::Vector3d(0.4, -9.7, 1.1));
  s.b.addDamping(0.05);
  s.b.addConfigForce("q0", "u0");
  if (extra) extra(s);
  return std::move(s).finish();
}

/// Three subtrees hanging from the world (frames added in turn): a 3D chain of 18 joints (two
/// blocks of directions), a 3-joint chain and a 5-joint tree with two branches; every driven
/// joint kind, full inertias, a spring, damping and forces on coordinates of each. The tree pass
/// runs its blocks per subtree.
TestSystem threeSubtrees(std::uint32_t seed, const Extra& extra = {}) {
  std::mt19937 rng(seed);
  SystemBuilder s;
  auto link = [&](const std::string& name, const std::string& parent, int k) {
    s.frame(name, parent, drivenKind(k, std::string("q_").append(name)));
    s.frame(name + "_body", name, Transform::constSE3(se3(0.2 * k, {0.2, 0.8, 0.3}, {0.1, -0.2, 0.15})),
            Mass{0.2 + 0.05 * (k % 4), randomInertia(rng)});
    return name + "_body";
  };
  std::string a = "world", b = "world", cRoot;
  for (int k = 0; k < 18; ++k) {
    a = link(std::string("a").append(std::to_string(k)), a, k);
    if (k < 3) b = link(std::string("b").append(std::to_string(k)), b, k + 2);
    if (k == 0) cRoot = link("c0", "world", 3);
    if (k == 1) link("c1", cRoot, 1);  // two branches on c0: c1, and c2 → c3 → c4
    if (k == 2) link("c2", cRoot, 5);
    if (k == 3) link("c3", "c2_body", 0);
    if (k == 4) link("c4", "c3_body", 2);
  }
  s.b.addGravity(Eigen::Vector3d(0.3, -9.6, 1.2));
  s.b.addDamping(0.05);
  for (const char* q : {"q_a0", "q_a17", "q_b1", "q_c2", "q_c4"}) s.b.addConfigForce(q, std::string("u_").append(q));
  s.b.addConfigSpring("q_c1", 3.0, 0.2);
  if (extra) extra(s);
  return std::move(s).finish();
}

TEST_CASE("The contraction's tree pass against the recording and the tensors", "[second_order][tree]") {
  // Where the model holds only the tree, gravity and forces on coordinates, the workspace takes
  // the tree pass (second_order_tree.hpp); secondOrderForceTape makes it record the tape instead.
  // Both, and the sum of the hyper-dual tensors, agree to 1e-10 of the largest entry (three
  // computations that share no code beyond the KKT factor), at random states and weights, on
  // every block shape (the q and the q̇ directions in blocks of their own, 16 wide, the last 4, 8,
  // 12 or 16: n = 2, 3, 10, 13, 18 = 16 + 2, 8, 26 = 16 + 10, 20 = 16 + 4), blocks per subtree hanging
  // from the world (branchedTree(41): two; threeSubtrees: 18 = 16 + 2, 3 and 5) and every joint kind, in the
  // baseline build and (where the CPU has it) the AVX2+FMA build of the pass.
  std::vector<TestSystem> systems;
  for (const int links : {2, 3, 10, 13, 18}) systems.push_back(planarChain(links, 0.5, 1.0));
  systems.push_back(branchedTree(41));
  systems.push_back(branchedTree(43, 3));
  systems.push_back(spatialChain(20, 47));
  systems.push_back(threeSubtrees(53));
  {  // the forest: three subtrees from the world, of 18 (two blocks), 3 and 5 joints
    const Model& forest = systems.back().model;
    int roots = 0;
    for (const Joint& j : forest.joints()) roots += j.parent == kWorld ? 1 : 0;
    REQUIRE(roots == 3);
    REQUIRE(forest.nq() == 26);
  }
  for (const TransformType t : {TransformType::kRx, TransformType::kTy, TransformType::kRotAxis, TransformType::kTransAxis})
    systems.push_back(transformChain(t));
  for (const bool generic : {false, true}) {
    const ForceGeneric build(generic);
    INFO((detail::secondOrderSweepsUseAvx2() ? "AVX2+FMA build" : "baseline build"));
    std::mt19937 rng(4242);
    for (const TestSystem& sys : systems) {
      const Model& model = sys.model;
      const int n = model.nq(), N = 2 * n + model.nu();
      INFO("n = " << n << ", m = " << model.nu());
      REQUIRE(detail::treeSecondOrderApplies(model));
      Data data(model);
      TreeAndTape both(model);
      SecondOrderWorkspace &fast = both.fast, &tape = *both.tape;
      CHECK(detail::secondOrderUsesTreePath(fast));
      CHECK_FALSE(detail::secondOrderUsesTreePath(tape));
      for (int k = 0; k < 3; ++k) {
        const State s = randomState(model, rng);
        REQUIRE(computeSecondOrderTensors(model, data, fast, s.q, s.dq, s.u).ok());
        const Eigen::VectorXd w = uniformVector(rng, n, -1.0, 1.0);
        Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(N, N), Hfast(N, N), Htape(N, N);
        for (int i = 0; i < n; ++i) expected += w[i] * fast.qddHessian[i];
        REQUIRE(computeSecondOrderContraction(model, data, fast, s.q, s.dq, s.u, w, Eigen::VectorXd(), Hfast).ok());
        REQUIRE(computeSecondOrderContraction(model, data, tape, s.q, s.dq, s.u, w, Eigen::VectorXd(), Htape).ok());
        TRELLIS_CHECK_MATRIX(expected, Hfast, 1e-10, Scale::kMatrix);
        TRELLIS_CHECK_MATRIX(Htape, Hfast, 1e-10, Scale::kMatrix);
      }
    }
  }
}

TEST_CASE("The contraction's tree pass with point constraint rows and tendons", "[second_order][tree][constraints]") {
  // Point rows (second_order_tree.hpp: sites) on three trees: a branched tree with one point
  // pinned to the world (three rows) and two points of one subtree held together along y; a
  // forest whose 18-joint chain and 5-joint tree are joined by two rows (one component of 23
  // joints, two blocks of directions) and whose 3-joint chain has one row to the world; a 20-joint
  // 3D chain with its tip pinned (moving joints below ones that do not move with a block). At
  // random states (off the constraint manifold, where q̈ and λ are still defined) and random
  // weights w, ρ, the tree pass against the recording (1e-10 of the largest entry: the same
  // quantity by two computations sharing only the KKT factor), against the sum of the hyper-dual
  // tensors (1e-10), and against central differences of the exact Jacobians (1e-6 of each
  // column's scale, the file comment's tolerance), in both builds of the pass. Then tendons
  // (header: segments between two bodies): on the branched tree, one from a world anchor across
  // both subtrees (joining them) with two points on one body, and one within the hip's subtree
  // beside the point rows; and the hand scene (examples/scenes/hand.json: 23 tendons, 15 point
  // rows, configuration springs, damping) at random states near its initial one.
  std::vector<TestSystem> systems;
  systems.push_back(branchedTree(61, 1, [](SystemBuilder& s) {
    s.frame("anchor", "world", Transform::constSE3(se3(0.3, {0.1, 0.2, 1.0}, {0.9, 0.4, 0.3})));
    for (int axis = 0; axis < 3; ++axis) s.b.addPointConstraint("hand", "anchor", axis);
    s.b.addPointConstraint("lift_tip", "foot", 1);
  }));
  systems.push_back(threeSubtrees(67, [](SystemBuilder& s) {
    s.frame("anchor", "world", Transform::constSE3(se3(-0.2, {1.0, 0.0, 0.3}, {0.2, -0.8, 0.5})));
    s.b.addPointConstraint("a5_body", "c4_body", 0);
    s.b.addPointConstraint("a5_body", "c4_body", 2);
    s.b.addPointConstraint("anchor", "b2_body", 1);
  }));
  systems.push_back(spatialChain(20, 71, [](SystemBuilder& s) {
    s.frame("anchor", "world", Transform::constSE3(se3(0.0, {0.0, 0.0, 1.0}, {0.5, 2.0, -0.3})));
    for (int axis = 0; axis < 3; ++axis) s.b.addPointConstraint("body19", "anchor", axis);
  }));
  systems.push_back(branchedTree(79, 1, [](SystemBuilder& s) {
    s.frame("origin", "world", Transform::constSE3(se3(0.2, {0.3, 1.0, 0.1}, {-0.4, 0.6, 0.9})));
    s.frame("via_upper", "upper", Transform::constSE3(se3(0.0, {0.0, 0.0, 1.0}, {0.1, -0.05, 0.2})));
    s.frame("via_upper2", "upper", Transform::constSE3(se3(0.0, {0.0, 0.0, 1.0}, {-0.1, 0.15, 0.3})));
    s.frame("via_tip", "lift_tip", Transform::constSE3(se3(0.0, {0.0, 0.0, 1.0}, {0.05, 0.1, -0.1})));
    s.b.addTendon({"origin", "via_upper", "via_upper2", "hand", "via_tip"}, "u_t1");
    s.b.addTendon({"shin", "foot", "leg"}, "u_t2");
    s.b.addPointConstraint("hand", "origin", 0);
    s.b.addPointConstraint("hand", "origin", 2);
  }));
  const Scene hand = loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand.json");
  REQUIRE(!hand.model.tendons().empty());
  REQUIRE(hand.model.nc() == 15);
  systems.push_back(TestSystem{hand.model, {}});
  for (const bool generic : {false, true}) {
    const ForceGeneric build(generic);
    INFO((detail::secondOrderSweepsUseAvx2() ? "AVX2+FMA build" : "baseline build"));
    std::mt19937 rng(4343);
    for (const TestSystem& sys : systems) {
      const Model& model = sys.model;
      const int n = model.nq(), nc = model.nc(), N = 2 * n + model.nu();
      INFO("n = " << n << ", m = " << model.nu() << ", nc = " << nc);
      REQUIRE(detail::treeSecondOrderApplies(model));
      Data data(model);
      TreeAndTape both(model);
      SecondOrderWorkspace &fast = both.fast, &tape = *both.tape;
      REQUIRE(detail::secondOrderUsesTreePath(fast));
      REQUIRE_FALSE(detail::secondOrderUsesTreePath(tape));
      const bool isHand = model.nc() == hand.model.nc() && model.nq() == hand.model.nq();
      for (int k = 0; k < 2; ++k) {
        State s = randomState(model, rng);
        if (isHand) {  // near the scene's grasp: ±0.1 rad, ±0.5 rad/s, tensions 0 … 20 N
          s = randomState(model, rng, 0.1, 0.5, 10.0);
          s.q += hand.q;
          s.u.array() += 10.0;
        }
        REQUIRE(computeSecondOrderTensors(model, data, fast, s.q, s.dq, s.u).ok());
        const Eigen::VectorXd w = uniformVector(rng, n, -1.0, 1.0), rho = uniformVector(rng, nc, -1.0, 1.0);
        Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(N, N), Hfast(N, N), Htape(N, N);
        for (int i = 0; i < n; ++i) expected += w[i] * fast.qddHessian[i];
        for (int r = 0; r < nc; ++r) expected += rho[r] * fast.lambdaHessian[r];
        REQUIRE(computeSecondOrderContraction(model, data, fast, s.q, s.dq, s.u, w, rho, Hfast).ok());
        REQUIRE(computeSecondOrderContraction(model, data, tape, s.q, s.dq, s.u, w, rho, Htape).ok());
        TRELLIS_CHECK_MATRIX(Htape, Hfast, 1e-10, Scale::kMatrix);
        TRELLIS_CHECK_MATRIX(expected, Hfast, 1e-10, Scale::kMatrix);
        if (generic || k > 0) continue;  // the differences once per model (2N linearizations)
        auto contracted = [&](double stepScale) {
          const Tensors fd = differenceOfJacobians(model, s, stepScale);
          Eigen::MatrixXd sum = Eigen::MatrixXd::Zero(N, N);
          for (int i = 0; i < n; ++i) sum += w[i] * fd.qdd[i];
          for (int r = 0; r < nc; ++r) sum += rho[r] * fd.lambda[r];
          return sum;
        };
        Eigen::MatrixXd fromDifferences = contracted(1.0);
        // The hand (light phalanges, contacts on a ball: a KKT solve of large amplification) is
        // rounding-limited at the default step: its central differences miss by up to 5e-5 of a
        // column, and the miss falls as the step grows (Richardson's extrapolation over (h, 2h)
        // at 4h: 1.7e-5, at 32h: 2.3e-6; measured on branch h-tree3). So there it is the
        // extrapolation (4 D(h) − D(2h))/3 at h = 128 eps^(1/3) ≈ 8e-4 (truncation O(h⁴)).
        if (isHand) fromDifferences = (4.0 * contracted(128.0) - contracted(256.0)) / 3.0;
        TRELLIS_CHECK_MATRIX(fromDifferences, Hfast, kFdTolerance, Scale::kColumn);
      }
    }
  }
}

TEST_CASE("The contraction's tree pass stays off where the model has more than the tree", "[second_order][tree]") {
  // Springs between points, tendons, body wrenches and constraint rows of other kinds than point
  // rows (alone or beside point rows): the recording.
  std::vector<TestSystem> systems;
  systems.push_back(kitchenSink(3, false));
  systems.push_back(kitchenSink(3, true));
  systems.push_back(planarSkate(0.3));
  systems.push_back(paperPendulum());
  systems.push_back(spatialChain(6, 73, [](SystemBuilder& s) {  // point rows and a distance row
    s.frame("anchor", "world", Transform::ty(1.0));
    s.b.addPointConstraint("body5", "anchor", 0);
    s.b.addDistanceConstraint("body2", "anchor", 1.2);
  }));
  for (const TestSystem& sys : systems) {
    CHECK_FALSE(detail::treeSecondOrderApplies(sys.model));
    const SecondOrderWorkspace ws(sys.model, false);
    CHECK_FALSE(detail::secondOrderUsesTreePath(ws));
  }
}

// ---- Closed forms --------------------------------------------------------------------------------

TEST_CASE("Second derivatives: closed form of the damped pendulum", "[second_order][closed_form]") {
  // Bob of mass m at distance l below the pivot (rz(θ) then ty(−l)): p = (l sin θ, −l cos θ),
  // V = −m g l cos θ, so m l² θ̈ = u − c θ̇ − m g l sin θ:
  //   θ̈ = −(g/l) sin θ + (u − c θ̇)/(m l²).
  // Its only nonzero second derivative is ∂²θ̈/∂θ² = (g/l) sin θ (θ̇ and u enter linearly).
  const double m = 0.7, l = 1.3, g = 9.81, c = 0.4;
  ModelBuilder b("pendulum");
  b.addFrame("pin", "world", Transform::rz("theta"));
  b.addFrame("bob", "pin", Transform::ty(-l), Mass{m, Eigen::Matrix3d::Zero()});
  b.addGravity({0.0, -g, 0.0});
  b.addConfigForce("theta", "u");
  b.addDamping(c, {});
  const Model model = std::move(b).finalize();
  Data data(model);
  SecondOrderWorkspace ws(model);
  for (const double theta : {-2.1, -0.4, 0.0, 0.9, 2.7}) {
    const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, theta), dq = Eigen::VectorXd::Constant(1, 1.7),
                          u = Eigen::VectorXd::Constant(1, -0.3);
    REQUIRE(computeSecondOrderTensors(model, data, ws, q, dq, u).ok());
    Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(3, 3);
    expected(0, 0) = g / l * std::sin(theta);
    INFO("theta = " << theta);
    TRELLIS_CHECK_MATRIX(expected, ws.qddHessian[0], 1e-12, Scale::kAbsolute);
  }
}

TEST_CASE("Second derivatives: closed form of the cart-pole", "[second_order][closed_form]") {
  // support/cart_pole_model.hpp: cart x (mass mc, force u), pole θ (rz) with a point mass mp at
  // distance l along its +y: p = (x − l s, l c), s = sin θ, c = cos θ, ω = θ̇. With
  //   T = ½ (mc + mp) ẋ² − mp l c ẋ ω + ½ mp l² ω²,  V = mp g l c,
  // the equations are (mc + mp) ẍ − mp l c θ̈ + mp l s ω² = u and l θ̈ = c ẍ + g s, so
  //   ẍ = N / D,  N = u + mp s (g c − l ω²),  D = mc + mp s²,   θ̈ = (c ẍ + g s) / l.
  // Derivatives (by hand; x and ẋ do not enter):
  //   N_θ = mp (g (c² − s²) − l ω² c),  N_θθ = mp (−4 g s c + l ω² s),  N_ω = −2 mp l s ω,
  //   N_ωω = −2 mp l s,  N_θω = −2 mp l c ω,  N_u = 1;   D_θ = 2 mp s c,  D_θθ = 2 mp (c² − s²);
  //   ẍ_θ = N_θ/D − N D_θ/D²,  ẍ_θθ = N_θθ/D − 2 N_θ D_θ/D² − N D_θθ/D² + 2 N D_θ²/D³,
  //   ẍ_ω = N_ω/D,  ẍ_ωω = N_ωω/D,  ẍ_θω = N_θω/D − N_ω D_θ/D²,  ẍ_u = 1/D,  ẍ_uθ = −D_θ/D²;
  //   θ̈_θθ = (−c ẍ − 2 s ẍ_θ + c ẍ_θθ − g s)/l,  θ̈_θω = (−s ẍ_ω + c ẍ_θω)/l,  θ̈_ωω = c ẍ_ωω/l,
  //   θ̈_uθ = (−s ẍ_u + c ẍ_uθ)/l;  every pair with ω–u, u–u, x or ẋ is 0.
  const double mc = 1.0, mp = 0.2, l = 0.5, g = 9.81;
  const Model model = cartPole(mc, mp, l);
  Data data(model);
  SecondOrderWorkspace ws(model);
  std::mt19937 rng(9001);
  for (int k = 0; k < 5; ++k) {
    const State st = randomState(model, rng, 3.0, 2.0, 5.0);
    const double th = st.q[1], w = st.dq[1], u = st.u[0];
    const double s = std::sin(th), c = std::cos(th);
    const double N = u + mp * s * (g * c - l * w * w), D = mc + mp * s * s;
    const double Nt = mp * (g * (c * c - s * s) - l * w * w * c), Ntt = mp * (-4 * g * s * c + l * w * w * s);
    const double Nw = -2 * mp * l * s * w, Nww = -2 * mp * l * s, Ntw = -2 * mp * l * c * w;
    const double Dt = 2 * mp * s * c, Dtt = 2 * mp * (c * c - s * s);
    const double xdd = N / D, xt = Nt / D - N * Dt / (D * D);
    const double xtt = Ntt / D - 2 * Nt * Dt / (D * D) - N * Dtt / (D * D) + 2 * N * Dt * Dt / (D * D * D);
    const double xw = Nw / D, xww = Nww / D, xtw = Ntw / D - Nw * Dt / (D * D), xu = 1 / D, xut = -Dt / (D * D);
    // z = [x, θ, ẋ, ω, u]
    Eigen::MatrixXd Hx = Eigen::MatrixXd::Zero(5, 5), Ht = Eigen::MatrixXd::Zero(5, 5);
    Hx(1, 1) = xtt;
    Hx(1, 3) = Hx(3, 1) = xtw;
    Hx(3, 3) = xww;
    Hx(1, 4) = Hx(4, 1) = xut;
    Ht(1, 1) = (-c * xdd - 2 * s * xt + c * xtt - g * s) / l;
    Ht(1, 3) = Ht(3, 1) = (-s * xw + c * xtw) / l;
    Ht(3, 3) = c * xww / l;
    Ht(1, 4) = Ht(4, 1) = (-s * xu + c * xut) / l;
    REQUIRE(computeSecondOrderTensors(model, data, ws, st.q, st.dq, st.u).ok());
    INFO("state #" << k);
    TRELLIS_CHECK_MATRIX(Hx, ws.qddHessian[0], 1e-12, Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(Ht, ws.qddHessian[1], 1e-12, Scale::kMatrix);
    // The six blocks in the issue's layout, output index first.
    const auto uq = ws.qddBlock(SecondOrderWorkspace::Block::kUQ);
    REQUIRE(uq.size() == 2);
    CHECK(uq[1](0, 1) == ws.qddHessian[1](4, 1));
  }
}

namespace {

// A second-order jet in the paper example's five variables z = [θ1, θ2, θ̇1, θ̇2, u]: a value with
// its exact gradient and Hessian, carried through + − × ÷ sin cos by the product and chain rules
// (forward-mode differentiation of the hand-written equations below, no tree and no differences).
struct Jet {
  double v = 0.0;
  Eigen::Matrix<double, 5, 1> g = Eigen::Matrix<double, 5, 1>::Zero();
  Eigen::Matrix<double, 5, 5> H = Eigen::Matrix<double, 5, 5>::Zero();
  static Jet variable(double value, int i) {
    Jet j;
    j.v = value;
    j.g(i) = 1.0;
    return j;
  }
};
Jet operator+(Jet a, const Jet& b) { a.v += b.v; a.g += b.g; a.H += b.H; return a; }
Jet operator-(Jet a, const Jet& b) { a.v -= b.v; a.g -= b.g; a.H -= b.H; return a; }
Jet operator+(Jet a, double c) { a.v += c; return a; }
Jet operator*(double c, Jet a) { a.v *= c; a.g *= c; a.H *= c; return a; }
Jet operator-(const Jet& a) { return -1.0 * a; }
Jet operator*(const Jet& a, const Jet& b) {
  Jet r;
  r.v = a.v * b.v;
  r.g = a.v * b.g + b.v * a.g;
  r.H = a.v * b.H + b.v * a.H + a.g * b.g.transpose() + b.g * a.g.transpose();
  return r;
}
Jet reciprocal(const Jet& b) {  // 1/b: −b'/b², −b''/b² + 2 b' b'ᵀ/b³
  Jet r;
  r.v = 1.0 / b.v;
  r.g = -b.g / (b.v * b.v);
  r.H = -b.H / (b.v * b.v) + 2.0 * b.g * b.g.transpose() / (b.v * b.v * b.v);
  return r;
}
Jet operator/(const Jet& a, const Jet& b) { return a * reciprocal(b); }
Jet sin(const Jet& a) {
  Jet r;
  r.v = std::sin(a.v);
  r.g = std::cos(a.v) * a.g;
  r.H = std::cos(a.v) * a.H - std::sin(a.v) * a.g * a.g.transpose();
  return r;
}
Jet cos(const Jet& a) {
  Jet r;
  r.v = std::cos(a.v);
  r.g = -std::sin(a.v) * a.g;
  r.H = -std::sin(a.v) * a.H - std::cos(a.v) * a.g * a.g.transpose();
  return r;
}

}  // namespace

TEST_CASE("Second derivatives: closed form of the paper's constrained double pendulum (Sec. IV)",
          "[second_order][closed_form][constraints]") {
  // Worked out by hand for support/test_models.hpp paperPendulum(): unit masses at A and B, unit
  // links, g = 9.8, u on θ1, anchor C = (2, 0), h = ‖p_B − p_C‖² − 1 (the core's distance form).
  //   p_A = (s1, −c1),  p_B = p_A + (s12, −c12)           (s12 = sin(θ1 + θ2), ω = θ̇1 + θ̇2)
  //   T = ½ θ̇1² + ½ (θ̇1² + ω² + 2 θ̇1 ω c2),  V = −g (2 c1 + c12)
  //   M = [3 + 2 c2, 1 + c2; 1 + c2, 1],
  //   F = τ − (Ṁ q̇ − ∂T/∂q) − ∂V/∂q = [u + s2 (2 θ̇1 θ̇2 + θ̇2²) − g (2 s1 + s12), −s2 θ̇1² − g s12]
  //   d = p_B − p_C,  J = ∂p_B/∂q = [c1 + c12, c12; s1 + s12, s12],  A = 2 dᵀ J,
  //   Ȧ q̇ = q̇ᵀ ∇²h q̇ = 2 (‖J q̇‖² + dᵀ p̈_B|q̈=0),  p̈_B|q̈=0 = (−s1 θ̇1² − s12 ω², c1 θ̇1² + c12 ω²)
  //   M q̈ = F + Aᵀ λ,  A q̈ = −Ȧ q̇   ⇒   λ = −(Ȧ q̇ + A M⁻¹ F) / (A M⁻¹ Aᵀ),  q̈ = M⁻¹ (F + Aᵀ λ).
  // Its second derivatives here come from carrying these formulas in second-order jets (exact
  // forward differentiation: an independent route from the tree's passes and the KKT sweeps).
  const double g = 9.8;
  const TestSystem sys = paperPendulum();
  const Model& model = sys.model;
  REQUIRE(model.nq() == 2);
  REQUIRE(model.nu() == 1);
  REQUIRE(model.nc() == 1);
  Data data(model);
  SecondOrderWorkspace ws(model);
  const double pi = std::acos(-1.0);
  std::mt19937 rng(4242);
  std::uniform_real_distribution<double> angle(-pi, pi), rate(-3.0, 3.0), torque(-5.0, 5.0);
  std::vector<std::array<double, 5>> states = {
      // On the manifold: (π/6, π/3) has h = 0 exactly (ERRATA); the rate spans A's null space.
      {pi / 6, pi / 3, 1.0, 0.0, 2.0},
      // The paper's printed state (slightly off the constraint), with the errata's velocity.
      {0.5246, 1.0472, 1.0, -2.00116, 2.0}};
  for (int k = 0; k < 6; ++k) states.push_back({angle(rng), angle(rng), rate(rng), rate(rng), torque(rng)});
  {
    // Make the first state's velocity tangent: q̇ ∝ (A2, −A1) at (π/6, π/3).
    const double t1 = pi / 6, t2 = pi / 3, s1 = std::sin(t1), c1 = std::cos(t1);
    const double s12 = std::sin(t1 + t2), c12 = std::cos(t1 + t2);
    const double dx = s1 + s12 - 2.0, dy = -c1 - c12;
    const double A1 = 2.0 * (dx * (c1 + c12) + dy * (s1 + s12)), A2 = 2.0 * (dx * c12 + dy * s12);
    states[0][2] = A2;
    states[0][3] = -A1;
  }
  for (std::size_t k = 0; k < states.size(); ++k) {
    const auto& st = states[k];
    const Jet t1 = Jet::variable(st[0], 0), t2 = Jet::variable(st[1], 1);
    const Jet w1 = Jet::variable(st[2], 2), w2 = Jet::variable(st[3], 3), u = Jet::variable(st[4], 4);
    const Jet s1 = sin(t1), c1 = cos(t1), s2 = sin(t2), c2 = cos(t2);
    const Jet s12 = sin(t1 + t2), c12 = cos(t1 + t2), w = w1 + w2;
    const Jet M11 = 2.0 * c2 + 3.0, M12 = c2 + 1.0;  // M22 = 1
    const Jet F1 = u + s2 * (2.0 * (w1 * w2) + w2 * w2) - g * (2.0 * s1 + s12);
    const Jet F2 = -(s2 * (w1 * w1)) - g * s12;
    const Jet dx = s1 + s12 + (-2.0), dy = -(c1 + c12);
    const Jet J11 = c1 + c12, J12 = c12, J21 = s1 + s12, J22 = s12;
    const Jet A1 = 2.0 * (dx * J11 + dy * J21), A2 = 2.0 * (dx * J12 + dy * J22);
    const Jet vx = J11 * w1 + J12 * w2, vy = J21 * w1 + J22 * w2;
    const Jet ax = -(s1 * (w1 * w1) + s12 * (w * w)), ay = c1 * (w1 * w1) + c12 * (w * w);
    const Jet gamma = 2.0 * (vx * vx + vy * vy + dx * ax + dy * ay);
    // M⁻¹ = [1, −M12; −M12, M11] / det,  det = M11 − M12².
    const Jet det = M11 - M12 * M12;
    const Jet a1 = (F1 - M12 * F2) / det, a2 = (M11 * F2 - M12 * F1) / det;  // M⁻¹ F
    const Jet b1 = (A1 - M12 * A2) / det, b2 = (M11 * A2 - M12 * A1) / det;  // M⁻¹ Aᵀ
    const Jet lambda = -((gamma + A1 * a1 + A2 * a2) / (A1 * b1 + A2 * b2));
    const Jet qdd1 = a1 + b1 * lambda, qdd2 = a2 + b2 * lambda;

    const Eigen::VectorXd q = Eigen::Vector2d(st[0], st[1]), dq = Eigen::Vector2d(st[2], st[3]);
    const Eigen::VectorXd uu = Eigen::VectorXd::Constant(1, st[4]);
    REQUIRE(computeSecondOrderTensors(model, data, ws, q, dq, uu).ok());
    INFO("state #" << k << ": q = (" << st[0] << ", " << st[1] << "), dq = (" << st[2] << ", " << st[3]
                   << "), u = " << st[4] << ", h = " << dx.v * dx.v + dy.v * dy.v - 1.0);
    // The values and first derivatives the same route gives (a check of the hand-written model).
    CHECK(data.qdd(0) == Approx(qdd1.v).epsilon(1e-12).margin(1e-12));
    CHECK(data.qdd(1) == Approx(qdd2.v).epsilon(1e-12).margin(1e-12));
    CHECK(data.lambda(0) == Approx(lambda.v).epsilon(1e-12).margin(1e-12));
    Eigen::MatrixXd jac(2, 5);
    jac.row(0) = qdd1.g.transpose();
    jac.row(1) = qdd2.g.transpose();
    Eigen::MatrixXd core(2, 5);
    core << data.dqdd_dq, data.dqdd_ddq, data.dqdd_du;
    TRELLIS_CHECK_MATRIX(jac, core, 1e-12, Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(lambda.g.transpose()), data.dlambda_dx, 1e-12, Scale::kMatrix);
    // The second derivatives.
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(qdd1.H), ws.qddHessian[0], 1e-12, Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(qdd2.H), ws.qddHessian[1], 1e-12, Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(lambda.H), ws.lambdaHessian[0], 1e-12, Scale::kMatrix);
  }
}

TEST_CASE("Second-order functions reject bad input", "[second_order]") {
  const Model model = cartPole();
  Data data(model);
  SecondOrderWorkspace ws(model, false);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(2), u = Eigen::VectorXd::Zero(1);
  CHECK_THROWS_WITH(computeSecondOrderTensors(model, data, ws, q, q, u), Catch::Contains("without tensors"));
  Eigen::MatrixXd H(5, 5), bad(4, 5);
  CHECK_THROWS_WITH(computeSecondOrderContraction(model, data, ws, q, q, u, Eigen::VectorXd::Zero(3), Eigen::VectorXd(), H),
                    Catch::Contains("w: expected 2 entries, got 3"));
  CHECK_THROWS_WITH(computeSecondOrderContraction(model, data, ws, q, q, u, q, Eigen::VectorXd(), bad),
                    Catch::Contains("H: expected 5×5, got 4×5"));
  CHECK_THROWS_WITH(computeSecondOrderContraction(model, data, ws, q, Eigen::VectorXd::Zero(3), u, q, Eigen::VectorXd(), H),
                    Catch::Contains("dq"));
  const Model other = planarChain(3).model;
  CHECK_THROWS_WITH(computeSecondOrderContraction(other, data, ws, q, q, u, q, Eigen::VectorXd(), H),
                    Catch::Contains("workspace was built for a model"));
}

TEST_CASE("Second derivatives with coordinate couplings (URDF <mimic>)", "[second_order][fd][mimic]") {
  const Model model = mimicChain();  // test_models.hpp: revolute, prismatic and continuous couplings
  REQUIRE(model.nc() == 2);
  checkAtRandomStates(model, 4100);
}
