// Tests for trellis/optimization/transcription.hpp: the NLP's cost gradient and constraint
// Jacobian against central differences on every example problem (and variants), the declared
// sparsity pattern, a closed-form linear case, and the evaluation cache.
#include <trellis/core.hpp>
#include <trellis/optimization.hpp>

#include <catch2/catch.hpp>

#include "skate_model.hpp"

#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <utility>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::CollocationMethod;
using trellis::OptimalControlProblem;
using trellis::Transcription;

namespace {

std::string problemPath(const std::string& name) {
  return std::string(TRELLIS_SOURCE_DIR) + "/examples/problems/" + name + ".json";
}

/// A point away from the guess (random, seeded): the checks must hold at any z, not only where
/// the defects vanish. Slack and T are perturbed too.
VectorXd randomPoint(const Transcription& t, std::mt19937& rng) {
  std::uniform_real_distribution<double> d(-0.3, 0.3);
  VectorXd z = t.initialGuess();
  for (int i = 0; i < z.size(); ++i) z(i) += d(rng);
  if (t.horizonIndex() >= 0) {
    const auto& p = t.problem();
    z(t.horizonIndex()) = 0.5 * (p.minHorizon + p.maxHorizon) + 0.1 * d(rng) * (p.maxHorizon - p.minHorizon);
  }
  return z;
}

/// Dense central-difference Jacobian of g and gradient of J, step ε^(1/3)·max(1, |z_i|).
void finiteDifferences(Transcription& t, const VectorXd& z, MatrixXd& jac, VectorXd& grad) {
  const double eps = std::cbrt(std::numeric_limits<double>::epsilon());
  const int nv = t.numVariables(), nc = t.numConstraints();
  jac.resize(nc, nv);
  grad.resize(nv);
  VectorXd zp = z, gp(nc), gm(nc);
  for (int j = 0; j < nv; ++j) {
    const double step = eps * std::max(1.0, std::abs(z(j)));
    double jp = 0.0, jm = 0.0;
    zp(j) = z(j) + step;
    const double up = zp(j);
    REQUIRE(t.evalConstraints(zp.data(), gp.data()));
    REQUIRE(t.evalCost(zp.data(), jp));
    zp(j) = z(j) - step;
    const double down = zp(j);
    REQUIRE(t.evalConstraints(zp.data(), gm.data()));
    REQUIRE(t.evalCost(zp.data(), jm));
    zp(j) = z(j);
    jac.col(j) = (gp - gm) / (up - down);
    grad(j) = (jp - jm) / (up - down);
  }
}

/// Compares the exact derivatives with central differences at z. Tolerance: the step
/// h_i ≈ 6e-6·max(1, |z_i|) gives a truncation error h²|g'''|/6 ≈ 6e-12·|g'''| and a rounding
/// error ε|g|/h ≈ 4e-11·|g|; the defects of these scenes have |g|, |g'''| of order 1e2–1e3
/// (h·f with q̈ up to ~1e3 at perturbed states), so the error is ≲ 1e-7 relative to
/// max(1, |entry|) — 1e-6 leaves a margin, and a wrong block (a missing factor h/6, a sign, a
/// transposed A) is off by O(1).
void checkDerivatives(Transcription& t, const VectorXd& z) {
  const int nv = t.numVariables(), nc = t.numConstraints();
  MatrixXd fdJac;
  VectorXd fdGrad;
  finiteDifferences(t, z, fdJac, fdGrad);

  VectorXd grad(nv);
  REQUIRE(t.evalCostGradient(z.data(), grad.data()));
  double worstGrad = 0.0;
  int worstGradIndex = -1;
  for (int j = 0; j < nv; ++j) {
    const double err = std::abs(grad(j) - fdGrad(j)) / std::max(1.0, std::abs(fdGrad(j)));
    if (err > worstGrad) worstGrad = err, worstGradIndex = j;
  }
  INFO("gradient: worst relative error " << worstGrad << " at variable " << worstGradIndex);
  CHECK(worstGrad < 1e-6);

  const auto& rows = t.jacobianRows();
  const auto& cols = t.jacobianCols();
  VectorXd values(rows.size());
  REQUIRE(t.evalJacobian(z.data(), values.data()));
  MatrixXd exact = MatrixXd::Zero(nc, nv);
  std::set<std::pair<int, int>> pattern;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    REQUIRE(rows[k] >= 0);
    REQUIRE(rows[k] < nc);
    REQUIRE(cols[k] >= 0);
    REQUIRE(cols[k] < nv);
    // No duplicates: each declared entry is one element of ∂g/∂z.
    REQUIRE(pattern.insert({rows[k], cols[k]}).second);
    exact(rows[k], cols[k]) = values(k);
  }
  // Every entry, inside the pattern (value) and outside it (structurally zero, so the finite
  // difference must vanish too: the declared pattern is complete).
  double worst = 0.0;
  int wr = -1, wc = -1;
  for (int c = 0; c < nv; ++c) {
    for (int r = 0; r < nc; ++r) {
      const double err = std::abs(exact(r, c) - fdJac(r, c)) / std::max(1.0, std::abs(fdJac(r, c)));
      if (err > worst) worst = err, wr = r, wc = c;
    }
  }
  INFO("Jacobian: worst relative error " << worst << " at row " << wr << ", column " << wc
       << " (exact " << (wr >= 0 ? exact(wr, wc) : 0.0) << ", finite difference "
       << (wr >= 0 ? fdJac(wr, wc) : 0.0) << ", in pattern: "
       << (wr >= 0 && pattern.count({wr, wc}) ? "yes" : "no") << ")");
  CHECK(worst < 1e-6);
}

OptimalControlProblem smaller(OptimalControlProblem p, int knots) {
  p.knots = knots;  // the checker is dense: a few knots exercise every block
  return p;
}

}  // namespace

TEST_CASE("transcription: gradient and Jacobian agree with central differences",
          "[transcription][derivatives]") {
  std::mt19937 rng(4242);
  for (const char* name : {"cart_pole_swingup", "acrobot_swingup", "paper_pendulum_transfer"}) {
    const OptimalControlProblem file = trellis::loadProblem(problemPath(name));
    for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
      for (const bool freeHorizon : {false, true}) {
        OptimalControlProblem p = smaller(file, 5);
        p.method = method;
        if (freeHorizon) {
          p.minHorizon = 0.5 * p.horizon;
          p.maxHorizon = 2.0 * p.horizon;
          p.timeWeight = 0.3;
        }
        // Non-zero state weights, a goal and a terminal weight so that every cost term counts.
        p.Q = MatrixXd::Identity(p.nx(), p.nx()) * 0.7;
        p.Q(0, 1) = p.Q(1, 0) = 0.2;
        p.Qf = MatrixXd::Identity(p.nx(), p.nx()) * 3.0;
        p.goalState = VectorXd::LinSpaced(p.nx(), 0.1, 0.9);
        DYNAMIC_SECTION(name << (method == CollocationMethod::kHermiteSimpson ? " hermite_simpson"
                                 : method == CollocationMethod::kRadau        ? " radau"
                                                                             : " trapezoidal")
                             << (freeHorizon ? " free T" : " fixed T")) {
          Transcription t(p);
          checkDerivatives(t, randomPoint(t, rng));
        }
      }
    }
  }
}

TEST_CASE("transcription: knife edge and non-uniform mesh derivatives agree with central differences",
          "[transcription][derivatives][knife_edge]") {
  // A skate whose blade sits off the centre of mass (the knife-edge row's ∂A/∂q is then not
  // symmetric, unlike a Hessian), both methods, fixed and free T, on a non-uniform mesh.
  const auto model = trellis::test::skateModel();
  std::mt19937 rng(77);
  for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
    for (const bool freeHorizon : {false, true}) {
      OptimalControlProblem p(model);
      p.method = method;
      p.knots = 5;
      p.mesh.resize(5);
      p.mesh << 0.0, 0.1, 0.45, 0.6, 1.0;
      p.setFixedHorizon(2.0);
      if (freeHorizon) {
        p.minHorizon = 1.0;
        p.maxHorizon = 3.0;
        p.timeWeight = 0.2;
      }
      p.finalState << 1.0, 0.5, 0.3, 0.0, 0.0, 0.0;
      p.Q = MatrixXd::Identity(6, 6) * 0.4;
      p.goalState = p.finalState;
      DYNAMIC_SECTION((method == CollocationMethod::kHermiteSimpson ? "hermite_simpson" : method == CollocationMethod::kRadau ? "radau" : "trapezoidal")
                      << (freeHorizon ? " free T" : " fixed T")) {
        Transcription t(p);
        // One knife-edge row: A q̇ rows at every knot, μ slack only (no h rows, no γ).
        CHECK(t.numConstraints() ==
              (p.knots - 1) * (method == CollocationMethod::kHermiteSimpson ? 2 * 6 + 2
                                      : method == CollocationMethod::kRadau ? 3 * 6 + 2 * 2
                                                                            : 6) + p.knots);
        checkDerivatives(t, randomPoint(t, rng));
        // The knots sit on the mesh.
        const VectorXd z = t.initialGuess();
        const trellis::Trajectory traj = t.trajectory(z.data());
        CHECK(traj.times()(2) == Approx(0.45 * t.horizon(z.data())));
      }
    }
  }
}

TEST_CASE("transcription: the implicit dynamics form's derivatives agree with central differences",
          "[transcription][derivatives][implicit]") {
  // q̈ and λ as variables, the rows M q̈ + b − Aᵀλ = 0 and A q̈ + Ȧ q̇ = 0 at every point: every
  // example problem (the paper's pendulum has a closed chain), both rules, fixed and free T, with
  // bounds on the constraint forces where there are constraints (linear rows in λ).
  std::mt19937 rng(777);
  for (const char* name : {"cart_pole_swingup", "acrobot_swingup", "paper_pendulum_transfer"}) {
    const OptimalControlProblem file = trellis::loadProblem(problemPath(name));
    for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
      for (const bool freeHorizon : {false, true}) {
        OptimalControlProblem p = smaller(file, 4);
        p.dynamics = trellis::DynamicsForm::kImplicit;
        p.method = method;
        if (freeHorizon) {
          p.minHorizon = 0.5 * p.horizon;
          p.maxHorizon = 2.0 * p.horizon;
          p.timeWeight = 0.3;
        }
        p.Q = MatrixXd::Identity(p.nx(), p.nx()) * 0.7;
        p.goalState = VectorXd::LinSpaced(p.nx(), 0.1, 0.9);
        p.accelerationWeights = VectorXd::LinSpaced(p.nq(), 0.2, 0.9);  // ∫ q̈ᵀ W_a q̈ dt
        const int nc = p.model->nc();
        if (nc > 0) {
          p.forceLower(0) = -5.0;
          OptimalControlProblem::ForceCombination c;
          c.name = "sum";
          c.coefficients = VectorXd::Ones(nc);
          c.upper = 4.0;
          p.forceCombinations.push_back(c);
        }
        DYNAMIC_SECTION(name << (method == CollocationMethod::kHermiteSimpson ? " hermite_simpson" : method == CollocationMethod::kRadau ? " radau" : " trapezoidal")
                             << (freeHorizon ? " free T" : " fixed T")) {
          Transcription t(p);
          const int n = p.nq(), P = t.numPoints();
          // Per point 2n + m + n + nc variables and n + nc implicit rows.
          CHECK(t.stateIndex(1) - t.stateIndex(0) == 3 * n + p.nu() + nc);
          CHECK(t.hessianAvailable());
          checkDerivatives(t, randomPoint(t, rng));
          // The guess's λ is the least-squares balance of M q̈ + b at each point: the residual
          // r = M q̈ + b − Aᵀλ left in the implicit rows is orthogonal to the rows of A.
          const VectorXd z = t.initialGuess();
          VectorXd g(t.numConstraints());
          REQUIRE(t.evalConstraints(z.data(), g.data()));
          trellis::Data data(*p.model);
          for (int q = 0; q < P && nc > 0; ++q) {
            const VectorXd x = z.segment(t.stateIndex(q), p.nx());
            trellis::computeConstraints(*p.model, data, x.head(n), x.tail(n));
            const VectorXd r = g.segment(g.size() - P * (n + nc) + q * (n + nc), n);
            CHECK((data.constraintJacobian * r).cwiseAbs().maxCoeff() <= 1e-9 * (1.0 + r.cwiseAbs().maxCoeff()));
          }
        }
      }
    }
  }
}

TEST_CASE("transcription: finite-difference mode matches the exact Jacobian to FD accuracy",
          "[transcription][derivatives]") {
  const OptimalControlProblem p = smaller(trellis::loadProblem(problemPath("acrobot_swingup")), 4);
  Transcription exact(p), fd(p, trellis::DerivativeMode::kFiniteDifference);
  std::mt19937 rng(7);
  const VectorXd z = randomPoint(exact, rng);
  VectorXd a(exact.jacobianRows().size()), b(fd.jacobianRows().size());
  REQUIRE(a.size() == b.size());  // same pattern
  REQUIRE(exact.evalJacobian(z.data(), a.data()));
  REQUIRE(fd.evalJacobian(z.data(), b.data()));
  // Central differences of q̈: error ≈ 1e-10·|q̈'''| relative (see checkDerivatives); 1e-6
  // distinguishes a correct baseline from a wrong one while allowing FD error.
  CHECK((a - b).cwiseAbs().maxCoeff() < 1e-6 * std::max(1.0, a.cwiseAbs().maxCoeff()));
}

TEST_CASE("transcription: closed form on a linear spring-mass system", "[transcription][closed_form]") {
  // m q̈ = −k q + u: f = A x + B u with A = [[0, 1], [−k/m, 0]], B = [0; 1/m]. The trapezoidal
  // defect x_b − x_a − h/2 (f_a + f_b) then has Jacobian blocks −I − h/2 A, I − h/2 A, −h/2 B.
  const double mass = 2.0, k = 3.0, T = 1.5;
  trellis::ModelBuilder b("spring_mass");
  b.addFrame("cart", "world", trellis::Transform::tx("x"), trellis::Mass{mass});
  b.addConfigSpring("x", k, 0.0);
  b.addConfigForce("x", "push");
  OptimalControlProblem p(std::make_shared<const trellis::Model>(std::move(b).finalize()));
  p.knots = 3;
  p.setFixedHorizon(T);
  p.method = CollocationMethod::kTrapezoidal;
  Transcription t(p);
  const double h = T / 2;
  MatrixXd A(2, 2), B(2, 1);
  A << 0, 1, -k / mass, 0;
  B << 0, 1 / mass;
  MatrixXd expected = MatrixXd::Zero(4, t.numVariables());  // 2 intervals × 2 rows; z = [x u] × 3
  for (int interval = 0; interval < 2; ++interval) {
    const int a = interval * 3, bcol = (interval + 1) * 3;
    expected.block(2 * interval, a, 2, 2) = -MatrixXd::Identity(2, 2) - h / 2 * A;
    expected.block(2 * interval, a + 2, 2, 1) = -h / 2 * B;
    expected.block(2 * interval, bcol, 2, 2) = MatrixXd::Identity(2, 2) - h / 2 * A;
    expected.block(2 * interval, bcol + 2, 2, 1) = -h / 2 * B;
  }
  VectorXd z(9);
  z << 0.3, -0.2, 1.0, 0.5, 0.4, -2.0, 0.1, 0.0, 0.7;
  VectorXd values(t.jacobianRows().size());
  REQUIRE(t.evalJacobian(z.data(), values.data()));
  MatrixXd got = MatrixXd::Zero(4, 9);
  for (Eigen::Index e = 0; e < values.size(); ++e) got(t.jacobianRows()[e], t.jacobianCols()[e]) = values(e);
  // The core's A, B are exact; the only error is rounding of O(1) sums.
  CHECK((got - expected).cwiseAbs().maxCoeff() < 1e-13);
  // The defect of the linear system equals the formula applied by hand.
  VectorXd g(4);
  REQUIRE(t.evalConstraints(z.data(), g.data()));
  for (int interval = 0; interval < 2; ++interval) {
    const VectorXd xa = z.segment(3 * interval, 2), xb = z.segment(3 * interval + 3, 2);
    const double ua = z(3 * interval + 2), ub = z(3 * interval + 5);
    const VectorXd d = xb - xa - h / 2 * (A * xa + B * ua + A * xb + B * ub);
    CHECK((g.segment(2 * interval, 2) - d).cwiseAbs().maxCoeff() < 1e-13);
  }
}

TEST_CASE("transcription: the core is evaluated once per point and iterate",
          "[transcription][cache]") {
  OptimalControlProblem p = smaller(trellis::loadProblem(problemPath("cart_pole_swingup")), 6);
  Transcription t(p);
  const int P = t.numPoints();
  REQUIRE(P == 11);
  VectorXd z = t.initialGuess(), g(t.numConstraints()), values(t.jacobianRows().size());
  REQUIRE(t.evalConstraints(z.data(), g.data()));
  CHECK(t.dynamicsEvaluations() == P);
  REQUIRE(t.evalConstraints(z.data(), g.data()));
  REQUIRE(t.evalJacobian(z.data(), values.data()));
  REQUIRE(t.evalJacobian(z.data(), values.data()));
  REQUIRE(t.evalConstraints(z.data(), g.data()));
  CHECK(t.dynamicsEvaluations() == P);
  CHECK(t.linearizationEvaluations() == P);
  z(5) += 1e-3;  // a new iterate
  REQUIRE(t.evalJacobian(z.data(), values.data()));
  REQUIRE(t.evalConstraints(z.data(), g.data()));
  CHECK(t.dynamicsEvaluations() == P);
  CHECK(t.linearizationEvaluations() == 2 * P);
}

TEST_CASE("transcription: default guess interpolates the boundary states inside the bounds",
          "[transcription]") {
  const OptimalControlProblem p = trellis::loadProblem(problemPath("cart_pole_swingup"));
  Transcription t(p);
  const VectorXd z = t.initialGuess();
  const trellis::Trajectory guess = t.trajectory(z.data());
  REQUIRE(guess.size() == p.knots);
  for (int k = 0; k < p.knots; ++k) {
    const double s = static_cast<double>(k) / (p.knots - 1);
    const VectorXd expected = (1 - s) * p.initialState + s * p.finalState;
    CHECK((guess.states().col(k) - expected).cwiseAbs().maxCoeff() < 1e-14);
    CHECK(guess.times()(k) == Approx(s * p.horizon).margin(1e-14));
  }
  CHECK(guess.inputs().cwiseAbs().maxCoeff() == 0.0);
}

TEST_CASE("transcription: the acceleration weights add the quadrature of q̈ᵀ W_a q̈, implicit form only",
          "[transcription][implicit]") {
  // The cost with W_a minus the cost without, at the same point, is Σ_p w_p q̈_pᵀ W_a q̈_p with
  // Simpson's weights (h/6 at the end knots, 2h/6 inside, 4h/6 at the midpoints) — computed here
  // from the layout, not from the transcription's own weights.
  const OptimalControlProblem file = trellis::loadProblem(problemPath("acrobot_swingup"));
  OptimalControlProblem p = smaller(file, 5);
  p.dynamics = trellis::DynamicsForm::kImplicit;
  p.method = CollocationMethod::kHermiteSimpson;
  const int n = p.nq(), m = p.nu();
  std::mt19937 rng(99);
  Transcription plain(p);
  const VectorXd z = randomPoint(plain, rng);
  double without = 0.0, with = 0.0;
  REQUIRE(plain.evalCost(z.data(), without));
  p.accelerationWeights = VectorXd::LinSpaced(n, 0.5, 2.0);
  Transcription weighted(p);
  REQUIRE(weighted.evalCost(z.data(), with));
  const int N = weighted.numKnots(), P = weighted.numPoints();
  REQUIRE(P == 2 * N - 1);
  const double h = p.horizon / (N - 1);
  double expected = 0.0;
  for (int q = 0; q < P; ++q) {
    const double w = q % 2 == 1 ? 4.0 * h / 6.0 : (q == 0 || q == P - 1 ? h / 6.0 : 2.0 * h / 6.0);
    const VectorXd acc = z.segment(weighted.stateIndex(q) + 2 * n + m, n);
    expected += w * acc.dot(p.accelerationWeights.cwiseProduct(acc));
  }
  CHECK(expected > 1e-3);  // the random point's q̈ are not zero: the comparison is not vacuous
  CHECK(std::abs((with - without) - expected) <= 1e-12 * std::max(1.0, std::abs(with)));

  // Refused: with the explicit form (q̈ is no variable there), the wrong size, a negative entry.
  OptimalControlProblem explicitForm = p;
  explicitForm.dynamics = trellis::DynamicsForm::kExplicit;
  CHECK_THROWS_WITH(explicitForm.validate(), Catch::Contains("accelerationWeights needs dynamics = implicit"));
  OptimalControlProblem wrongSize = p;
  wrongSize.accelerationWeights = VectorXd::Ones(n + 1);
  CHECK_THROWS_WITH(wrongSize.validate(), Catch::Contains("accelerationWeights has " + std::to_string(n + 1)));
  OptimalControlProblem negative = p;
  negative.accelerationWeights(1) = -0.1;
  CHECK_THROWS_WITH(negative.validate(), Catch::Contains("accelerationWeights[1] (" + p.model->configNames()[1] + ") = -0.1"));
}

TEST_CASE("transcription: flagged end accelerations are fixed at 0, implicit form only", "[transcription][implicit]") {
  // initial/finalAccelerationFixed: the flagged q̈ of the first and last knot get the bounds 0, 0
  // (and the guess 0 there); the others and every other point keep q̈ free. Both rules with
  // interior points (HS midpoints, Radau stages), so the last knot's block is not P − 1 by luck.
  const OptimalControlProblem file = trellis::loadProblem(problemPath("acrobot_swingup"));
  for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kRadau}) {
    OptimalControlProblem p = smaller(file, 4);
    p.dynamics = trellis::DynamicsForm::kImplicit;
    p.method = method;
    const int n = p.nq(), m = p.nu();
    p.initialAccelerationFixed = {true, false};
    p.finalAccelerationFixed = {false, true};
    REQUIRE(n == 2);
    Transcription t(p);
    Eigen::VectorXd lo, hi;
    t.variableBounds(lo, hi);
    const Eigen::VectorXd z = t.initialGuess();
    const int first = t.stateIndex(t.knotPoint(0)) + 2 * n + m, last = t.stateIndex(t.knotPoint(p.knots - 1)) + 2 * n + m;
    CHECK(lo(first) == 0.0);
    CHECK(hi(first) == 0.0);
    CHECK(z(first) == 0.0);
    CHECK(std::isinf(lo(first + 1)));
    CHECK(std::isinf(lo(last)));
    CHECK(lo(last + 1) == 0.0);
    CHECK(hi(last + 1) == 0.0);
    CHECK(z(last + 1) == 0.0);
    int fixedAccelerations = 0;  // no other q̈ is bounded
    for (int q = 0; q < t.numPoints(); ++q)
      for (int i = 0; i < n; ++i) fixedAccelerations += lo(t.stateIndex(q) + 2 * n + m + i) == hi(t.stateIndex(q) + 2 * n + m + i);
    CHECK(fixedAccelerations == 2);
  }
  OptimalControlProblem bad = smaller(file, 4);
  bad.initialAccelerationFixed = {true, true};
  CHECK_THROWS_WITH(bad.validate(), Catch::Contains("initialAccelerationFixed needs dynamics = implicit"));
  bad.dynamics = trellis::DynamicsForm::kImplicit;
  bad.finalAccelerationFixed = {true};
  CHECK_THROWS_WITH(bad.validate(), Catch::Contains("finalAccelerationFixed has 1 flags"));
}
