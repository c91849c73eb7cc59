// Hard cases for solveRiccati, run with every method: BDF with the dense solver, BDF with
// preconditioned and unpreconditioned GMRES, Adams, and the factored (Cholesky) form with the
// dense and the Krylov solver. Each case is accurate against an independent reference (closed
// form or solveCare) or ends with a clear status — never a silent NaN — and S stays symmetric
// positive semidefinite along the solution.
#include "control_test_support.hpp"

#include <trellis/control.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <string>
#include <vector>

using Eigen::MatrixXd;
using trellis::LqrWeights;
using trellis::RiccatiLinearSolver;
using trellis::RiccatiMethod;
using trellis::RiccatiOptions;
using trellis::RiccatiSolution;
using trellis::RiccatiCode;

namespace {

struct Config {
  const char* name;
  RiccatiMethod method;
  RiccatiLinearSolver linearSolver;
  bool preconditioner;
};

const std::vector<Config>& configs() {
  static const std::vector<Config> c = {
      {"BDF dense", RiccatiMethod::kBDF, RiccatiLinearSolver::kDense, true},
      {"BDF Krylov (Lyapunov preconditioner)", RiccatiMethod::kBDF, RiccatiLinearSolver::kKrylov,
       true},
      {"BDF Krylov (no preconditioner)", RiccatiMethod::kBDF, RiccatiLinearSolver::kKrylov, false},
      {"Adams", RiccatiMethod::kAdams, RiccatiLinearSolver::kAuto, false},
      {"factored dense", RiccatiMethod::kFactored, RiccatiLinearSolver::kDense, true},
      {"factored Krylov", RiccatiMethod::kFactored, RiccatiLinearSolver::kKrylov, true},
  };
  return c;
}

RiccatiOptions optionsFor(const Config& c, double rtol, double atol) {
  RiccatiOptions o;
  o.method = c.method;
  o.linearSolver = c.linearSolver;
  o.krylovPreconditioner = c.preconditioner;
  o.rtol = rtol;
  o.atol = atol;
  return o;
}

trellis::LinearizationCallback constantSystem(const MatrixXd& A, const MatrixXd& B) {
  return [A, B](double, MatrixXd& a, MatrixXd& b) {
    a = A;
    b = B;
    return trellis::ReferenceStatus{};
  };
}

double relativeError(const MatrixXd& expected, const MatrixXd& got) {
  return (got - expected).cwiseAbs().maxCoeff() / expected.cwiseAbs().maxCoeff();
}

// S(t) at every stored step and half-way between steps (dense output): finite, symmetric and
// min eig ≥ −tol·max|S_ij|. Returns the worst min eig / max|S_ij| found.
double worstPsdViolation(const RiccatiSolution& sol) {
  const std::vector<double> ts = sol.stepTimes();
  double worst = 0.0;
  for (std::size_t k = 0; k < ts.size(); ++k) {
    for (double t : {ts[k], k + 1 < ts.size() ? 0.5 * (ts[k] + ts[k + 1]) : ts[k]}) {
      const MatrixXd S = sol.S(t);
      if (!S.allFinite()) return -std::numeric_limits<double>::infinity();
      if ((S - S.transpose()).cwiseAbs().maxCoeff() != 0.0) {
        return -std::numeric_limits<double>::infinity();
      }
      const double scale = S.cwiseAbs().maxCoeff();
      if (scale == 0.0) continue;
      const double lmin =
          Eigen::SelfAdjointEigenSolver<MatrixXd>(S, Eigen::EigenvaluesOnly).eigenvalues()(0);
      worst = std::min(worst, lmin / scale);
    }
  }
  return worst;
}

// A failed solve must say what, where and how big; S is still usable on [validFrom, T].
void checkCleanFailure(const RiccatiSolution& sol, double t0, double T) {
  INFO(sol.status.message);
  CHECK(!sol.status.message.empty());
  CHECK(std::isfinite(sol.status.t));
  CHECK(sol.status.t >= t0);
  CHECK(sol.status.t <= T);
  CHECK(std::isfinite(sol.failureNorm));
  CHECK(sol.S(sol.validFrom()).allFinite());
}

// Adams (functional iteration, non-stiff) and unpreconditioned GMRES (whose iteration count grows
// with the stiffness γ‖J‖) may give up on a stiff case: then it must be a reported integrator
// failure within the step budget, with a usable partial solution.
bool nonStiffGaveUp(const Config& c, const RiccatiSolution& sol, double t0, double T) {
  const bool nonStiff = c.method == RiccatiMethod::kAdams ||
                        (c.linearSolver == RiccatiLinearSolver::kKrylov && !c.preconditioner);
  if (!nonStiff || sol.ok()) return false;
  CHECK(sol.status.code == RiccatiCode::kIntegratorFailure);
  checkCleanFailure(sol, t0, T);
  return true;
}

// PSD tolerance: an unfactored method carries a local error ≈ rtol·|S| per entry, which can move
// an eigenvalue by about nx·rtol·max|S|; 1e-7 covers rtol ≤ 1e-9 with a wide margin. The
// factored form is PSD by construction: only the eigen-solver's rounding (≈ nx·ε) remains.
double psdTolerance(const Config& c) {
  return c.method == RiccatiMethod::kFactored ? 1e-13 : 1e-7;
}

}  // namespace

TEST_CASE("hard: stiff mode, a lightly damped spring at 1e4 rad/s", "[riccati][hard]") {
  // A slow double integrator and a fast, critically damped spring (ω = 1e4 rad/s) driven by the
  // same input: eigenvalues of the Riccati Jacobian span 1e-1 … 2e4 (stiffness ratio ~1e5).
  const double wn = 1e4, zeta = 1.0, T = 30.0;
  MatrixXd A = MatrixXd::Zero(4, 4), B(4, 1);
  A(0, 1) = 1.0;
  A(2, 3) = 1.0;
  A(3, 2) = -wn * wn;
  A(3, 3) = -2 * zeta * wn;
  B << 0, 1, 0, 1;
  LqrWeights w;
  w.Q = MatrixXd::Identity(4, 4);
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = MatrixXd::Identity(4, 4);
  // Reference: the CARE solution; the slow closed-loop poles (|Re| ≈ 0.7) make the finite-horizon
  // S(0) equal to it within e^{-2·0.7·30} ≈ 1e-18 relative.
  const auto care = trellis::solveCare(A, B, w.Q, w.R);
  REQUIRE(care.ok());
  for (const Config& c : configs()) {
    INFO(c.name);
    RiccatiOptions o = optionsFor(c, 1e-10, 1e-16);  // the fast block's entries are ~1e-9…1e-5
    o.maxSteps = 20000;  // Adams (non-stiff) cannot do this: a bounded, reported failure
    const auto sol = trellis::solveRiccati(0.0, T, 4, 1, constantSystem(A, B), w, o);
    if (nonStiffGaveUp(c, sol, 0.0, T)) continue;
    INFO(sol.status.message);
    REQUIRE(sol.ok());
    INFO("steps " << sol.steps);
    // 1e-7 over the whole matrix and 1e-5 on the fast block alone (its entries are 1e-5 of the
    // slow ones, so its relative error is amplified by up to that ratio of atol/rtol effects).
    CHECK(relativeError(care.S, sol.S(0.0)) < 1e-7);
    CHECK(relativeError(care.S.bottomRightCorner(2, 2), sol.S(0.0).bottomRightCorner(2, 2)) < 1e-5);
    CHECK(relativeError(care.K, sol.K(0.0)) < 1e-7);
    CHECK(sol.steps < 5000);  // stiff methods take large steps once the fast transient has died
    CHECK(worstPsdViolation(sol) >= -psdTolerance(c));
  }
}

TEST_CASE("hard: 100 s horizon on an open-loop unstable system converges to the CARE solution",
          "[riccati][hard]") {
  // Two coupled inverted pendulums (eigenvalues of A: ±√10, ±√(10 ± 2)), two inputs; after
  // 100 s the finite-horizon S is the CARE solution to machine precision.
  MatrixXd A = MatrixXd::Zero(4, 4), B = MatrixXd::Zero(4, 2);
  A.topRightCorner(2, 2).setIdentity();
  A.bottomLeftCorner(2, 2) << 10, 2, 2, 10;
  B.bottomRows(2) << 1, 0, 0.5, 1;
  LqrWeights w;
  w.Q = MatrixXd::Identity(4, 4);
  w.R = MatrixXd::Identity(2, 2);
  w.Qf = 10.0 * MatrixXd::Identity(4, 4);
  const double T = 100.0;
  const auto care = trellis::solveCare(A, B, w.Q, w.R);
  REQUIRE(care.ok());
  for (const Config& c : configs()) {
    INFO(c.name);
    const auto sol = trellis::solveRiccati(0.0, T, 4, 2, constantSystem(A, B), w,
                                           optionsFor(c, 1e-11, 1e-12));
    INFO(sol.status.message);
    REQUIRE(sol.ok());
    // rtol 1e-11: the converged S is an attracting fixed point, so the error stays at the local
    // error level; 1e-8 leaves a factor ~1e3 for the dense output and the error constant.
    for (double t : {0.0, 50.0, 90.0}) {
      INFO("t = " << t);
      CHECK(relativeError(care.S, sol.S(t)) < 1e-8);
    }
    CHECK(relativeError(care.K, sol.K(0.0)) < 1e-8);
    CHECK(worstPsdViolation(sol) >= -psdTolerance(c));
  }
}

TEST_CASE("hard: cheap control R = 1e-6 I", "[riccati][hard]") {
  // Two decoupled double integrators, Q = I, R = r I: per axis the CARE solution is
  // s12 = √r, s22 = √(r(1 + 2√r)), s11 = s12 s22 / r (closed form); closed-loop poles ~ r^{-1/4}
  // = 31.6 rad/s, so over 5 s S(0) has converged to it (e^{-2·22·5}).
  const double r = 1e-6;
  MatrixXd A = MatrixXd::Zero(4, 4), B = MatrixXd::Zero(4, 2);
  A(0, 1) = A(2, 3) = 1.0;
  B(1, 0) = B(3, 1) = 1.0;
  LqrWeights w;
  w.Q = MatrixXd::Identity(4, 4);
  w.R = r * MatrixXd::Identity(2, 2);
  w.Qf = MatrixXd::Identity(4, 4);
  const double s12 = std::sqrt(r), s22 = std::sqrt(r * (1 + 2 * std::sqrt(r)));
  MatrixXd Sexact = MatrixXd::Zero(4, 4);
  for (int k : {0, 2}) {
    Sexact(k, k) = s12 * s22 / r;
    Sexact(k, k + 1) = Sexact(k + 1, k) = s12;
    Sexact(k + 1, k + 1) = s22;
  }
  for (const Config& c : configs()) {
    INFO(c.name);
    // Stiff at the start: K = R⁻¹BᵀQf ~ 1e6 gives closed-loop rates ~1e6 until S has decayed.
    RiccatiOptions o = optionsFor(c, 1e-11, 1e-15);
    o.maxSteps = 20000;
    const auto sol = trellis::solveRiccati(0.0, 5.0, 4, 2, constantSystem(A, B), w, o);
    if (nonStiffGaveUp(c, sol, 0.0, 5.0)) continue;
    INFO(sol.status.message);
    REQUIRE(sol.ok());
    INFO("steps " << sol.steps);
    // Entries span 1e-3 … 1: entry-wise relative error (floor 1e-12) at 1e-7.
    CONTROL_CHECK_CLOSE(Sexact, sol.S(0.0), 1e-7, 1e-12);
    CHECK(worstPsdViolation(sol) >= -psdTolerance(c));
  }
}

TEST_CASE("hard: Qf = 0", "[riccati][hard]") {
  // Unstable system from the 100 s case but with zero terminal cost: S starts singular.
  MatrixXd A = MatrixXd::Zero(4, 4), B = MatrixXd::Zero(4, 2);
  A.topRightCorner(2, 2).setIdentity();
  A.bottomLeftCorner(2, 2) << 10, 2, 2, 10;
  B.bottomRows(2) << 1, 0, 0.5, 1;
  LqrWeights w;
  w.Q = MatrixXd::Identity(4, 4);
  w.R = MatrixXd::Identity(2, 2);
  w.Qf = MatrixXd::Zero(4, 4);
  const double T = 20.0;
  const auto care = trellis::solveCare(A, B, w.Q, w.R);
  REQUIRE(care.ok());
  for (const Config& c : configs()) {
    INFO(c.name);
    RiccatiOptions o = optionsFor(c, 1e-11, 1e-14);
    if (c.method == RiccatiMethod::kFactored) {
      // Without a shift the factor U(T) = chol(0) does not exist: a clear invalid_argument.
      CHECK_THROWS_WITH(trellis::solveRiccati(0.0, T, 4, 2, constantSystem(A, B), w, o),
                        Catch::Matchers::Contains("Qf's smallest eigenvalue is 0") &&
                            Catch::Matchers::Contains("factoredQfShift"));
      o.factoredQfShift = 1e-12;  // effect on S(0): 1e-12·e^{-2·1.6·20}, nil
    }
    const auto sol = trellis::solveRiccati(0.0, T, 4, 2, constantSystem(A, B), w, o);
    INFO(sol.status.message);
    REQUIRE(sol.ok());
    INFO("steps " << sol.steps);
    CHECK(relativeError(care.S, sol.S(0.0)) < 1e-8);  // converged (closed-loop |Re λ| ≥ 1.6)
    // Near T, S(t) ≈ (T − t) Q: the first-order term of the Taylor expansion, error O((T−t)²).
    const double h = 1e-4;
    CHECK(relativeError(h * w.Q, sol.S(T - h)) < 1e-2);
    CHECK(worstPsdViolation(sol) >= -psdTolerance(c));
  }
}

TEST_CASE("hard: rank-deficient B gives the solution of the equivalent full-rank input",
          "[riccati][hard]") {
  // B = [b b] (rank 1) with R = I has B R⁻¹ Bᵀ = 2 b bᵀ = b' b'ᵀ, b' = √2 b: the Riccati equation
  // is the same as with the single input b'. Time-varying A(t) so the check is not just CARE.
  const auto Aof = [](double t) {
    MatrixXd A = MatrixXd::Zero(4, 4);
    A.topRightCorner(2, 2).setIdentity();
    A.bottomLeftCorner(2, 2) << -4 - std::sin(t), 1, 1, -2 + 0.5 * std::cos(2 * t);
    return A;
  };
  Eigen::Vector4d b(0, 0, 1, 0.3);
  MatrixXd B2(4, 2);
  B2 << b, b;
  const MatrixXd B1 = std::sqrt(2.0) * b;
  LqrWeights w2, w1;
  w2.Q = w1.Q = MatrixXd::Identity(4, 4);
  w2.R = MatrixXd::Identity(2, 2);
  w1.R = MatrixXd::Identity(1, 1);
  w2.Qf = w1.Qf = MatrixXd::Identity(4, 4);
  auto lin2 = [&](double t, MatrixXd& A, MatrixXd& B) { A = Aof(t); B = B2; return trellis::ReferenceStatus{}; };
  auto lin1 = [&](double t, MatrixXd& A, MatrixXd& B) { A = Aof(t); B = B1; return trellis::ReferenceStatus{}; };
  RiccatiOptions ref;
  ref.rtol = 1e-12;
  ref.atol = 1e-14;
  const auto reference = trellis::solveRiccati(0.0, 5.0, 4, 1, lin1, w1, ref);
  REQUIRE(reference.ok());
  for (const Config& c : configs()) {
    INFO(c.name);
    const auto sol = trellis::solveRiccati(0.0, 5.0, 4, 2, lin2, w2, optionsFor(c, 1e-10, 1e-12));
    INFO(sol.status.message);
    REQUIRE(sol.ok());
    for (double t : {0.0, 2.5, 4.9}) {
      INFO("t = " << t);
      CHECK(relativeError(reference.S(t), sol.S(t)) < 1e-7);  // rtol 1e-10, 1e3 margin
      // Both columns of K are equal (the inputs are indistinguishable) and sum to K'·√2.
      const MatrixXd K = sol.K(t);
      CHECK((K.row(0) - K.row(1)).cwiseAbs().maxCoeff() <= 1e-12 * K.cwiseAbs().maxCoeff());
    }
    CHECK(worstPsdViolation(sol) >= -psdTolerance(c));
  }
}

TEST_CASE("hard: uncontrollable stable direction converges, uncontrollable unstable one blows up",
          "[riccati][hard]") {
  // x₁' = −x₁ (no input), x₂' = x₂ + u. Q = I, R = 1, Qf = I. The equation decouples:
  // ds₁₁/dτ = −2 s₁₁ + 1 → s₁₁ = ½ + ½ e^{−2τ}; s₁₂ = 0; ds₂₂/dτ = 1 + 2 s₂₂ − s₂₂² =
  // −(s₂₂ − s₊)(s₂₂ − s₋), s± = 1 ± √2: w = (s₂₂ − s₊)/(s₂₂ − s₋) = w₀ e^{−2√2 τ}.
  const double sp = 1 + std::sqrt(2.0), sm = 1 - std::sqrt(2.0);
  const auto s22 = [&](double tau) {
    const double wt = (1 - sp) / (1 - sm) * std::exp(-2 * std::sqrt(2.0) * tau);
    return (sp - wt * sm) / (1 - wt);
  };
  MatrixXd A(2, 2), B(2, 1);
  A << -1, 0, 0, 1;
  B << 0, 1;
  LqrWeights w;
  w.Q = MatrixXd::Identity(2, 2);
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = MatrixXd::Identity(2, 2);
  const double T = 5.0;
  for (const Config& c : configs()) {
    INFO(c.name);
    const auto sol =
        trellis::solveRiccati(0.0, T, 2, 1, constantSystem(A, B), w, optionsFor(c, 1e-11, 1e-13));
    INFO(sol.status.message);
    REQUIRE(sol.ok());
    for (double t : {0.0, 2.0, 4.5, 4.99}) {
      INFO("t = " << t);  // rtol 1e-11: 1e-8 leaves a factor 1e3 for the accumulated error
      CHECK(sol.S(t)(0, 0) == Approx(0.5 + 0.5 * std::exp(-2 * (T - t))).epsilon(1e-8));
      CHECK(sol.S(t)(1, 1) == Approx(s22(T - t)).epsilon(1e-8));
      CHECK(std::abs(sol.S(t)(0, 1)) < 1e-10);
    }
    CHECK(worstPsdViolation(sol) >= -psdTolerance(c));
  }

  // Unstable and unreachable: ds₁₁/dτ = 2 s₁₁ + 1, s₁₁(0) = 1 → s₁₁ = 1.5 e^{2τ} − ½, which
  // crosses maxNorm = 1e8 at τ* = ½ ln((1e8 + ½)/1.5).
  A(0, 0) = 1.0;
  const double maxNorm = 1e8, T2 = 50.0;
  const double tauCross = 0.5 * std::log((maxNorm + 0.5) / 1.5);
  for (const Config& c : configs()) {
    INFO(c.name);
    RiccatiOptions o = optionsFor(c, 1e-10, 1e-12);
    o.maxNorm = maxNorm;
    const auto sol = trellis::solveRiccati(0.0, T2, 2, 1, constantSystem(A, B), w, o);
    REQUIRE(sol.status.code == RiccatiCode::kBlowUp);
    checkCleanFailure(sol, 0.0, T2);
    CHECK_THAT(sol.status.message, Catch::Matchers::Contains("blew up at t =") &&
                                Catch::Matchers::Contains("maxNorm = 1e+08"));
    // Stopped at the first step past the crossing: within one step (< 1 in τ) of it.
    const double tauFail = T2 - sol.status.t;
    CHECK(tauFail >= tauCross - 1e-9);
    CHECK(tauFail < tauCross + 1.0);
    // The reported norm is max|S_ij| = s₁₁ at the reported time (closed form, rtol-accurate).
    CHECK(sol.failureNorm > maxNorm);
    CHECK(sol.failureNorm == Approx(1.5 * std::exp(2 * tauFail) - 0.5).epsilon(1e-7));
    CHECK(sol.validFrom() == Approx(sol.status.t));
    CHECK(worstPsdViolation(sol) >= -psdTolerance(c));
  }
}

TEST_CASE("hard: factored form keeps S positive semidefinite where the entries are tiny",
          "[riccati][hard]") {
  // Q = 0 on a strongly stable, uncontrollable direction: s₁₁ = e^{−100τ} (closed form) decays to
  // 1e-87 over τ = 2. Integrating S's entries resolves it only to atol (values of either sign
  // ~1e-12 are allowed); the factor's u₁₁ = e^{−50τ} is also only atol-accurate but S = UᵀU is
  // PSD at every output point whatever its error.
  MatrixXd A(2, 2), B(2, 1);
  A << -50, 0, 0, -1;
  B << 0, 1;
  LqrWeights w;
  w.Q = MatrixXd::Zero(2, 2);
  w.Q(1, 1) = 1.0;
  w.R = MatrixXd::Identity(1, 1);
  w.Qf = MatrixXd::Identity(2, 2);
  const double T = 2.0;
  const Config& f = configs()[4];
  // The pure factored form: its PSD guarantee is the point here, so no switch to the plain form
  // when S nears singularity (test_riccati_factored_singular.cpp tests the switch).
  RiccatiOptions fo = optionsFor(f, 1e-8, 1e-12);
  fo.factoredSwitchCondition = 0.0;
  const auto sol = trellis::solveRiccati(0.0, T, 2, 1, constantSystem(A, B), w, fo);
  REQUIRE(sol.ok());
  CHECK(sol.minEigenvalue >= 0.0);
  CHECK(worstPsdViolation(sol) >= -1e-13);
  // s₁₁: the global error of u₁₁ accumulates over ~100 steps of local errors rtol·u₁₁ + atol
  // (1e-8, 1e-12); |s₁₁ error| ≤ 1e-5·s₁₁ + 1e-10 (observed worst: about 1e-6·s₁₁).
  double worst = 0.0;
  for (const double t : sol.stepTimes()) {
    const double exact = std::exp(-100 * (T - t));
    CHECK(sol.S(t)(0, 0) >= 0.0);
    worst = std::max(worst, std::abs(sol.S(t)(0, 0) - exact) / (1e-5 * exact + 1e-10));
  }
  CHECK(worst <= 1.0);
  // s₂₂ and the rest against a tight BDF solve of the plain form.
  RiccatiOptions ref;
  ref.rtol = 1e-12;
  ref.atol = 1e-14;
  const auto r = trellis::solveRiccati(0.0, T, 2, 1, constantSystem(A, B), w, ref);
  REQUIRE(r.ok());
  for (double t : {0.0, 1.0, 1.9}) CHECK(relativeError(r.S(t), sol.S(t)) < 1e-6);  // rtol 1e-8
}
