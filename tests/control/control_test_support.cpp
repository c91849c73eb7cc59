#include "control_test_support.hpp"

#include "support/cart_pole_model.hpp"

#include <cmath>
#include <limits>
#include <sstream>

namespace trellis::ctest {

Comparison compareRelative(const Eigen::MatrixXd& expected, const Eigen::MatrixXd& got,
                           double floor) {
  Comparison c;
  std::ostringstream m;
  m.precision(17);
  if (expected.rows() != got.rows() || expected.cols() != got.cols()) {
    c.worst = std::numeric_limits<double>::infinity();
    m << "size mismatch: expected " << expected.rows() << "x" << expected.cols() << ", got "
      << got.rows() << "x" << got.cols();
    c.message = m.str();
    return c;
  }
  Eigen::Index wi = 0, wj = 0;
  for (Eigen::Index j = 0; j < got.cols(); ++j) {
    for (Eigen::Index i = 0; i < got.rows(); ++i) {
      const double e = std::isfinite(got(i, j))
                           ? std::abs(got(i, j) - expected(i, j)) /
                                 std::max(floor, std::abs(expected(i, j)))
                           : std::numeric_limits<double>::infinity();
      if (!(e <= c.worst)) {
        c.worst = e;
        wi = i;
        wj = j;
      }
    }
  }
  if (got.size() > 0) {
    m << "worst entry (" << wi << "," << wj << "): expected " << expected(wi, wj) << ", got "
      << got(wi, wj) << ", relative error " << c.worst;
  }
  c.message = m.str();
  return c;
}

Model makeCartPole(double mc, double mp, double l) { return trellis::test::cartPole(mc, mp, l); }

Model makeConstrainedCarts() {
  ModelBuilder b("carts");
  b.addFrame("cart1", "world", Transform::tx("x1"), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addFrame("cart2", "world", Transform::tx("x2"), Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addPointConstraint("cart1", "cart2", 0);
  b.addConfigForce("x1", "push");
  return std::move(b).finalize();
}

Model makeDampedChain(int links) {
  ModelBuilder b("chain");
  std::string parent = "world";
  for (int i = 1; i <= links; ++i) {
    const std::string n = std::to_string(i);
    b.addFrame("l" + n, parent, Transform::rz("q" + n));
    b.addFrame("m" + n, "l" + n, Transform::ty(-0.1), Mass{0.1, Eigen::Matrix3d::Zero()});
    b.addConfigForce("q" + n, "u" + n);
    parent = "m" + n;
  }
  b.addGravity({0.0, -9.81, 0.0});
  b.addDamping(0.1);
  return std::move(b).finalize();
}

}  // namespace trellis::ctest
