// Constraint projection (projection.hpp).
#include "trellis/core/projection.hpp"

#include "trellis/core/dynamics.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace trellis {
namespace {

/// The metric W = M restricted to the free coordinates, factorized; Euclidean if M is not
/// positive definite there.
struct Metric {
  Eigen::LLT<Eigen::MatrixXd> llt;
  Eigen::MatrixXd W;  ///< the metric itself (M on the free coordinates, or I)
  bool massWeighted = false;

  void compute(const Eigen::MatrixXd& M, const std::vector<int>& free) {
    const auto nf = static_cast<Eigen::Index>(free.size());
    W.resize(nf, nf);
    for (Eigen::Index i = 0; i < nf; ++i)
      for (Eigen::Index j = 0; j < nf; ++j) W(i, j) = M(free[i], free[j]);
    llt.compute(W);
    // A tiny pivot (relative to the largest diagonal entry) counts as not positive definite.
    massWeighted = W.allFinite() && nf > 0 && llt.info() == Eigen::Success &&
                   llt.matrixL().toDenseMatrix().diagonal().minCoeff() >
                       1e-8 * std::sqrt(W.diagonal().cwiseAbs().maxCoeff());
    if (!massWeighted) W.setIdentity(nf, nf);
  }
  /// δ of least δᵀWδ with J δ = rhs (least squares if inconsistent): δ = L⁻ᵀ (J L⁻ᵀ)⁺ rhs.
  Eigen::VectorXd minimumNormStep(const Eigen::MatrixXd& J, const Eigen::VectorXd& rhs) const {
    // No free coordinate (every one fixed) or no row: nothing can move (a decomposition of an
    // empty matrix is not defined).
    if (J.rows() == 0 || J.cols() == 0) return Eigen::VectorXd::Zero(J.cols());
    Eigen::MatrixXd G = J;
    if (massWeighted) llt.matrixU().solveInPlace<Eigen::OnTheRight>(G);  // G = J L⁻ᵀ = J U⁻¹
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(G);
    Eigen::VectorXd y = cod.solve(rhs);
    if (massWeighted) llt.matrixU().solveInPlace(y);  // δ = U⁻¹ y = L⁻ᵀ y
    return y;
  }
};

/// The velocity projection's check, relative to the terms of A q̇: well above the rounding of a
/// least-squares solve (≈ cond·eps), far below any real violation.
constexpr double kVelocityTolerance = 1e-9;

std::string format(double x) {
  std::ostringstream s;
  s.precision(3);
  s << x;
  return s.str();
}

}  // namespace

std::string ProjectionResult::describe() const {
  const Status<ProjectionCode>& s = status;
  return s.describe() + " (" + std::to_string(iterations) + " iterations, |h| " +
         formatStatusNumber(positionResidualBefore) + " -> " + formatStatusNumber(positionResidual) +
         ", |A dq| " + formatStatusNumber(velocityResidualBefore) + " -> " +
         formatStatusNumber(velocityResidual) + (massWeighted ? "" : ", Euclidean metric") + ")";
}

std::string ProjectionResult::json() const {
  const Status<ProjectionCode>& s = status;
  detail::ReportJson j = detail::statusJson(s);
  j["iterations"] = iterations;
  j["h_before"] = detail::toJson(positionResidualBefore);
  j["h_after"] = detail::toJson(positionResidual);
  j["velocity_before"] = detail::toJson(velocityResidualBefore);
  j["velocity_after"] = detail::toJson(velocityResidual);
  j["last_step"] = detail::toJson(lastStep);
  j["mass_weighted"] = massWeighted;
  j["q"] = detail::toJson(q);
  j["dq"] = detail::toJson(dq);
  return j.dump();
}

void ProjectionOptions::validate(const Model& model) const {
  const auto bad = [](const std::string& field, const std::string& value, const char* need) {
    throw std::invalid_argument("ProjectionOptions: " + field + " = " + value + " must be " + need);
  };
  if (!(tolerance > 0.0)) bad("tolerance", format(tolerance), "> 0");
  if (!(stepTolerance > 0.0)) bad("stepTolerance", format(stepTolerance), "> 0");
  if (maxIterations < 1) bad("maxIterations", std::to_string(maxIterations), ">= 1");
  for (std::size_t k = 0; k < fixed.size(); ++k) {
    if (fixed[k] < 0 || fixed[k] >= model.nq()) {
      bad("fixed[" + std::to_string(k) + "]", std::to_string(fixed[k]),
          ("a coordinate index in [0, " + std::to_string(model.nq()) + ")").c_str());
    }
  }
}

ProjectionResult projectState(const Model& model, Data& data, const Eigen::VectorXd& q0,
                              const Eigen::VectorXd& dq0, const ProjectionOptions& options) {
  const int n = model.nq();
  if (q0.size() != n || dq0.size() != n) {
    throw std::invalid_argument("projectState: q has " + std::to_string(q0.size()) + " and dq " +
                                std::to_string(dq0.size()) + " entries, the model n = " + std::to_string(n));
  }
  options.validate(model);
  ProjectionResult r;
  r.q = q0;
  r.dq = dq0;
  if (model.nc() == 0) return r;

  std::vector<int> free, holonomic;
  for (int i = 0; i < n; ++i)
    if (std::find(options.fixed.begin(), options.fixed.end(), i) == options.fixed.end()) free.push_back(i);
  for (int c = 0; c < model.nc(); ++c)
    if (model.constraints()[c].holonomic()) holonomic.push_back(c);
  const auto nf = static_cast<Eigen::Index>(free.size());
  const auto nh = static_cast<Eigen::Index>(holonomic.size());
  Eigen::VectorXd h(nh);
  Eigen::MatrixXd Ah(nh, nf);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  // h and A over the holonomic rows and free columns at q; false if not finite.
  const auto evaluate = [&](const Eigen::VectorXd& q) {
    computeConstraints(model, data, q, zero);
    for (Eigen::Index i = 0; i < nh; ++i) {
      h(i) = data.constraintValue(holonomic[i]);
      for (Eigen::Index j = 0; j < nf; ++j) Ah(i, j) = data.constraintJacobian(holonomic[i], free[j]);
    }
    return h.allFinite() && Ah.allFinite();
  };
  const auto fail = [&r](ProjectionCode status, std::string message) {
    r.status.code = status;
    r.status.message = std::move(message);
  };

  // ---- velocities before (A at q0, all rows) ------------------------------------------------
  computeConstraints(model, data, q0, dq0);
  r.velocityResidualBefore = (data.constraintJacobian * dq0).cwiseAbs().maxCoeff();

  // ---- positions ----------------------------------------------------------------------------
  Metric metric;
  computeMassMatrix(model, data, q0);
  metric.compute(data.M, free);
  r.massWeighted = metric.massWeighted;
  if (nh > 0) {
    if (!evaluate(r.q)) {
      fail(ProjectionCode::kNonFinite, "h(q) or its Jacobian is not finite at the given q");
      r.positionResidualBefore = r.positionResidual = std::numeric_limits<double>::infinity();
      return r;
    }
    r.positionResidualBefore = h.cwiseAbs().maxCoeff();
    if (nf == 0 && r.positionResidualBefore > options.tolerance) {
      r.positionResidual = r.positionResidualBefore;
      fail(ProjectionCode::kNotConverged, "every coordinate is fixed, so none can move onto h(q) = 0: |h|inf = " +
                                                format(r.positionResidual));
      computeConstraints(model, data, r.q, r.dq);
      r.velocityResidual = (data.constraintJacobian * r.dq).cwiseAbs().maxCoeff();
      return r;
    }
    // Restoration: minimum-W-norm Newton steps q ← q − W⁻¹Aᵀ(A W⁻¹ Aᵀ)⁺ h (quadratic near the
    // manifold). Returns false (q left at the last finite iterate) if |h| ≤ tolerance is not
    // reached; leaves h, Ah evaluated at q.
    bool nonFinite = false;
    const auto restore = [&](Eigen::VectorXd& q) {
      for (int k = 0;; ++k) {
        if (h.cwiseAbs().maxCoeff() <= options.tolerance) return true;
        if (k == options.maxIterations) return false;
        const Eigen::VectorXd step = metric.minimumNormStep(Ah, h);
        Eigen::VectorXd next = q;
        for (Eigen::Index j = 0; j < nf; ++j) next(free[j]) -= step(j);
        ++r.iterations;
        if (!next.allFinite() || !evaluate(next)) {
          evaluate(q);
          nonFinite = true;
          return false;
        }
        q = next;
      }
    };
    const auto distance = [&](const Eigen::VectorXd& q) {  // ½ (q − q0)ᵀ W (q − q0) over free
      Eigen::VectorXd e(nf);
      for (Eigen::Index j = 0; j < nf; ++j) e(j) = q(free[j]) - q0(free[j]);
      return 0.5 * e.dot(metric.W * e);
    };
    const auto scale = [&] { return options.stepTolerance * (1.0 + r.q.cwiseAbs().maxCoeff()); };
    if (!restore(r.q)) {
      r.positionResidual = h.cwiseAbs().maxCoeff();
      fail(nonFinite ? ProjectionCode::kNonFinite : ProjectionCode::kNotConverged,
           nonFinite ? std::string("a Gauss-Newton step produced a non-finite q, h(q) or Jacobian")
                     : "Gauss-Newton did not reach |h| <= " + format(options.tolerance) + " in " +
                           std::to_string(options.maxIterations) + " iterations: |h|inf = " +
                           format(r.positionResidual) + " (are the constraints reachable from this q?)");
    } else if (std::isfinite(options.stepTolerance) && nf > 0) {  // nf = 0: nothing can move
      // Closest point: descend ½ (q − q0)ᵀ W (q − q0) along the manifold. The direction is minus
      // the W-orthogonal tangent component of q − q0, d = −(I − W⁻¹Aᵀ(A W⁻¹ Aᵀ)⁺ A) (q − q0)
      // (zero exactly at the first-order conditions W (q − q0) = Aᵀ ν); each trial point is
      // restored onto h = 0 and accepted when the distance decreases (step halved otherwise).
      Eigen::VectorXd e(nf);
      bool converged = false;
      for (int outer = 0; outer < options.maxIterations && !converged; ++outer) {
        for (Eigen::Index j = 0; j < nf; ++j) e(j) = r.q(free[j]) - q0(free[j]);
        const Eigen::VectorXd d = metric.minimumNormStep(Ah, Ah * e) - e;
        if (d.cwiseAbs().maxCoeff() <= scale()) {
          converged = true;
          break;
        }
        const double d0 = distance(r.q);
        bool accepted = false;
        for (double alpha = 1.0; alpha >= 1.0 / 1024.0; alpha *= 0.5) {
          Eigen::VectorXd trial = r.q;
          for (Eigen::Index j = 0; j < nf; ++j) trial(free[j]) += alpha * d(j);
          if (trial.allFinite() && evaluate(trial) && restore(trial) && distance(trial) < d0) {
            r.lastStep = (trial - r.q).cwiseAbs().maxCoeff();
            r.q = trial;
            accepted = true;
            break;
          }
        }
        evaluate(r.q);
        // No decrease along a descent direction: q is a minimum to the precision of the steps.
        if (!accepted) converged = true;
      }
      r.positionResidual = h.cwiseAbs().maxCoeff();
      if (!converged) {
        fail(ProjectionCode::kNotConverged,
             "on the manifold (|h|inf = " + format(r.positionResidual) + ") but the closest point was not reached in " +
                 std::to_string(options.maxIterations) + " descent steps (last step " + format(r.lastStep) + ")");
      }
    } else {
      r.positionResidual = h.cwiseAbs().maxCoeff();
    }
  }

  // ---- velocities: least-kinetic-energy correction onto A(q*) q̇ = 0 -------------------------
  if (options.velocities && r.status.code != ProjectionCode::kNonFinite) {
    computeMassMatrix(model, data, r.q);
    metric.compute(data.M, free);
    r.massWeighted = r.massWeighted && metric.massWeighted;
    computeConstraints(model, data, r.q, r.dq);
    Eigen::MatrixXd Af(model.nc(), nf);
    for (Eigen::Index j = 0; j < nf; ++j) Af.col(j) = data.constraintJacobian.col(free[j]);
    const Eigen::VectorXd delta = metric.minimumNormStep(Af, data.constraintJacobian * r.dq);
    for (Eigen::Index j = 0; j < nf; ++j) r.dq(free[j]) -= delta(j);
    if (!r.dq.allFinite()) {
      r.dq = dq0;
      fail(ProjectionCode::kNonFinite, "the velocity projection produced a non-finite q̇");
    }
  }
  computeConstraints(model, data, r.q, r.dq);
  const Eigen::VectorXd velocityRows = data.constraintJacobian * r.dq;
  r.velocityResidual = velocityRows.cwiseAbs().maxCoeff();
  if (options.velocities && r.status.code == ProjectionCode::kOk) {
    // kOk promises A q̇* = 0 to rounding: row by row against the terms Σ_j |A_rj| (|q̇*_j| + |q̇0_j|)
    // (relative, so the verdict does not depend on units). It fails when the free coordinates
    // cannot cancel a row (--fix holds the ones that could).
    const Eigen::VectorXd rowScale = data.constraintJacobian.cwiseAbs() * (r.dq.cwiseAbs() + dq0.cwiseAbs());
    for (int c = 0; c < model.nc(); ++c) {
      if (std::abs(velocityRows(c)) > kVelocityTolerance * rowScale(c)) {
        fail(ProjectionCode::kNotConverged,
             "the velocity constraint '" + model.constraints()[c].name + "' is still violated after the projection: " +
                 "A q' = " + format(velocityRows(c)) + " (the free coordinates cannot cancel it; " +
                 std::to_string(options.fixed.size()) + " of " + std::to_string(n) + " coordinates are fixed)");
        break;
      }
    }
  }
  return r;
}

}  // namespace trellis
