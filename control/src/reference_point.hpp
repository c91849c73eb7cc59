// reference_point.hpp (private) — the exact linearization and the constraint tangent space at one
// time of a reference trajectory, in a preallocated workspace: x(t), u(t) from the trajectory's
// interpolation, then the core's computeLinearization (A, B) and computeConstraintTangentBasis
// (Tc, 2n×d_c, orthonormal). Used by the tangent-basis transport and ReducedLinearization.
#pragma once

#include "trellis/core/trajectory.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <Eigen/Core>

#include <sstream>
#include <stdexcept>
#include <string>

namespace trellis::detail {

struct ReferencePoint {
  const Model& model;
  const Trajectory& trajectory;
  Data data;
  Eigen::VectorXd x, u, q, dq;
  long evaluations = 0;

  ReferencePoint(const Model& m, const Trajectory& tr)
      : model(m), trajectory(tr), data(m), x(tr.nx()), u(tr.nu()), q(tr.nq()), dq(tr.nq()) {}

  /// A, B and, when `tangent`, Tc at t. Throws std::runtime_error naming t when the dynamics fail.
  void evaluate(double t, bool tangent) {
    trajectory.evaluate(t, x, u);
    const Eigen::Index n = trajectory.nq();
    q = x.head(n);
    dq = x.tail(n);
    ++evaluations;
    const DynamicsStatus s = computeLinearization(model, data, q, dq, u);
    if (!s.ok()) {
      std::ostringstream m;
      m << "linearization failed at t = " << t << ": " << s.message;
      throw std::runtime_error(m.str());
    }
    if (tangent) computeConstraintTangentBasis(model, data);
  }
  const Eigen::MatrixXd& A() const { return data.A; }
  const Eigen::MatrixXd& B() const { return data.B; }
  const Eigen::MatrixXd& Tc() const { return data.tangentBasis; }

  /// Throws std::runtime_error unless the tangent space at t has dimension d.
  void requireDimension(double t, Eigen::Index d) const {
    if (data.tangentBasis.cols() != d) {
      std::ostringstream m;
      m << "the tangent space changed dimension from " << d << " to " << data.tangentBasis.cols()
        << " at t = " << t << " (the constraints changed rank)";
      throw std::runtime_error(m.str());
    }
  }
};

}  // namespace trellis::detail
