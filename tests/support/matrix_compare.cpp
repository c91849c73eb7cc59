// tests/support/matrix_compare.cpp
#include "support/matrix_compare.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

namespace trellis::test {

bool allFinite(const Eigen::MatrixXd& m) {
  for (Eigen::Index j = 0; j < m.cols(); ++j)
    for (Eigen::Index i = 0; i < m.rows(); ++i)
      if (!std::isfinite(m(i, j))) return false;
  return true;
}

MatrixComparison compareMatrices(const Eigen::MatrixXd& expected, const Eigen::MatrixXd& got,
                                 double tolerance, Scale scale, const std::string& label,
                                 double entryFloor) {
  MatrixComparison r;
  std::ostringstream os;
  os << std::setprecision(12);
  if (!label.empty()) os << label << ": ";
  if (expected.rows() != got.rows() || expected.cols() != got.cols()) {
    r.ok = false;
    os << "size mismatch: expected " << expected.rows() << "x" << expected.cols() << ", got "
       << got.rows() << "x" << got.cols();
    r.message = os.str();
    return r;
  }
  const double matrixScale =
      std::max(1.0, expected.size() > 0 ? expected.cwiseAbs().maxCoeff() : 0.0);
  bool nonFinite = false;
  for (Eigen::Index j = 0; j < expected.cols(); ++j) {
    double s = 1.0;
    if (scale == Scale::kColumn) s = std::max(1.0, expected.col(j).cwiseAbs().maxCoeff());
    if (scale == Scale::kMatrix) s = matrixScale;
    for (Eigen::Index i = 0; i < expected.rows(); ++i) {
      if (scale == Scale::kEntry) s = std::max(entryFloor, std::abs(expected(i, j)));
      const double g = got(i, j);
      double err = std::abs(g - expected(i, j)) / s;
      if (!std::isfinite(g) || !std::isfinite(expected(i, j))) {
        err = std::numeric_limits<double>::infinity();
        nonFinite = true;
      }
      if (r.row < 0 || err > r.worstError) {
        r.worstError = err;
        r.row = i;
        r.col = j;
        r.expected = expected(i, j);
        r.got = g;
      }
    }
  }
  r.ok = !nonFinite && r.worstError <= tolerance;
  static const char* names[] = {"absolute", "column-relative", "matrix-relative", "entry-relative"};
  os << (r.ok ? "ok" : "MISMATCH") << " (" << expected.rows() << "x" << expected.cols()
     << "); worst entry (" << r.row << ", " << r.col << "): expected " << r.expected << ", got "
     << r.got << ", " << names[static_cast<int>(scale)] << " error " << std::setprecision(3)
     << r.worstError << " (tolerance " << tolerance << ")";
  if (nonFinite) os << "; got/expected contains NaN or Inf";
  r.message = os.str();
  return r;
}

}  // namespace trellis::test
