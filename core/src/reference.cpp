// reference.cpp — ReferenceEvaluator: the checks once, then allocation-free queries.
#include "trellis/core/reference.hpp"

#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <sstream>

namespace trellis {

ReferenceEvaluator::ReferenceEvaluator(const Model& model, Trajectory trajectory,
                                       const ReferenceOptions& options)
    : model_(&model), trajectory_(std::move(trajectory)), data_(model) {
  trajectory_.checkCompatible(model);
  if (trajectory_.size() < options.minimumKnots) {
    throw TrajectoryError("reference: " + std::to_string(trajectory_.size()) + " knot" +
                          (trajectory_.size() == 1 ? "" : "s") + ", need at least " +
                          std::to_string(options.minimumKnots));
  }
  const bool keep = options.stateDerivatives == ReferenceOptions::StateDerivatives::kKeepSupplied &&
                    trajectory_.hasStateDerivatives();
  if (!keep) trajectory_.computeStateDerivatives(model, data_);  // names the failing knot
  const int n = model.nq();
  x_.resize(2 * n);
  xdot_.resize(2 * n);
  u_.resize(model.nu());
  q_.resize(n);
  dq_.resize(n);
}

void ReferenceEvaluator::evaluate(double t) { trajectory_.evaluate(t, x_, u_, xdot_); }

ReferenceStatus ReferenceEvaluator::linearize(double t) {
  evaluate(t);
  const int n = nq();
  q_ = x_.head(n);
  dq_ = x_.tail(n);
  const DynamicsStatus status = computeLinearization(*model_, data_, q_, dq_, u_);
  ReferenceStatus out;
  out.t = t;
  if (!status.ok() || !data_.A.allFinite() || !data_.B.allFinite()) {
    out.ok = false;
    std::ostringstream m;
    m.precision(17);
    m << "linearization failed at t = " << t << ": "
      << (status.ok() ? std::string("A or B is not finite") : status.message);
    out.message = m.str();
  }
  return out;
}

}  // namespace trellis
