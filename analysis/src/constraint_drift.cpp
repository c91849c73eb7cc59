// constraint_drift.cpp — drift measurement and projection for the simulator (see the header), and
// the public projectOntoConstraints.
#include "constraint_drift.hpp"

#include "trellis/core/detail/report_json.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/model.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace trellis::detail {

ConstraintDrift::ConstraintDrift(const Model& model, int maxIterations)
    : model_(model), data_(model), n_(model.nq()), q_(n_), dq_(n_), r_(model.nc()) {
  options_.maxIterations = maxIterations;
  // Feasibility only: the nearest point of the manifold in the metric of M is not needed to undo
  // an integration error of the tolerance's size, the restoration's Newton point is as good.
  options_.stepTolerance = std::numeric_limits<double>::infinity();
}

double ConstraintDrift::drift(const Eigen::VectorXd& x) {
  if (model_.nc() == 0) return 0.0;
  q_ = x.head(n_);
  dq_ = x.tail(n_);
  computeConstraints(model_, data_, q_, dq_);
  r_.noalias() = data_.constraintJacobian * dq_;
  const double d =
      std::max(data_.constraintValue.cwiseAbs().maxCoeff(), r_.cwiseAbs().maxCoeff());
  return std::isfinite(d) ? d : std::numeric_limits<double>::infinity();
}

ConstraintProjection ConstraintDrift::project(Eigen::VectorXd& x) {
  ConstraintProjection p;
  if (model_.nc() == 0) return p;
  p.driftBefore = drift(x);  // over every row, like the drift after
  q_ = x.head(n_);
  dq_ = x.tail(n_);
  const ProjectionResult r = projectState(model_, data_, q_, dq_, options_);
  p.iterations = r.iterations;
  p.status = r.status;
  x.head(n_) = r.q;
  x.tail(n_) = r.dq;
  // The residuals of projectState cover the holonomic rows for h and all rows for A q̇: the
  // simulator's drift over the same rows, measured again at the result.
  p.driftAfter = drift(x);
  if (r.status.code == ProjectionCode::kNonFinite) p.driftAfter = std::numeric_limits<double>::infinity();
  return p;
}

}  // namespace trellis::detail

namespace trellis {

std::string ConstraintProjection::describe() const {
  return status.describe() + " (drift " + formatStatusNumber(driftBefore) + " -> " +
         formatStatusNumber(driftAfter) + ", " + std::to_string(iterations) + " iterations)";
}

std::string ConstraintProjection::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["drift_before"] = detail::toJson(driftBefore);
  j["drift_after"] = detail::toJson(driftAfter);
  j["iterations"] = iterations;
  return j.dump();
}

ConstraintProjection projectOntoConstraints(const Model& model, Eigen::VectorXd& x,
                                            int maxIterations) {
  if (x.size() != 2 * model.nq()) {
    throw std::invalid_argument("projectOntoConstraints: x has size " + std::to_string(x.size()) +
                                ", expected 2n = " + std::to_string(2 * model.nq()));
  }
  if (maxIterations < 1) {
    throw std::invalid_argument("projectOntoConstraints: maxIterations = " +
                                std::to_string(maxIterations) + " must be >= 1");
  }
  detail::ConstraintDrift projector(model, maxIterations);
  return projector.project(x);
}

}  // namespace trellis
