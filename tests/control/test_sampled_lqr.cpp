// test_sampled_lqr.cpp — sampled-data (zero-order-hold) LQR: the exact discretization against an
// independent fixed-step integration (and against the frozen-A shortcut), the recursion with cross
// term against brute-force minimization, the DARE limit, convergence to the continuous gains, the
// cart-pole held at 50 Hz with input bounds, constrained scenes, and solveTvlqr's result.
#include "control_test_support.hpp"

#include <trellis/control.hpp>
#include <trellis/control/sampled_lqr.hpp>
#include <trellis/control/tvlqr.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <unsupported/Eigen/MatrixFunctions>

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::GainSchedule;
using trellis::LqrWeights;
using trellis::Model;
using trellis::SampledInterval;
using trellis::SimulationOptions;
using trellis::SimulationResult;
using trellis::Trajectory;

namespace {

// A time-varying test system with fast-changing A(t), B(t) (nx = 2, m = 1).
trellis::ReferenceStatus tvSystem(double t, MatrixXd& A, MatrixXd& B) {
  A.resize(2, 2);
  B.resize(2, 1);
  A << 0.0, 1.0, -(1.0 + 3.0 * std::sin(4.0 * t)), -0.2 + t;
  B << 0.1 * t, 1.0 + 0.5 * std::cos(3.0 * t);
  return {};
}

/// A stiff (|λ| up to ~1.4e3: λh ≈ 140 at 10 Hz) time-varying mechanical pair: x = [q; v],
/// A = [[0, I], [Aq(t), Av(t)]] with a slowly varying coupling, B = [0; Bv(t)] (nx = 4, m = 2).
/// qdotDrift > 0 breaks the structure from t = 1: q̇₀ = (1 + qdotDrift (t − 1)) v₀.
trellis::ReferenceStatus stiffPair(double t, MatrixXd& A, MatrixXd& B, double qdotDrift = 0.0) {
  A = MatrixXd::Zero(4, 4);
  A.topRightCorner(2, 2).setIdentity();
  if (qdotDrift > 0.0 && t >= 1.0) A(0, 2) = 1.0 + qdotDrift * (t - 1.0);
  A.bottomLeftCorner(2, 2) << -1e4, 30.0 + 20.0 * std::sin(2.0 * t), 30.0 + 20.0 * std::sin(2.0 * t), -10.0;
  A.bottomRightCorner(2, 2) << -1400.0 * (1.0 + 0.2 * std::cos(t)), 2.0, 2.0, -0.5;
  B = MatrixXd::Zero(4, 2);
  B.bottomRows(2) << 1.0, 0.3 * std::cos(3.0 * t), 0.0, 1.0;
  return {};
}

/// Independent reference: classical RK4 with `steps` fixed steps on Y = [Φ Γ] and the cost W.
SampledInterval rk4Interval(double a, double b, const MatrixXd& Q, const MatrixXd& R, int steps) {
  const int nx = 2, m = 1, c = nx + m;
  auto f = [&](double t, const MatrixXd& Y, MatrixXd& dY, MatrixXd& dW) {
    MatrixXd A, B;
    tvSystem(t, A, B);
    dY = A * Y;
    dY.rightCols(m) += B;
    dW = Y.transpose() * Q * Y;
    dW.bottomRightCorner(m, m) += R;
  };
  MatrixXd Y = MatrixXd::Zero(nx, c), W = MatrixXd::Zero(c, c);
  Y.leftCols(nx).setIdentity();
  const double h = (b - a) / steps;
  MatrixXd k1, k2, k3, k4, l1, l2, l3, l4;
  for (int i = 0; i < steps; ++i) {
    const double t = a + i * h;
    f(t, Y, k1, l1);
    f(t + h / 2, Y + h / 2 * k1, k2, l2);
    f(t + h / 2, Y + h / 2 * k2, k3, l3);
    f(t + h, Y + h * k3, k4, l4);
    Y += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
    W += h / 6 * (l1 + 2 * l2 + 2 * l3 + l4);
  }
  SampledInterval iv;
  iv.t0 = a;
  iv.t1 = b;
  iv.Phi = Y.leftCols(nx);
  iv.Gamma = Y.rightCols(m);
  iv.Q = W.topLeftCorner(nx, nx);
  iv.N = W.topRightCorner(nx, m);
  iv.R = W.bottomRightCorner(m, m);
  return iv;
}

double relErr(const MatrixXd& ref, const MatrixXd& got) {
  return (ref - got).cwiseAbs().maxCoeff() / std::max(1e-300, ref.cwiseAbs().maxCoeff());
}

Trajectory constantReference(const Model& model, const VectorXd& x, const VectorXd& u, double T) {
  MatrixXd X(x.size(), 2), U(u.size(), 2);
  X << x, x;
  U << u, u;
  Trajectory ref(model.configNames(), model.inputNames(), (VectorXd(2) << 0.0, T).finished(), X, U);
  trellis::Data data(model);
  ref.computeStateDerivatives(model, data);
  return ref;
}

/// The cart-pole's free swing from θ = 2.5 rad (u = 0) on [0, T]: a time-varying reference.
Trajectory swingReference(const Model& model, double T) {
  SimulationOptions opt;
  opt.rtol = 1e-11;
  opt.atol = 1e-12;
  opt.outputStep = 0.01;
  const trellis::Policy zero = [](double, const VectorXd&, VectorXd& u) { u.setZero(); };
  const SimulationResult r =
      trellis::simulate(model, (VectorXd(4) << 0.0, 2.5, 0.0, 0.0).finished(), 0.0, T, zero, opt);
  REQUIRE(r.ok());
  return r.trajectory;
}

LqrWeights cartPoleWeights() {
  LqrWeights w;
  w.Q = VectorXd((VectorXd(4) << 10.0, 10.0, 1.0, 1.0).finished()).asDiagonal();
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = w.Q;
  return w;
}

}  // namespace

TEST_CASE("sampled LQR: exact discretization of a time-varying system vs RK4 and frozen-A ZOH",
          "[sampled]") {
  const MatrixXd Q = (MatrixXd(2, 2) << 3.0, 0.5, 0.5, 1.0).finished();
  const MatrixXd R = MatrixXd::Constant(1, 1, 0.7);
  LqrWeights w;
  w.Q = Q;
  w.R = R;
  const double h = 0.1;
  const VectorXd times = (VectorXd(3) << 0.3, 0.3 + h, 0.3 + 2 * h).finished();
  const auto disc = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w);
  REQUIRE(disc.ok());
  REQUIRE(disc.intervals.size() == 2);
  double exactErr = 0.0, frozenErr = 0.0;
  for (const SampledInterval& iv : disc.intervals) {
    const SampledInterval ref = rk4Interval(iv.t0, iv.t1, Q, R, 4000);
    INFO("interval [" << iv.t0 << ", " << iv.t1 << "]");
    CHECK(relErr(ref.Phi, iv.Phi) < 1e-9);
    CHECK(relErr(ref.Gamma, iv.Gamma) < 1e-9);
    CHECK(relErr(ref.Q, iv.Q) < 1e-8);
    CHECK(relErr(ref.N, iv.N) < 1e-8);
    CHECK(relErr(ref.R, iv.R) < 1e-8);
    exactErr = std::max({exactErr, relErr(ref.Phi, iv.Phi), relErr(ref.Gamma, iv.Gamma)});
    // The shortcut: ZOH of A, B frozen at the interval's midpoint.
    MatrixXd A, B;
    tvSystem(0.5 * (iv.t0 + iv.t1), A, B);
    const auto zoh = trellis::discretizeZeroOrderHold(A, B, iv.t1 - iv.t0);
    frozenErr = std::max({frozenErr, relErr(ref.Phi, zoh.Ad), relErr(ref.Gamma, zoh.Bd)});
  }
  INFO("exact " << exactErr << ", frozen midpoint " << frozenErr);
  // The frozen-A error is the O(h³) term of Ȧ, Ḃ (here ~1e-3): what the exact integration removes.
  CHECK(frozenErr > 1e-4);
  CHECK(frozenErr > 1e4 * exactErr);
  // The joint cost matrix is symmetric PSD (it is an integral of Gram matrices + R).
  for (const SampledInterval& iv : disc.intervals) {
    MatrixXd M(3, 3);
    M << iv.Q, iv.N, iv.N.transpose(), iv.R;
    CHECK(Eigen::SelfAdjointEigenSolver<MatrixXd>(M).eigenvalues().minCoeff() > -1e-12);
  }
}

TEST_CASE("sampled LQR: the recursion with cross term minimizes the stacked cost (manufactured)",
          "[sampled]") {
  // Random intervals (nx = 3, m = 2, 4 steps) with a PSD joint cost; the optimal cost
  // x0ᵀ S0 x0 and the first input against the brute-force minimization over all inputs.
  std::mt19937 rng(11);
  std::normal_distribution<double> g;
  auto rnd = [&](int r, int c) {
    MatrixXd M(r, c);
    for (int i = 0; i < r; ++i)
      for (int j = 0; j < c; ++j) M(i, j) = g(rng);
    return M;
  };
  const int nx = 3, m = 2, N = 4;
  std::vector<SampledInterval> ivs(N);
  for (int k = 0; k < N; ++k) {
    SampledInterval& iv = ivs[k];
    iv.t0 = k;
    iv.t1 = k + 1;
    iv.Phi = rnd(nx, nx);
    iv.Gamma = rnd(nx, m);
    const MatrixXd L = rnd(nx + m, nx + m);
    MatrixXd J = L * L.transpose();
    J.bottomRightCorner(m, m) += 0.5 * MatrixXd::Identity(m, m);
    iv.Q = J.topLeftCorner(nx, nx);
    iv.N = J.topRightCorner(nx, m);
    iv.R = J.bottomRightCorner(m, m);
  }
  const MatrixXd L = rnd(nx, nx);
  const MatrixXd Qf = L * L.transpose();
  const auto rec = trellis::solveSampledRiccatiRecursion(ivs, Qf);
  REQUIRE(rec.ok());
  REQUIRE(rec.S.size() == std::size_t(N + 1));
  REQUIRE(rec.K.size() == std::size_t(N));

  // x_k = Ex[k] x0 + Eu[k] u (u stacked), J = Σ [x_k; u_k]ᵀ W_k [x_k; u_k] + x_Nᵀ Qf x_N.
  std::vector<MatrixXd> Ex(N + 1), Eu(N + 1);
  Ex[0] = MatrixXd::Identity(nx, nx);
  Eu[0] = MatrixXd::Zero(nx, N * m);
  MatrixXd H = MatrixXd::Zero(N * m, N * m), Lx = MatrixXd::Zero(N * m, nx), P = MatrixXd::Zero(nx, nx);
  for (int k = 0; k < N; ++k) {
    Ex[k + 1] = ivs[k].Phi * Ex[k];
    Eu[k + 1] = ivs[k].Phi * Eu[k];
    Eu[k + 1].middleCols(k * m, m) += ivs[k].Gamma;
    MatrixXd Su = Eu[k];  // [x_k; u_k] = Zx x0 + Zu u
    MatrixXd Zx(nx + m, nx), Zu(nx + m, N * m);
    Zx << Ex[k], MatrixXd::Zero(m, nx);
    Zu << Su, MatrixXd::Zero(m, N * m);
    Zu.block(nx, k * m, m, m).setIdentity();
    MatrixXd W(nx + m, nx + m);
    W << ivs[k].Q, ivs[k].N, ivs[k].N.transpose(), ivs[k].R;
    H += Zu.transpose() * W * Zu;
    Lx += Zu.transpose() * W * Zx;
    P += Zx.transpose() * W * Zx;
  }
  H += Eu[N].transpose() * Qf * Eu[N];
  Lx += Eu[N].transpose() * Qf * Ex[N];
  P += Ex[N].transpose() * Qf * Ex[N];
  // min over u of uᵀHu + 2uᵀLx x0 + x0ᵀPx0 = x0ᵀ(P − Lxᵀ H⁻¹ Lx)x0, u* = −H⁻¹ Lx x0.
  const Eigen::LLT<MatrixXd> llt(H);
  REQUIRE(llt.info() == Eigen::Success);
  const MatrixXd S0 = P - Lx.transpose() * llt.solve(Lx);
  const MatrixXd Ustar = -llt.solve(Lx);  // columns: u* for x0 = e_j
  CHECK(relErr(S0, rec.S[0]) < 1e-10);
  CHECK(relErr(Ustar.topRows(m), -rec.K[0]) < 1e-10);
  // Along the optimal sequence the feedback reproduces every input.
  const VectorXd x0 = rnd(nx, 1);
  VectorXd x = x0;
  const VectorXd ustar = Ustar * x0;
  for (int k = 0; k < N; ++k) {
    const VectorXd u = -rec.K[k] * x;
    CHECK((u - ustar.segment(k * m, m)).norm() < 1e-9 * (1.0 + ustar.norm()));
    x = ivs[k].Phi * x + ivs[k].Gamma * u;
  }
}

TEST_CASE("sampled LQR: a long horizon on a time-invariant system converges to the DARE",
          "[sampled]") {
  // The cart-pole's upright linearization (unstable), h = 0.02.
  const Model model = trellis::ctest::makeCartPole();
  trellis::Data data(model);
  const VectorXd z2 = VectorXd::Zero(2), u = VectorXd::Zero(1);
  REQUIRE(trellis::computeLinearization(model, data, z2, z2, u).ok());
  const MatrixXd A = data.A, B = data.B;
  const LqrWeights w = cartPoleWeights();
  const double h = 0.02;
  const trellis::LinearizationCallback lin = [&](double, MatrixXd& Am, MatrixXd& Bm) {
    Am = A;
    Bm = B;
    return trellis::ReferenceStatus{};
  };
  const auto disc = trellis::discretizeSampledData((VectorXd(2) << 0.0, h).finished(), 4, 1, lin, w);
  REQUIRE(disc.ok());
  const SampledInterval iv = disc.intervals[0];
  // Time invariant: Φ, Γ are the matrix-exponential ZOH.
  const auto zoh = trellis::discretizeZeroOrderHold(A, B, h);
  CHECK(relErr(zoh.Ad, iv.Phi) < 1e-9);
  CHECK(relErr(zoh.Bd, iv.Gamma) < 1e-9);
  // Cost by Van Loan's block exponential: exp([[−Aᵀ, Q, 0], [0, A, B], [0, 0, 0]]·h)... checked
  // here more simply at h → the midpoint rule: Q_k ≈ h Q, R_k ≈ h R to O(h²).
  CHECK(relErr(h * w.Q, iv.Q) < 0.1);
  CHECK(relErr(h * w.R, iv.R) < 0.01);

  const std::vector<SampledInterval> ivs(3000, iv);  // 60 s
  const auto rec = trellis::solveSampledRiccatiRecursion(ivs, w.Qf);
  REQUIRE(rec.ok());
  // The DARE with cross term equals the plain DARE of (Φ − ΓR⁻¹Nᵀ, Γ, Q − NR⁻¹Nᵀ, R), with
  // K = K̃ + R⁻¹Nᵀ.
  const MatrixXd RiNt = iv.R.llt().solve(iv.N.transpose());
  const MatrixXd At = iv.Phi - iv.Gamma * RiNt;
  MatrixXd Qt = iv.Q - iv.N * RiNt;
  Qt = 0.5 * (Qt + Qt.transpose());
  const auto dare = trellis::solveDare(At, iv.Gamma, Qt, iv.R);
  REQUIRE(dare.ok());
  CHECK(relErr(dare.S, rec.S[0]) < 1e-8);
  CHECK(relErr(dare.K + RiNt, rec.K[0]) < 1e-8);
  // And the sampled gain differs from the continuous CARE gain by O(h) (the reason to compute it).
  const auto care = trellis::solveCare(A, B, w.Q, w.R);
  REQUIRE(care.ok());
  const double diff = relErr(care.K, rec.K[0]);
  INFO("|K_sampled - K_care| / |K_care| = " << diff);
  CHECK(diff > 1e-3);
  CHECK(diff < 0.5);
}

TEST_CASE("sampled LQR: gains approach the continuous gains as the rate grows, at O(h)",
          "[sampled]") {
  const Model model = trellis::ctest::makeCartPole();
  const Trajectory ref = swingReference(model, 1.5);
  const LqrWeights w = cartPoleWeights();
  trellis::RiccatiOptions ro;
  ro.rtol = 1e-11;
  ro.atol = 1e-12;
  const trellis::RiccatiSolution cont = trellis::solveRiccati(model, ref, w, ro);
  REQUIRE(cont.ok());
  std::vector<double> errors;
  std::ostringstream table;
  for (double rate : {50.0, 100.0, 200.0, 400.0}) {
    trellis::TvlqrOptions opt;
    opt.sampleRate = rate;
    const trellis::TvlqrSolution sol = trellis::solveTvlqr(model, ref, w, opt);
    REQUIRE(sol.ok());
    REQUIRE(sol.gains.isSampled());
    double err = 0.0, scale = 0.0;
    for (int k = 0; k + 1 < sol.gains.size(); ++k) {
      const MatrixXd Kc = cont.K(sol.gains.times()(k));
      err = std::max(err, (Kc - sol.gains.gains()[k]).cwiseAbs().maxCoeff());
      scale = std::max(scale, Kc.cwiseAbs().maxCoeff());
    }
    errors.push_back(err / scale);
    table << rate << " Hz: " << err / scale << "\n";
  }
  INFO("max |K_k - K(t_k)| / max |K|:\n" << table.str());
  for (std::size_t i = 1; i < errors.size(); ++i) {
    const double ratio = errors[i - 1] / errors[i];
    INFO("ratio " << ratio);
    CHECK(ratio > 1.7);  // first order: halving h halves the difference
    CHECK(ratio < 2.3);
  }
  CHECK(errors.back() < 0.02);
}

TEST_CASE("sampled LQR: the cart-pole held upright by a 50 Hz controller with input bounds",
          "[sampled]") {
  const Model model = trellis::ctest::makeCartPole();
  const double T = 8.0;
  const Trajectory ref = constantReference(model, VectorXd::Zero(4), VectorXd::Zero(1), T);
  trellis::TvlqrOptions opt;
  opt.sampleRate = 50.0;
  const trellis::TvlqrSolution sol = trellis::solveTvlqr(model, ref, cartPoleWeights(), opt);
  REQUIRE(sol.ok());
  CHECK(sol.gains.size() == 401);  // 0, 0.02, …, 7.98 and T
  CHECK(sol.gains.sampleRate() == 50.0);
  CHECK(sol.S.size() == 401);
  const double limit = 4.0;
  SimulationOptions so;
  so.sampleRate = 50.0;
  so.outputStep = 0.02;
  so.inputLower = VectorXd::Constant(1, -limit);
  so.inputUpper = VectorXd::Constant(1, limit);
  for (double angle : {0.15, -0.2}) {
    const VectorXd x0 = (VectorXd(4) << 0.1, angle, 0.0, 0.0).finished();
    const SimulationResult r = trellis::simulateClosedLoop(model, ref, sol.gains, x0, so);
    REQUIRE(r.ok());
    INFO("angle " << angle << ": final error " << r.trackingError(r.trackingError.size() - 1));
    CHECK(r.trackingError(r.trackingError.size() - 1) < 1e-2 * r.trackingError(0));
    CHECK(r.saturatedSamples > 0);  // the bound was active
    CHECK(r.trajectory.inputs().cwiseAbs().maxCoeff() <= limit);
    // u at a sample time is clip(−K_k x_k) with the sample's own gain.
    for (int k = 0; k < r.trajectory.size() - 1; k += 37) {
      const double uk = std::clamp(-(sol.gains.gains()[k] * r.trajectory.states().col(k))(0), -limit, limit);
      CHECK(r.trajectory.inputs()(0, k) == Approx(uk).epsilon(1e-10).margin(1e-12));
    }
  }
}

TEST_CASE("sampled LQR: on a constrained scene, on the tangent space", "[sampled]") {
  const Model model = trellis::ctest::makeConstrainedCarts();
  const double T = 3.0;
  const Trajectory ref = constantReference(model, VectorXd::Zero(4), VectorXd::Zero(1), T);
  LqrWeights w;
  w.Q = MatrixXd::Identity(4, 4);
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = w.Q;
  trellis::TvlqrOptions opt;
  opt.sampleRate = 100.0;
  const trellis::TvlqrSolution sol = trellis::solveTvlqr(model, ref, w, opt);
  REQUIRE(sol.ok());
  CHECK(sol.constrained);
  CHECK(sol.dimension == 2);
  // The gain ignores the direction that leaves the manifold (x1 − x2 ≠ 0), and S is singular there.
  const VectorXd normalPos = (VectorXd(4) << 1.0, -1.0, 0.0, 0.0).finished().normalized();
  const VectorXd normalVel = (VectorXd(4) << 0.0, 0.0, 1.0, -1.0).finished().normalized();
  for (int k = 0; k < sol.gains.size(); k += 50) {
    CHECK((sol.gains.gains()[k] * normalPos).norm() < 1e-10);
    CHECK((sol.gains.gains()[k] * normalVel).norm() < 1e-10);
    CHECK((sol.S[k] * normalPos).norm() < 1e-10);
  }
  // Two unit masses moving together: the reduced system is a double integrator of mass 2; the
  // gains converge (as the rate grows) to those of the continuous manifold solve.
  opt.sampleRate = 0.0;
  opt.riccati.rtol = 1e-11;
  opt.riccati.atol = 1e-12;
  const trellis::TvlqrSolution cont = trellis::solveTvlqr(model, ref, w, opt);
  REQUIRE(cont.ok());
  const MatrixXd K0c = cont.gains.gains()[0];
  const MatrixXd K0d = sol.gains.gains()[0];
  INFO("continuous K0 " << K0c << ", sampled K0 " << K0d);
  CHECK(relErr(K0c, K0d) < 0.05);
  CHECK(relErr(K0c, K0d) > 1e-5);
}

namespace {

/// Loads its own model, solves, returns the solution; the model dies on return.
trellis::RiccatiSolution solveWithOwnModel(std::vector<std::pair<double, MatrixXd>>& alive) {
  const Model model = trellis::ctest::makeCartPole();
  const Trajectory ref = swingReference(model, 1.0);
  trellis::RiccatiSolution sol = trellis::solveRiccati(model, ref, cartPoleWeights());
  REQUIRE(sol.ok());
  // K with the model alive, by an independent path (R⁻¹ Bᵀ S from a fresh linearization), at
  // step times and between them.
  const auto lin = trellis::makeTrajectoryLinearization(model, ref);
  for (double t : {0.0, 0.1234, 0.5, 0.777, 1.0}) {
    MatrixXd A(4, 4), B(4, 1);
    lin(t, A, B);
    alive.emplace_back(t, B.transpose() * sol.S(t));  // R = 1
  }
  return sol;
}

/// The 6-link damped chain's free swing from q_i = 0.3 rad at rest, u = 0, over [0, T] (rtol 1e-11,
/// knots every 20 ms): the stiff moving reference of the sampled tests.
SimulationResult chainSwing(const Model& model, double T) {
  SimulationOptions so;
  so.rtol = 1e-11;
  so.atol = 1e-12;
  so.outputStep = 0.02;
  const trellis::Policy zero = [](double, const VectorXd&, VectorXd& u) { u.setZero(); };
  const VectorXd x0 = (VectorXd(12) << VectorXd::Constant(6, 0.3), VectorXd::Zero(6)).finished();
  return trellis::simulate(model, x0, 0.0, T, zero, so);
}

/// Q = I (nx), R = I (nu), Qf = Q.
LqrWeights unitWeights(int nx, int nu) {
  LqrWeights w;
  w.Q = MatrixXd::Identity(nx, nx);
  w.R = MatrixXd::Identity(nu, nu);
  w.Qf = w.Q;
  return w;
}

}  // namespace

TEST_CASE("riccati: a solution outlives its model (run under asan)", "[sampled][lifetime]") {
  std::vector<std::pair<double, MatrixXd>> alive;
  trellis::RiccatiSolution copy;
  {
    const trellis::RiccatiSolution returned = solveWithOwnModel(alive);
    copy = returned;  // copy, then the original dies too
  }
  REQUIRE(copy.ok());
  for (const auto& [t, K] : alive) {
    INFO("t = " << t);
    // Between nodes the stored R⁻¹Bᵀ is interpolated by a cubic: error O(h⁴) in the step size.
    CHECK(relErr(K, copy.K(t)) < 1e-5);
    CHECK(copy.S(t).allFinite());
  }
  // At the stored nodes the gain is exact.
  const std::vector<double> nodes = copy.gainNodeTimes();
  REQUIRE(nodes.size() >= 3);
  CHECK(nodes.front() == Approx(0.0).margin(1e-12));
  CHECK(nodes.back() == 1.0);
}

TEST_CASE("gain schedule: named columns, sample rate, checks against the scene", "[sampled]") {
  const Model model = trellis::ctest::makeCartPole();
  const Trajectory ref = constantReference(model, VectorXd::Zero(4), VectorXd::Zero(1), 1.0);
  trellis::TvlqrOptions opt;
  opt.sampleRate = 20.0;
  const trellis::TvlqrSolution sol = trellis::solveTvlqr(model, ref, cartPoleWeights(), opt);
  REQUIRE(sol.ok());
  std::stringstream csv;
  sol.gains.writeCsv(csv);
  const std::string text = csv.str();
  INFO(text.substr(0, 200));
  CHECK(text.find("# trellis gain schedule: m=1 nx=4 sample_rate_hz=20") == 0);
  CHECK(text.find("t,K[push|x],K[push|theta],K[push|dx],K[push|dtheta],uff[push]\n") != std::string::npos);
  const GainSchedule back = GainSchedule::readCsv(csv, "mem");
  CHECK(back.sampleRate() == 20.0);
  // A held equilibrium: the held input u_ref carries it exactly, so the feed-forward is u_ref.
  REQUIRE(back.hasFeedforward());
  for (const VectorXd& u : back.feedforward()) CHECK(u(0) == 0.0);
  CHECK(back.size() == sol.gains.size());
  CHECK((back.gains()[3] - sol.gains.gains()[3]).norm() == 0.0);
  const auto states = GainSchedule::stateNames(model.configNames());
  CHECK_NOTHROW(back.checkNames(model.inputNames(), states, "mem"));
  // Same sizes, other names: refused, naming the column.
  const std::vector<std::string> other = {"y", "phi", "dy", "dphi"};
  try {
    back.checkNames(model.inputNames(), other, "mem");
    FAIL("expected a name mismatch");
  } catch (const trellis::TrajectoryError& e) {
    CHECK(std::string(e.what()).find("column 2 is 'K[push|x]', but the scene's gain column there is 'K[push|y]'") !=
          std::string::npos);
  }
  // The older layout (no metadata line, K_i_j) is read as continuous gains.
  std::stringstream old("t,K_0_0,K_0_1\n0,1,2\n1,3,4\n");
  const GainSchedule legacy = GainSchedule::readCsv(old, "old");
  CHECK(legacy.sampleRate() == 0.0);
  CHECK(legacy.columnNames().empty());
  CHECK(legacy.nx() == 2);
  // Named columns without the metadata line: a clear refusal.
  std::stringstream named("t,K_push_x,K_push_theta\n0,1,2\n");
  CHECK_THROWS_WITH(GainSchedule::readCsv(named, "named"),
                    Catch::Contains("need the '# trellis gain schedule: m=.. nx=..' line"));
  // The summary and JSON say what the gains are.
  CHECK(sol.summary().find("zero-order-hold gains for a controller sampling at 20 Hz") != std::string::npos);
  CHECK(sol.json().find("\"mode\":\"sampled\",\"sample_rate_hz\":20.0") != std::string::npos);
}

namespace {

/// Loads its own model, solves with solveTvlqr (continuous or sampled), records what the gains are
/// while the model is alive, and returns the solution; the model dies on return.
trellis::TvlqrSolution tvlqrWithOwnModel(double rate, std::vector<MatrixXd>& alive) {
  const Model model = trellis::ctest::makeCartPole();
  const Trajectory ref = swingReference(model, 1.0);
  trellis::TvlqrOptions opt;
  opt.sampleRate = rate;
  trellis::TvlqrSolution sol = trellis::solveTvlqr(model, ref, cartPoleWeights(), opt);
  REQUIRE(sol.ok());
  // Independently of the solution's storage: continuous K = R⁻¹ Bᵀ S from a fresh linearization
  // (R = 1); sampled K_k = (R_k + ΓᵀS_{k+1}Γ)⁻¹(ΓᵀS_{k+1}Φ + N_kᵀ) is checked at one step.
  alive.clear();
  const auto lin = trellis::makeTrajectoryLinearization(model, ref);
  for (int k = 0; k < sol.gains.size(); k += 17) {
    MatrixXd A(4, 4), B(4, 1);
    lin(sol.gains.times()(k), A, B);
    alive.push_back(rate > 0.0 ? sol.gains.gains()[k] : MatrixXd(B.transpose() * sol.S[k]));
  }
  return sol;
}

}  // namespace

TEST_CASE("solveTvlqr: a solution outlives its model, continuous and sampled (run under asan)",
          "[sampled][lifetime]") {
  for (double rate : {0.0, 100.0}) {
    INFO("rate " << rate);
    std::vector<MatrixXd> alive;
    trellis::TvlqrSolution copy;
    {
      const trellis::TvlqrSolution returned = tvlqrWithOwnModel(rate, alive);
      copy = returned;  // copy, then the original dies too
    }
    REQUIRE(copy.ok());
    CHECK(copy.gains.isSampled() == (rate > 0.0));
    REQUIRE(copy.S.size() == std::size_t(copy.gains.size()));
    std::size_t i = 0;
    for (int k = 0; k < copy.gains.size(); k += 17, ++i) {
      REQUIRE(i < alive.size());
      // Continuous: the stored K(t_k) against R⁻¹BᵀS(t_k) (both from the solve, the second with a
      // linearization made while the model lived); sampled: the gains read back after the model died.
      CHECK(relErr(alive[i], copy.gains.gains()[k]) < 1e-8);
      CHECK(copy.S[k].allFinite());
    }
    CHECK(!copy.summary().empty());
    CHECK(copy.json().find("\"ok\":true") != std::string::npos);
  }
}

TEST_CASE("solveTvlqr: numerical failure is the status, with describe() and json() reports",
          "[tvlqr][status]") {
  const trellis::TvlqrSolution unsolved;
  CHECK_FALSE(unsolved.ok());
  CHECK(std::string(unsolved.status.name()) == "not_solved");

  const Model model = trellis::ctest::makeCartPole();
  const Trajectory ref = swingReference(model, 1.5);
  const LqrWeights w = cartPoleWeights();
  trellis::TvlqrOptions opt;
  opt.riccati.maxSteps = 3;  // far too few: the continuous solve stops
  trellis::TvlqrSolution sol;
  REQUIRE_NOTHROW(sol = trellis::solveTvlqr(model, ref, w, opt));
  CHECK_FALSE(sol.ok());
  CHECK(sol.status.code == trellis::TvlqrCode::kRiccatiFailure);
  CHECK_THAT(sol.status.message, Catch::Contains("integrator_failure") && Catch::Contains("maxSteps = 3"));
  CHECK(std::isfinite(sol.status.t));
  CHECK(sol.gains.size() == 0);
  CHECK_THAT(sol.describe(), Catch::StartsWith("riccati_failure at t = "));
  CHECK_THAT(sol.json(), Catch::StartsWith("{\"status\":\"riccati_failure\",\"ok\":false,\"message\":"));
  CHECK_THAT(sol.json(), Catch::Contains("\"rows\":0") && Catch::Contains("\"t0\":null"));

  opt = {};
  opt.sampleRate = 100.0;
  const trellis::TvlqrSolution good = trellis::solveTvlqr(model, ref, w, opt);
  REQUIRE(good.ok());
  CHECK_THAT(good.describe(), Catch::StartsWith("ok (sampled at 100 Hz, full state, "));
  CHECK_THAT(good.json(), Catch::StartsWith("{\"status\":\"ok\",\"ok\":true,\"message\":\"\",\"t\":null,"
                                           "\"index\":null,\"mode\":\"sampled\""));
}

namespace {

/// max |got − expected| over the gains, relative to max |expected|.
double gainDifference(const std::vector<MatrixXd>& expected, const std::vector<MatrixXd>& got) {
  REQUIRE(expected.size() == got.size());
  double scale = 0.0, diff = 0.0;
  for (std::size_t k = 0; k < expected.size(); ++k) {
    scale = std::max(scale, expected[k].cwiseAbs().maxCoeff());
    diff = std::max(diff, (got[k] - expected[k]).cwiseAbs().maxCoeff());
  }
  return diff / scale;
}

/// The recursion's gains on both discretizations (each must succeed) and gainDifference of them.
double recursionGainDifference(const trellis::SampledDiscretization& expected,
                               const trellis::SampledDiscretization& got, const MatrixXd& Qf) {
  const auto e = trellis::solveSampledRiccatiRecursion(expected.intervals, Qf);
  const auto g = trellis::solveSampledRiccatiRecursion(got.intervals, Qf);
  REQUIRE(e.ok());
  REQUIRE(g.ok());
  return gainDifference(e.K, g.K);
}

/// max over the blocks of |got − expected| relative to the block's own max |entry|.
double intervalDifference(const SampledInterval& e, const SampledInterval& g) {
  auto rel = [](const MatrixXd& x, const MatrixXd& y) {
    return (x - y).cwiseAbs().maxCoeff() / std::max(x.cwiseAbs().maxCoeff(), 1e-300);
  };
  return std::max({rel(e.Phi, g.Phi), rel(e.Gamma, g.Gamma), rel(e.Q, g.Q), rel(e.N, g.N), rel(e.R, g.R)});
}

}  // namespace

TEST_CASE("sampled LQR: constant intervals by the exact block exponential agree with the integration",
          "[sampled][exponential]") {
  // Two coupled damped oscillators, one stiff: λ ≈ −7.2 and −1393, so λh ≈ 139 at h = 0.1 — where
  // Van Loan's single exponential over h has no correct digit left in the cost blocks.
  MatrixXd A = MatrixXd::Zero(4, 4);
  A.topRightCorner(2, 2).setIdentity();
  A.bottomLeftCorner(2, 2) << -1e4, 30.0, 30.0, -10.0;
  A.bottomRightCorner(2, 2) << -1400.0, 2.0, 2.0, -0.5;
  MatrixXd B = MatrixXd::Zero(4, 2);
  B.bottomRows(2) << 1.0, 0.3, 0.0, 1.0;
  LqrWeights w;
  w.Q = VectorXd((VectorXd(4) << 10.0, 10.0, 1.0, 1.0).finished()).asDiagonal();
  w.R = (MatrixXd(2, 2) << 1.0, 0.2, 0.2, 0.5).finished();
  w.Qf = w.Q;
  const trellis::LinearizationCallback lin = [&](double, MatrixXd& Am, MatrixXd& Bm) {
    Am = A;
    Bm = B;
    return trellis::ReferenceStatus{};
  };
  trellis::SampledDiscretizationOptions tight;  // the integration, as the reference
  tight.integrator = trellis::SampledIntegrator::kBdf;
  tight.rtol = 1e-12;
  tight.atol = 1e-14;
  for (double h : {0.1, 0.01}) {
    INFO("h = " << h);
    SampledInterval exact;
    trellis::discretizeConstantInterval(A, B, w.Q, w.R, h, exact);
    const auto integrated = trellis::discretizeSampledData((VectorXd(2) << 0.0, h).finished(), 4, 2, lin, w, tight);
    REQUIRE(integrated.ok());
    // rtol 1e-12 on the integration: its blocks carry ~1e-11; the exponential is exact to rounding.
    CHECK(intervalDifference(integrated.intervals[0], exact) < 1e-9);
    // The cost blocks are a Gramian: symmetric PSD.
    MatrixXd W(6, 6);
    W << exact.Q, exact.N, exact.N.transpose(), exact.R;
    CHECK(Eigen::SelfAdjointEigenSolver<MatrixXd>(W).eigenvalues()(0) > -1e-12 * W.norm());
  }

  // A mild system (‖M‖h ≈ 1), where Van Loan's single exponential of the 2c×2c matrix (Eigen's
  // generic Padé) is accurate: an independent path to the structured Padé and doublings.
  {
    std::mt19937 rng(31);
    std::normal_distribution<double> normal;
    const MatrixXd Am = MatrixXd::NullaryExpr(4, 4, [&] { return normal(rng); });
    const MatrixXd Bm = MatrixXd::NullaryExpr(4, 2, [&] { return normal(rng); });
    const MatrixXd L = MatrixXd::NullaryExpr(4, 4, [&] { return normal(rng); });
    const MatrixXd Qm = L * L.transpose();
    const double h = 0.3;
    MatrixXd C = MatrixXd::Zero(12, 12);  // [[−M̃ᵀ, Q̃], [0, M̃]] h
    C.block(6, 6, 4, 4) = Am * h;
    C.block(6, 10, 4, 2) = Bm * h;
    C.topLeftCorner(6, 6) = -C.bottomRightCorner(6, 6).transpose();
    C.block(0, 6, 4, 4) = Qm * h;
    C.block(4, 10, 2, 2) = w.R * h;
    const MatrixXd F = C.exp();
    const MatrixXd Wv = F.bottomRightCorner(6, 6).transpose() * F.topRightCorner(6, 6);
    SampledInterval structured;
    trellis::discretizeConstantInterval(Am, Bm, Qm, w.R, h, structured);
    CHECK(relErr(F.block(6, 6, 4, 4), structured.Phi) < 1e-13);
    CHECK(relErr(F.block(6, 10, 4, 2), structured.Gamma) < 1e-13);
    CHECK(relErr(Wv.topLeftCorner(4, 4), structured.Q) < 1e-12);
    CHECK(relErr(Wv.topRightCorner(4, 2), structured.N) < 1e-12);
    CHECK(relErr(Wv.bottomRightCorner(2, 2), structured.R) < 1e-12);
  }

  // The recursion over 20 intervals: the exponential path (every interval declared constant,
  // sharing one exponential) against the integration of every interval.
  const VectorXd times = trellis::sampleTimes(0.0, 2.0, 10.0);
  const trellis::ConstantSpanCallback constant = [](double, double) { return 0.0; };
  const auto byExp = trellis::discretizeSampledData(times, 4, 2, lin, w, {}, {constant, {}});
  REQUIRE(byExp.ok());
  CHECK(byExp.constantIntervals == 20);
  CHECK(byExp.exponentials == 1);
  CHECK(byExp.steps == 0);
  const auto byOde = trellis::discretizeSampledData(times, 4, 2, lin, w, tight);
  REQUIRE(byOde.ok());
  CHECK(byOde.constantIntervals == 0);
  const auto recExp = trellis::solveSampledRiccatiRecursion(byExp.intervals, w.Qf);
  const auto recOde = trellis::solveSampledRiccatiRecursion(byOde.intervals, w.Qf);
  REQUIRE(recExp.ok());
  REQUIRE(recOde.ok());
  CHECK(gainDifference(recOde.K, recExp.K) < 1e-8);
  // Radau (the default) integrates only the difference to the system frozen at each interval's
  // start, whose blocks are the exact exponential: on a constant system the difference is zero to
  // rounding, so one step per interval is exact however stiff A is (λh ≈ 139 here; integrating Y
  // itself took hundreds of steps to resolve the fast mode's restart in every interval).
  SampledInterval exact;
  trellis::discretizeConstantInterval(A, B, w.Q, w.R, 0.1, exact);
  const auto byRadau = trellis::discretizeSampledData(times, 4, 2, lin, w);
  REQUIRE(byRadau.ok());
  CHECK(byRadau.steps == 20);
  CHECK(byRadau.exponentials == 20);
  for (std::size_t k = 0; k < byRadau.intervals.size(); ++k) {
    INFO("interval " << k);
    CHECK(intervalDifference(byRadau.intervals[k], exact) < 1e-12);
  }
  // exactConstantIntervals = false ignores the callback.
  trellis::SampledDiscretizationOptions off;
  off.exactConstantIntervals = false;
  CHECK(trellis::discretizeSampledData(times, 4, 2, lin, w, off, {constant, {}}).constantIntervals == 0);
  // A callback that throws is the status, naming the interval.
  const trellis::ConstantSpanCallback throws = [](double, double) -> double { throw std::runtime_error("no"); };
  const auto failed = trellis::discretizeSampledData(times, 4, 2, lin, w, {}, {throws, {}});
  CHECK(failed.status.code == trellis::SampledCode::kCallbackFailure);
  CHECK(failed.status.message.find("interval 0") != std::string::npos);
  SampledInterval unused;
  CHECK_THROWS_AS(trellis::discretizeConstantInterval(A, B, w.Q, w.R, 0.0, unused), std::invalid_argument);
}

TEST_CASE("solveTvlqr sampled: a held pose and a reference at rest on part of its span use the exponential",
          "[sampled][exponential]") {
  const Model model = trellis::ctest::makeCartPole();
  trellis::TvlqrOptions exact, integrated;
  exact.sampleRate = integrated.sampleRate = 50.0;
  integrated.sampled.exactConstantIntervals = false;
  integrated.sampled.integrator = trellis::SampledIntegrator::kBdf;
  integrated.sampled.rtol = 1e-12;
  integrated.sampled.atol = 1e-14;
  SECTION("held upright") {
    const Trajectory ref = constantReference(model, VectorXd::Zero(4), VectorXd::Zero(1), 2.0);
    const trellis::TvlqrSolution a = trellis::solveTvlqr(model, ref, cartPoleWeights(), exact);
    const trellis::TvlqrSolution b = trellis::solveTvlqr(model, ref, cartPoleWeights(), integrated);
    REQUIRE(a.ok());
    REQUIRE(b.ok());
    CHECK(a.steps == 0);  // no interval integrated
    CHECK(b.steps > 0);
    CHECK(gainDifference(b.gains.gains(), a.gains.gains()) < 1e-8);
  }
  SECTION("at rest for 0.5 s, then moving") {
    // Knots 0, 0.5 at rest upright (ẋ = 0 there: the upright is an equilibrium), then a motion:
    // the first 25 intervals are constant, the rest are integrated.
    MatrixXd X = MatrixXd::Zero(4, 4), U = MatrixXd::Zero(1, 4);
    X.col(2) << 0.1, 0.05, 0.2, 0.1;
    X.col(3) << 0.3, 0.1, 0.2, 0.0;
    U << 0.0, 0.0, 0.5, -0.2;
    Trajectory ref(model.configNames(), model.inputNames(), (VectorXd(4) << 0.0, 0.5, 1.0, 1.5).finished(), X, U);
    trellis::Data data(model);
    ref.computeStateDerivatives(model, data);
    REQUIRE(ref.stateDerivatives().leftCols(2).isZero(0.0));
    const trellis::TvlqrSolution a = trellis::solveTvlqr(model, ref, cartPoleWeights(), exact);
    trellis::TvlqrOptions loose = exact;
    loose.sampled.exactConstantIntervals = false;
    const trellis::TvlqrSolution c = trellis::solveTvlqr(model, ref, cartPoleWeights(), loose);
    const trellis::TvlqrSolution b = trellis::solveTvlqr(model, ref, cartPoleWeights(), integrated);
    REQUIRE(a.ok());
    REQUIRE(b.ok());
    REQUIRE(c.ok());
    CHECK(a.steps > 0);
    CHECK(a.steps < c.steps);  // the constant part was not integrated
    // The moving part is integrated at the default tolerances (rtol 1e-10): its own error.
    CHECK(gainDifference(b.gains.gains(), a.gains.gains()) < 1e-8);
  }
}

TEST_CASE("sampled LQR: the Radau and Magnus integrations agree with CVODES on time-varying and stiff systems",
          "[sampled][magnus][radau]") {
  trellis::SampledDiscretizationOptions bdf;  // the reference: every interval by CVODES, tight
  bdf.integrator = trellis::SampledIntegrator::kBdf;
  bdf.rtol = 1e-12;
  bdf.atol = 1e-14;
  const trellis::SampledIntegrator method =
      GENERATE(trellis::SampledIntegrator::kRadau, trellis::SampledIntegrator::kMagnus);
  trellis::SampledDiscretizationOptions fast;
  fast.integrator = method;
  INFO(trellis::toString(method));
  // The interval blocks are compared at 1e-9, below what Radau's default rtol (kRadauRtol, sized
  // for the gains) leaves on them (~1e-9): those sections set 1e-10; the gains' sections keep
  // each method's default.
  trellis::SampledDiscretizationOptions blocks = fast;
  blocks.rtol = trellis::SampledDiscretizationOptions::kRtol;
  SECTION("fast-changing 2-state system") {
    LqrWeights w;
    w.Q = (MatrixXd(2, 2) << 3.0, 0.5, 0.5, 1.0).finished();
    w.R = MatrixXd::Constant(1, 1, 0.7);
    w.Qf = w.Q;
    const VectorXd times = trellis::sampleTimes(0.0, 3.0, 10.0);
    const auto magnus = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w, blocks);
    const auto ref = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w, bdf);
    REQUIRE(magnus.ok());
    REQUIRE(ref.ok());
    for (std::size_t k = 0; k < ref.intervals.size(); ++k) {
      INFO("interval " << k);
      CHECK(intervalDifference(ref.intervals[k], magnus.intervals[k]) < 1e-9);
    }
    CHECK(recursionGainDifference(ref, magnus, w.Qf) < 1e-8);
    CHECK(magnus.steps < ref.steps);  // no restart per interval
    // The gains at the method's default rtol.
    const auto byDefault = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w, fast);
    REQUIRE(byDefault.ok());
    CHECK(recursionGainDifference(ref, byDefault, w.Qf) < 1e-8);
  }
  SECTION("a state weight that drops 1e6-fold from one interval to the next") {
    // Radau measures the cost's error against (among others) the previous interval's cost rate:
    // a weight that falls at a sample time must not loosen the next interval's test.
    LqrWeights w;
    w.Qfun = [](double t, MatrixXd& Q) {
      Q = (MatrixXd(2, 2) << 3.0, 0.5, 0.5, 1.0).finished();
      if (t < 1.0) Q *= 1e6;
    };
    w.R = MatrixXd::Constant(1, 1, 0.7);
    w.Qf = MatrixXd::Identity(2, 2);
    const VectorXd times = trellis::sampleTimes(0.0, 2.0, 10.0);
    const auto fastOut = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w, blocks);
    const auto ref = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w, bdf);
    REQUIRE(fastOut.ok());
    REQUIRE(ref.ok());
    for (std::size_t k = 0; k < ref.intervals.size(); ++k) {
      INFO("interval " << k);
      CHECK(intervalDifference(ref.intervals[k], fastOut.intervals[k]) < 1e-9);
    }
  }
  SECTION("stiff (λh ≈ 140) and time-varying") {
    // The stiff oscillator pair of the exponential test with a slowly varying coupling and input.
    const trellis::LinearizationCallback lin = [](double t, MatrixXd& A, MatrixXd& B) { return stiffPair(t, A, B); };
    LqrWeights w;
    w.Q = VectorXd((VectorXd(4) << 10.0, 10.0, 1.0, 1.0).finished()).asDiagonal();
    w.R = MatrixXd::Identity(2, 2);
    w.Qf = w.Q;
    const VectorXd times = trellis::sampleTimes(0.0, 2.0, 10.0);
    const auto magnus = trellis::discretizeSampledData(times, 4, 2, lin, w, fast);
    const auto ref = trellis::discretizeSampledData(times, 4, 2, lin, w, bdf);
    REQUIRE(magnus.ok());
    REQUIRE(ref.ok());
    CHECK(recursionGainDifference(ref, magnus, w.Qf) < 1e-8);
  }
  SECTION("solveTvlqr along the cart-pole's swing, knots every 10 ms") {
    const Model model = trellis::ctest::makeCartPole();
    const Trajectory ref = swingReference(model, 1.0);
    trellis::TvlqrOptions magnus, cvodes;
    magnus.sampleRate = cvodes.sampleRate = 50.0;
    magnus.sampled = fast;
    cvodes.sampled = bdf;
    const trellis::TvlqrSolution a = trellis::solveTvlqr(model, ref, cartPoleWeights(), magnus);
    const trellis::TvlqrSolution b = trellis::solveTvlqr(model, ref, cartPoleWeights(), cvodes);
    REQUIRE(a.ok());
    REQUIRE(b.ok());
    CHECK(gainDifference(b.gains.gains(), a.gains.gains()) < 1e-8);
  }
}

TEST_CASE("sampled LQR: Radau's halved stage solve of a mechanical system equals the full solve",
          "[sampled][radau]") {
  // x = [q; v] with A = [[0, I], [Aq, Av]], B = [0; Bv] takes the halved stage system (3p×3p
  // instead of 3nx×3nx, and p×p filters and twin solves); the same system written as [v; q] is not
  // detected and takes the full ones. With P that permutation the blocks must be P-congruent
  // (Φ' = PΦPᵀ, Γ' = PΓ, the cost likewise) to rounding, on the same steps (the error norms are
  // permutation-invariant). The stiff time-varying pair (|λ|h ≈ 140) and, from t = 1, an A whose
  // q̇ row is no longer the identity (the full solve also inside the [q; v] run: both paths, one
  // interval after the other, against CVODES).
  for (const bool breakFromOne : {false, true}) {
    INFO((breakFromOne ? "structure broken from t = 1" : "mechanical throughout"));
    const trellis::LinearizationCallback lin = [breakFromOne](double t, MatrixXd& A, MatrixXd& B) {
      return stiffPair(t, A, B, breakFromOne ? 0.1 : 0.0);
    };
    Eigen::PermutationMatrix<Eigen::Dynamic> P(4);  // [q; v] → [v; q]
    P.indices() << 2, 3, 0, 1;
    const trellis::LinearizationCallback swapped = [&](double t, MatrixXd& A, MatrixXd& B) {
      MatrixXd A0, B0;
      lin(t, A0, B0);
      A = P * A0 * P.transpose();
      B = P * B0;
      return trellis::ReferenceStatus{};
    };
    LqrWeights w, ws;
    w.Q = (MatrixXd(4, 4) << 10, 1, 0.5, 0, 1, 10, 0, 0.2, 0.5, 0, 1, 0.1, 0, 0.2, 0.1, 1).finished();
    w.R = (MatrixXd(2, 2) << 1.0, 0.2, 0.2, 2.0).finished();
    w.Qf = w.Q;
    ws.Q = P * w.Q * P.transpose();
    ws.R = w.R;
    ws.Qf = ws.Q;
    const VectorXd times = trellis::sampleTimes(0.0, 2.0, 10.0);
    const auto halved = trellis::discretizeSampledData(times, 4, 2, lin, w);
    const auto full = trellis::discretizeSampledData(times, 4, 2, swapped, ws);
    REQUIRE(halved.ok());
    REQUIRE(full.ok());
    CHECK(halved.steps == full.steps);
    for (std::size_t k = 0; k < full.intervals.size(); ++k) {
      INFO("interval " << k);
      SampledInterval back = full.intervals[k];
      back.Phi = P.transpose() * full.intervals[k].Phi * P;
      back.Gamma = P.transpose() * full.intervals[k].Gamma;
      back.Q = P.transpose() * full.intervals[k].Q * P;
      back.N = P.transpose() * full.intervals[k].N;
      CHECK(intervalDifference(back, halved.intervals[k]) < 1e-11);
    }
    // Both right, not only equal: the gains against CVODES at rtol 1e-12.
    trellis::SampledDiscretizationOptions bdf;
    bdf.integrator = trellis::SampledIntegrator::kBdf;
    bdf.rtol = 1e-12;
    bdf.atol = 1e-14;
    const auto ref = trellis::discretizeSampledData(times, 4, 2, lin, w, bdf);
    REQUIRE(ref.ok());
    CHECK(recursionGainDifference(ref, halved, w.Qf) < 1e-8);
  }
}

TEST_CASE("sampled LQR: the Magnus exponential over whole intervals checks itself against its halves",
          "[sampled][magnus]") {
  trellis::SampledDiscretizationOptions bdf;  // the reference: every interval by CVODES, tight
  bdf.integrator = trellis::SampledIntegrator::kBdf;
  bdf.rtol = 1e-12;
  bdf.atol = 1e-14;
  trellis::SampledDiscretizationOptions magnus;
  magnus.integrator = trellis::SampledIntegrator::kMagnus;
  SECTION("one step per interval is not enough: the check bisects, or refuses when it may not") {
    // tvSystem at 2 Hz: A(t) turns over ~1 rad per 0.25 s, so a single sixth-order step over
    // 0.5 s misses rtol by orders of magnitude; with a smoothly varying Q(t) as well.
    LqrWeights w;
    w.Qfun = [](double t, MatrixXd& Q) {
      Q = (MatrixXd(2, 2) << 3.0 + std::sin(5.0 * t), 0.5, 0.5, 1.0 + 0.5 * std::cos(2.0 * t)).finished();
    };
    w.R = MatrixXd::Constant(1, 1, 0.7);
    w.Qf = MatrixXd::Identity(2, 2);
    const VectorXd times = trellis::sampleTimes(0.0, 3.0, 2.0);
    const auto ref = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w, bdf);
    const auto got = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w, magnus);
    REQUIRE(ref.ok());
    REQUIRE(got.ok());
    CHECK(got.bisections >= static_cast<long>(times.size() - 1));  // every interval was split
    for (std::size_t k = 0; k < ref.intervals.size(); ++k) {
      INFO("interval " << k);
      CHECK(intervalDifference(ref.intervals[k], got.intervals[k]) < 1e-9);
    }
    // Room for one check only (its two half steps): the first failing check is the status.
    trellis::SampledDiscretizationOptions tight = magnus;
    tight.maxSteps = 2;
    const auto refused = trellis::discretizeSampledData(times, 2, 1, &tvSystem, w, tight);
    CHECK(refused.status.code == trellis::SampledCode::kIntegratorFailure);
    CHECK(refused.status.index == 0);
    CHECK(refused.status.message.find("maxSteps = 2") != std::string::npos);
  }
  SECTION("the stiff 6-link chain's free swing at 10 and 100 Hz against CVODES at rtol 1e-12") {
    // |λ|h ≈ 140 / 14 for the fast modes; knots every 20 ms (at 10 Hz five pieces per interval).
    const Model model = trellis::ctest::makeDampedChain(6);
    const SimulationResult swing = chainSwing(model, 0.4);
    REQUIRE(swing.ok());
    const LqrWeights w = unitWeights(12, 6);
    for (double rate : {10.0, 100.0}) {
      INFO("rate " << rate);
      trellis::TvlqrOptions a, b;
      a.sampleRate = b.sampleRate = rate;
      a.sampled = magnus;
      b.sampled = bdf;
      const trellis::TvlqrSolution got = trellis::solveTvlqr(model, swing.trajectory, w, a);
      const trellis::TvlqrSolution exact = trellis::solveTvlqr(model, swing.trajectory, w, b);
      REQUIRE(got.ok());
      REQUIRE(exact.ok());
      CHECK(gainDifference(exact.gains.gains(), got.gains.gains()) < 1e-8);
    }
  }
}

TEST_CASE("sampled LQR: Radau's embedded estimate at its default rtol on the stiff chain at 10, 100, 1000 Hz",
          "[sampled][radau]") {
  // The 6-link chain's free swing (fast modes |λ| up to ~1.4e3: |λ|h ≈ 140 / 14 / 1.4): the default
  // integrator at its default tolerance (SampledDiscretizationOptions::kRadauRtol) against every
  // interval by CVODES at rtol 1e-12.
  const Model model = trellis::ctest::makeDampedChain(6);
  // 0.3 s (3 and 30 intervals at 10 and 100 Hz), its first 60 ms at 1000 Hz (the reference costs
  // ~10 ms per interval).
  const SimulationResult swing = chainSwing(model, 0.3);
  const SimulationResult start = chainSwing(model, 0.06);
  REQUIRE(swing.ok());
  REQUIRE(start.ok());
  const LqrWeights w = unitWeights(12, 6);
  trellis::TvlqrOptions fast, exact;
  exact.sampled.integrator = trellis::SampledIntegrator::kBdf;
  exact.sampled.rtol = 1e-12;
  exact.sampled.atol = 1e-14;
  REQUIRE(fast.sampled.integrator == trellis::SampledIntegrator::kRadau);
  CHECK(fast.sampled.relativeTolerance() == trellis::SampledDiscretizationOptions::kRadauRtol);
  CHECK(exact.sampled.relativeTolerance() == 1e-12);
  for (double rate : {10.0, 100.0, 1000.0}) {
    INFO("rate " << rate);
    fast.sampleRate = exact.sampleRate = rate;
    const Trajectory& reference = rate > 100.0 ? start.trajectory : swing.trajectory;
    const trellis::TvlqrSolution got = trellis::solveTvlqr(model, reference, w, fast);
    const trellis::TvlqrSolution ref = trellis::solveTvlqr(model, reference, w, exact);
    REQUIRE(got.ok());
    REQUIRE(ref.ok());
    CHECK(gainDifference(ref.gains.gains(), got.gains.gains()) < 1e-8);
  }
  SECTION("too few steps is the status, and a negative rtol is refused") {
    trellis::TvlqrOptions tight;
    tight.sampleRate = 10.0;
    tight.sampled.maxSteps = 3;  // the restart transient alone needs more
    const trellis::TvlqrSolution refused = trellis::solveTvlqr(model, swing.trajectory, w, tight);
    CHECK(!refused.ok());
    CHECK_THAT(refused.status.message, Catch::Contains("maxSteps = 3") && Catch::Contains("Radau"));
    tight.sampled.rtol = -1e-6;
    CHECK_THROWS_WITH(tight.sampled.validate(), Catch::Contains("rtol = -1e-06"));
  }
}

TEST_CASE("sampled LQR: Radau's A(t), B(t) interpolated between knots agree with the exact ones, and are exact where not smooth",
          "[sampled][radau][interpolation]") {
  // SampledStructure::smoothBetweenBreakpoints: A, B from a checked Chebyshev interpolant of exact
  // linearizations per piece between breakpoints (sampled_lqr.cpp, ChebyshevLinearization). The
  // blocks and gains against the same integration with A, B exact at every node.
  LqrWeights w;
  w.Q = VectorXd((VectorXd(4) << 10.0, 10.0, 1.0, 1.0).finished()).asDiagonal();
  w.R = MatrixXd::Identity(2, 2);
  w.Qf = w.Q;
  const VectorXd times = trellis::sampleTimes(0.0, 0.5, 100.0);
  trellis::SampledStructure knots;
  for (int i = 0; i <= 25; ++i) knots.breakpoints.push_back(0.02 * i);  // knots every 20 ms
  knots.smoothBetweenBreakpoints = true;
  trellis::SampledDiscretizationOptions on, off;
  off.interpolateLinearization = false;
  auto compare = [&](const trellis::LinearizationCallback& lin, const trellis::SampledStructure& s, long* pieces,
                     long* fallbacks) {
    const auto a = trellis::discretizeSampledData(times, 4, 2, lin, w, on, s);
    const auto b = trellis::discretizeSampledData(times, 4, 2, lin, w, off, s);
    REQUIRE(a.ok());
    REQUIRE(b.ok());
    CHECK(b.interpolationPieces == 0);
    double worst = 0.0;
    for (std::size_t k = 0; k < a.intervals.size(); ++k) worst = std::max(worst, intervalDifference(b.intervals[k], a.intervals[k]));
    INFO("pieces " << a.interpolationPieces << ", fallbacks " << a.interpolationFallbacks << ", linearizations "
                   << a.linearizations << " against " << b.linearizations);
    CHECK(worst < 1e-10);
    CHECK(recursionGainDifference(b, a, w.Qf) < 1e-10);
    CHECK(a.steps == b.steps);  // the same steps: A, B agree to far below what the estimate sees
    *pieces = a.interpolationPieces;
    *fallbacks = a.interpolationFallbacks;
    return a.linearizations < b.linearizations;
  };
  long pieces = 0, fallbacks = 0;
  SECTION("smooth between the knots: every span interpolated, far fewer linearizations") {
    const trellis::LinearizationCallback lin = [](double t, MatrixXd& A, MatrixXd& B) { return stiffPair(t, A, B); };
    CHECK(compare(lin, knots, &pieces, &fallbacks));
    CHECK(pieces == 25);
    CHECK(fallbacks == 0);
    // Without the caller's word nothing is interpolated.
    trellis::SampledStructure unknown = knots;
    unknown.smoothBetweenBreakpoints = false;
    const auto d = trellis::discretizeSampledData(times, 4, 2, lin, w, on, unknown);
    REQUIRE(d.ok());
    CHECK(d.interpolationPieces == 0);
    CHECK_THAT(d.json(), Catch::Contains("\"interpolation_pieces\":0"));
  }
  SECTION("a kink and a jump the caller did not declare: those pieces halved, then evaluated exactly") {
    for (const bool jump : {false, true}) {
      INFO((jump ? "jump" : "kink") << " at t = 0.1537");
      const trellis::LinearizationCallback lin = [jump](double t, MatrixXd& A, MatrixXd& B) {
        stiffPair(t, A, B);
        const double s = t - 0.1537;
        A(3, 0) += jump ? (s > 0.0 ? 40.0 : 0.0) : 400.0 * std::abs(s);
        B(2, 1) += jump ? 0.0 : 3.0 * std::abs(s);
        return trellis::ReferenceStatus{};
      };
      compare(lin, knots, &pieces, &fallbacks);
      CHECK(fallbacks == 1);  // the one piece (1/8 of a span) that holds the kink
      CHECK(pieces >= 25 + 2);  // the span's other pieces, interpolated
    }
  }
  SECTION("the check's verdicts do not depend on the states' units") {
    // x' = D x: A' = D A D⁻¹, B' = D B, Q' = D⁻¹ Q D⁻¹ (the same cost); the same pieces and
    // fallbacks (a kink included).
    const VectorXd dvec = (VectorXd(4) << 1e3, 1.0, 1e-2, 7.0).finished();
    const MatrixXd D = dvec.asDiagonal(), Di = dvec.cwiseInverse().asDiagonal();
    auto base = [](double t, MatrixXd& A, MatrixXd& B) {
      stiffPair(t, A, B);
      A(3, 0) += 400.0 * std::abs(t - 0.1537);
      return trellis::ReferenceStatus{};
    };
    const trellis::LinearizationCallback lin = base;
    const trellis::LinearizationCallback scaled = [&](double t, MatrixXd& A, MatrixXd& B) {
      base(t, A, B);
      A = D * A * Di;
      B = D * B;
      return trellis::ReferenceStatus{};
    };
    LqrWeights ws = w;
    ws.Q = Di * w.Q * Di;
    ws.Qf = Di * w.Qf * Di;
    const auto a = trellis::discretizeSampledData(times, 4, 2, lin, w, on, knots);
    const auto b = trellis::discretizeSampledData(times, 4, 2, scaled, ws, on, knots);
    REQUIRE(a.ok());
    REQUIRE(b.ok());
    CHECK(a.interpolationPieces == b.interpolationPieces);
    CHECK(a.interpolationFallbacks == b.interpolationFallbacks);
    CHECK(a.interpolationFallbacks == 1);
    // Each against its own exact-A integration (the integrator's step control is not what is
    // tested here).
    const auto offA = trellis::discretizeSampledData(times, 4, 2, lin, w, off, knots);
    const auto offB = trellis::discretizeSampledData(times, 4, 2, scaled, ws, off, knots);
    CHECK(recursionGainDifference(offA, a, w.Qf) < 1e-10);
    CHECK(recursionGainDifference(offB, b, ws.Qf) < 1e-10);
  }
}

TEST_CASE("solveTvlqr sampled: an unconstrained reference's linearization is interpolated between knots, the gains unchanged",
          "[sampled][radau][interpolation]") {
  // The 6-link chain's swing at 100 Hz (knots every 20 ms): the same gains as with A, B exact at
  // every node, from a fraction of the linearizations.
  const Model model = trellis::ctest::makeDampedChain(6);
  const SimulationResult swing = chainSwing(model, 0.3);
  REQUIRE(swing.ok());
  const LqrWeights w = unitWeights(12, 6);
  trellis::TvlqrOptions on, off;
  on.sampleRate = off.sampleRate = 100.0;
  off.sampled.interpolateLinearization = false;
  const trellis::TvlqrSolution a = trellis::solveTvlqr(model, swing.trajectory, w, on);
  const trellis::TvlqrSolution b = trellis::solveTvlqr(model, swing.trajectory, w, off);
  REQUIRE(a.ok());
  REQUIRE(b.ok());
  INFO("linearizations " << a.linearizations << " against " << b.linearizations);
  CHECK(gainDifference(b.gains.gains(), a.gains.gains()) < 1e-10);
  CHECK(3 * a.linearizations < b.linearizations);
}
