// controllability.cpp — rank and singular values of the (reduced) controllability matrix.
#include "trellis/control/controllability.hpp"

#include "trellis/core/detail/report_json.hpp"
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

std::string ControllabilityReport::describe() const {
  return status.describe() + " (rank " + std::to_string(rank) + " of " + std::to_string(dimension) +
         ", singular values " + formatStatusNumber(smallestSingularValue) + " .. " +
         formatStatusNumber(largestSingularValue) + ")";
}

std::string ControllabilityReport::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["dimension"] = dimension;
  j["rank"] = rank;
  j["controllable"] = controllable();
  j["smallest_singular_value"] = detail::toJson(smallestSingularValue);
  j["largest_singular_value"] = detail::toJson(largestSingularValue);
  j["scale"] = detail::toJson(scale);
  j["singular_values"] = detail::toJson(singularValues);
  return j.dump();
}

std::string GramianReport::describe() const {
  // Below 1e-10 λ_max the smallest eigenvalue is the integration's rounding (controllable()):
  // its value, possibly negative, is not a result and is not printed as one.
  const std::string smallest = !ok() || controllable() || dimension == 0
                                   ? formatStatusNumber(minEigenvalue)
                                   : std::string("(unresolved, below 1e-10 x max)");
  return status.describe() + " (dimension " + std::to_string(dimension) + ", eigenvalues " + smallest + " .. " +
         formatStatusNumber(maxEigenvalue) + ", " + std::to_string(steps) + " steps)";
}

std::string GramianReport::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["dimension"] = dimension;
  j["min_eigenvalue"] = ok() ? detail::toJson(minEigenvalue) : detail::ReportJson(nullptr);
  j["max_eigenvalue"] = ok() ? detail::toJson(maxEigenvalue) : detail::ReportJson(nullptr);
  j["steps"] = steps;
  j["linearizations"] = linearizations;
  return j.dump();
}

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
  if (q.size() != model.nq() || dq.size() != model.nq() || u.size() != model.nu()) {
    throw std::invalid_argument("computeControllabilityAt: q, dq must have " + std::to_string(model.nq()) +
                                " entries and u " + std::to_string(model.nu()) + ", got " +
                                std::to_string(q.size()) + ", " + std::to_string(dq.size()) + ", " +
                                std::to_string(u.size()));
  }
  const DynamicsStatus st = computeLinearization(model, data, q, dq, u);
  if (!st.ok()) {
    ControllabilityReport r;
    r.dimension = 2 * model.nq();
    r.status.set(ControllabilityCode::kLinearizationFailed,
                 std::string("the linearization failed (") + st.name() + "): " + st.message);
    return r;
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
    ControllabilityReport r = computeControllabilityAt(model, data, q, dq, u, relativeTolerance);
    if (!r.ok()) {
      std::ostringstream m;
      m << "knot " << k + 1 << " (t = " << trajectory.times()(k) << "): " << r.status.message;
      r.status.set(r.status.code, m.str(), trajectory.times()(k), k);
    }
    reports.push_back(std::move(r));
  }
  return reports;
}

}  // namespace trellis
