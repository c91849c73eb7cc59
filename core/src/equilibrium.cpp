// Static equilibria (equilibrium.hpp).
#include "trellis/core/equilibrium.hpp"

#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

std::string EquilibriumResult::describe() const {
  const Status<EquilibriumCode>& s = status;
  return s.describe() + " (" + std::to_string(iterations) + " iterations, |qdd| " +
         formatStatusNumber(accelerationResidual) + ", |h| " + formatStatusNumber(constraintResidual) +
         ", relative " + formatStatusNumber(relativeResidual) + ", rank " + std::to_string(jacobianRank) + (isolated ? "" : ", not isolated") +
         ", max Re(eig) " + formatStatusNumber(maxRealEigenvalue) + ")";
}

std::string EquilibriumResult::json() const {
  const Status<EquilibriumCode>& s = status;
  detail::ReportJson j = detail::statusJson(s);
  j["iterations"] = iterations;
  j["qdd_residual"] = detail::toJson(accelerationResidual);
  j["h_residual"] = detail::toJson(constraintResidual);
  j["relative_residual"] = detail::toJson(relativeResidual);
  j["jacobian_rank"] = jacobianRank;
  j["isolated"] = isolated;
  j["max_real_eigenvalue"] = detail::toJson(maxRealEigenvalue);
  j["q"] = detail::toJson(q);
  j["u"] = detail::toJson(u);
  j["lambda"] = detail::toJson(lambda);
  return j.dump();
}

EquilibriumResult findEquilibrium(const Model& model, Data& data, const Eigen::VectorXd& q0,
                                  const Eigen::VectorXd& u, const EquilibriumOptions& options) {
  const int n = model.nq(), nc = model.nc();
  if (q0.size() != n || u.size() != model.nu()) {
    throw std::invalid_argument("findEquilibrium: q has " + std::to_string(q0.size()) + " entries (n = " +
                                std::to_string(n) + "), u " + std::to_string(u.size()) +
                                " (m = " + std::to_string(model.nu()) + ")");
  }
  if (!(options.tolerance > 0.0 && options.tolerance <= 1e-3) || options.maxIterations < 1) {
    std::ostringstream m;
    m << "EquilibriumOptions: tolerance = " << options.tolerance << " must be in (0, 1e-3] (relative: the "
      << "configuration change, in radians or model lengths, the residual amounts to) and maxIterations = "
      << options.maxIterations << " >= 1";
    throw std::invalid_argument(m.str());
  }
  std::vector<int> holonomic;
  for (int c = 0; c < nc; ++c)
    if (model.constraints()[c].holonomic()) holonomic.push_back(c);
  const int nh = static_cast<int>(holonomic.size());
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);

  EquilibriumResult r;
  r.u = u;
  r.q = q0;
  Eigen::VectorXd F(n + nh);
  DynamicsStatus dyn;
  // F(q) and, with jacobian, ∂F/∂q in J; false if the dynamics cannot be solved at q.
  Eigen::MatrixXd J(n + nh, n);
  const auto evaluate = [&](const Eigen::VectorXd& q, bool jacobian) {
    dyn = jacobian ? computeLinearization(model, data, q, zero, u) : computeDynamics(model, data, q, zero, u);
    if (!dyn.ok() || !data.qdd.allFinite()) return false;
    F.head(n) = data.qdd;
    for (int i = 0; i < nh; ++i) F(n + i) = data.constraintValue(holonomic[i]);
    if (jacobian) {
      J.topRows(n) = data.dqdd_dq;
      for (int i = 0; i < nh; ++i) J.row(n + i) = data.constraintJacobian.row(holonomic[i]);
    }
    return F.allFinite();
  };
  // Converged when every row of F is no larger than what a configuration change of `tolerance`
  // (in radians, or in the model's length scale L for a prismatic coordinate) would produce:
  // |F_i| ≤ tol · Σ_j |∂F_i/∂q_j| s_j. Each side carries row i's units (q̈ᵢ's or hᵢ's), so
  // scaling the model's lengths, masses or time leaves the verdict unchanged — a fixed floor on
  // |q̈| would not (1e-10 m/s² is 1e-7 mm/s²). relativeResidual = max_i |F_i| / (Σ_j |J_ij| s_j).
  const Eigen::VectorXd s = coordinateScales(model);
  Eigen::VectorXd rowScale(n + nh);
  const auto converged = [&] {
    r.accelerationResidual = n ? F.head(n).cwiseAbs().maxCoeff() : 0.0;
    r.constraintResidual = nh ? F.tail(nh).cwiseAbs().maxCoeff() : 0.0;
    rowScale.noalias() = J.cwiseAbs() * s;
    r.relativeResidual = 0.0;
    for (int i = 0; i < n + nh; ++i) {
      const double ratio = rowScale(i) > 0.0 ? std::abs(F(i)) / rowScale(i) : (F(i) != 0.0 ? HUGE_VAL : 0.0);
      r.relativeResidual = std::max(r.relativeResidual, ratio);
    }
    return r.relativeResidual <= options.tolerance;
  };
  const auto dynamicsFailure = [&](const char* where) {
    r.status.code = EquilibriumCode::kDynamicsFailure;
    r.status.message = std::string("the dynamics cannot be solved ") + where + ": " +
                (dyn.message.empty() ? "status " + std::to_string(static_cast<int>(dyn.code)) : dyn.message);
  };

  if (!evaluate(r.q, true)) {
    dynamicsFailure("at the initial guess");
    return r;
  }
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod;
  for (int k = 0;; ++k) {
    cod.compute(J);
    r.jacobianRank = static_cast<int>(cod.rank());
    if (converged()) break;
    if (k == options.maxIterations) {
      r.status.code = EquilibriumCode::kNotConverged;
      std::ostringstream m;
      m << "no equilibrium within " << k << " Newton iterations: |q''|inf = " << r.accelerationResidual
        << ", |h|inf = " << r.constraintResidual << ", relative residual " << r.relativeResidual
        << " > tolerance " << options.tolerance << " (rank of dF/dq " << r.jacobianRank << " of " << n << ")";
      r.status.message = m.str();
      break;
    }
    const Eigen::VectorXd step = -cod.solve(F);
    const double merit = F.squaredNorm();
    const Eigen::VectorXd qk = r.q;
    bool accepted = false;
    for (double alpha = 1.0; alpha > 1e-6; alpha *= 0.5) {
      const Eigen::VectorXd trial = qk + alpha * step;
      if (trial.allFinite() && evaluate(trial, false) && F.squaredNorm() < (1.0 - 1e-4 * alpha) * merit) {
        r.q = trial;
        accepted = true;
        break;
      }
    }
    if (!accepted) {
      evaluate(qk, true);
      converged();
      r.status.code = EquilibriumCode::kNotConverged;
      std::ostringstream m;
      m << "the Newton step does not reduce |F| at iteration " << k + 1
        << " (a minimum of |q''|^2 + |h|^2 that is not an equilibrium?): |q''|inf = "
        << r.accelerationResidual << ", |h|inf = " << r.constraintResidual << ", relative residual "
        << r.relativeResidual;
      r.status.message = m.str();
      break;
    }
    r.iterations = k + 1;
    if (!evaluate(r.q, true)) {
      dynamicsFailure("at an iterate");
      return r;
    }
  }
  r.isolated = r.jacobianRank == n;
  r.lambda = data.lambda;
  // Stability from the linearization on the constraint tangent space at the final q.
  computeConstraintTangentBasis(model, data);
  if (data.reducedA.size() > 0 && data.reducedA.allFinite()) {
    const Eigen::EigenSolver<Eigen::MatrixXd> eig(data.reducedA, false);
    r.maxRealEigenvalue = eig.eigenvalues().real().maxCoeff();
  } else {
    r.maxRealEigenvalue = data.reducedA.size() ? std::numeric_limits<double>::quiet_NaN() : 0.0;
  }
  return r;
}

InverseDynamicsResult computeHoldingInputs(const Model& model, Data& data, const Eigen::VectorXd& q,
                                           const InverseDynamicsOptions& options) {
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq());
  return computeInverseDynamics(model, data, q, zero, zero, options);
}

}  // namespace trellis
