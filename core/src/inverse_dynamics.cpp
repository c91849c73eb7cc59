// Inverse dynamics with inputs and constraint forces as unknowns (inverse_dynamics.hpp).
#include "trellis/core/inverse_dynamics.hpp"

#include "trellis/core/dynamics.hpp"
#include "trellis/core/detail/report_json.hpp"

#include "internal.hpp"

#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <vector>
#include <sstream>
#include <stdexcept>

namespace trellis {

std::string InverseDynamicsResult::describe() const {
  const Status<InverseDynamicsCode>& s = status;
  return s.describe() + " (residual " + formatStatusNumber(residualNorm) + ", constraint residual " +
         formatStatusNumber(constraintResidual) + ", rank " + std::to_string(rank) +
         (unique ? "" : ", not unique") + ")";
}

std::string InverseDynamicsResult::json() const {
  const Status<InverseDynamicsCode>& s = status;
  detail::ReportJson j = detail::statusJson(s);
  j["residual"] = detail::toJson(residualNorm);
  j["constraint_residual"] = detail::toJson(constraintResidual);
  j["rank"] = rank;
  j["unique"] = unique;
  j["bound_iterations"] = boundIterations;
  j["u"] = detail::toJson(u);
  j["lambda"] = detail::toJson(lambda);
  j["bound_excess"] = detail::toJson(boundExcess);
  return j.dump();
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
  if (!(options.tolerance > 0.0 && options.tolerance <= 0.1)) {
    throw std::invalid_argument("InverseDynamicsOptions: tolerance " + std::to_string(options.tolerance) +
                                " must be in (0, 0.1] (relative to the terms compared)");
  }
  const bool bounded = options.lowerBound.size() > 0 || options.upperBound.size() > 0;
  if (bounded) {
    if (options.lowerBound.size() != m || options.upperBound.size() != m)
      throw std::invalid_argument("InverseDynamicsOptions: lowerBound and upperBound have " +
                                  std::to_string(options.lowerBound.size()) + " and " +
                                  std::to_string(options.upperBound.size()) + " entries, the model has m = " +
                                  std::to_string(m) + " inputs");
    for (int i = 0; i < m; ++i)
      if (std::isnan(options.lowerBound[i]) || std::isnan(options.upperBound[i]) ||
          options.lowerBound[i] > options.upperBound[i])
        throw std::invalid_argument("InverseDynamicsOptions: bounds of input '" + model.inputNames()[i] + "' are [" +
                                    std::to_string(options.lowerBound[i]) + ", " +
                                    std::to_string(options.upperBound[i]) + "] (need lower ≤ upper, not NaN)");
  }
  InverseDynamicsResult r;
  r.u = Eigen::VectorXd::Zero(m);
  r.lambda = Eigen::VectorXd::Zero(nc);
  r.residual = Eigen::VectorXd::Zero(n);
  if (!q.allFinite() || !dq.allFinite() || !qdd.allFinite()) {
    r.status.code = InverseDynamicsCode::kNonFinite;
    r.status.message = "q, dq or qdd is not finite";
    return r;
  }
  // M, b = ID(q, q̇, 0) − Q(q, q̇, 0), A and Ȧ q̇ from the forward dynamics' passes at u = 0 (its
  // KKT status does not matter here: M need not be invertible to be multiplied).
  computeDynamics(model, data, q, dq, Eigen::VectorXd::Zero(m));
  computeInputMatrix(model, data, q);
  const Eigen::VectorXd rhs = data.M * qdd + data.bias;
  // The size of the terms that make up each row of r = M q̈ + b, b = ID(q, q̇, 0) − Q_cfg: the
  // residual of row i is judged against them, not against a fixed floor (a floor of 1 N·m held a
  // 1 mg / 1 mm pendulum with u = 0). Row i carries the units of coordinate i's force, so the
  // verdict is the same in any units. The wrench part and the configuration forces (springs)
  // count apart: at a held pose they cancel, and b alone would be round-off.
  Eigen::VectorXd configForces = Eigen::VectorXd::Zero(n);
  detail::addConfigurationForces(model, q, dq, Eigen::VectorXd::Zero(m), configForces);
  Eigen::VectorXd rowScale = (data.M.cwiseAbs() * qdd.cwiseAbs()) + (data.bias + configForces).cwiseAbs() +
                             configForces.cwiseAbs();
  Eigen::MatrixXd G(n, m + nc);
  G << data.inputMatrix, data.constraintJacobian.transpose();
  if (!rhs.allFinite() || !G.allFinite()) {
    r.status.code = InverseDynamicsCode::kNonFinite;
    r.status.message = "M q̈ + b or the input and constraint Jacobians are not finite at this state";
    return r;
  }
  const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(G);
  Eigen::VectorXd z = cod.solve(rhs);
  const Eigen::VectorXd zUnbounded = z;
  r.rank = static_cast<int>(cod.rank());
  int boundInput = -1;  // the input whose bound the unbounded answer exceeds most
  if (bounded && z.allFinite()) {
    r.boundExcess = Eigen::VectorXd::Zero(m);
    for (int i = 0; i < m; ++i)
      r.boundExcess[i] = std::max({0.0, z[i] - options.upperBound[i], options.lowerBound[i] - z[i]});
    if (m > 0 && r.boundExcess.maxCoeff(&boundInput) > 0.0) {
      // Active set on the bounds of min ½‖G z − r‖²: held inputs sit at a bound, the free unknowns
      // (the other inputs and λ) are the least squares of the rest. Hold the input that leaves its
      // interval most; release a held input whose gradient g_i = (Gᵀ(G z − r))_i points into the
      // interval (g_i > 0 at the upper bound, < 0 at the lower). Each step decreases the residual,
      // so the iteration ends; 4 (m + 1) steps bound it.
      std::vector<int> held(static_cast<size_t>(m), 0);  // 0 free, +1 upper, −1 lower
      for (int it = 0; it < 4 * (m + 1); ++it) {
        r.boundIterations = it + 1;
        int worstFree = -1;
        double worstExcess = 0.0;
        for (int i = 0; i < m; ++i) {
          if (held[i]) continue;
          const double e = std::max(z[i] - options.upperBound[i], options.lowerBound[i] - z[i]);
          if (e > worstExcess) worstExcess = e, worstFree = i;
        }
        if (worstFree >= 0) {
          held[worstFree] = z[worstFree] > options.upperBound[worstFree] ? 1 : -1;
        } else {
          const Eigen::VectorXd g = G.transpose() * (G * z - rhs);
          int release = -1;
          // g_i = G_iᵀ(G z − r) is judged against G_iᵀ's weight of the rows' scales (units of u_i·force).
          double worstRatio = 1.0;
          for (int i = 0; i < m; ++i) {
            const double gScale = options.tolerance * G.col(i).cwiseAbs().dot(rowScale);
            const double ratio = gScale > 0.0 ? std::abs(g[i]) / gScale : (g[i] != 0.0 ? HUGE_VAL : 0.0);
            if (((held[i] > 0 && g[i] > 0.0) || (held[i] < 0 && g[i] < 0.0)) && ratio > worstRatio)
              worstRatio = ratio, release = i;
          }
          if (release < 0) break;  // optimal: every held input is pushed against its bound
          held[release] = 0;
        }
        // Re-solve with the held inputs fixed.
        Eigen::VectorXd fixedPart = rhs;
        std::vector<int> freeCols;
        for (int i = 0; i < m + nc; ++i) {
          if (i < m && held[i]) {
            z[i] = held[i] > 0 ? options.upperBound[i] : options.lowerBound[i];
            fixedPart -= G.col(i) * z[i];
          } else {
            freeCols.push_back(i);
          }
        }
        Eigen::MatrixXd Gf(n, static_cast<Eigen::Index>(freeCols.size()));
        for (size_t c = 0; c < freeCols.size(); ++c) Gf.col(static_cast<Eigen::Index>(c)) = G.col(freeCols[c]);
        const Eigen::VectorXd zf = Gf.cols() ? Eigen::VectorXd(Gf.completeOrthogonalDecomposition().solve(fixedPart))
                                              : Eigen::VectorXd();
        for (size_t c = 0; c < freeCols.size(); ++c) z[freeCols[c]] = zf[static_cast<Eigen::Index>(c)];
      }
    }
  }
  r.u = z.head(m);
  r.lambda = z.tail(nc);
  r.unique = r.rank == m + nc;
  r.residual = G * z - rhs;
  int worst = 0;
  r.residualNorm = n > 0 ? r.residual.cwiseAbs().maxCoeff(&worst) : 0.0;
  // Row by row: |(G z − r)_i| ≤ tolerance · (Σ_j |M_ij q̈_j| + |ID_i| + |Q_cfg,i| + Σ_j |G_ij z_j|).
  rowScale += G.cwiseAbs() * z.cwiseAbs();
  const auto rowsExceed = [&](const Eigen::VectorXd& residual, const Eigen::VectorXd& scale, int& worstRow) {
    double worstRatio = 1.0;
    for (int i = 0; i < residual.size(); ++i) {
      const double bound = options.tolerance * scale[i];
      // A row whose terms are all zero has residual exactly zero (a sum of zeros).
      const double ratio = bound > 0.0 ? std::abs(residual[i]) / bound : (residual[i] != 0.0 ? HUGE_VAL : 0.0);
      if (ratio > worstRatio) worstRatio = ratio, worstRow = i;
    }
    return worstRatio > 1.0;
  };
  int worstRow = worst;
  const bool residualExceeds = rowsExceed(r.residual, rowScale, worstRow);
  if (residualExceeds) worst = worstRow;

  int worstConstraint = 0;
  bool constraintExceeds = false;
  if (nc > 0) {
    // A q̈ + Ȧ q̇ row by row against |A| |q̈| + |Ȧ q̇| (units of the constraint's acceleration).
    const Eigen::VectorXd c = data.constraintJacobian * qdd + data.constraintDrift;
    r.constraintResidual = c.cwiseAbs().maxCoeff(&worstConstraint);
    const Eigen::VectorXd cScale =
        data.constraintJacobian.cwiseAbs() * qdd.cwiseAbs() + data.constraintDrift.cwiseAbs();
    constraintExceeds = rowsExceed(c, cScale, worstConstraint);
  }
  std::ostringstream msg;
  if (!z.allFinite()) {
    r.status.code = InverseDynamicsCode::kNonFinite;
    msg << "the least-squares solution is not finite";
  } else if (constraintExceeds) {
    r.status.code = InverseDynamicsCode::kInadmissibleAcceleration;
    msg << "q̈ violates the constraint " << model.constraints()[worstConstraint].name
        << ": A q̈ + Ȧ q̇ = " << r.constraintResidual;
  } else if (boundInput >= 0 && residualExceeds) {
    r.status.code = InverseDynamicsCode::kInputBounds;
    const bool upper = zUnbounded[boundInput] > options.upperBound[boundInput];
    msg << "the inputs that produce this q̈ violate the " << (upper ? "upper" : "lower") << " bound "
        << (upper ? options.upperBound[boundInput] : options.lowerBound[boundInput]) << " of input '"
        << model.inputNames()[boundInput] << "' by " << r.boundExcess[boundInput]
        << "; within the bounds the least-squares residual is " << r.residualNorm << ", largest on "
        << model.configNames()[worst];
  } else if (residualExceeds) {
    r.status.code = InverseDynamicsCode::kUnreachable;
    msg << "no inputs produce this q̈ (rank of [B_u A^T] = " << r.rank << " < n = " << n
        << "): least-squares residual " << r.residualNorm << ", largest on " << model.configNames()[worst];
  }
  r.status.message = msg.str();
  return r;
}

}  // namespace trellis
