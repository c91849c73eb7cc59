// tests/core/test_closed_form.cpp — leg 3: systems whose q̈ and whose derivatives ∂q̈/∂q, ∂q̈/∂q̇,
// ∂q̈/∂u are derived by hand (formulas in the comments), against computeDynamics and
// computeLinearization.
//
// Tolerance: 1e-12 relative to max(1, largest entry of the matrix compared). Both sides are exact
// in exact arithmetic; they differ only by rounding. Each side takes a few hundred floating-point
// operations, each with relative error ≤ eps/2 ≈ 1.1e-16, amplified by the conditioning of M
// (≤ ~50 for these parameters), so the expected difference is ~1e-14 … 1e-13 — 1e-12 leaves a
// margin of 10 and still fails any wrong term (those are O(1e-3) or larger).
//
// Conventions: gravity (0, −g, 0); rz(θ) = [[c, −s, 0], [s, c, 0], [0, 0, 1]]; V = −Σ m g·p.
#include <catch2/catch.hpp>

#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"

#include <trellis/core.hpp>

#include <cmath>

using namespace trellis;
using namespace trellis::test;

namespace {

constexpr double kClosedFormTolerance = 1e-12;
constexpr double kG = 9.81;

/// The expected q̈ and the lower blocks of A and B.
struct Expected {
  Eigen::VectorXd qdd;
  Eigen::MatrixXd dq, ddq, du;
};

void compare(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
             const Eigen::VectorXd& u, const Expected& e) {
  const int n = model.nq(), m = model.nu();
  INFO("q = " << q.transpose() << ", dq = " << dq.transpose() << ", u = " << u.transpose());
  Data data(model);
  const DynamicsStatus dyn = computeDynamics(model, data, q, dq, u);
  INFO(dyn.message);
  REQUIRE(dyn.ok());
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(e.qdd), Eigen::MatrixXd(data.qdd), kClosedFormTolerance,
                       Scale::kMatrix);
  Data lin(model);
  REQUIRE(computeLinearization(model, lin, q, dq, u).ok());
  TRELLIS_CHECK_MATRIX(e.dq, lin.dqdd_dq, kClosedFormTolerance, Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(e.ddq, lin.dqdd_ddq, kClosedFormTolerance, Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(e.du, lin.dqdd_du, kClosedFormTolerance, Scale::kMatrix);
  Eigen::MatrixXd A(2 * n, 2 * n), B(2 * n, m);
  A << Eigen::MatrixXd::Zero(n, n), Eigen::MatrixXd::Identity(n, n), e.dq, e.ddq;
  B << Eigen::MatrixXd::Zero(n, m), e.du;
  TRELLIS_CHECK_MATRIX(A, lin.A, kClosedFormTolerance, Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(B, lin.B, kClosedFormTolerance, Scale::kMatrix);
}

// ---- Simple pendulum ---------------------------------------------------------------------------
// world → pivot rz(θ) → bob ty(−l), mass m, inertia tensor I about the bob (body axes).
// p = (l sin θ, −l cos θ), ω_b = (0, 0, θ̇) ⇒ T = ½ (m l² + I_zz) θ̇² (the other entries of I do not
// enter: ω_b has only a z component), V = −m g l cos θ. With a torque u and damping c on θ:
//   (m l² + I_zz) θ̈ = u − c θ̇ − m g l sin θ
//   θ̈ = (u − c θ̇ − m g l sin θ) / J,  J = m l² + I_zz
//   ∂θ̈/∂θ = −m g l cos θ / J,  ∂θ̈/∂θ̇ = −c / J,  ∂θ̈/∂u = 1 / J.
struct Pendulum {
  double m, l, c;
  Eigen::Matrix3d I;
  Model build() const {
    ModelBuilder b;
    b.addFrame("pivot", "world", Transform::rz("theta"));
    b.addFrame("bob", "pivot", Transform::ty(-l), Mass{m, I});
    b.addGravity(Eigen::Vector3d(0.0, -kG, 0.0));
    b.addConfigForce("theta", "u");
    if (c != 0.0) b.addDamping(c);
    return std::move(b).finalize();
  }
  Expected expected(double th, double thd, double u) const {
    const double J = m * l * l + I(2, 2);
    Expected e;
    e.qdd = Eigen::VectorXd::Constant(1, (u - c * thd - m * kG * l * std::sin(th)) / J);
    e.dq = Eigen::MatrixXd::Constant(1, 1, -m * kG * l * std::cos(th) / J);
    e.ddq = Eigen::MatrixXd::Constant(1, 1, -c / J);
    e.du = Eigen::MatrixXd::Constant(1, 1, 1.0 / J);
    return e;
  }
};

// ---- Cart-pole ---------------------------------------------------------------------------------
// world → cart tx(x), mass M → pole rz(θ) → bob ty(l), mass m (θ = 0 upright).
// p_bob = (x − l s, l c), s = sin θ, c = cos θ; force F on x, viscous friction b on x.
//   T = ½ (M + m) ẋ² − m l c ẋ θ̇ + ½ m l² θ̇²,   V = m g l c
//   x: (M + m) ẍ − m l c θ̈ + m l s θ̇² = F − b ẋ
//   θ: −m l c ẍ + m l² θ̈ − m g l s = 0            ⇒ θ̈ = (g s + c ẍ) / l
// Substituting θ̈: (M + m s²) ẍ = F − b ẋ + m s (g c − l θ̇²), so with
//   D = M + m s²,  N = F − b ẋ + m s (g c − l θ̇²):   ẍ = N / D,  θ̈ = (g s + c ẍ) / l.
// Derivatives (x does not appear; ẋ only through −b ẋ):
//   ∂N/∂θ = m (g cos 2θ − l c θ̇²),  ∂D/∂θ = 2 m s c
//   ∂ẍ/∂θ = (∂N/∂θ · D − N · ∂D/∂θ) / D²,  ∂ẍ/∂ẋ = −b / D,  ∂ẍ/∂θ̇ = −2 m l s θ̇ / D,  ∂ẍ/∂F = 1 / D
//   ∂θ̈/∂θ = (g c − s ẍ + c ∂ẍ/∂θ) / l,  ∂θ̈/∂(ẋ, θ̇, F) = (c / l) ∂ẍ/∂(ẋ, θ̇, F),  ∂·/∂x = 0.
struct CartPole {
  double M, m, l, b;
  Model build() const {
    ModelBuilder mb;
    mb.addFrame("cart", "world", Transform::tx("x"), Mass{M, Eigen::Matrix3d::Zero()});
    mb.addFrame("pole", "cart", Transform::rz("theta"));
    mb.addFrame("bob", "pole", Transform::ty(l), Mass{m, Eigen::Matrix3d::Zero()});
    mb.addGravity(Eigen::Vector3d(0.0, -kG, 0.0));
    mb.addConfigForce("x", "F");
    if (b != 0.0) mb.addDamping(0.0, {{"x", b}});
    return std::move(mb).finalize();
  }
  Expected expected(const Eigen::Vector2d& q, const Eigen::Vector2d& dq, double F) const {
    const double th = q[1], xd = dq[0], thd = dq[1];
    const double s = std::sin(th), c = std::cos(th);
    const double D = M + m * s * s;
    const double N = F - b * xd + m * s * (kG * c - l * thd * thd);
    const double xdd = N / D, thdd = (kG * s + c * xdd) / l;
    const double dN_dth = m * (kG * std::cos(2.0 * th) - l * c * thd * thd);
    const double dD_dth = 2.0 * m * s * c;
    const double dxdd_dth = (dN_dth * D - N * dD_dth) / (D * D);
    const double dxdd_dxd = -b / D, dxdd_dthd = -2.0 * m * l * s * thd / D, dxdd_dF = 1.0 / D;
    Expected e;
    e.qdd = Eigen::Vector2d(xdd, thdd);
    e.dq.resize(2, 2);
    e.dq << 0.0, dxdd_dth,  //
        0.0, (kG * c - s * xdd + c * dxdd_dth) / l;
    e.ddq.resize(2, 2);
    e.ddq << dxdd_dxd, dxdd_dthd,  //
        c / l * dxdd_dxd, c / l * dxdd_dthd;
    e.du.resize(2, 1);
    e.du << dxdd_dF, c / l * dxdd_dF;
    return e;
  }
};

// ---- Planar two-link arm -----------------------------------------------------------------------
// world → J1 rz(θ1) → C1 tx(r1), mass m1, inertia I1 (I1_zz enters); J1 → E1 tx(l1) → J2 rz(θ2) →
// C2 tx(r2), mass m2, inertia I2. p1 = r1 (c1, s1), p2 = l1 (c1, s1) + r2 (c12, s12).
// Torques u1, u2 on θ1, θ2. With h = m2 l1 r2 sin θ2:
//   M = [[I1 + I2 + m1 r1² + m2 (l1² + r2² + 2 l1 r2 c2), I2 + m2 (r2² + l1 r2 c2)],
//        [I2 + m2 (r2² + l1 r2 c2),                       I2 + m2 r2²]]
//   C = [−h (2 θ̇1 θ̇2 + θ̇2²), h θ̇1²]               (Coriolis and centripetal)
//   G = [g (m1 r1 c1 + m2 (l1 c1 + r2 c12)), g m2 r2 c12]   (∂V/∂q)
//   M q̈ = u − C − G
// Differentiating M(q) q̈ = u − C(q, q̇) − G(q) with q̈ as the unknown:
//   ∂q̈/∂q_k = M⁻¹ (−(∂M/∂q_k) q̈ − ∂C/∂q_k − ∂G/∂q_k),  ∂q̈/∂q̇_k = −M⁻¹ ∂C/∂q̇_k,  ∂q̈/∂u = M⁻¹
// with ∂M/∂θ1 = 0, ∂M/∂θ2 = −m2 l1 r2 s2 [[2, 1], [1, 0]],
//   ∂C/∂θ1 = 0, ∂C/∂θ2 = m2 l1 r2 c2 [−(2 θ̇1 θ̇2 + θ̇2²), θ̇1²],
//   ∂C/∂θ̇1 = [−2 h θ̇2, 2 h θ̇1], ∂C/∂θ̇2 = [−2 h (θ̇1 + θ̇2), 0],
//   ∂G/∂θ1 = [−g (m1 r1 s1 + m2 (l1 s1 + r2 s12)), −g m2 r2 s12], ∂G/∂θ2 = [−g m2 r2 s12, −g m2 r2
//   s12].
// M⁻¹ is the explicit 2×2 inverse.
struct TwoLinkArm {
  double m1, m2, l1, r1, r2;
  Eigen::Matrix3d I1, I2;
  Model build() const {
    ModelBuilder b;
    b.addFrame("J1", "world", Transform::rz("theta1"));
    b.addFrame("C1", "J1", Transform::tx(r1), Mass{m1, I1});
    b.addFrame("E1", "J1", Transform::tx(l1));
    b.addFrame("J2", "E1", Transform::rz("theta2"));
    b.addFrame("C2", "J2", Transform::tx(r2), Mass{m2, I2});
    b.addGravity(Eigen::Vector3d(0.0, -kG, 0.0));
    b.addConfigForce("theta1", "u1");
    b.addConfigForce("theta2", "u2");
    return std::move(b).finalize();
  }
  Expected expected(const Eigen::Vector2d& q, const Eigen::Vector2d& dq,
                    const Eigen::Vector2d& u) const {
    const double c1 = std::cos(q[0]), s1 = std::sin(q[0]);
    const double c2 = std::cos(q[1]), s2 = std::sin(q[1]);
    const double c12 = std::cos(q[0] + q[1]), s12 = std::sin(q[0] + q[1]);
    const double d1 = dq[0], d2 = dq[1];
    const double J1 = I1(2, 2), J2 = I2(2, 2);
    Eigen::Matrix2d M;
    M(0, 0) = J1 + J2 + m1 * r1 * r1 + m2 * (l1 * l1 + r2 * r2 + 2.0 * l1 * r2 * c2);
    M(0, 1) = M(1, 0) = J2 + m2 * (r2 * r2 + l1 * r2 * c2);
    M(1, 1) = J2 + m2 * r2 * r2;
    const double det = M(0, 0) * M(1, 1) - M(0, 1) * M(1, 0);
    Eigen::Matrix2d Minv;
    Minv << M(1, 1) / det, -M(0, 1) / det,  //
        -M(1, 0) / det, M(0, 0) / det;
    const double h = m2 * l1 * r2 * s2, hp = m2 * l1 * r2 * c2;
    const Eigen::Vector2d C(-h * (2.0 * d1 * d2 + d2 * d2), h * d1 * d1);
    const Eigen::Vector2d G(kG * (m1 * r1 * c1 + m2 * (l1 * c1 + r2 * c12)), kG * m2 * r2 * c12);
    const Eigen::Vector2d qdd = Minv * (u - C - G);

    Eigen::Matrix2d dM2;
    dM2 << 2.0, 1.0,  //
        1.0, 0.0;
    dM2 *= -m2 * l1 * r2 * s2;
    const Eigen::Vector2d dC2(-hp * (2.0 * d1 * d2 + d2 * d2), hp * d1 * d1);
    const Eigen::Vector2d dG1(-kG * (m1 * r1 * s1 + m2 * (l1 * s1 + r2 * s12)),
                              -kG * m2 * r2 * s12);
    const Eigen::Vector2d dG2(-kG * m2 * r2 * s12, -kG * m2 * r2 * s12);
    const Eigen::Vector2d dCd1(-2.0 * h * d2, 2.0 * h * d1);
    const Eigen::Vector2d dCd2(-2.0 * h * (d1 + d2), 0.0);

    Expected e;
    e.qdd = qdd;
    e.dq.resize(2, 2);
    e.dq.col(0) = Minv * (-dG1);
    e.dq.col(1) = Minv * (-dM2 * qdd - dC2 - dG2);
    e.ddq.resize(2, 2);
    e.ddq.col(0) = -Minv * dCd1;
    e.ddq.col(1) = -Minv * dCd2;
    e.du = Minv;
    return e;
  }
};

}  // namespace

TEST_CASE("Closed form: simple pendulum", "[closed_form]") {
  std::mt19937 rng(2101);
  SECTION("point mass, undamped") {
    const Pendulum p{1.3, 0.9, 0.0, Eigen::Matrix3d::Zero()};
    const Model model = p.build();
    for (int k = 0; k < 4; ++k) {
      const double th = uniform(rng, -3.0, 3.0), thd = uniform(rng, -2.0, 2.0),
                   u = uniform(rng, -1.0, 1.0);
      compare(model, Eigen::VectorXd::Constant(1, th), Eigen::VectorXd::Constant(1, thd),
              Eigen::VectorXd::Constant(1, u), p.expected(th, thd, u));
    }
  }
  SECTION("rod with full inertia tensor, damped") {
    // A uniform rod of length L = 2 l about its centre: I_zz = m L² / 12; the other entries are
    // arbitrary (but positive definite) and must not matter in planar motion.
    const double m = 0.8, l = 0.6, L = 2.0 * l;
    Eigen::Matrix3d I;
    I << 0.05, 0.01, 0.004,  //
        0.01, 0.04, -0.003,  //
        0.004, -0.003, m * L * L / 12.0;
    const Pendulum p{m, l, 0.15, I};
    const Model model = p.build();
    for (int k = 0; k < 4; ++k) {
      const double th = uniform(rng, -3.0, 3.0), thd = uniform(rng, -2.0, 2.0),
                   u = uniform(rng, -1.0, 1.0);
      compare(model, Eigen::VectorXd::Constant(1, th), Eigen::VectorXd::Constant(1, thd),
              Eigen::VectorXd::Constant(1, u), p.expected(th, thd, u));
    }
  }
}

TEST_CASE("Closed form: cart-pole", "[closed_form]") {
  std::mt19937 rng(2201);
  SECTION("frictionless") {
    const CartPole cp{1.3, 0.4, 0.7, 0.0};
    const Model model = cp.build();
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d q = uniformVector(rng, 2, -2.0, 2.0),
                            dq = uniformVector(rng, 2, -2.0, 2.0);
      const double F = uniform(rng, -1.0, 1.0);
      compare(model, q, dq, Eigen::VectorXd::Constant(1, F), cp.expected(q, dq, F));
    }
  }
  SECTION("with viscous friction on the cart") {
    const CartPole cp{1.3, 0.4, 0.7, 0.25};
    const Model model = cp.build();
    // The state the formulas were cross-checked at (symbolic differentiation) first.
    compare(model, Eigen::Vector2d(0.3, 0.9), Eigen::Vector2d(-0.6, 1.7),
            Eigen::VectorXd::Constant(1, 0.8), cp.expected({0.3, 0.9}, {-0.6, 1.7}, 0.8));
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d q = uniformVector(rng, 2, -2.0, 2.0),
                            dq = uniformVector(rng, 2, -2.0, 2.0);
      const double F = uniform(rng, -1.0, 1.0);
      compare(model, q, dq, Eigen::VectorXd::Constant(1, F), cp.expected(q, dq, F));
    }
  }
  SECTION("upright equilibrium: the textbook linearization") {
    // At x = θ = ẋ = θ̇ = F = 0 (b = 0): ∂ẍ/∂θ = m g / M, ∂θ̈/∂θ = (M + m) g / (M l),
    // ∂ẍ/∂F = 1 / M, ∂θ̈/∂F = 1 / (M l).
    const CartPole cp{1.3, 0.4, 0.7, 0.0};
    const Expected e = cp.expected(Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero(), 0.0);
    CHECK(e.dq(0, 1) == Approx(0.4 * kG / 1.3).epsilon(1e-14));
    CHECK(e.dq(1, 1) == Approx(1.7 * kG / (1.3 * 0.7)).epsilon(1e-14));
    CHECK(e.du(1, 0) == Approx(1.0 / (1.3 * 0.7)).epsilon(1e-14));
    compare(cp.build(), Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero(), Eigen::VectorXd::Zero(1),
            e);
  }
}

TEST_CASE("Closed form: planar two-link arm", "[closed_form]") {
  std::mt19937 rng(2301);
  SECTION("two point masses at the link ends") {
    const TwoLinkArm arm{1.0, 0.7, 0.9, 0.9, 0.6, Eigen::Matrix3d::Zero(), Eigen::Matrix3d::Zero()};
    const Model model = arm.build();
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d q = uniformVector(rng, 2, -3.0, 3.0),
                            dq = uniformVector(rng, 2, -2.0, 2.0),
                            u = uniformVector(rng, 2, -1.0, 1.0);
      compare(model, q, dq, u, arm.expected(q, dq, u));
    }
  }
  SECTION("rods with full inertia tensors") {
    Eigen::Matrix3d I1, I2;
    I1 << 0.05, 0.01, 0.004,  //
        0.01, 0.04, -0.003,   //
        0.004, -0.003, 0.03;
    I2 << 0.02, -0.005, 0.002,  //
        -0.005, 0.03, 0.001,    //
        0.002, 0.001, 0.02;
    const TwoLinkArm arm{0.9, 0.6, 0.8, 0.35, 0.45, I1, I2};
    const Model model = arm.build();
    // The state the formulas were cross-checked at (symbolic differentiation) first.
    compare(model, Eigen::Vector2d(0.4, -1.1), Eigen::Vector2d(0.7, -1.3),
            Eigen::Vector2d(0.5, -0.2), arm.expected({0.4, -1.1}, {0.7, -1.3}, {0.5, -0.2}));
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d q = uniformVector(rng, 2, -3.0, 3.0),
                            dq = uniformVector(rng, 2, -2.0, 2.0),
                            u = uniformVector(rng, 2, -1.0, 1.0);
      compare(model, q, dq, u, arm.expected(q, dq, u));
    }
  }
}
