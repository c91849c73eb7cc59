// Tests for trellis/analysis/dense_output.hpp: the step polynomials of an integration.
#include <trellis/analysis/dense_output.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Core>

#include <stdexcept>

using Eigen::MatrixXd;
using Eigen::VectorXd;

TEST_CASE("dense output: a step's polynomial from its derivatives at the step end", "[dense_output]") {
  // y(s) = [1 + 2s + 3s², −s³] on a step ending at s = 1 (order 3): D = [y, y', y'', y'''](1).
  MatrixXd D(2, 4);
  D << 6.0, 8.0, 6.0, 0.0,  //
      -1.0, -3.0, -6.0, -6.0;
  trellis::DenseOutput out;
  out.append(0.0, VectorXd::Zero(2));  // the initial point (a constant)
  out.append(1.0, D);
  REQUIRE(out.size() == 2);
  CHECK(out.dimension() == 2);
  CHECK(out.order(0) == 0);
  CHECK(out.order(1) == 3);
  VectorXd y(2);
  for (double s : {0.25, 0.5, 0.9, 1.0}) {
    out.evaluate(s, y);
    CHECK(y(0) == Approx(1.0 + 2.0 * s + 3.0 * s * s).epsilon(1e-14));
    CHECK(y(1) == Approx(-s * s * s).margin(1e-14));
  }
  // The first step covers s ≤ its end: the constant.
  CHECK(out.locate(0.0) == 0);
  CHECK(out.locate(1e-9) == 1);
  CHECK(out.locate(2.0) == 1);  // beyond the last end: the last polynomial (callers range-check)
}

TEST_CASE("dense output refuses steps out of order or of another size", "[dense_output]") {
  trellis::DenseOutput out;
  CHECK_THROWS_AS(out.locate(0.0), std::out_of_range);
  CHECK_THROWS_AS(out.append(0.0, MatrixXd(2, 0)), std::invalid_argument);
  out.append(1.0, VectorXd::Ones(2));
  CHECK_THROWS_AS(out.append(0.5, VectorXd::Ones(2)), std::invalid_argument);
  CHECK_THROWS_AS(out.append(2.0, VectorXd::Ones(3)), std::invalid_argument);
}
