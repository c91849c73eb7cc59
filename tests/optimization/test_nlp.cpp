// Tests of trellis/optimization/nlp.hpp: solveNlp on programs with closed-form answers.
#include <trellis/optimization/nlp.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <stdexcept>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using namespace trellis;

namespace {

/// min (x0 − 2)² + (x1 − 1)²  s.t.  x0 + x1 = c,  x0 ≥ lower0: the projection of (2, 1) on the line,
/// ((c + 1)/2, (c − 1)/2) while x0 stays above lower0.
NlpProblem projection(double c, double lower0) {
  NlpProblem p;
  const double inf = std::numeric_limits<double>::infinity();
  p.lower = VectorXd::Constant(2, -inf);
  p.lower(0) = lower0;
  p.upper = VectorXd::Constant(2, inf);
  p.constraintLower = p.constraintUpper = VectorXd::Constant(1, c);
  p.start = VectorXd::Constant(2, 5.0);
  p.objective = [](const VectorXd& x, double& f, VectorXd& g) {
    f = (x(0) - 2.0) * (x(0) - 2.0) + (x(1) - 1.0) * (x(1) - 1.0);
    g << 2.0 * (x(0) - 2.0), 2.0 * (x(1) - 1.0);
    return true;
  };
  p.constraints = [](const VectorXd& x, VectorXd& g, MatrixXd& J) {
    g(0) = x(0) + x(1);
    J << 1.0, 1.0;
    return true;
  };
  return p;
}

}  // namespace

TEST_CASE("solveNlp: the projection onto a line, with and without an active bound", "[nlp]") {
  SECTION("bound inactive: ((c + 1)/2, (c − 1)/2), multiplier 2·(distance along the normal)") {
    const NlpResult r = solveNlp(projection(1.0, -10.0));
    INFO(r.status.message);
    REQUIRE(r.ok());
    CHECK(r.x(0) == Approx(1.0).margin(1e-8));
    CHECK(r.x(1) == Approx(0.0).margin(1e-8));
    CHECK(r.constraintViolation <= 1e-10);
    CHECK(r.iterations > 0);
  }
  SECTION("bound active: x0 = 3 on its bound, x1 = c − 3, the bound's multiplier 2·(3 − 2) − ν") {
    const NlpResult r = solveNlp(projection(1.0, 3.0));
    INFO(r.status.message);
    REQUIRE(r.ok());
    CHECK(r.x(0) == Approx(3.0).margin(1e-7));
    CHECK(r.x(1) == Approx(-2.0).margin(1e-7));
    // Stationarity: ∇f + ν ∇g − z_L e0 = 0 → ν = −2(x1 − 1) = 6, z_L = 2(x0 − 2) + ν = 8.
    CHECK(r.lowerBoundMultipliers(0) == Approx(8.0).epsilon(1e-6));
  }
}

TEST_CASE("solveNlp: an infeasible program is a status, not a success", "[nlp]") {
  // x0 + x1 = 1 with x0 ≥ 3 and x1 ≥ 0: no point.
  NlpProblem p = projection(1.0, 3.0);
  p.lower(1) = 0.0;
  const NlpResult r = solveNlp(p);
  CHECK_FALSE(r.ok());
  CHECK(r.status.code == OptimizationCode::kInfeasible);
  CHECK(r.constraintViolation > 1e-3);
  CHECK_THAT(r.status.message, Catch::Contains("Infeasible"));
}

TEST_CASE("solveNlp: a success Ipopt reports is checked again at the returned x", "[nlp]") {
  // Ipopt's iterates are deterministic: the first run counts the constraint calls, the second
  // answers differently only at the call after them (solveNlp's own evaluation at the returned x),
  // as a model that is not a function of x would. Either way the result must not be ok.
  const NlpResult clean = solveNlp(projection(1.0, -10.0));
  REQUIRE(clean.ok());
  const long calls = clean.evaluations;
  SECTION("the constraints do not evaluate there") {
    NlpProblem p = projection(1.0, -10.0);
    long n = 0;
    auto inner = p.constraints;
    p.constraints = [&n, calls, inner](const VectorXd& x, VectorXd& g, MatrixXd& J) {
      return ++n <= calls && inner(x, g, J);
    };
    const NlpResult r = solveNlp(p);
    CHECK_FALSE(r.ok());
    CHECK(r.status.code == OptimizationCode::kFailed);
    CHECK_THAT(r.status.message, Catch::Contains("do not evaluate"));
  }
  SECTION("a row is violated there beyond the tolerance") {
    NlpProblem p = projection(1.0, -10.0);
    long n = 0;
    auto inner = p.constraints;
    p.constraints = [&n, calls, inner](const VectorXd& x, VectorXd& g, MatrixXd& J) {
      const bool ok = inner(x, g, J);
      if (++n > calls) g(0) += 1e-6;
      return ok;
    };
    const NlpResult r = solveNlp(p);
    CHECK_FALSE(r.ok());
    CHECK(r.status.code == OptimizationCode::kFailed);
    CHECK_THAT(r.status.message, Catch::Contains("violates a constraint"));
    CHECK(r.constraintViolation == Approx(1e-6).epsilon(1e-3));
  }
}

TEST_CASE("solveNlp: bad problems throw, naming the field", "[nlp]") {
  NlpProblem p = projection(1.0, 0.0);
  p.upper(0) = -1.0;
  CHECK_THROWS_WITH(solveNlp(p), Catch::Contains("lower") && Catch::Contains("upper"));
  NlpProblem q = projection(1.0, 0.0);
  q.constraints = nullptr;
  CHECK_THROWS_WITH(solveNlp(q), Catch::Contains("callback"));
}
