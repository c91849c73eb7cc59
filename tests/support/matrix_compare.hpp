// tests/support/matrix_compare.hpp — compare two matrices entry by entry and report the worst one.
//
// The error of entry (i, j) is |got − expected| / scale(i, j), with the scale chosen by `Scale`:
//   kAbsolute  1
//   kColumn    max(1, ‖expected column j‖∞)   — for Jacobians: a column is one derivative
//   direction,
//                                               and finite-difference error scales with it
//   kMatrix    max(1, ‖expected‖max)          — for results of one computation (rounding ∝ size)
//   kEntry     max(floor, |expected(i, j)|)   — plain relative error with an absolute floor
// A failed comparison names the label, the worst entry (row, col), expected, got, the error and
// the tolerance; a size mismatch or a non-finite entry in `got` always fails.
#pragma once

#include <Eigen/Core>

#include <string>

namespace trellis::test {

enum class Scale { kAbsolute, kColumn, kMatrix, kEntry };

struct MatrixComparison {
  bool ok = true;
  double worstError = 0.0;  ///< largest scaled error
  Eigen::Index row = -1, col = -1;
  double expected = 0.0, got = 0.0;
  std::string message;  ///< one line; empty only when ok and empty matrices
};

MatrixComparison compareMatrices(const Eigen::MatrixXd& expected, const Eigen::MatrixXd& got,
                                 double tolerance, Scale scale, const std::string& label = "",
                                 double entryFloor = 1.0);

/// True if every entry is finite.
bool allFinite(const Eigen::MatrixXd& m);

}  // namespace trellis::test

/// CHECK that `got` matches `expected` (see compareMatrices); on failure the worst entry is
/// printed.
#define TRELLIS_CHECK_MATRIX(expected, got, tolerance, scale)                                \
  do {                                                                                       \
    const ::trellis::test::MatrixComparison trellis_cmp_ = ::trellis::test::compareMatrices( \
        (expected), (got), (tolerance), (scale), #got " vs " #expected);                     \
    INFO(trellis_cmp_.message);                                                              \
    CHECK(trellis_cmp_.ok);                                                                  \
  } while (false)

#define TRELLIS_REQUIRE_MATRIX(expected, got, tolerance, scale)                              \
  do {                                                                                       \
    const ::trellis::test::MatrixComparison trellis_cmp_ = ::trellis::test::compareMatrices( \
        (expected), (got), (tolerance), (scale), #got " vs " #expected);                     \
    INFO(trellis_cmp_.message);                                                              \
    REQUIRE(trellis_cmp_.ok);                                                                \
  } while (false)
