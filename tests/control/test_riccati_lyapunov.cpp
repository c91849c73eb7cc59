// Tests for RiccatiLinearSolver::kLyapunov (trellis/control/riccati.hpp) and the Bartels–Stewart
// solve behind it (control/src/riccati_lyapunov.hpp, private): the solve against the Kronecker
// form of the operator, the Riccati solution against the dense-Jacobian BDF, a tight reference
// and the CARE limit, the statistics that show no Krylov iteration ran, and failures.
#include "control_test_support.hpp"
#include "riccati_lyapunov.hpp"

#include <trellis/control.hpp>
#include <trellis/core/data.hpp>
#include <trellis/core/linearization.hpp>
#include <trellis/core/scene.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cmath>
#include <string>

using Eigen::MatrixXd;
using trellis::LqrWeights;
using trellis::RiccatiLinearSolver;
using trellis::RiccatiMethod;
using trellis::RiccatiOptions;
using trellis::RiccatiCode;

namespace {

// X − γ(AᵀX + XA) = R as one Kronecker system on vec(X) (column-major), solved by full-pivot LU:
// the independent reference for SchurLyapunov.
MatrixXd kroneckerSolve(const MatrixXd& A, double gamma, const MatrixXd& R) {
  const Eigen::Index n = A.rows();
  MatrixXd L = MatrixXd::Identity(n * n, n * n);
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Index row = j * n + i;  // entry (i, j) of AᵀX + XA
      for (Eigen::Index k = 0; k < n; ++k) {
        L(row, j * n + k) -= gamma * A(k, i);  // (AᵀX)_ij = Σ_k A_ki X_kj
        L(row, k * n + i) -= gamma * A(k, j);  // (XA)_ij = Σ_k X_ik A_kj
      }
    }
  }
  const Eigen::VectorXd x =
      L.fullPivLu().solve(Eigen::Map<const Eigen::VectorXd>(R.data(), n * n));
  return Eigen::Map<const MatrixXd>(x.data(), n, n);
}

// A(t) = A0 + sin(2t) A1, B(t) = B0 + t B1: a time-varying system with nx = 12, m = 3.
struct TimeVarying {
  MatrixXd A0, A1, B0, B1;
  TimeVarying() {
    std::srand(7);
    A0 = MatrixXd::Random(12, 12);
    A1 = 0.3 * MatrixXd::Random(12, 12);
    B0 = MatrixXd::Random(12, 3);
    B1 = 0.2 * MatrixXd::Random(12, 3);
  }
  trellis::LinearizationCallback callback() const {
    return [this](double t, MatrixXd& A, MatrixXd& B) {
      A = A0 + std::sin(2.0 * t) * A1;
      B = B0 + t * B1;
      return trellis::ReferenceStatus{};
    };
  }
};

LqrWeights unitWeights(int nx, int nu) {
  LqrWeights w;
  w.Q = MatrixXd::Identity(nx, nx);
  w.R = MatrixXd::Identity(nu, nu);
  w.Qf = MatrixXd::Identity(nx, nx);
  return w;
}

RiccatiOptions withSolver(RiccatiLinearSolver ls, double rtol) {
  RiccatiOptions o;
  o.linearSolver = ls;
  o.rtol = rtol;
  o.atol = rtol * 1e-2;
  return o;
}

}  // namespace

TEST_CASE("SchurLyapunov solves X - g(A'X + XA) = R like the Kronecker system", "[riccati]") {
  std::srand(11);
  for (int n : {1, 2, 7, 12}) {
    const MatrixXd A = MatrixXd::Random(n, n);  // real and complex-pair eigenvalues (1×1, 2×2 blocks)
    MatrixXd R = MatrixXd::Random(n, n);
    R = (R + R.transpose()).eval();  // symmetric (the solver's contract)
    trellis::detail::SchurLyapunov lyap(n);
    REQUIRE(lyap.factor(A));
    for (double gamma : {0.05, 0.3, 2.0}) {
      MatrixXd X = R;
      REQUIRE(lyap.solve(gamma, X));
      const MatrixXd ref = kroneckerSolve(A, gamma, R);
      INFO("n = " << n << ", gamma = " << gamma);
      CHECK((X - ref).cwiseAbs().maxCoeff() <= 1e-10 * (1.0 + ref.cwiseAbs().maxCoeff()));
      CHECK((X - X.transpose()).cwiseAbs().maxCoeff() == 0.0);
      const MatrixXd residual = X - gamma * (A.transpose() * X + X * A) - R;
      CHECK(residual.cwiseAbs().maxCoeff() <= 1e-10 * (1.0 + R.cwiseAbs().maxCoeff()));
    }
  }
  // Singular operator: A = I, γ = ½ makes 1 − γ(λ_i + λ_j) = 0 for every pair.
  trellis::detail::SchurLyapunov lyap(3);
  REQUIRE(lyap.factor(MatrixXd::Identity(3, 3)));
  MatrixXd X = MatrixXd::Identity(3, 3);
  CHECK_FALSE(lyap.solve(0.5, X));
}

TEST_CASE("kLyapunov agrees with the dense-Jacobian BDF and a tight reference, without Krylov "
          "iterations",
          "[riccati]") {
  const TimeVarying sys;
  const auto w = unitWeights(12, 3);
  const auto ref = trellis::solveRiccati(0.0, 1.5, 12, 3, sys.callback(), w,
                                         withSolver(RiccatiLinearSolver::kDense, 1e-12));
  REQUIRE(ref.ok());
  const auto dense = trellis::solveRiccati(0.0, 1.5, 12, 3, sys.callback(), w,
                                           withSolver(RiccatiLinearSolver::kDense, 1e-8));
  const auto lyap = trellis::solveRiccati(0.0, 1.5, 12, 3, sys.callback(), w,
                                          withSolver(RiccatiLinearSolver::kLyapunov, 1e-8));
  const auto gmres = trellis::solveRiccati(0.0, 1.5, 12, 3, sys.callback(), w,
                                           withSolver(RiccatiLinearSolver::kKrylov, 1e-8));
  REQUIRE(dense.ok());
  REQUIRE(lyap.ok());
  REQUIRE(gmres.ok());
  const double scale = ref.S(0.0).cwiseAbs().maxCoeff();
  for (double t : {0.0, 0.4, 1.0, 1.45}) {
    INFO("t = " << t);
    CHECK((lyap.S(t) - ref.S(t)).cwiseAbs().maxCoeff() <= 1e-6 * scale);
    CHECK((lyap.S(t) - dense.S(t)).cwiseAbs().maxCoeff() <= 1e-6 * scale);
    CHECK((lyap.S(t) - gmres.S(t)).cwiseAbs().maxCoeff() <= 1e-6 * scale);
  }
  // The direct solver really ran: Lyapunov solves, no Krylov iteration, no dense Jacobian.
  CHECK(lyap.linearIterations == 0);
  CHECK(lyap.preconditionerSolves > 0);
  CHECK(lyap.jacobianEvaluations == 0);
  CHECK(gmres.linearIterations > 0);
  CHECK(dense.jacobianEvaluations > 0);
  // The integrator's statistics: at least one Newton iteration per step, at most one Lyapunov
  // solve per Newton iteration (CVODES skips the solve when the residual is already below the
  // linear tolerance); each fresh A_cl gets one Schur form, and a fresh A_cl needs a set-up call.
  CHECK(lyap.newtonIterations >= lyap.steps);
  CHECK(lyap.preconditionerSolves <= lyap.newtonIterations);
  CHECK(lyap.schurFactorizations >= 1);
  CHECK(lyap.schurFactorizations <= lyap.linearSolverSetups);
  CHECK(lyap.errorTestFailures >= 0);
  CHECK(lyap.convergenceFailures >= 0);
  CHECK(dense.schurFactorizations == 0);
  const std::vector<int> orders = lyap.stepOrders();
  REQUIRE(orders.size() == lyap.stepTimes().size());
  CHECK(orders.back() == 0);  // the terminal point S(T) = Qf
  for (std::size_t k = 0; k + 1 < orders.size(); ++k) {
    CHECK(orders[k] >= 1);
    CHECK(orders[k] <= 5);  // BDF
  }
  // kAuto above nx = 10 is kLyapunov: the identical computation.
  const auto autoSol = trellis::solveRiccati(0.0, 1.5, 12, 3, sys.callback(), w,
                                             withSolver(RiccatiLinearSolver::kAuto, 1e-8));
  REQUIRE(autoSol.ok());
  CHECK(autoSol.steps == lyap.steps);
  CHECK(autoSol.preconditionerSolves == lyap.preconditionerSolves);
  CHECK((autoSol.S(0.0) - lyap.S(0.0)).cwiseAbs().maxCoeff() == 0.0);
}

TEST_CASE("kLyapunov on a time-invariant system converges to the CARE solution", "[riccati]") {
  std::srand(3);
  const MatrixXd A = 0.5 * MatrixXd::Random(12, 12), B = MatrixXd::Random(12, 4);
  LqrWeights w = unitWeights(12, 4);
  w.Qf = MatrixXd::Zero(12, 12);
  const auto care = trellis::solveCare(A, B, w.Q, w.R);
  REQUIRE(care.ok());
  auto o = withSolver(RiccatiLinearSolver::kLyapunov, 1e-10);
  const auto sol = trellis::solveRiccati(
      0.0, 30.0, 12, 4,
      [&](double, MatrixXd& a, MatrixXd& b) {
        a = A;
        b = B;
        return trellis::ReferenceStatus{};
      },
      w, o);
  REQUIRE(sol.ok());
  CONTROL_CHECK_CLOSE(care.S, sol.S(0.0), 1e-7, 1.0);
  CHECK(sol.linearIterations == 0);
}

TEST_CASE("kLyapunov: names, the factored form, and failures name the time", "[riccati]") {
  CHECK(std::string(trellis::toString(RiccatiLinearSolver::kLyapunov)) == "lyapunov");
  CHECK(trellis::parseRiccatiLinearSolver("lyapunov") == RiccatiLinearSolver::kLyapunov);
  CHECK(trellis::parseRiccatiLinearSolver("krylov") == RiccatiLinearSolver::kKrylov);
  CHECK_THROWS_WITH(trellis::parseRiccatiLinearSolver("lu"),
                    Catch::Contains("'lu' is not one of auto, dense, krylov, lyapunov"));
  const TimeVarying sys;
  auto f = withSolver(RiccatiLinearSolver::kLyapunov, 1e-6);
  f.method = RiccatiMethod::kFactored;
  CHECK_THROWS_WITH(trellis::solveRiccati(0.0, 1.0, 12, 3, sys.callback(), unitWeights(12, 3), f),
                    Catch::Contains("lyapunov needs the plain form"));

  // Uncontrolled (B = 0), A = 30·I: S grows like e^{60(T−t)}; the Newton matrix
  // 1 − γ(λ_i + λ_j) = 1 − 60γ passes through singular step sizes on the way. The solve stops
  // with kBlowUp at a named time, never ok.
  const auto blow = trellis::solveRiccati(
      0.0, 2.0, 12, 1,
      [](double, MatrixXd& a, MatrixXd& b) {
        a = 30.0 * MatrixXd::Identity(12, 12);
        b.setZero();
        return trellis::ReferenceStatus{};
      },
      unitWeights(12, 1), withSolver(RiccatiLinearSolver::kLyapunov, 1e-6));
  REQUIRE_FALSE(blow.ok());
  CHECK(blow.status.code == RiccatiCode::kBlowUp);
  CHECK(blow.status.t > 0.0);
  CHECK(blow.status.t < 2.0);
  CHECK_THAT(blow.status.message, Catch::Contains("S blew up at t = "));

  // A callback failing inside the horizon: kCallbackFailure at its time.
  const auto cb = trellis::solveRiccati(
      0.0, 1.0, 12, 3,
      [&sys](double t, MatrixXd& a, MatrixXd& b) {
        sys.callback()(t, a, b);
        if (t < 0.5) a(3, 4) = std::nan("");
        return trellis::ReferenceStatus{};
      },
      unitWeights(12, 3), withSolver(RiccatiLinearSolver::kLyapunov, 1e-6));
  REQUIRE_FALSE(cb.ok());
  CHECK(cb.status.code == RiccatiCode::kCallbackFailure);
  CHECK(cb.status.t < 0.5);
  CHECK(cb.status.t > 0.4);
  CHECK_THAT(cb.status.message, Catch::Contains("non-finite"));
}

TEST_CASE("mechanical structure A = [0 I; Aq Av] gives the solution of the unstructured form",
          "[riccati]") {
  // The same time-varying system in x = [q; v] (structure detected: half-size products) and in
  // x' = [v; q] (not detected: dense products): S' = P S Pᵀ.
  std::srand(5);
  const int h = 6, nx = 12, nu = 4;
  const MatrixXd Aq0 = MatrixXd::Random(h, h), Av0 = MatrixXd::Random(h, h),
                 Aq1 = 0.3 * MatrixXd::Random(h, h), Bv0 = MatrixXd::Random(h, nu);
  auto structured = [&](double t, MatrixXd& A, MatrixXd& B) {
    A.setZero();
    A.topRightCorner(h, h).setIdentity();
    A.bottomLeftCorner(h, h) = Aq0 + std::cos(t) * Aq1;
    A.bottomRightCorner(h, h) = Av0;
    B.setZero();
    B.bottomRows(h) = Bv0;
    return trellis::ReferenceStatus{};
  };
  MatrixXd P = MatrixXd::Zero(nx, nx);
  P.topRightCorner(h, h).setIdentity();
  P.bottomLeftCorner(h, h).setIdentity();  // x' = P x = [v; q]
  auto permuted = [&](double t, MatrixXd& A, MatrixXd& B) {
    MatrixXd a(nx, nx), b(nx, nu);
    structured(t, a, b);
    A = P * a * P.transpose();
    B = P * b;
    return trellis::ReferenceStatus{};
  };
  LqrWeights w = unitWeights(nx, nu);
  w.Q.diagonal().head(h).setConstant(3.0);  // not permutation-invariant
  w.R = 2.0 * MatrixXd::Identity(nu, nu) + 0.3 * MatrixXd::Ones(nu, nu);  // G = R⁻¹Bᵀ ≠ Bᵀ
  LqrWeights wp = w;
  wp.Q = P * w.Q * P.transpose();
  const auto o = withSolver(RiccatiLinearSolver::kAuto, 1e-11);
  const auto s1 = trellis::solveRiccati(0.0, 2.0, nx, nu, structured, w, o);
  const auto s2 = trellis::solveRiccati(0.0, 2.0, nx, nu, permuted, wp, o);
  REQUIRE(s1.ok());
  REQUIRE(s2.ok());
  for (double t : {0.0, 0.7, 1.9}) {
    const MatrixXd back = P.transpose() * s2.S(t) * P;
    CONTROL_CHECK_CLOSE(back, s1.S(t), 1e-8, 1.0);
    CONTROL_CHECK_CLOSE((s2.K(t) * P).eval(), s1.K(t), 1e-8, 1.0);
  }
}

TEST_CASE("lyapunov: no false blow-up at loose tolerances (the 20-link chain held, issue 31)",
          "[riccati][lyapunov]") {
  // The damped 20-link chain of bench/chain_scene.py (0.1 kg, 0.1 m links) held hanging: at
  // rtol 1e-4, atol 1e-6 the error test kept cutting the step at BDF order 5, whose variable-step
  // form is then not zero-stable: max |S_ij| went 1 → 1e15 within Δτ = 1e-11 and the solve
  // reported "S blew up" although S stays bounded. It is now redone at order ≤ 2.
  std::string frames, forces;
  const int n = 20;
  for (int i = n; i >= 1; --i) {
    const std::string id = std::to_string(i);
    frames = R"({"name": "l)" + id + R"(", "type": "rz", "config": "q)" + id + R"(", "children": [{"name": "m)" + id +
             R"(", "type": "ty", "value": -0.1, "mass": {"m": 0.1}, "children": [)" + frames + "]}]}";
    forces += R"({"type": "config_force", "config": "q)" + id + R"(", "input": "u)" + id + R"("}, )";
  }
  const trellis::Scene scene = trellis::parseScene(
      R"({"name": "chain", "frames": [)" + frames + R"(], "potentials": [{"type": "gravity", "g": [0, -9.81, 0]}],
          "forces": [)" + forces + R"({"type": "damping", "default": 0.1}]})",
      "20-link chain");
  trellis::Data data(scene.model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  REQUIRE(trellis::computeLinearization(scene.model, data, zero, zero, zero).ok());
  const MatrixXd A = data.A, B = data.B;
  const trellis::LinearizationCallback lin = [&](double, MatrixXd& a, MatrixXd& b) {
    a = A;
    b = B;
    return trellis::ReferenceStatus{};
  };
  const LqrWeights w = unitWeights(2 * n, n);
  RiccatiOptions loose;
  loose.rtol = 1e-4;
  loose.atol = 1e-6;
  const auto sol = trellis::solveRiccati(0.0, 2.0, 2 * n, n, lin, w, loose);
  INFO(sol.describe());
  REQUIRE(sol.ok());
  CHECK(sol.lowOrderRetry);
  CHECK_THAT(sol.firstAttempt, Catch::Contains("blow_up"));
  CHECK_THAT(sol.json(), Catch::Contains("\"low_order_retry\":true"));
  CHECK(sol.maxEigenvalue == Approx(26.76).epsilon(1e-3));
  // Against the default tolerances: the gains agree to the loose tolerance's accuracy.
  const auto ref = trellis::solveRiccati(0.0, 2.0, 2 * n, n, lin, w);
  REQUIRE(ref.ok());
  CHECK_FALSE(ref.lowOrderRetry);
  for (double t : {0.0, 1.0, 1.9}) {
    const MatrixXd K = sol.K(t), Kref = ref.K(t);
    INFO("t = " << t);
    CHECK((K - Kref).cwiseAbs().maxCoeff() < 1e-2 * Kref.cwiseAbs().maxCoeff());
  }
  // maxOrder out of range names the field.
  RiccatiOptions bad;
  bad.maxOrder = 6;
  CHECK_THROWS_WITH(bad.validate(), Catch::Contains("maxOrder"));
}
