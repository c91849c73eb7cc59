// Tests for trellis/control/manifold_lqr.hpp and the Gramian of controllability.hpp: the
// transported tangent basis (orthonormal, tangent, TᵀṪ = 0 against central differences), the
// reduced linear system against nonlinear perturbations (O(ε²)), the closed form of two tied carts
// (a double integrator of mass 2) against the CARE, the unconstrained case against solveRiccati,
// the Gramian's closed forms, and the closed loop of the manifold gains.
//
// Reference trajectories are built here by fixed-step RK4 on the core's forward dynamics (a test
// reference only; the product never uses it).
#include "control_test_support.hpp"

#include <trellis/control.hpp>
#include <trellis/control/manifold_lqr.hpp>
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cmath>
#include <functional>
#include <random>

using Eigen::MatrixXd;
using Eigen::VectorXd;

namespace {

using InputFunction = std::function<VectorXd(double)>;

VectorXd stateDerivative(const trellis::Model& model, trellis::Data& data, const VectorXd& x,
                         const VectorXd& u) {
  const int n = model.nq();
  const VectorXd q = x.head(n), dq = x.tail(n);
  const auto s = trellis::computeDynamics(model, data, q, dq, u);
  REQUIRE(s.ok());
  VectorXd f(2 * n);
  f << dq, data.qdd;
  return f;
}

/// RK4 with `substeps` steps per knot interval; returns the states at the knots (2n×N).
MatrixXd integrateRk4(const trellis::Model& model, const VectorXd& x0, const InputFunction& u,
                      double t0, double tf, int knots, int substeps) {
  trellis::Data data(model);
  MatrixXd X(x0.size(), knots);
  X.col(0) = x0;
  VectorXd x = x0;
  const double H = (tf - t0) / (knots - 1), h = H / substeps;
  for (int k = 1; k < knots; ++k) {
    for (int s = 0; s < substeps; ++s) {
      const double t = t0 + (k - 1) * H + s * h;
      const VectorXd k1 = stateDerivative(model, data, x, u(t));
      const VectorXd k2 = stateDerivative(model, data, x + 0.5 * h * k1, u(t + 0.5 * h));
      const VectorXd k3 = stateDerivative(model, data, x + 0.5 * h * k2, u(t + 0.5 * h));
      const VectorXd k4 = stateDerivative(model, data, x + h * k3, u(t + h));
      x += h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
    }
    X.col(k) = x;
  }
  return X;
}

trellis::Trajectory makeReference(const trellis::Model& model, const VectorXd& x0,
                                  const InputFunction& u, double t0, double tf, int knots,
                                  int substeps) {
  const MatrixXd X = integrateRk4(model, x0, u, t0, tf, knots, substeps);
  VectorXd times(knots);
  MatrixXd U(model.nu(), knots);
  for (int k = 0; k < knots; ++k) {
    times(k) = t0 + (tf - t0) * k / (knots - 1);
    U.col(k) = u(times(k));
  }
  trellis::Trajectory tr(model.configNames(), model.inputNames(), times, X, U);
  trellis::Data data(model);
  tr.computeStateDerivatives(model, data);
  return tr;
}

/// Moves x = [q; q̇] onto {h = 0, A q̇ = 0}: Gauss–Newton on h, then q̇ projected on null(A).
VectorXd projectToManifold(const trellis::Model& model, VectorXd x) {
  const int n = model.nq();
  trellis::Data data(model);
  for (int it = 0; it < 20; ++it) {
    const VectorXd q = x.head(n), dq = x.tail(n);
    trellis::computeConstraints(model, data, q, dq);
    const auto cod = data.constraintJacobian.completeOrthogonalDecomposition();
    x.head(n) -= cod.solve(data.constraintValue);
  }
  const VectorXd q = x.head(n), dq = x.tail(n);
  trellis::computeConstraints(model, data, q, dq);
  const MatrixXd& A = data.constraintJacobian;
  x.tail(n) -= A.completeOrthogonalDecomposition().solve(A * dq);
  return x;
}

struct PendulumCase {
  trellis::Scene scene;
  VectorXd x0;
  InputFunction u;
};

PendulumCase paperPendulum() {
  PendulumCase c{trellis::loadScene(TRELLIS_SOURCE_DIR "/examples/scenes/paper_pendulum.json"), {},
                 {}};
  VectorXd x(4);
  x << c.scene.q, c.scene.dq;
  c.x0 = projectToManifold(c.scene.model, x);
  c.u = [](double t) { return VectorXd::Constant(1, 0.5 * std::sin(2.0 * t)); };
  return c;
}

/// Projector on the core's tangent space at x.
MatrixXd coreProjector(const trellis::Model& model, const VectorXd& x, const VectorXd& u) {
  trellis::Data data(model);
  const int n = model.nq();
  const VectorXd q = x.head(n), dq = x.tail(n);
  REQUIRE(trellis::computeLinearization(model, data, q, dq, u).ok());
  trellis::computeConstraintTangentBasis(model, data);
  return data.tangentBasis * data.tangentBasis.transpose();
}

trellis::Model makeCart(bool extraFreeCart) {
  trellis::ModelBuilder b("cart");
  b.addFrame("cart", "world", trellis::Transform::tx("x"), trellis::Mass{1.0, Eigen::Matrix3d::Zero()});
  if (extraFreeCart) {
    b.addFrame("free", "world", trellis::Transform::ty("y"),
               trellis::Mass{1.0, Eigen::Matrix3d::Zero()});
  }
  b.addConfigForce("x", "push");
  return std::move(b).finalize();
}

}  // namespace

TEST_CASE("transported tangent basis on the paper pendulum", "[manifold]") {
  const PendulumCase pc = paperPendulum();
  const trellis::Model& model = pc.scene.model;
  // 2 s, knots every 0.01 s, RK4 at 1 ms: the knots are on the manifold to ~1e-12, the Hermite
  // interpolant between them to O(h⁴) ≈ 1e-8 (h = 0.01, derivatives of order 10²); the input is
  // interpolated linearly (O(h²)).
  const trellis::Trajectory ref = makeReference(model, pc.x0, pc.u, 0.0, 2.0, 201, 10);
  const trellis::TangentBasisTrajectory basis = trellis::transportTangentBasis(model, ref);
  REQUIRE(basis.ok());
  REQUIRE(basis.dimension() == 2);
  REQUIRE(basis.nx() == 4);
  // The correction onto the true tangent space is of the size of the reference's inconsistency:
  // u_ref is linear between knots, |u − u_lin| ≤ h²|ü|/8 = 2.5e-5 (h = 0.01, |ü| ≤ 2), which tilts
  // A by that much relative; measured ≈ 1.2e-6 (see the convergence test below). Bound 1e-5.
  CHECK(basis.maxCorrection() < 1e-5);

  for (int i = 0; i <= 40; ++i) {
    const double t = 0.003 + 1.99 * i / 40.0;  // off the knots as well
    INFO("t = " << t);
    MatrixXd T, Ar0, Br0;
    basis.reducedLinearization(model, t, T, Ar0, Br0);
    const MatrixXd Th = basis.basis(t), Tt = basis.transportedBasis(t);
    const MatrixXd I2 = MatrixXd::Identity(2, 2), I4 = MatrixXd::Identity(4, 4);
    const MatrixXd P = coreProjector(model, ref.state(t), ref.input(t));
    // Corrected basis (model-bound): orthonormal and tangent to rounding (it is a polar factor in
    // the core's basis), and close to the transported one.
    CHECK((T.transpose() * T - I2).norm() < 1e-13);
    CHECK(((I4 - P) * T).norm() < 1e-13);
    CHECK((T - Tt).norm() < 1e-5);
    // The held basis (plain data: Hermite on the knots, h = 0.01, then the polar factor):
    // orthonormal to rounding, and the model-bound correction moves it by the interpolation
    // error O(h⁴‖T⁗‖/384) only (‖T⁗‖ ~ 10⁴ here: ~3e-7; bound 1e-6).
    CHECK((Th.transpose() * Th - I2).norm() < 1e-13);
    CHECK((Th - T).norm() < 1e-6);
    // Transported basis: orthonormal up to the reference's inconsistency. Ṫ = (I − P)AT is
    // normal, so d/dt TᵀT = 2 sym(((I − P)T)ᵀ A T) vanishes while T is tangent; T leaves the
    // tangent space only by the inconsistency above (≤ 1e-5), which feeds TᵀT − I at second
    // order plus the neutral normal (constraint-drift) dynamics acting on it over time
    // (measured ≤ 1.5e-6 at t = 2). Bound 1e-5, the same as the correction.
    CHECK((Tt.transpose() * Tt - I2).norm() < 1e-5);
    // Tangent up to the reference's inconsistency (above) — the transport itself never sees P.
    CHECK(((I4 - P) * Tt).norm() < 1e-5);

    // Ṫ by central differences (step 1e-4: truncation ~1e-8·|T'''|, rounding ~1e-12/1e-4).
    if (t > 1e-3 && t < 2.0 - 1e-3) {
      const double h = 1e-4;
      const MatrixXd dT = (basis.transportedBasis(t + h) - basis.transportedBasis(t - h)) / (2 * h);
      // TᵀṪ = 0 for a tangent T; here T̃ is tangent up to the inconsistency (≤ 1e-5), and
      // Tᵀ(I − P)AT = ((I − P)T)ᵀAT is that times ‖A‖ ~ 10 (measured ≤ 4.4e-6). Bound 1e-4.
      CHECK((Tt.transpose() * dT).norm() < 1e-4);
      MatrixXd Tc, Ar, Br;
      basis.reducedLinearization(model, t, Tc, Ar, Br);
      trellis::Data data(model);
      const VectorXd x = ref.state(t);
      REQUIRE(trellis::computeLinearization(model, data, x.head(2), x.tail(2), ref.input(t)).ok());
      const MatrixXd expected = (I4 - P) * data.A * Tt;  // the transport ODE
      CHECK((dT - expected).norm() < 1e-6 * std::max(1.0, expected.norm()));
      // Ar, Br are the exact linearization restricted to T.
      CHECK((Ar - Tc.transpose() * data.A * Tc).norm() < 1e-12 * data.A.norm());
      CHECK((Br - Tc.transpose() * data.B).norm() < 1e-12 * std::max(1.0, data.B.norm()));
    }
  }

  SECTION("dynamics that fail at t0: a status with no basis anywhere, never an exception") {
    // Two carts tied by a point constraint, one carrying a spinner that moves no mass: M is
    // singular at every state, so there is no tangent basis even at t0.
    trellis::ModelBuilder b("carts_with_massless_spinner");
    b.addFrame("cart1", "world", trellis::Transform::tx("x1"), trellis::Mass{1.0, Eigen::Matrix3d::Zero()});
    b.addFrame("cart2", "world", trellis::Transform::tx("x2"), trellis::Mass{1.0, Eigen::Matrix3d::Zero()});
    b.addFrame("spinner", "cart2", trellis::Transform::rz("phi"));
    b.addPointConstraint("cart1", "cart2", 0);
    b.addConfigForce("x1", "push");
    const trellis::Model bad = std::move(b).finalize();
    trellis::Trajectory still(bad.configNames(), bad.inputNames(), (VectorXd(2) << 0.0, 1.0).finished(),
                              MatrixXd::Zero(6, 2), MatrixXd::Zero(1, 2));
    still.setStateDerivatives(MatrixXd::Zero(6, 2));
    trellis::TangentBasisTrajectory none;
    REQUIRE_NOTHROW(none = trellis::transportTangentBasis(bad, still));
    CHECK_FALSE(none.ok());
    CHECK_FALSE(none.hasBasis());
    CHECK(none.status().code == trellis::TransportCode::kDynamicsFailure);
    CHECK(none.status().t == 0.0);
    CHECK_THAT(none.status().message, Catch::Contains("no basis at t0") &&
                                          Catch::Contains("moves no mass"));
    CHECK_THROWS_AS(none.basis(0.0), std::out_of_range);
    CHECK_THAT(none.json(), Catch::Contains("\"valid_until\":null"));
    // The solvers report it as their status (no exception either).
    const auto lqr = trellis::solveManifoldRiccati(
        bad, still, {MatrixXd::Identity(6, 6), MatrixXd::Identity(1, 1), MatrixXd::Identity(6, 6), {}, {}});
    CHECK(lqr.status.code == trellis::ManifoldRiccatiCode::kTransportFailure);
    CHECK(lqr.status.t == 0.0);
    // Default-constructed: not transported.
    CHECK(trellis::TangentBasisTrajectory{}.status().code == trellis::TransportCode::kNotTransported);
  }

  SECTION("bad options and failure status") {
    trellis::TangentTransportOptions bad;
    bad.rtol = -1;
    CHECK_THROWS_AS(bad.validate(), std::invalid_argument);
    CHECK_THROWS_WITH(trellis::transportTangentBasis(model, ref, bad), Catch::Contains("rtol"));
    trellis::TangentTransportOptions few;
    few.maxSteps = 3;
    const auto partial = trellis::transportTangentBasis(model, ref, few);
    CHECK(!partial.ok());
    CHECK(partial.status().code == trellis::TransportCode::kIntegratorFailure);
    CHECK_THAT(partial.status().message, Catch::Contains("t = ") && Catch::Contains("maxSteps"));
    CHECK(partial.status().t <= 2.0);
    CHECK(partial.hasBasis());
    CHECK_THAT(partial.describe(), Catch::StartsWith("integrator_failure at t = "));
    CHECK_THAT(partial.json(), Catch::Contains("\"status\":\"integrator_failure\""));
    CHECK(partial.validUntil() < 2.0);
    CHECK_THROWS_AS(partial.basis(2.0), std::out_of_range);
    const auto lqr = trellis::solveManifoldRiccati(
        model, ref, {MatrixXd::Identity(4, 4), MatrixXd::Identity(1, 1), MatrixXd::Identity(4, 4), {}, {}},
        {}, few);
    CHECK(!lqr.ok());
    CHECK_THAT(lqr.status.message, Catch::Contains("maxSteps"));
  }
}

TEST_CASE("reduced linear system predicts on-manifold perturbations to O(eps^2)", "[manifold]") {
  const PendulumCase pc = paperPendulum();
  const trellis::Model& model = pc.scene.model;
  const double tf = 1.0;
  const int knots = 101, substeps = 10;
  const trellis::Trajectory ref = makeReference(model, pc.x0, pc.u, 0.0, tf, knots, substeps);
  const MatrixXd Xref = ref.states();
  const trellis::TangentBasisTrajectory basis = trellis::transportTangentBasis(model, ref);
  REQUIRE(basis.ok());

  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  VectorXd z0(2);
  z0 << g(rng), g(rng);
  z0.normalize();

  // Linear prediction: ż = Ar z by RK4 on the same grid (Ar from the interpolated reference).
  const double h = tf / ((knots - 1) * substeps);
  auto Ar = [&](double t) {
    MatrixXd T, A, B;
    basis.reducedLinearization(model, t, T, A, B);
    return A;
  };
  MatrixXd Z(2, knots);
  {
    VectorXd z = z0;
    Z.col(0) = z;
    for (int k = 1; k < knots; ++k) {
      for (int s = 0; s < substeps; ++s) {
        const double t = ((k - 1) * substeps + s) * h;
        const VectorXd k1 = Ar(t) * z, k2 = Ar(t + 0.5 * h) * (z + 0.5 * h * k1);
        const VectorXd k3 = Ar(t + 0.5 * h) * (z + 0.5 * h * k2), k4 = Ar(t + h) * (z + h * k3);
        z += h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
      }
      Z.col(k) = z;
    }
  }
  // Nonlinear: the perturbed start projected onto the manifold (an O(ε²) change), same RK4 grid,
  // so the discretization errors of the two nonlinear runs largely cancel.
  auto error = [&](double eps) {
    const VectorXd xp0 = projectToManifold(model, pc.x0 + eps * basis.basis(0.0) * z0);
    const MatrixXd Xp = integrateRk4(model, xp0, pc.u, 0.0, tf, knots, substeps);
    double worst = 0.0, size = 0.0;
    for (int k = 0; k < knots; ++k) {
      const VectorXd lin = eps * basis.basis(ref.times()(k)) * Z.col(k);
      worst = std::max(worst, (Xp.col(k) - Xref.col(k) - lin).norm());
      size = std::max(size, lin.norm());
    }
    INFO("eps = " << eps << ": max |dx_nonlinear - T z| = " << worst << ", max |T z| = " << size);
    CHECK(size > 0.5 * eps);  // the perturbation does not vanish
    return worst;
  };
  const double e1 = error(1e-3), e2 = error(5e-4);
  INFO("errors " << e1 << ", " << e2 << ", ratio " << e1 / e2);
  // O(ε²): halving ε divides the error by 4 (3..5 leaves room for the O(ε³) term and the
  // ~1e-8·ε error of the interpolated Ar); and the error is far below the perturbation.
  CHECK(e1 / e2 > 3.0);
  CHECK(e1 / e2 < 5.0);
  CHECK(e1 < 1e-5);  // ε² = 1e-6 times an O(1) second-order coefficient (measured 1.06e-6)
}

TEST_CASE("two tied carts: the reduced problem is a double integrator of mass 2", "[manifold]") {
  const trellis::Model model = trellis::ctest::makeConstrainedCarts();
  VectorXd x0(4);
  x0 << 0.3, 0.3, -0.2, -0.2;
  const trellis::Trajectory ref =
      makeReference(model, x0, [](double t) { return VectorXd::Constant(1, std::sin(t)); }, 0.0,
                    20.0, 201, 5);
  // E maps (x, v) to the full state on the manifold (x1 = x2 = x, ẋ1 = ẋ2 = v).
  MatrixXd E = MatrixXd::Zero(4, 2);
  E << 1, 0, 1, 0, 0, 1, 0, 1;
  MatrixXd Q(4, 4);
  Q << 2, 0.5, 0, 0.1,  //
      0.5, 1, 0.2, 0,   //
      0, 0.2, 1, 0.3,   //
      0.1, 0, 0.3, 1.5;
  const MatrixXd R = MatrixXd::Constant(1, 1, 0.7);
  trellis::LqrWeights w{Q, R, MatrixXd::Zero(4, 4), {}, {}};
  trellis::RiccatiOptions opt;
  opt.rtol = 1e-10;
  opt.atol = 1e-12;
  const auto sol = trellis::solveManifoldRiccati(model, ref, w, opt);
  REQUIRE(sol.ok());
  REQUIRE(sol.dimension() == 2);

  // Independent reference: CARE of ẍ = u / 2 with the cost restricted to the manifold, EᵀQE.
  MatrixXd A2(2, 2), B2(2, 1);
  A2 << 0, 1, 0, 0;
  B2 << 0, 0.5;
  const auto care = trellis::solveCare(A2, B2, E.transpose() * Q * E, R);
  REQUIRE(care.ok());
  // At t0 the 20 s horizon has converged (closed-loop decay rates ≈ 1/s: e^{−20} ≪ 1e-8);
  // the Riccati tolerance rtol 1e-10 leaves 1e-7 with margin.
  const MatrixXd K = sol.K(0.0), S = sol.S(0.0);
  CONTROL_CHECK_CLOSE(care.K, K * E, 1e-7, 1.0);
  CONTROL_CHECK_CLOSE(care.S, E.transpose() * S * E, 1e-7, 1.0);
  // The transported basis is constant here (A maps the tangent space into itself).
  CHECK((sol.basis.basis(13.0) - sol.basis.basis(0.0)).norm() < 1e-9);
  // The reduced closed loop at t0 is Hurwitz and its eigenvalues are those of the CARE.
  MatrixXd T, Ar, Br;
  sol.basis.reducedLinearization(model, 0.0, T, Ar, Br);
  const Eigen::VectorXcd ev = (Ar - Br * sol.reduced.K(0.0)).eigenvalues();
  const Eigen::VectorXcd evCare = (A2 - B2 * care.K).eigenvalues();
  CHECK(ev.real().maxCoeff() < 0.0);
  CHECK(std::abs(ev.real().sum() - evCare.real().sum()) < 1e-6);
  CHECK(std::abs(ev.prod() - evCare.prod()) < 1e-6);

  SECTION("the Gramian in (x, v) coordinates is b² [[T³/3, T²/2], [T²/2, T]], b = 1/2") {
    const double t1 = 3.0;
    const auto gr = trellis::computeControllabilityGramian(model, ref, 0.0, t1);
    REQUIRE(gr.ok());
    REQUIRE(gr.dimension == 2);
    // z = Tᵀ E (x, v): W_xv = (TᵀE)⁻¹ W (TᵀE)⁻ᵀ.
    const MatrixXd M = sol.basis.basis(t1).transpose() * E;
    const MatrixXd Wxv = M.inverse() * gr.W * M.inverse().transpose();
    MatrixXd expected(2, 2);
    expected << t1 * t1 * t1 / 3, t1 * t1 / 2, t1 * t1 / 2, t1;
    expected *= 0.25;
    CONTROL_CHECK_CLOSE(expected, Wxv, 1e-8, 1.0);  // rtol 1e-10 on W, entries of order 1
    CHECK(gr.controllable());
  }
}

TEST_CASE("without constraints the manifold Riccati is the full-state Riccati", "[manifold]") {
  const trellis::Model model = trellis::ctest::makeCartPole();
  VectorXd x0(4);
  x0 << 0.0, 0.3, 0.2, -0.5;
  const trellis::Trajectory ref =
      makeReference(model, x0, [](double) { return VectorXd::Zero(1); }, 0.0, 2.0, 101, 5);
  const MatrixXd Q = MatrixXd::Identity(4, 4), R = MatrixXd::Identity(1, 1);
  const trellis::LqrWeights w{Q, R, 10 * Q, {}, {}};
  const auto manifold = trellis::solveManifoldRiccati(model, ref, w);
  const auto full = trellis::solveRiccati(model, ref, w);
  REQUIRE(manifold.ok());
  REQUIRE(full.ok());
  CHECK(manifold.dimension() == 4);
  for (double t : {0.0, 0.37, 1.2, 2.0}) {
    INFO("t = " << t);
    CHECK(manifold.basis.basis(t) == MatrixXd::Identity(4, 4));
    // The same integrator on the same right-hand side (T = I exactly): agreement to rounding.
    CONTROL_CHECK_CLOSE(full.S(t), manifold.S(t), 1e-12, 1.0);
    CONTROL_CHECK_CLOSE(full.K(t), manifold.K(t), 1e-12, 1.0);
  }
}

TEST_CASE("manifold LQR on the paper pendulum: gains and closed loop", "[manifold]") {
  const PendulumCase pc = paperPendulum();
  const trellis::Model& model = pc.scene.model;
  const double tf = 3.0;
  const trellis::Trajectory ref = makeReference(model, pc.x0, pc.u, 0.0, tf, 301, 10);
  const MatrixXd Q = MatrixXd::Identity(4, 4), R = MatrixXd::Identity(1, 1);
  const auto sol = trellis::solveManifoldRiccati(model, ref, {Q, R, 5 * Q, {}, {}});
  INFO(sol.status.message);
  REQUIRE(sol.ok());
  REQUIRE(sol.dimension() == 2);

  for (double t : {0.0, 0.55, 1.5, 2.99}) {
    INFO("t = " << t);
    const MatrixXd K = sol.K(t), S = sol.S(t), T = sol.basis.basis(t);
    REQUIRE(K.rows() == 1);
    REQUIRE(K.cols() == 4);
    CHECK(K.allFinite());
    // Off-manifold directions get no feedback (K = Kr Tᵀ and Tᵀ(I − TTᵀ) = 0).
    CHECK((K * (MatrixXd::Identity(4, 4) - T * T.transpose())).norm() < 1e-13 * std::max(1.0, K.norm()));
    // S is symmetric PSD with rank d = 2.
    const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<MatrixXd>(S).eigenvalues();
    CHECK(ev(0) > -1e-10);
    CHECK(std::abs(ev(1)) < 1e-10 * ev(3));
    CHECK(ev(2) > 1e-3);
  }

  // Reduced closed loop ż = (Ar − Br Kr) z: the cost-to-go V = zᵀ Sr z must decrease,
  // dV/dt = −zᵀ(Qr + KrᵀR Kr)z < 0 (RK4 at 1 ms; V falls by a finite amount between samples, much
  // more than the ~1e-10 integration error). The open loop, for contrast, is merely oscillatory.
  VectorXd z(2);
  z << 1.0, -0.5;
  auto closedLoop = [&](double t, const VectorXd& zz) {
    MatrixXd T, Ar, Br;
    sol.basis.reducedLinearization(model, t, T, Ar, Br);
    return VectorXd((Ar - Br * sol.reduced.K(t)) * zz);
  };
  const double h = 1e-3;
  double V = z.dot(sol.reduced.S(0.0) * z);
  const double V0 = V;
  for (int k = 0; k < 3000; ++k) {
    const double t = k * h;
    const VectorXd k1 = closedLoop(t, z), k2 = closedLoop(t + 0.5 * h, z + 0.5 * h * k1);
    const VectorXd k3 = closedLoop(t + 0.5 * h, z + 0.5 * h * k2), k4 = closedLoop(t + h, z + h * k3);
    z += h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
    if ((k + 1) % 100 == 0) {
      const double Vn = z.dot(sol.reduced.S(t + h) * z);
      INFO("t = " << t + h << ": V = " << Vn << " previous " << V);
      CHECK(Vn < V);
      V = Vn;
    }
  }
  CHECK(V < 0.5 * V0);
}

TEST_CASE("reachability Gramian", "[manifold][controllability]") {
  SECTION("double integrator closed form") {
    const trellis::Model model = makeCart(false);
    VectorXd x0(2);
    x0 << 0.1, 0.0;
    const auto ref =
        makeReference(model, x0, [](double) { return VectorXd::Zero(1); }, 0.0, 3.0, 31, 2);
    const double T = 2.0;
    const auto gr = trellis::computeControllabilityGramian(model, ref, 0.5, 0.5 + T);
    REQUIRE(gr.ok());
    MatrixXd expected(2, 2);
    expected << T * T * T / 3, T * T / 2, T * T / 2, T;
    CONTROL_CHECK_CLOSE(expected, gr.W, 1e-8, 1.0);  // rtol 1e-10, entries of order 1
    CHECK(gr.controllable());
    CHECK(gr.minEigenvalue > 0.1);
  }
  SECTION("an uncontrollable direction gives a zero eigenvalue") {
    const trellis::Model model = makeCart(true);  // second cart y: no input, no coupling
    VectorXd x0(4);
    x0 << 0.1, 0.0, 0.0, 0.3;
    const auto ref =
        makeReference(model, x0, [](double) { return VectorXd::Zero(1); }, 0.0, 3.0, 31, 2);
    const auto gr = trellis::computeControllabilityGramian(model, ref, 0.0, 2.0);
    REQUIRE(gr.ok());
    CHECK(gr.dimension == 4);
    CHECK(std::abs(gr.minEigenvalue) < 1e-12 * gr.maxEigenvalue);
    CHECK(!gr.controllable());
  }
  SECTION("paper pendulum: positive definite, agrees with an RK4 Lyapunov integration") {
    const PendulumCase pc = paperPendulum();
    const trellis::Model& model = pc.scene.model;
    const auto ref = makeReference(model, pc.x0, pc.u, 0.0, 1.5, 151, 10);
    const double t0 = 0.2, t1 = 1.2;
    const auto gr = trellis::computeControllabilityGramian(model, ref, t0, t1);
    INFO(gr.status.message);
    REQUIRE(gr.ok());
    CHECK(gr.dimension == 2);
    CHECK(gr.controllable(1e-8));
    CHECK(gr.minEigenvalue > 0.0);
    // Independent integration of Ẇ = Ar W + W Arᵀ + Br Brᵀ (RK4, 1 ms: error ~h⁴ ≈ 1e-12·|W^(5)|).
    const auto basis = trellis::transportTangentBasis(model, ref);
    auto f = [&](double t, const MatrixXd& W) {
      MatrixXd T, Ar, Br;
      basis.reducedLinearization(model, t, T, Ar, Br);
      return MatrixXd(Ar * W + W * Ar.transpose() + Br * Br.transpose());
    };
    MatrixXd W = MatrixXd::Zero(2, 2);
    const int steps = 1000;
    const double h = (t1 - t0) / steps;
    for (int k = 0; k < steps; ++k) {
      const double t = t0 + k * h;
      const MatrixXd k1 = f(t, W), k2 = f(t + 0.5 * h, W + 0.5 * h * k1);
      const MatrixXd k3 = f(t + 0.5 * h, W + 0.5 * h * k2), k4 = f(t + h, W + h * k3);
      W += h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
    }
    CONTROL_CHECK_CLOSE(W, gr.W, 1e-7, gr.maxEigenvalue);
  }
  SECTION("bad input") {
    const trellis::Model model = makeCart(false);
    VectorXd x0(2);
    x0 << 0.1, 0.0;
    const auto ref =
        makeReference(model, x0, [](double) { return VectorXd::Zero(1); }, 0.0, 1.0, 11, 2);
    CHECK_THROWS_AS(trellis::computeControllabilityGramian(model, ref, 0.5, 0.5),
                    std::invalid_argument);
    CHECK_THROWS_WITH(trellis::computeControllabilityGramian(model, ref, 0.0, 2.0),
                      Catch::Contains("span"));
  }
}

TEST_CASE("controllability at every knot", "[manifold][controllability]") {
  const PendulumCase pc = paperPendulum();
  const trellis::Model& model = pc.scene.model;
  const auto ref = makeReference(model, pc.x0, pc.u, 0.0, 1.0, 21, 20);
  const auto reports = trellis::controllabilityAtKnots(model, ref);
  REQUIRE(reports.size() == 21);
  for (const auto& r : reports) {
    CHECK(r.ok());
    CHECK(r.dimension == 2);
    CHECK(r.controllable());
  }
  // Each report is the point test on the knot's reduced linearization.
  trellis::Data data(model);
  const VectorXd x = ref.states().col(5);
  const auto direct =
      trellis::computeControllabilityAt(model, data, x.head(2), x.tail(2), ref.inputs().col(5));
  CHECK(direct.singularValues == reports[5].singularValues);
}
TEST_CASE("the correction onto the tangent space converges with the knot spacing", "[manifold]") {
  // The transport follows A(x_ref(t), u_ref(t)); x_ref is a cubic Hermite spline (error O(h⁴)) but
  // u_ref is piecewise linear (error O(h²)), so the pair is dynamically consistent only to O(h²)
  // unless u is constant. The correction ‖T − T̃‖ must therefore shrink like h⁴ for a zero input
  // and like h² for a smooth non-constant one; halving h divides it by ≈ 16 and ≈ 4.
  const PendulumCase pc = paperPendulum();
  const trellis::Model& model = pc.scene.model;
  trellis::TangentTransportOptions tight;  // integration error well below the corrections
  tight.rtol = 1e-12;
  tight.atol = 1e-14;
  auto correction = [&](const InputFunction& u, int knots) {
    const trellis::Trajectory ref = makeReference(model, pc.x0, u, 0.0, 2.0, knots, 4000 / (knots - 1));
    const auto basis = trellis::transportTangentBasis(model, ref, tight);
    REQUIRE(basis.ok());
    const double hk = 2.0 / (knots - 1);
    double worst = 0.0;
    for (int k = 0; k + 1 < knots; ++k) {  // midpoints, where the spline is least accurate
      const double t = (k + 0.5) * hk;
      MatrixXd T, Ar, Br;  // the correction onto the exact tangent space at x_ref(t)
      basis.reducedLinearization(model, t, T, Ar, Br);
      worst = std::max(worst, (T - basis.transportedBasis(t)).norm());
    }
    return worst;
  };
  const InputFunction zero = [](double) { return VectorXd::Zero(1); };
  const double z1 = correction(zero, 101), z2 = correction(zero, 201);
  const double s1 = correction(pc.u, 101), s2 = correction(pc.u, 201);
  INFO("zero input: " << z1 << " -> " << z2 << "; sine input: " << s1 << " -> " << s2);
  CHECK(z1 / z2 > 8.0);
  CHECK(z1 < 1e-6);
  CHECK(s1 / s2 > 3.0);
  CHECK(s1 / s2 < 6.0);
}

TEST_CASE("the transport and the Gramian use exact Jacobian products only", "[manifold]") {
  // Both integrate with Newton–GMRES on the exact products ((I − P)A E for the transport, the
  // Lyapunov operator for the Gramian): CVODES never falls back to difference quotients, whose
  // right-hand sides it counts separately.
  const PendulumCase pc = paperPendulum();
  const trellis::Model& model = pc.scene.model;
  const trellis::Trajectory ref = makeReference(model, pc.x0, pc.u, 0.0, 1.0, 101, 10);
  const auto basis = trellis::transportTangentBasis(model, ref);
  REQUIRE(basis.ok());
  CHECK(basis.steps() > 10);
  CHECK(basis.differenceQuotientEvaluations() == 0);
  const auto gr = trellis::computeControllabilityGramian(model, ref, 0.0, 1.0);
  REQUIRE(gr.ok());
  CHECK(gr.steps > 10);
  CHECK(gr.linearizations > 0);
  CHECK(gr.differenceQuotientEvaluations == 0);
}

TEST_CASE("Gramian at the summary's tolerance against the closed form", "[manifold][controllability]") {
  // Double integrator (a free cart of mass 1): W(0, T) = [[T³/3, T²/2], [T²/2, T]]. The default
  // GramianOptions (rtol 1e-5: a summary prints two or three digits) must meet it to 10·rtol
  // relative, and its eigenvalues (0.592 and 11.41) to 1e-4 relative each.
  const trellis::Model model = makeCart(false);
  VectorXd x0(2);
  x0 << 0.1, 0.0;
  const auto ref = makeReference(model, x0, [](double) { return VectorXd::Zero(1); }, 0.0, 3.0, 31, 2);
  const double T = 3.0;
  const auto gr = trellis::computeControllabilityGramian(model, ref, 0.0, T, trellis::GramianOptions{});
  REQUIRE(gr.ok());
  MatrixXd expected(2, 2);
  expected << T * T * T / 3, T * T / 2, T * T / 2, T;
  CONTROL_CHECK_CLOSE(expected, gr.W, 1e-4, expected.norm());
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<MatrixXd>(expected).eigenvalues();
  CHECK(std::abs(gr.minEigenvalue - ev(0)) <= 1e-4 * ev(0));
  CHECK(std::abs(gr.maxEigenvalue - ev(1)) <= 1e-4 * ev(1));
  trellis::GramianOptions bad;
  bad.rtol = 0.0;
  CHECK_THROWS_WITH(trellis::computeControllabilityGramian(model, ref, 0.0, T, bad), Catch::Contains("rtol"));
}

namespace {

struct HeldValues {
  trellis::ManifoldRiccatiSolution solution;
  std::vector<double> times;
  std::vector<MatrixXd> K, S, T;  // evaluated while the model was alive
};

/// Loads its own model, solves, evaluates, and returns the solution: the model dies on return.
HeldValues solveWithLocalModel() {
  const PendulumCase pc = paperPendulum();  // owns the scene (and the model)
  const trellis::Trajectory ref = makeReference(pc.scene.model, pc.x0, pc.u, 0.0, 1.0, 101, 10);
  const MatrixXd Q = MatrixXd::Identity(4, 4), R = MatrixXd::Identity(1, 1);
  HeldValues h;
  h.solution = trellis::solveManifoldRiccati(pc.scene.model, ref, {Q, R, Q, {}, {}});
  h.times = {0.0, 0.123, 0.5, 0.77, 1.0};
  for (double t : h.times) {
    h.K.push_back(h.solution.K(t));
    h.S.push_back(h.solution.S(t));
    MatrixXd T, Ar, Br;
    h.solution.basis.reducedLinearization(pc.scene.model, t, T, Ar, Br);
    h.T.push_back(T);
  }
  return h;
}

}  // namespace

TEST_CASE("a manifold solution outlives its model (plain data)", "[manifold]") {
  const HeldValues held = solveWithLocalModel();
  REQUIRE(held.solution.ok());
  const trellis::ManifoldRiccatiSolution copy = held.solution;  // a copy, the model long gone
  for (std::size_t i = 0; i < held.times.size(); ++i) {
    const double t = held.times[i];
    INFO("t = " << t);
    const MatrixXd K = copy.K(t), S = copy.S(t);
    CHECK(K == held.K[i]);  // bit for bit: the same stored data, the same arithmetic
    CHECK(S == held.S[i]);
    // The held basis against the model-bound correction computed while the model lived.
    CHECK((copy.basis.basis(t) - held.T[i]).norm() < 1e-6);
  }
  CHECK_THROWS_AS(copy.K(1.5), std::out_of_range);
}

TEST_CASE("node linearizations: interpolated Ar, Br and the gains against the exact ones", "[manifold]") {
  // kNodes interpolates Ar_i, Br_i from the knots (h = 0.01) by the C¹ cubic Hermite with
  // three-point slopes: error O(h³‖Ar'''‖) for a smooth reference, plus the kink of the exact A(t)
  // between knots (u_ref is linear there: |u − u_smooth| ≤ h²|ü|/8 = 2.5e-5 at |ü| ≤ 2), so both
  // differ by ~1e-5 relative; bound 1e-4 (measured values in the INFO).
  const PendulumCase pc = paperPendulum();
  const trellis::Model& model = pc.scene.model;
  const trellis::Trajectory ref = makeReference(model, pc.x0, pc.u, 0.0, 2.0, 201, 10);
  trellis::TangentTransportOptions exact, nodes;
  exact.linearization = trellis::ReducedLinearizationMode::kExact;
  nodes.linearization = trellis::ReducedLinearizationMode::kNodes;
  const auto be = trellis::transportTangentBasis(model, ref, exact);
  const auto bn = trellis::transportTangentBasis(model, ref, nodes);
  REQUIRE(be.ok());
  REQUIRE(bn.ok());
  CHECK(!be.usesNodeLinearization());
  CHECK(bn.usesNodeLinearization());
  trellis::ReducedLinearization le(model, be), ln(model, bn);
  double worstA = 0.0, worstB = 0.0;
  for (int k = 0; k < 200; k += 7) {
    for (double f : {0.0, 0.5, 0.25}) {
      const double t = 0.01 * (k + f);
      REQUIRE(le.evaluate(t).ok());
      REQUIRE(ln.evaluate(t).ok());
      worstA = std::max(worstA, (le.Ar() - ln.Ar()).norm() / le.Ar().norm());
      worstB = std::max(worstB, (le.Br() - ln.Br()).norm() / le.Br().norm());
      if (f == 0.0) {  // at a node: the same numbers up to the basis (exact there)
        CHECK((le.Ar() - ln.Ar()).norm() < 1e-12 * le.Ar().norm());
      }
    }
  }
  INFO("max relative difference Ar " << worstA << ", Br " << worstB);
  CHECK(worstA < 1e-4);
  CHECK(worstB < 1e-4);
  CHECK(le.evaluations() > 0);
  CHECK(ln.evaluations() == 0);  // the node path never linearizes, nor does its solve below
  const MatrixXd Q = MatrixXd::Identity(4, 4), R = MatrixXd::Identity(1, 1);
  trellis::RiccatiOptions ro;
  ro.rtol = 1e-8;
  const auto se = trellis::solveManifoldRiccati(model, ref, {Q, R, Q, {}, {}}, ro, exact);
  const auto sn = trellis::solveManifoldRiccati(model, ref, {Q, R, Q, {}, {}}, ro, nodes);
  REQUIRE(se.ok());
  REQUIRE(sn.ok());
  CHECK(se.linearizations > 0);
  CHECK(sn.linearizations == 0);
  double worstK = 0.0;
  for (double t : {0.0, 0.333, 1.0, 1.777, 2.0}) {
    worstK = std::max(worstK, (se.K(t) - sn.K(t)).norm() / se.K(t).norm());
  }
  INFO("max relative difference of K " << worstK);
  CHECK(worstK < 1e-4);
}
