// tests/support/linearization_checks.cpp
#include "support/linearization_checks.hpp"

#include "support/finite_difference.hpp"
#include "support/matrix_compare.hpp"

#include <catch2/catch.hpp>

#include <Eigen/LU>
#include <Eigen/SVD>

#include <sstream>

namespace trellis::test {

namespace {
std::string describe(const State& s) {
  std::ostringstream os;
  os.precision(17);
  const Eigen::IOFormat row(Eigen::FullPrecision, Eigen::DontAlignCols, ", ", ", ", "", "", "[",
                            "]");
  os << "state: q = " << s.q.transpose().format(row) << ", dq = " << s.dq.transpose().format(row)
     << ", u = " << s.u.transpose().format(row);
  return os.str();
}
}  // namespace

void checkLinearizationAgainstFd(const Model& model, const State& s, double tolerance,
                                 double stepScale, Stencil stencil) {
  const int n = model.nq(), m = model.nu(), nc = model.nc();
  INFO(describe(s));
  Data data(model);
  const DynamicsStatus status = computeLinearization(model, data, s.q, s.dq, s.u);
  INFO("status message: " << status.message);
  REQUIRE(status.ok());
  REQUIRE(data.A.rows() == 2 * n);
  REQUIRE(data.A.cols() == 2 * n);
  REQUIRE(data.B.rows() == 2 * n);
  REQUIRE(data.B.cols() == m);

  // Block structure: exact (these are assignments, not computations).
  Eigen::MatrixXd top(n, 2 * n);
  top << Eigen::MatrixXd::Zero(n, n), Eigen::MatrixXd::Identity(n, n);
  TRELLIS_CHECK_MATRIX(top, Eigen::MatrixXd(data.A.topRows(n)), 0.0, Scale::kAbsolute);
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd::Zero(n, m), Eigen::MatrixXd(data.B.topRows(n)), 0.0,
                       Scale::kAbsolute);
  TRELLIS_CHECK_MATRIX(data.dqdd_dq, Eigen::MatrixXd(data.A.block(n, 0, n, n)), 0.0,
                       Scale::kAbsolute);
  TRELLIS_CHECK_MATRIX(data.dqdd_ddq, Eigen::MatrixXd(data.A.block(n, n, n, n)), 0.0,
                       Scale::kAbsolute);
  if (data.B.cols() > 0) {  // a block of a 2n×0 matrix offsets a null pointer (clang UBSan)
    TRELLIS_CHECK_MATRIX(data.dqdd_du, Eigen::MatrixXd(data.B.bottomRows(n)), 0.0, Scale::kAbsolute);
  }

  // The q̈ the linearization is taken at is the one computeDynamics returns. Both are the same
  // computation; allow rounding differences in case of a different evaluation order (1e-13
  // relative to max(1, ‖q̈‖∞) is ~500 eps).
  Data reference(model);
  const DynamicsStatus refStatus = computeDynamics(model, reference, s.q, s.dq, s.u);
  REQUIRE(refStatus.ok());
  TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(reference.qdd), Eigen::MatrixXd(data.qdd), 1e-13,
                       Scale::kMatrix);

  const DynamicsFiniteDifference fd =
      finiteDifferenceDynamics(model, s.q, s.dq, s.u, stepScale, stencil);
  INFO(fd.failure);
  REQUIRE(fd.ok);
  TRELLIS_CHECK_MATRIX(fd.dq(), data.dqdd_dq, tolerance, Scale::kColumn);
  TRELLIS_CHECK_MATRIX(fd.ddq(), data.dqdd_ddq, tolerance, Scale::kColumn);
  TRELLIS_CHECK_MATRIX(fd.du(), data.dqdd_du, tolerance, Scale::kColumn);
  if (nc > 0) {
    REQUIRE(data.dlambda_dx.rows() == nc);
    REQUIRE(data.dlambda_dx.cols() == 2 * n + m);
    TRELLIS_CHECK_MATRIX(fd.dlambda, data.dlambda_dx, tolerance, Scale::kColumn);
  }
}

DenseKkt denseKktSolve(const Data& data) {
  const Eigen::Index n = data.M.rows(), nc = data.constraintJacobian.rows();
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(n + nc, n + nc);
  K.topLeftCorner(n, n) = data.M;
  K.topRightCorner(n, nc) = data.constraintJacobian.transpose();
  K.bottomLeftCorner(nc, n) = data.constraintJacobian;
  Eigen::VectorXd rhs(n + nc);
  rhs << -data.bias, -data.constraintDrift;
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(K);
  DenseKkt out;
  out.condition = svd.singularValues()(0) / svd.singularValues()(n + nc - 1);
  out.solution = Eigen::FullPivLU<Eigen::MatrixXd>(K).solve(rhs);
  return out;
}

}  // namespace trellis::test
