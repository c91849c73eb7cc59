// bench/finite_differences.cpp — see finite_differences.hpp.
#include "finite_differences.hpp"

#include "trellis/core/dynamics.hpp"

#include <algorithm>
#include <cmath>

namespace trellis::bench {

FdWorkspace::FdWorkspace(const Model& model)
    : numdiff(model), coarse(model.nq(), 2 * model.nq() + model.nu()) {}

bool centralDifferences(const Model& model, Data& data, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& dq, const Eigen::VectorXd& u, double relStep,
                        FdWorkspace& ws, Eigen::MatrixXd& J) {
  NumDiffOptions options;
  options.scheme = DifferenceScheme::kCentral;
  options.relativeStep = relStep;
  return differenceDynamics(model, data, q, dq, u, options, ws.numdiff, J).ok();
}

bool richardsonDifferences(const Model& model, Data& data, const Eigen::VectorXd& q,
                           const Eigen::VectorXd& dq, const Eigen::VectorXd& u, double relStep,
                           FdWorkspace& ws, Eigen::MatrixXd& J) {
  bool ok = centralDifferences(model, data, q, dq, u, relStep, ws, ws.coarse);
  ok = centralDifferences(model, data, q, dq, u, 0.5 * relStep, ws, J) && ok;
  J = (4.0 * J - ws.coarse) / 3.0;
  return ok;
}

double maxRelativeError(const Eigen::MatrixXd& J, const Eigen::MatrixXd& ref) {
  if (J.size() == 0) return 0.0;
  return (J - ref).cwiseAbs().maxCoeff() / std::max(1.0, ref.cwiseAbs().maxCoeff());
}

double maxColumnRelativeError(const Eigen::MatrixXd& J, const Eigen::MatrixXd& ref) {
  double worst = 0.0;
  for (Eigen::Index j = 0; j < J.cols(); ++j) {
    worst = std::max(worst, (J.col(j) - ref.col(j)).cwiseAbs().maxCoeff() /
                                std::max(1.0, ref.col(j).cwiseAbs().maxCoeff()));
  }
  return worst;
}

}  // namespace trellis::bench
