// controllability.cpp — rank and singular values of the (reduced) controllability matrix.
#include "trellis/control/controllability.hpp"

#include "trellis/core/trajectory.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <Eigen/SVD>

#include <algorithm>
#include <sstream>
#include <stdexcept>
#include <string>

namespace trellis {

ControllabilityReport computeControllability(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B,
                                             double relativeTolerance) {
  const Eigen::Index d = A.rows(), m = B.cols();
  if (A.cols() != d || B.rows() != d) {
    throw std::invalid_argument("computeControllability: A must be dxd and B dxm, got A " +
                                std::to_string(A.rows()) + "x" + std::to_string(A.cols()) +
                                ", B " + std::to_string(B.rows()) + "x" + std::to_string(B.cols()));
  }
  ControllabilityReport r;
  r.dimension = static_cast<int>(d);
  if (d == 0) return r;
  r.scale = std::max(1.0, A.norm());
  const Eigen::MatrixXd As = A / r.scale;
  Eigen::MatrixXd C(d, d * m);
  if (m > 0) {
    C.leftCols(m) = B;
    for (Eigen::Index k = 1; k < d; ++k) C.middleCols(k * m, m) = As * C.middleCols((k - 1) * m, m);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(C);
  r.singularValues = svd.singularValues();
  r.largestSingularValue = r.singularValues.size() ? r.singularValues(0) : 0.0;
  const double tol = relativeTolerance * r.largestSingularValue;
  r.rank = 0;
  for (Eigen::Index i = 0; i < r.singularValues.size(); ++i) {
    if (r.singularValues(i) > tol) ++r.rank;
  }
  r.smallestSingularValue = r.singularValues.size() >= d ? r.singularValues(d - 1) : 0.0;
  return r;
}

ControllabilityReport computeControllabilityAt(const Model& model, Data& data,
                                               const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                               const Eigen::VectorXd& u, double relativeTolerance) {
  const DynamicsStatus st = computeLinearization(model, data, q, dq, u);
  if (!st.ok()) {
    throw std::runtime_error("computeControllabilityAt: linearization failed: " + st.message);
  }
  computeConstraintTangentBasis(model, data);
  return computeControllability(data.reducedA, data.reducedB, relativeTolerance);
}

std::vector<ControllabilityReport> controllabilityAtKnots(const Model& model,
                                                          const Trajectory& trajectory,
                                                          double relativeTolerance) {
  trajectory.checkCompatible(model);
  Data data(model);
  const int n = trajectory.nq();
  std::vector<ControllabilityReport> reports;
  reports.reserve(trajectory.size());
  for (int k = 0; k < trajectory.size(); ++k) {
    const Eigen::VectorXd q = trajectory.states().col(k).head(n);
    const Eigen::VectorXd dq = trajectory.states().col(k).tail(n);
    const Eigen::VectorXd u = trajectory.inputs().col(k);
    try {
      reports.push_back(computeControllabilityAt(model, data, q, dq, u, relativeTolerance));
    } catch (const std::runtime_error& e) {  // the dynamics failed at this knot
      ControllabilityReport r;
      r.ok = false;
      std::ostringstream m;
      m << "knot " << k + 1 << " (t = " << trajectory.times()(k) << "): " << e.what();
      r.message = m.str();
      reports.push_back(std::move(r));
    }
  }
  return reports;
}

}  // namespace trellis
