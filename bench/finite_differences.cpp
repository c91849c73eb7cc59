// bench/finite_differences.cpp — see finite_differences.hpp.
#include "finite_differences.hpp"

#include "trellis/core/dynamics.hpp"

#include <algorithm>
#include <cmath>

namespace trellis::bench {

FdWorkspace::FdWorkspace(const Model& model)
    : q(model.nq()), dq(model.nq()), u(model.nu()), qddPlus(model.nq()),
      coarse(model.nq(), 2 * model.nq() + model.nu()) {}

bool centralDifferences(const Model& model, Data& data, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& dq, const Eigen::VectorXd& u, double relStep,
                        FdWorkspace& ws, Eigen::MatrixXd& J) {
  ws.q = q;
  ws.dq = dq;
  ws.u = u;
  bool ok = true;
  int column = 0;
  // Perturbs one block of z = [q; q̇; u] in place, restoring each entry afterwards.
  auto sweep = [&](Eigen::VectorXd& x) {
    for (Eigen::Index i = 0; i < x.size(); ++i, ++column) {
      const double xi = x[i];
      const double h = relStep * std::max(1.0, std::abs(xi));
      x[i] = xi + h;
      const double xPlus = x[i];
      ok = computeDynamics(model, data, ws.q, ws.dq, ws.u).ok() && ok;
      ws.qddPlus = data.qdd;
      x[i] = xi - h;
      const double xMinus = x[i];
      ok = computeDynamics(model, data, ws.q, ws.dq, ws.u).ok() && ok;
      J.col(column) = (ws.qddPlus - data.qdd) / (xPlus - xMinus);
      x[i] = xi;
    }
  };
  sweep(ws.q);
  sweep(ws.dq);
  sweep(ws.u);
  return ok;
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
