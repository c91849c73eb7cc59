// tests/core/test_hard_cases.cpp — where exact linearizations usually break: many bodies, extreme
// mass ratios, singular and redundant constraints, massless coordinates. The rule throughout:
// either the result is accurate (against central differences) or the status says it is not, with
// a message — never NaN or garbage behind an ok status.
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/linearization_checks.hpp"
#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>

#include <numbers>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <string>

using namespace trellis;
using namespace trellis::test;

namespace {

bool resultsFinite(const Data& d) {
  return allFinite(d.qdd) && allFinite(d.lambda) && allFinite(d.A) && allFinite(d.B);
}

/// ‖A q̈ + Ȧ q̇‖∞ relative to max(1, ‖A‖max ‖q̈‖∞ + ‖Ȧ q̇‖∞).
double constraintResidual(const Model& model, const State& s, const Data& dyn) {
  Data c(model);
  computeConstraints(model, c, s.q, s.dq);
  if (model.nc() == 0) return 0.0;
  const Eigen::VectorXd r = c.constraintJacobian * dyn.qdd + c.constraintDrift;
  const double scale =
      std::max(1.0, c.constraintJacobian.cwiseAbs().maxCoeff() * dyn.qdd.cwiseAbs().maxCoeff() +
                        c.constraintDrift.cwiseAbs().maxCoeff());
  return r.cwiseAbs().maxCoeff() / scale;
}

}  // namespace

TEST_CASE("Hard case: a 64-link planar chain", "[hard][chain]") {
  const TestSystem sys = planarChain(64);
  const Model& model = sys.model;
  REQUIRE(model.nq() == 64);
  std::mt19937 rng(3101);
  // Angles in ±0.5 rad per joint: a crumpled but not folded chain.
  const State s = randomState(model, rng, 0.5, 1.0, 0.01);

  SECTION("mass matrix is symmetric positive definite") {
    Data data(model);
    computeMassMatrix(model, data, s.q);
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(data.M.transpose()), data.M, 1e-14, Scale::kMatrix);
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(data.M);
    INFO("eigenvalues of M in [" << eig.eigenvalues().minCoeff() << ", "
                                 << eig.eigenvalues().maxCoeff() << "]");
    CHECK(eig.eigenvalues().minCoeff() > 0.0);
  }
  SECTION("dynamics and linearization are finite and agree with central differences") {
    Data data(model);
    const DynamicsStatus status = computeLinearization(model, data, s.q, s.dq, s.u);
    INFO(status.message);
    REQUIRE(status.ok());
    CHECK(resultsFinite(data));
    // M of a 64-link chain has cond(M) ≈ 1.6e7 (eigenvalues 7e-5 … 1.2e3 at this state; it grows
    // like n⁴), so every evaluation of q̈ carries a rounding error δ ≈ κ·eps·|q̈| ≈ 1e-9·|q̈|
    // rather than eps·|q̈|. The second-order difference would then err by ~δ^(2/3) ≈ 1e-4
    // column-relative (measured: 6e-4 at the standard step, shrinking as the step grows). The
    // fourth-order stencil with 5× its standard step (h ≈ 3.7e-3) errs by ~δ^(4/5) ≈ 1e-6
    // (measured: 1.2e-6 for ∂q̈/∂q, 2e-8 for ∂q̈/∂q̇, 1e-11 for ∂q̈/∂u). Tolerance 1e-4
    // column-relative: a wrong term would show at 1e-2 … 1.
    checkLinearizationAgainstFd(model, s, 1e-4, 5.0, Stencil::kFourthOrder);
  }
}

TEST_CASE("Hard case: mass ratio 1e6 between bodies", "[hard][mass_ratio]") {
  // Three bodies on rz, ry, rx joints; 1e3 and 1e-3 kg (ratio 1e6), inertias scaled alike.
  // The Jacobian then has entries spanning ~1e6; comparison relative to the column scale.
  const auto build = [](double heavy, double light, bool heavyFirst) {
    std::mt19937 rng(3201);
    const double m1 = heavyFirst ? heavy : light, m2 = heavyFirst ? light : heavy;
    ModelBuilder b;
    b.addFrame("j1", "world", Transform::rz("a"));
    b.addFrame("l1", "j1", Transform::tx(1.0), Mass{m1, m1 * randomInertia(rng)});
    b.addFrame("j2", "l1", Transform::ry("b"));
    b.addFrame("l2", "j2", Transform::tz(0.5), Mass{m2, m2 * randomInertia(rng)});
    b.addFrame("j3", "l2", Transform::rx("c"));
    b.addFrame("l3", "j3", Transform::ty(0.3), Mass{m2, m2 * randomInertia(rng)});
    b.addGravity(Eigen::Vector3d(0.2, -9.81, 0.5));
    b.addConfigForce("a", "ua");
    b.addConfigForce("c", "uc");
    b.addLinearSpring("l3", "world", 0.01, 0.2);
    return std::move(b).finalize();
  };
  SECTION("heavy proximal body, light distal bodies") {
    const Model model = build(1e3, 1e-3, true);
    std::mt19937 rng(3202);
    for (int k = 0; k < 2; ++k) checkLinearizationAgainstFd(model, randomState(model, rng));
  }
  SECTION("light proximal body, heavy distal bodies") {
    const Model model = build(1e3, 1e-3, false);
    std::mt19937 rng(3203);
    for (int k = 0; k < 2; ++k) checkLinearizationAgainstFd(model, randomState(model, rng));
  }
  SECTION("with a constraint") {
    ModelBuilder b;
    b.addFrame("j1", "world", Transform::rz("a"));
    b.addFrame("l1", "j1", Transform::ty(-1.0), Mass{1e3, Eigen::Matrix3d::Identity() * 1e2});
    b.addFrame("j2", "l1", Transform::rz("b"));
    b.addFrame("l2", "j2", Transform::ty(-1.0), Mass{1e-3, Eigen::Matrix3d::Identity() * 1e-4});
    b.addFrame("j3", "l2", Transform::rz("c"));
    b.addFrame("l3", "j3", Transform::ty(-1.0), Mass{1e-3, Eigen::Matrix3d::Identity() * 1e-4});
    b.addFrame("C", "world", Transform::tx(2.0));
    b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
    b.addConfigForce("a", "ua");
    b.addDistanceConstraint("l3", "C", 1.5);
    const Model model = std::move(b).finalize();
    std::mt19937 rng(3204);
    for (int k = 0; k < 2; ++k) checkLinearizationAgainstFd(model, randomState(model, rng));
  }
}

namespace {

/// The paper's double pendulum with the anchor C moved to (0, 2), straight above the pivot, and
/// the distance set so that h = 0 at θ = (0, δ). At θ = (0, 0) the arm hangs fully extended away
/// from C, ‖p_B − p_C‖ = 4 is maximal, and A = 2 (p_B − p_C)ᵀ ∂p_B/∂q = 0 exactly
/// (p_B − p_C = (0, −4), ∂p_B/∂θ1 = (2, 0), ∂p_B/∂θ2 = (1, 0)). Near it, ‖A‖ = O(δ).
Model nearlyExtended(double delta) {
  // p_B(0, δ) = (sin δ, −1 − cos δ), p_C = (0, 2): d² = sin² δ + (3 + cos δ)².
  const double d = std::sqrt(std::pow(std::sin(delta), 2) + std::pow(3.0 + std::cos(delta), 2));
  ModelBuilder b;
  b.addFrame("Link1", "world", Transform::rz("theta1"));
  b.addFrame("A", "Link1", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addFrame("Link2", "A", Transform::rz("theta2"));
  b.addFrame("B", "Link2", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addFrame("C", "world", Transform::ty(2.0));
  b.addGravity(Eigen::Vector3d(0.0, -9.8, 0.0));
  b.addConfigForce("theta1", "u");
  b.addDistanceConstraint("B", "C", d);
  return std::move(b).finalize();
}

/// Either ok and accurate (finite, A q̈ + Ȧ q̇ = 0, and — when `fd` — the linearization matches
/// central differences), or not ok with a message.
///
/// Differences near the singularity: A = O(δ), so q̈ and λ vary on the length scale δ in q (and
/// grow like 1/δ, λ like 1/δ²), and each evaluation carries a rounding error ~eps/δ² relative.
/// The fourth-order stencil with step h = 10·δ·eps^(1/5) ≈ 7e-3·δ keeps the truncation error
/// (h/δ)⁴/30 ≈ 1e-10 and the rounding error ~eps/(δ·h) ≈ 3e-14/δ² ≤ 3e-8 for δ ≥ 1e-3, so
/// kFdTolerance (1e-6, column-relative) still holds with margin (measured: ≤ 1e-7 at δ = 1e-3).
/// Below δ ≈ 1e-4 rounding dominates any difference quotient, which therefore is no reference.
void checkAccurateOrReported(const Model& model, const State& s, double delta, bool fd) {
  Data data(model);
  const DynamicsStatus status = computeLinearization(model, data, s.q, s.dq, s.u);
  INFO("delta = " << delta << ", status code " << static_cast<int>(status.code) << ": "
                  << status.message << ", conditioning " << status.constraintConditioning);
  if (!status.ok()) {
    CHECK(!status.message.empty());
    return;
  }
  REQUIRE(resultsFinite(data));
  // KKT backward error ~eps·cond(A M⁻¹ Aᵀ), relative to the scale of the terms: 1e-10 leaves
  // margin (the 1×1 Schur complement is exactly conditioned; M is well conditioned).
  CHECK(constraintResidual(model, s, data) <= 1e-10);
  if (fd) {
    checkLinearizationAgainstFd(model, s, kFdTolerance, std::min(1.0, 10.0 * delta),
                                Stencil::kFourthOrder);
  }
}

}  // namespace

TEST_CASE("Hard case: distance constraint near full extension", "[hard][singular]") {
  for (double delta : {0.3, 0.05, 1e-2, 1e-3, 1e-6}) {
    const bool fd = delta >= 1e-3;  // see checkAccurateOrReported
    const std::string name = std::string("delta = ").append(std::to_string(delta));
    SECTION(name + ", consistent state") {
      const Model model = nearlyExtended(delta);
      Eigen::VectorXd q = Eigen::Vector2d(0.0, delta), dq = Eigen::Vector2d(0.8, -0.3);
      REQUIRE(projectToConstraints(model, q, dq));
      checkAccurateOrReported(model, State{q, dq, Eigen::VectorXd::Constant(1, 0.5)}, delta, fd);
    }
    SECTION(name + ", inconsistent velocity") {
      const Model model = nearlyExtended(delta);
      const State s{Eigen::Vector2d(0.0, delta), Eigen::Vector2d(0.8, -0.3),
                    Eigen::VectorXd::Constant(1, 0.5)};
      checkAccurateOrReported(model, s, delta, fd);
    }
  }
  SECTION("exactly singular, A qdd + Adot dq = 0 unsatisfiable: must not report ok") {
    // At θ = (0, 0), A = 0 exactly while Ȧ q̇ = q̇ᵀ (∂²h/∂q²) q̇ < 0 (a strict maximum of h), so no q̈
    // satisfies the constraint equation: the only honest answer is a failure status.
    const Model model = nearlyExtended(0.0);
    const State s{Eigen::Vector2d::Zero(), Eigen::Vector2d(0.8, -0.3),
                  Eigen::VectorXd::Constant(1, 0.5)};
    Data data(model);
    computeConstraints(model, data, s.q, s.dq);
    CHECK(data.constraintJacobian.cwiseAbs().maxCoeff() == 0.0);
    CHECK(data.constraintDrift[0] < -1e-3);
    const DynamicsStatus dyn = computeDynamics(model, data, s.q, s.dq, s.u);
    INFO("status code " << static_cast<int>(dyn.code) << ": " << dyn.message);
    CHECK_FALSE(dyn.ok());
    CHECK(!dyn.message.empty());
    const DynamicsStatus lin = computeLinearization(model, data, s.q, s.dq, s.u);
    CHECK_FALSE(lin.ok());
    CHECK(!lin.message.empty());
  }
  SECTION("exactly singular at rest: ok only with finite results that satisfy the constraint") {
    const Model model = nearlyExtended(0.0);
    const State s{Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero(),
                  Eigen::VectorXd::Constant(1, 0.5)};
    Data data(model);
    const DynamicsStatus status = computeLinearization(model, data, s.q, s.dq, s.u);
    INFO("status code " << static_cast<int>(status.code) << ": " << status.message);
    if (status.ok()) {
      CHECK(resultsFinite(data));
      CHECK(constraintResidual(model, s, data) <= 1e-12);
    } else {
      CHECK(!status.message.empty());
    }
  }
}

TEST_CASE("Hard case: the same constraint twice (rank-deficient A)", "[hard][redundant]") {
  const Model once = paperPendulum(1).model, twice = paperPendulum(2).model;
  REQUIRE(twice.nc() == 2);
  std::mt19937 rng(3401);
  for (int k = 0; k < 3; ++k) {
    const State s = k == 0 ? State{Eigen::Vector2d(std::numbers::pi / 6, std::numbers::pi / 3),
                                   Eigen::Vector2d(0.5, -1.0), Eigen::VectorXd::Constant(1, 2.0)}
                           : randomState(once, rng);
    INFO("state #" << k);
    Data d1(once), d2(twice);
    const DynamicsStatus s1 = computeDynamics(once, d1, s.q, s.dq, s.u);
    const DynamicsStatus s2 = computeDynamics(twice, d2, s.q, s.dq, s.u);
    INFO(s2.message);
    REQUIRE(s1.code == DynamicsStatus::Code::kOk);
    // Rank deficient: q̈ is determined, λ is not — reported, not ok (issue 15).
    CHECK(s2.code == DynamicsStatus::Code::kRedundantConstraints);
    CHECK_FALSE(s2.ok());
    CHECK(s2.constraintRank == 1);
    CHECK(!s2.message.empty());
    // Same q̈: the duplicated row changes nothing but the rank. The pseudo-inverse solve is
    // backward stable on the range of A M⁻¹ Aᵀ; 1e-10 relative to max(1, ‖q̈‖∞).
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(d1.qdd), Eigen::MatrixXd(d2.qdd), 1e-10, Scale::kMatrix);
    // Minimum-norm λ (data.hpp) splits the force equally between the two copies.
    Eigen::MatrixXd half = Eigen::MatrixXd::Constant(2, 1, 0.5 * d1.lambda[0]);
    TRELLIS_CHECK_MATRIX(half, Eigen::MatrixXd(d2.lambda), 1e-10, Scale::kMatrix);

    // q̈(x) is the same function of the state for both models (the rank is 1 everywhere), so the
    // linearizations agree too. Same tolerance argument, one differentiation more: 1e-9.
    Data l1(once), l2(twice);
    REQUIRE(computeLinearization(once, l1, s.q, s.dq, s.u).ok());
    const DynamicsStatus ls2 = computeLinearization(twice, l2, s.q, s.dq, s.u);
    INFO(ls2.message);
    REQUIRE(ls2.code == DynamicsStatus::Code::kRedundantConstraints);
    TRELLIS_CHECK_MATRIX(l1.A, l2.A, 1e-9, Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(l1.B, l2.B, 1e-9, Scale::kMatrix);
  }
}

TEST_CASE("Hard case: a coordinate that moves no mass", "[hard][massless]") {
  const auto expectSingular = [](const Model& model, const std::string& config) {
    std::mt19937 rng(3501);
    const State s = randomState(model, rng);
    Data data(model);
    const DynamicsStatus dyn = computeDynamics(model, data, s.q, s.dq, s.u);
    INFO("status code " << static_cast<int>(dyn.code) << ": " << dyn.message);
    CHECK(dyn.code == DynamicsStatus::Code::kSingularMassMatrix);
    CHECK_FALSE(dyn.ok());
    // The message names the configuration variable that carries no mass.
    CHECK_THAT(dyn.message, Catch::Matchers::Contains(config));
    CHECK(data.status.code == dyn.code);
    const DynamicsStatus lin = computeLinearization(model, data, s.q, s.dq, s.u);
    CHECK(lin.code == DynamicsStatus::Code::kSingularMassMatrix);
    CHECK_FALSE(lin.ok());
  };
  SECTION("massless prismatic leaf") {
    ModelBuilder b;
    b.addFrame("base", "world", Transform::rz("base_angle"),
               Mass{1.0, Eigen::Matrix3d::Identity() * 0.1});
    b.addFrame("slide", "base", Transform::tx("slide_x"));
    b.addFrame("tip", "slide", Transform::ty(0.5));
    b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
    expectSingular(std::move(b).finalize(), "slide_x");
  }
  SECTION("point mass on its own rotation axis") {
    ModelBuilder b;
    b.addFrame("j", "world", Transform::rz("swing"));
    b.addFrame("bob", "j", Transform::ty(-1.0), Mass{1.0, Eigen::Matrix3d::Zero()});
    b.addFrame("spin", "bob", Transform::rz("spin_angle"), Mass{0.5, Eigen::Matrix3d::Zero()});
    b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
    expectSingular(std::move(b).finalize(), "spin_angle");
  }
  SECTION("massless chain in the middle of a system, with a constraint") {
    ModelBuilder b;
    b.addFrame("j1", "world", Transform::rz("first"), Mass{1.0, Eigen::Matrix3d::Identity() * 0.1});
    b.addFrame("l1", "j1", Transform::ty(-1.0));
    b.addFrame("j2", "l1", Transform::tz("lift"));  // moves along z: nothing below has mass
    b.addFrame("l2", "j2", Transform::ty(-1.0));
    b.addFrame("C", "world", Transform::tx(1.0));
    b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
    b.addDistanceConstraint("l1", "C", 1.2);
    expectSingular(std::move(b).finalize(), "lift");
  }
}
