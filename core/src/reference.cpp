// reference.cpp — ReferenceEvaluator: the checks once, then allocation-free queries.
#include "trellis/core/reference.hpp"

#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <algorithm>
#include <cmath>

#include <sstream>
#include <stdexcept>

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
  using Derivatives = ReferenceOptions::StateDerivatives;
  if (options.stateDerivatives == Derivatives::kRequireSupplied && !trajectory_.hasStateDerivatives()) {
    throw std::logic_error(options.caller +
                           ": the trajectory has no state derivatives (call computeStateDerivatives)");
  }
  const bool keep =
      options.stateDerivatives != Derivatives::kFromDynamics && trajectory_.hasStateDerivatives();
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
  ++linearizations_;
  const DynamicsStatus status = computeLinearization(*model_, data_, q_, dq_, u_);
  ReferenceStatus out;
  if (!status.ok() || !data_.A.allFinite() || !data_.B.allFinite()) {
    std::ostringstream m;
    m.precision(17);
    m << "linearization failed at t = " << t << ": "
      << (status.ok() ? std::string("A or B is not finite") : status.message);
    out.set(status.ok() ? ReferenceCode::kNonFinite : ReferenceCode::kLinearizationFailed, m.str(), t);
  }
  return out;
}

ReferenceStatus ReferenceEvaluator::linearizeWithTangentBasis(double t,
                                                              Eigen::Index expectedDimension) {
  ReferenceStatus out = linearize(t);
  if (!out.ok()) return out;
  const Eigen::Index d = computeConstraintTangentBasis(*model_, data_);
  if (expectedDimension >= 0 && d != expectedDimension) {
    std::ostringstream m;
    m << "the tangent space changed dimension from " << expectedDimension << " to " << d
      << " at t = " << t << " (the constraints changed rank)";
    out.set(ReferenceCode::kTangentRankChanged, m.str(), t, static_cast<long>(d));
  }
  return out;
}

ReferenceConstraintCheck checkReferenceOnConstraints(const Model& model, const Trajectory& trajectory,
                                                     double tolerance) {
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) {
    throw std::invalid_argument("checkReferenceOnConstraints: tolerance = " + std::to_string(tolerance) +
                                " must be > 0 and finite");
  }
  trajectory.checkCompatible(model);
  ReferenceConstraintCheck out;
  out.tolerance = tolerance;
  if (model.nc() == 0) return out;
  const int n = model.nq();
  const double L = modelLengthScale(model);
  const double duration = trajectory.size() > 1 ? trajectory.endTime() - trajectory.startTime() : 1.0;
  Data data(model);
  Eigen::VectorXd q(n), dq(n), hdot(model.nc());
  for (int k = 0; k < trajectory.size(); ++k) {
    q = trajectory.states().col(k).head(n);
    dq = trajectory.states().col(k).tail(n);
    computeConstraints(model, data, q, dq);
    hdot.noalias() = data.constraintJacobian * dq;
    for (int r = 0; r < model.nc(); ++r) {
      const Constraint& c = model.constraints()[static_cast<std::size_t>(r)];
      const double h = data.constraintValue(r);
      const double rowNorm = data.constraintJacobian.row(r).norm();
      // hScale: the size of h's terms; lengthScale: the row's own size in h's units.
      double hScale = 0.0, lengthScale = L;
      switch (c.type) {
        case ConstraintType::kDistance:
          lengthScale = 2.0 * c.distance * c.distance;
          hScale = h + lengthScale;  // ‖d‖² + ℓ²
          break;
        case ConstraintType::kPoint:
        case ConstraintType::kPointOnPlane: hScale = std::max(L, rowNorm * q.norm()); break;
        case ConstraintType::kKnifeEdge: hScale = 0.0; break;  // nonholonomic: h = 0
        case ConstraintType::kCoordinateCoupling:  // q_j − m q_i − o: its terms, in rad or m
          hScale = std::abs(q[c.a.joint]) + std::abs(c.coupling.multiplier * q[c.b.joint]) + std::abs(c.coupling.offset);
          lengthScale = hScale;
          break;
      }
      // A q̇ against ‖A_r‖‖q̇‖, floored by the row's size over the reference's duration (a knot at
      // rest must not be held to the rounding of a zero velocity).
      const double vScale = std::max(rowNorm * dq.norm(), lengthScale / duration);
      const bool hBad = !(std::abs(h) <= tolerance * hScale);
      const bool vBad = !(std::abs(hdot(r)) <= tolerance * vScale);
      if (!hBad && !vBad) continue;
      out.constraint = r;
      out.position = hBad;
      out.value = hBad ? h : hdot(r);
      out.scale = hBad ? hScale : vScale;
      std::ostringstream m;
      m.precision(3);
      m << "knot " << k << " violates the constraint '" << c.name << "': "
        << (hBad ? "h(q) = " : "A(q) q' = ") << out.value << " against the size of its terms "
        << out.scale << " (tolerance " << tolerance << " relative)";
      out.status.set(ReferenceCode::kOffConstraints, m.str(), trajectory.times()(k), k);
      return out;
    }
  }
  return out;
}

}  // namespace trellis
