// Inverse dynamics with inputs and constraint forces as unknowns (inverse_dynamics.hpp).
#include "trellis/core/inverse_dynamics.hpp"

#include "trellis/core/dynamics.hpp"

#include <Eigen/QR>

#include <algorithm>
#include <sstream>
#include <stdexcept>

namespace trellis {

const char* toString(InverseDynamicsStatus status) {
  switch (status) {
    case InverseDynamicsStatus::kOk: return "ok";
    case InverseDynamicsStatus::kUnreachable: return "unreachable";
    case InverseDynamicsStatus::kInadmissibleAcceleration: return "inadmissible_acceleration";
    case InverseDynamicsStatus::kNonFinite: return "non_finite";
  }
  return "unknown";
}

InverseDynamicsResult computeInverseDynamics(const Model& model, Data& data, const Eigen::VectorXd& qIn,
                                             const Eigen::VectorXd& dqIn, const Eigen::VectorXd& qddIn,
                                             const InverseDynamicsOptions& options) {
  // Copies: the arguments may be members of `data` (data.qdd after a forward solve), which the
  // evaluation below overwrites.
  const Eigen::VectorXd q = qIn, dq = dqIn, qdd = qddIn;
  const int n = model.nq(), m = model.nu(), nc = model.nc();
  if (q.size() != n || dq.size() != n || qdd.size() != n) {
    throw std::invalid_argument("computeInverseDynamics: q, dq, qdd have " + std::to_string(q.size()) +
                                ", " + std::to_string(dq.size()) + ", " + std::to_string(qdd.size()) +
                                " entries, the model n = " + std::to_string(n));
  }
  if (!(options.tolerance > 0.0)) {
    throw std::invalid_argument("InverseDynamicsOptions: tolerance must be > 0");
  }
  InverseDynamicsResult r;
  r.u = Eigen::VectorXd::Zero(m);
  r.lambda = Eigen::VectorXd::Zero(nc);
  r.residual = Eigen::VectorXd::Zero(n);
  if (!q.allFinite() || !dq.allFinite() || !qdd.allFinite()) {
    r.status = InverseDynamicsStatus::kNonFinite;
    r.message = "q, dq or qdd is not finite";
    return r;
  }
  // M, b = ID(q, q̇, 0) − Q(q, q̇, 0), A and Ȧ q̇ from the forward dynamics' passes at u = 0 (its
  // KKT status does not matter here: M need not be invertible to be multiplied).
  computeDynamics(model, data, q, dq, Eigen::VectorXd::Zero(m));
  computeInputMatrix(model, data, q);
  const Eigen::VectorXd rhs = data.M * qdd + data.bias;
  Eigen::MatrixXd G(n, m + nc);
  G << data.inputMatrix, data.constraintJacobian.transpose();
  if (!rhs.allFinite() || !G.allFinite()) {
    r.status = InverseDynamicsStatus::kNonFinite;
    r.message = "M q̈ + b or the input and constraint Jacobians are not finite at this state";
    return r;
  }
  const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(G);
  const Eigen::VectorXd z = cod.solve(rhs);
  r.u = z.head(m);
  r.lambda = z.tail(nc);
  r.rank = static_cast<int>(cod.rank());
  r.unique = r.rank == m + nc;
  r.residual = G * z - rhs;
  int worst = 0;
  r.residualNorm = n > 0 ? r.residual.cwiseAbs().maxCoeff(&worst) : 0.0;
  const double gNorm = G.size() ? G.cwiseAbs().rowwise().sum().maxCoeff() : 0.0;
  const double scale = std::max({1.0, rhs.cwiseAbs().maxCoeff(), gNorm * z.cwiseAbs().maxCoeff()});

  int worstConstraint = 0;
  if (nc > 0) {
    const Eigen::VectorXd c = data.constraintJacobian * qdd + data.constraintDrift;
    r.constraintResidual = c.cwiseAbs().maxCoeff(&worstConstraint);
  }
  const double aNorm = nc ? data.constraintJacobian.cwiseAbs().rowwise().sum().maxCoeff() : 0.0;
  const double cScale = std::max({1.0, aNorm * qdd.cwiseAbs().maxCoeff(),
                                  nc ? data.constraintDrift.cwiseAbs().maxCoeff() : 0.0});
  std::ostringstream msg;
  if (!z.allFinite()) {
    r.status = InverseDynamicsStatus::kNonFinite;
    msg << "the least-squares solution is not finite";
  } else if (r.constraintResidual > options.tolerance * cScale) {
    r.status = InverseDynamicsStatus::kInadmissibleAcceleration;
    msg << "q̈ violates the constraint " << model.constraints()[worstConstraint].name
        << ": A q̈ + Ȧ q̇ = " << r.constraintResidual;
  } else if (r.residualNorm > options.tolerance * scale) {
    r.status = InverseDynamicsStatus::kUnreachable;
    msg << "no inputs produce this q̈ (rank of [B_u A^T] = " << r.rank << " < n = " << n
        << "): least-squares residual " << r.residualNorm << ", largest on " << model.configNames()[worst];
  }
  r.message = msg.str();
  return r;
}

}  // namespace trellis
