// Tests for the Lagrangian Hessian of trellis/optimization/transcription.hpp: σ∇²J + Σ μ_c ∇²g_c
// against central differences of the exact gradient σ∇J + (∂g/∂z)ᵀ μ on every example problem
// (both methods, fixed and free horizon, every cost term), the closed chain's slack and knot rows
// included; the declared lower-triangular pattern (no duplicates, complete, row ≥ column).
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

/// ∇L = σ ∇J + (∂g/∂z)ᵀ μ from the exact first derivatives (dense).
VectorXd lagrangianGradient(Transcription& t, const VectorXd& z, double sigma, const VectorXd& mu) {
  VectorXd grad(t.numVariables());
  REQUIRE(t.evalCostGradient(z.data(), grad.data()));
  grad *= sigma;
  VectorXd values(t.jacobianRows().size());
  REQUIRE(t.evalJacobian(z.data(), values.data()));
  for (Eigen::Index k = 0; k < values.size(); ++k) {
    grad(t.jacobianCols()[k]) += values(k) * mu(t.jacobianRows()[k]);
  }
  return grad;
}

/// Worst entry error of the exact Hessian against central differences of ∇L, relative to
/// max(1, |entry|), over the whole matrix (so symmetry and the pattern's completeness are checked:
/// an entry outside the pattern is zero in the exact matrix and must be so in the differences).
/// Step ε^(1/3)·max(1, |z_j|): truncation ≈ 6e-12·|∇L'''|, rounding ≈ 4e-11·|∇L|, with |∇L| up to
/// ~1e3 at these perturbed points: ≲ 1e-7 relative, so 1e-6 leaves a margin while a missing term
/// (a dropped third derivative, a wrong factor h/6) is off by O(1e-2) or more.
void checkHessian(Transcription& t, const VectorXd& z, double sigma, const VectorXd& mu) {
  const int nv = t.numVariables();
  REQUIRE(t.hessianAvailable());
  const auto& rows = t.hessianRows();
  const auto& cols = t.hessianCols();
  VectorXd values(rows.size());
  REQUIRE(t.evalHessian(z.data(), sigma, mu.data(), values.data()));
  MatrixXd exact = MatrixXd::Zero(nv, nv);
  std::set<std::pair<int, int>> pattern;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    REQUIRE(rows[k] >= cols[k]);  // lower triangle
    REQUIRE(cols[k] >= 0);
    REQUIRE(rows[k] < nv);
    REQUIRE(pattern.insert({rows[k], cols[k]}).second);  // no duplicates
    exact(rows[k], cols[k]) = values(k);
    exact(cols[k], rows[k]) = values(k);
  }
  const double eps = std::cbrt(std::numeric_limits<double>::epsilon());
  MatrixXd fd(nv, nv);
  VectorXd zp = z;
  for (int j = 0; j < nv; ++j) {
    const double step = eps * std::max(1.0, std::abs(z(j)));
    zp(j) = z(j) + step;
    const double up = zp(j);
    const VectorXd gp = lagrangianGradient(t, zp, sigma, mu);
    zp(j) = z(j) - step;
    const double down = zp(j);
    const VectorXd gm = lagrangianGradient(t, zp, sigma, mu);
    zp(j) = z(j);
    fd.col(j) = (gp - gm) / (up - down);
  }
  double worst = 0.0, asymmetry = 0.0;
  int wr = -1, wc = -1;
  for (int c = 0; c < nv; ++c) {
    for (int r = 0; r < nv; ++r) {
      const double err = std::abs(exact(r, c) - fd(r, c)) / std::max(1.0, std::abs(fd(r, c)));
      if (err > worst) worst = err, wr = r, wc = c;
      asymmetry = std::max(asymmetry, std::abs(fd(r, c) - fd(c, r)) / std::max(1.0, std::abs(fd(r, c))));
    }
  }
  INFO("Hessian: worst relative error " << worst << " at (" << wr << ", " << wc << "): exact "
       << (wr >= 0 ? exact(wr, wc) : 0.0) << ", finite difference " << (wr >= 0 ? fd(wr, wc) : 0.0)
       << ", in pattern: " << (wr >= 0 && (pattern.count({wr, wc}) || pattern.count({wc, wr})) ? "yes" : "no")
       << "; largest entry " << exact.cwiseAbs().maxCoeff() << "; asymmetry of the differences " << asymmetry);
  CHECK(worst < 1e-6);
}

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

VectorXd randomMultipliers(const Transcription& t, std::mt19937& rng) {
  std::uniform_real_distribution<double> d(-2.0, 2.0);
  VectorXd mu(t.numConstraints());
  for (int i = 0; i < mu.size(); ++i) mu(i) = d(rng);
  return mu;
}

/// One example problem as the Hessian checks take it: 4 knots on a non-uniform mesh (every interval
/// its own h), the given rule, a free horizon with a time weight if asked, and every cost term.
OptimalControlProblem hessianCase(const OptimalControlProblem& file, CollocationMethod method, bool freeHorizon) {
  OptimalControlProblem p = file;
  p.knots = 4;
  p.mesh.resize(4);
  p.mesh << 0.0, 0.2, 0.65, 1.0;
  p.method = method;
  if (freeHorizon) {
    p.minHorizon = 0.5 * p.horizon;
    p.maxHorizon = 2.0 * p.horizon;
    p.timeWeight = 0.3;
  }
  p.Q = MatrixXd::Identity(p.nx(), p.nx()) * 0.7;
  p.Qf = MatrixXd::Identity(p.nx(), p.nx()) * 3.0;
  p.goalState = VectorXd::LinSpaced(p.nx(), 0.1, 0.9);
  return p;
}

}  // namespace

TEST_CASE("hessian: the Lagrangian Hessian agrees with differences of the exact gradient",
          "[transcription][hessian]") {
  std::mt19937 rng(2030);
  for (const char* name : {"cart_pole_swingup", "acrobot_swingup", "paper_pendulum_transfer"}) {
    const OptimalControlProblem file = trellis::loadProblem(problemPath(name));
    for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
      for (const bool freeHorizon : {false, true}) {
        OptimalControlProblem p = hessianCase(file, method, freeHorizon);
        p.Q(0, 1) = p.Q(1, 0) = 0.2;
        DYNAMIC_SECTION(name << (method == CollocationMethod::kHermiteSimpson ? " hermite_simpson"
                                                                             : " trapezoidal")
                             << (freeHorizon ? " free T" : " fixed T")) {
          Transcription t(p);
          checkHessian(t, randomPoint(t, rng), 0.7, randomMultipliers(t, rng));
        }
      }
    }
  }
}

TEST_CASE("hessian: the implicit dynamics form's Lagrangian Hessian agrees with differences of the exact gradient",
          "[transcription][hessian][implicit]") {
  // q̈ and λ as variables (computeImplicitSecondOrder per point), with force rows on the closed
  // chain (linear in λ: no second derivatives of their own), both rules, fixed and free T.
  std::mt19937 rng(2031);
  for (const char* name : {"cart_pole_swingup", "acrobot_swingup", "paper_pendulum_transfer"}) {
    const OptimalControlProblem file = trellis::loadProblem(problemPath(name));
    for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
      for (const bool freeHorizon : {false, true}) {
        OptimalControlProblem p = hessianCase(file, method, freeHorizon);
        p.dynamics = trellis::DynamicsForm::kImplicit;
        p.R = MatrixXd::Identity(p.nu(), p.nu()) * 0.4;
        p.accelerationWeights = VectorXd::LinSpaced(p.nq(), 0.3, 1.1);  // its diagonal block
        if (p.model->nc() > 0) p.forceUpper(0) = 50.0;
        DYNAMIC_SECTION(name << (method == CollocationMethod::kHermiteSimpson ? " hermite_simpson" : method == CollocationMethod::kRadau ? " radau" : " trapezoidal")
                             << (freeHorizon ? " free T" : " fixed T")) {
          Transcription t(p);
          checkHessian(t, randomPoint(t, rng), 0.7, randomMultipliers(t, rng));
        }
      }
    }
  }
}

TEST_CASE("hessian: the implicit form's point blocks on several threads give the same values",
          "[transcription][hessian][implicit]") {
  // Transcription::setThreads: the points' second-order blocks are independent (each thread its own
  // Data and workspace) and gathered in point order: the values equal the one-thread ones to the bit,
  // also where some points' multipliers are zero (those blocks are skipped on every count).
  std::mt19937 rng(77);
  const OptimalControlProblem file = trellis::loadProblem(problemPath("paper_pendulum_transfer"));
  OptimalControlProblem p = hessianCase(file, CollocationMethod::kHermiteSimpson, true);
  p.dynamics = trellis::DynamicsForm::kImplicit;
  p.forceUpper(0) = 50.0;
  Transcription one(p), many(p);
  const VectorXd z = randomPoint(one, rng);
  VectorXd mu = randomMultipliers(one, rng);
  mu.head(mu.size() / 3).setZero();
  VectorXd a(one.hessianRows().size()), b(a.size());
  REQUIRE(one.evalHessian(z.data(), 0.7, mu.data(), a.data()));
  for (const int threads : {2, 3, 64}) {
    many.setThreads(threads);
    REQUIRE(many.evalHessian(z.data(), 0.7, mu.data(), b.data()));
    INFO(threads << " threads");
    CHECK(a == b);
    CHECK(many.secondOrderEvaluations() == one.secondOrderEvaluations() * (threads == 2 ? 1 : threads == 3 ? 2 : 3));
  }
  CHECK(a.cwiseAbs().maxCoeff() > 0.0);
  CHECK_THROWS_WITH(many.setThreads(0), Catch::Contains("threads = 0"));
  CHECK_THROWS_WITH(many.setThreads(Transcription::kMaxThreads + 1), Catch::Contains("threads = 257 must be in 1..256"));
  // The knots' third-derivative terms too, on both forms, with a knife edge beside a holonomic row
  // (the recorded implicit residual's path) and with the distance row alone.
  for (const auto form : {trellis::DynamicsForm::kExplicit, trellis::DynamicsForm::kImplicit}) {
    OptimalControlProblem q(trellis::test::skateModel(true));
    q.dynamics = form;
    q.knots = 5;
    q.setFixedHorizon(2.0);
    q.Q = MatrixXd::Identity(q.nx(), q.nx()) * 0.4;
    q.R = MatrixXd::Identity(q.nu(), q.nu()) * 0.3;
    q.initialFixed.assign(q.nx(), false);
    q.finalFixed.assign(q.nx(), false);
    Transcription serial(q), threaded(q);
    threaded.setThreads(3);
    const VectorXd zq = randomPoint(serial, rng);
    const VectorXd muq = randomMultipliers(serial, rng);
    VectorXd c(serial.hessianRows().size()), d(c.size());
    REQUIRE(serial.evalHessian(zq.data(), 0.3, muq.data(), c.data()));
    REQUIRE(threaded.evalHessian(zq.data(), 0.3, muq.data(), d.data()));
    INFO((form == trellis::DynamicsForm::kImplicit ? "implicit" : "explicit") << " skate with arm");
    CHECK(c == d);
    CHECK(threaded.secondOrderEvaluations() == serial.secondOrderEvaluations());
  }
}

TEST_CASE("hessian: objective only and constraints only", "[transcription][hessian]") {
  const OptimalControlProblem p = [] {
    OptimalControlProblem q = trellis::loadProblem(problemPath("paper_pendulum_transfer"));
    q.knots = 3;
    return q;
  }();
  Transcription t(p);
  std::mt19937 rng(5);
  const VectorXd z = randomPoint(t, rng);
  SECTION("σ = 1, μ = 0") { checkHessian(t, z, 1.0, VectorXd::Zero(t.numConstraints())); }
  SECTION("σ = 0, μ random") { checkHessian(t, z, 0.0, randomMultipliers(t, rng)); }
}

TEST_CASE("hessian: knife edges, alone and beside a holonomic row, on both forms",
          "[transcription][hessian][knife_edge]") {
  // A skate whose blade sits off the centre of mass (the knife-edge row's ∂A/∂q is then not
  // symmetric: the holonomic rows' third-derivative identity does not hold and the recorded
  // implicit residual gives ∇²_q(ρᵀA(q)v)); with `arm`, a link on the skate whose tip keeps its
  // distance to a world point (a holonomic row with h, γ and its own third derivatives) beside it.
  for (const bool arm : {false, true}) {
    const auto model = trellis::test::skateModel(arm);
    std::mt19937 rng(arm ? 31 : 13);
    for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
      for (const auto form : {trellis::DynamicsForm::kExplicit, trellis::DynamicsForm::kImplicit}) {
        for (const bool freeHorizon : {false, true}) {
          OptimalControlProblem p(model);
          p.method = method;
          p.dynamics = form;
          p.knots = 4;
          p.mesh.resize(4);
          p.mesh << 0.0, 0.3, 0.45, 1.0;
          p.setFixedHorizon(2.0);
          if (freeHorizon) {
            p.minHorizon = 1.0;
            p.maxHorizon = 3.0;
            p.timeWeight = 0.2;
          }
          p.Q = MatrixXd::Identity(p.nx(), p.nx()) * 0.4;
          p.R = MatrixXd::Identity(p.nu(), p.nu()) * 0.3;
          p.initialFixed.assign(p.nx(), false);  // zero boundary states are off the distance row
          p.finalFixed.assign(p.nx(), false);
          DYNAMIC_SECTION((arm ? "knife edge + distance, " : "knife edge, ")
                          << (method == CollocationMethod::kHermiteSimpson ? "hermite_simpson" : method == CollocationMethod::kRadau ? "radau" : "trapezoidal")
                          << (form == trellis::DynamicsForm::kImplicit ? ", implicit" : ", explicit")
                          << (freeHorizon ? ", free T" : ", fixed T")) {
            Transcription t(p);
            REQUIRE(t.hessianAvailable());
            CHECK(t.hessianUnavailableReason().empty());
            const VectorXd z = randomPoint(t, rng);
            checkHessian(t, z, 0.7, randomMultipliers(t, rng));
            checkHessian(t, z, 0.0, randomMultipliers(t, rng));
          }
        }
      }
    }
  }
}

TEST_CASE("hessian: constraint-force bounds add rows λ_r(x_p, u_p) with exact first and second derivatives",
          "[transcription][hessian][force_bounds]") {
  std::mt19937 rng(99);
  for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
    DYNAMIC_SECTION((method == CollocationMethod::kHermiteSimpson ? "hermite_simpson" : method == CollocationMethod::kRadau ? "radau" : "trapezoidal")) {
      OptimalControlProblem p = trellis::loadProblem(problemPath("paper_pendulum_transfer"));
      p.knots = 3;
      p.method = method;
      p.forceLower(0) = -5.0;  // one side only is enough to add the rows
      Transcription t(p);
      const int P = t.numPoints();
      REQUIRE(t.forceRowsPerPoint() == 1);
      REQUIRE(t.numConstraints() == t.forceRow(0) + P);
      VectorXd lower, upper;
      t.constraintBounds(lower, upper);
      CHECK(lower(t.forceRow(P - 1)) == -5.0);
      CHECK(std::isinf(upper(t.forceRow(P - 1))));
      CHECK(lower(0) == 0.0);
      CHECK(upper(0) == 0.0);
      const VectorXd z = randomPoint(t, rng);
      // The rows are λ at each point (the core's forward dynamics there).
      VectorXd g(t.numConstraints());
      REQUIRE(t.evalConstraints(z.data(), g.data()));
      trellis::Data data(*p.model);
      for (int q = 0; q < P; ++q) {
        const VectorXd x = z.segment(t.stateIndex(q), p.nx()), u = z.segment(t.inputIndex(q), p.nu());
        trellis::computeDynamics(*p.model, data, x.head(p.nq()), x.tail(p.nq()), u);
        CHECK(g(t.forceRow(q)) == Approx(data.lambda(0)).epsilon(1e-12));
      }
      // Jacobian rows against central differences of g.
      VectorXd values(t.jacobianRows().size());
      REQUIRE(t.evalJacobian(z.data(), values.data()));
      MatrixXd exact = MatrixXd::Zero(t.numConstraints(), t.numVariables());
      for (std::size_t k = 0; k < t.jacobianRows().size(); ++k) exact(t.jacobianRows()[k], t.jacobianCols()[k]) = values(k);
      const double eps = std::cbrt(std::numeric_limits<double>::epsilon());
      VectorXd zp = z, gp(g.size()), gm(g.size());
      double worst = 0.0;
      for (int j = 0; j < z.size(); ++j) {
        const double step = eps * std::max(1.0, std::abs(z(j)));
        zp(j) = z(j) + step;
        REQUIRE(t.evalConstraints(zp.data(), gp.data()));
        zp(j) = z(j) - step;
        REQUIRE(t.evalConstraints(zp.data(), gm.data()));
        zp(j) = z(j);
        for (int r = t.forceRow(0); r < t.numConstraints(); ++r) {
          const double fd = (gp(r) - gm(r)) / (2.0 * step);
          worst = std::max(worst, std::abs(exact(r, j) - fd) / std::max(1.0, std::abs(fd)));
        }
      }
      INFO("force rows of the Jacobian: worst relative error " << worst);
      CHECK(worst < 1e-6);
      checkHessian(t, z, 0.4, randomMultipliers(t, rng));
    }
  }
}

TEST_CASE("hessian: force combinations add rows cᵀλ(x_p, u_p) with exact first and second derivatives",
          "[transcription][hessian][force_bounds]") {
  // The rows a friction pyramid uses (cos θ λ_t1 + sin θ λ_t2 − μ' λ_n ≤ 0): linear combinations of
  // λ, after the box rows. On the closed-chain pendulum with a box row on λ_0 and two combinations
  // over every row, at a random point: values against the core's λ, Jacobian against central
  // differences of g, Hessian against differences of the exact gradient (checkHessian).
  std::mt19937 rng(2604);
  for (const auto method : {CollocationMethod::kHermiteSimpson, CollocationMethod::kTrapezoidal, CollocationMethod::kRadau}) {
    DYNAMIC_SECTION((method == CollocationMethod::kHermiteSimpson ? "hermite_simpson" : method == CollocationMethod::kRadau ? "radau" : "trapezoidal")) {
      OptimalControlProblem p = trellis::loadProblem(problemPath("paper_pendulum_transfer"));
      const int nc = p.model->nc();
      REQUIRE(nc >= 1);
      p.knots = 3;
      p.method = method;
      p.forceLower(0) = -5.0;
      std::uniform_real_distribution<double> unit(-1.0, 1.0);
      for (int k = 0; k < 2; ++k) {
        OptimalControlProblem::ForceCombination c;
        c.name = "combination " + std::to_string(k);
        c.coefficients = VectorXd(nc);
        for (int r = 0; r < nc; ++r) c.coefficients(r) = unit(rng);
        c.upper = 1.0 + k;
        p.forceCombinations.push_back(c);
      }
      Transcription t(p);
      const int P = t.numPoints();
      REQUIRE(t.forceRowsPerPoint() == 3);
      REQUIRE(t.numConstraints() == t.forceRow(0) + 3 * P);
      VectorXd lower, upper;
      t.constraintBounds(lower, upper);
      CHECK(lower(t.forceRow(P - 1)) == -5.0);
      CHECK(std::isinf(lower(t.forceRow(P - 1) + 1)));
      CHECK(upper(t.forceRow(P - 1) + 2) == 2.0);
      const VectorXd z = randomPoint(t, rng);
      VectorXd g(t.numConstraints());
      REQUIRE(t.evalConstraints(z.data(), g.data()));
      trellis::Data data(*p.model);
      for (int q = 0; q < P; ++q) {
        const VectorXd x = z.segment(t.stateIndex(q), p.nx()), u = z.segment(t.inputIndex(q), p.nu());
        trellis::computeDynamics(*p.model, data, x.head(p.nq()), x.tail(p.nq()), u);
        CHECK(g(t.forceRow(q)) == Approx(data.lambda(0)).epsilon(1e-12));
        for (int k = 0; k < 2; ++k) {
          const double expected = p.forceCombinations[k].coefficients.dot(data.lambda);
          CHECK(g(t.forceRow(q) + 1 + k) == Approx(expected).epsilon(1e-12).margin(1e-12 * data.lambda.norm()));
        }
      }
      VectorXd values(t.jacobianRows().size());
      REQUIRE(t.evalJacobian(z.data(), values.data()));
      MatrixXd exact = MatrixXd::Zero(t.numConstraints(), t.numVariables());
      for (std::size_t k = 0; k < t.jacobianRows().size(); ++k) exact(t.jacobianRows()[k], t.jacobianCols()[k]) = values(k);
      // Central differences, step eps^(1/3)·max(1, |z_j|): error ~eps^(2/3) ≈ 4e-11 relative to
      // the size of λ's second derivatives; 1e-6 as for the box rows above.
      const double eps = std::cbrt(std::numeric_limits<double>::epsilon());
      VectorXd zp = z, gp(g.size()), gm(g.size());
      double worst = 0.0;
      for (int j = 0; j < z.size(); ++j) {
        const double step = eps * std::max(1.0, std::abs(z(j)));
        zp(j) = z(j) + step;
        REQUIRE(t.evalConstraints(zp.data(), gp.data()));
        zp(j) = z(j) - step;
        REQUIRE(t.evalConstraints(zp.data(), gm.data()));
        zp(j) = z(j);
        for (int r = t.forceRow(0); r < t.numConstraints(); ++r) {
          const double fd = (gp(r) - gm(r)) / (2.0 * step);
          worst = std::max(worst, std::abs(exact(r, j) - fd) / std::max(1.0, std::abs(fd)));
        }
      }
      INFO("force rows of the Jacobian: worst relative error " << worst);
      CHECK(worst < 1e-6);
      checkHessian(t, z, 0.4, randomMultipliers(t, rng));
    }
  }
}

TEST_CASE("problem: a bad force combination is refused with its index, name and field",
          "[problem][force_bounds]") {
  OptimalControlProblem p = trellis::loadProblem(problemPath("paper_pendulum_transfer"));
  OptimalControlProblem::ForceCombination c;
  c.name = "facet";
  c.coefficients = VectorXd::Ones(p.model->nc() + 1);
  c.upper = 0.0;
  p.forceCombinations.push_back(c);
  CHECK_THROWS_WITH(p.validate(), Catch::Contains("forceCombinations[0] ('facet')") && Catch::Contains("coefficients"));
  p.forceCombinations[0].coefficients = VectorXd::Ones(p.model->nc());
  p.forceCombinations[0].upper = std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH(p.validate(), Catch::Contains("both infinite"));
  p.forceCombinations[0].upper = 0.0;
  CHECK_NOTHROW(p.validate());
}
