// trellis/core/reference.hpp — a trajectory bound to a model: the reference x(t), u(t), ẋ(t) and
// the exact linearization A(t), B(t) at any t, after one check.
//
// Everything that follows a reference (TV-LQR, the tangent-basis transport, the closed loop, the
// consistency check, the optimizer's mesh refinement) needs the same sequence: check that the
// trajectory's names are the model's, give it knot derivatives ẋ_k from the core's dynamics,
// then at each t interpolate (trajectory.hpp's rule: cubic Hermite state; linear or, with input
// derivatives, cubic Hermite input) and call computeLinearization at (x(t), u(t)). The evaluator
// does the checks once in its constructor and owns what the queries need:
//   - its copy of the trajectory (with state derivatives), so it does not depend on the caller's;
//   - a Data workspace for the model, so a query allocates nothing (tests/core/no_malloc);
//   - the buffers x, u, ẋ it answers in.
// It keeps a pointer to the Model (like an algorithm's arguments, the model must outlive it). One
// evaluator per thread: queries write its buffers.
#pragma once

#include "trellis/core/data.hpp"
#include "trellis/core/trajectory.hpp"

#include <Eigen/Core>

#include <string>

namespace trellis {

class Model;

/// A query's outcome: ok, or the time and what failed there (the core's status message).
struct ReferenceStatus {
  bool ok = true;
  double t = 0.0;
  std::string message;  ///< "linearization failed at t = …: …" when not ok
};

struct ReferenceOptions {
  /// Where the knot derivatives ẋ_k come from.
  ///  kFromDynamics: ẋ_k = [q̇_k; q̈(q_k, q̇_k, u_k)] by computeDynamics at every knot (the meaning
  ///                 of a trajectory file; supplied derivatives are replaced);
  ///  kKeepSupplied: the trajectory's own (setStateDerivatives, e.g. a designed motion's exact
  ///                 q̈) when it has them, else from the dynamics as above.
  enum class StateDerivatives { kFromDynamics, kKeepSupplied };
  StateDerivatives stateDerivatives = StateDerivatives::kKeepSupplied;
  int minimumKnots = 1;  ///< fewer knots are refused (a reference to follow needs 2)
};

class ReferenceEvaluator {
 public:
  /// Checks, once: the configuration and input names equal the model's (in order), at least
  /// options.minimumKnots knots, and the knot derivatives (computeDynamics at every knot unless
  /// kept). Throws TrajectoryError naming the mismatch, or the knot and time where the dynamics
  /// failed. (The knot values are finite by construction of a Trajectory.)
  ReferenceEvaluator(const Model& model, Trajectory trajectory, const ReferenceOptions& options = {});

  const Model& model() const { return *model_; }
  const Trajectory& trajectory() const { return trajectory_; }  ///< with state derivatives
  int nq() const { return trajectory_.nq(); }
  int nx() const { return trajectory_.nx(); }
  int nu() const { return trajectory_.nu(); }
  double startTime() const { return trajectory_.startTime(); }
  double endTime() const { return trajectory_.endTime(); }

  /// x(t), u(t) and the spline's ẋ(t) into x(), u(), xdot(). Throws std::out_of_range outside
  /// [t_0, t_{N-1}] (a relative slack of 1e-12 is clamped). No allocation.
  void evaluate(double t);
  /// evaluate(t), then the exact A(t) = ∂f/∂x, B(t) = ∂f/∂u at (x(t), u(t)) by computeLinearization
  /// into A(), B() (and everything else data() holds: M, the constraint Jacobian, ...). A failure of
  /// the dynamics is the returned status naming t, never thrown. No allocation when ok.
  ReferenceStatus linearize(double t);

  const Eigen::VectorXd& x() const { return x_; }        ///< 2n: x(t) of the last query
  const Eigen::VectorXd& u() const { return u_; }        ///< m: u(t)
  const Eigen::VectorXd& xdot() const { return xdot_; }  ///< 2n: the spline's dx/dt at t
  const Eigen::MatrixXd& A() const { return data_.A; }   ///< 2n×2n, valid after linearize ok
  const Eigen::MatrixXd& B() const { return data_.B; }   ///< 2n×m
  Data& data() { return data_; }                          ///< the workspace of the last query
  const Data& data() const { return data_; }

 private:
  const Model* model_;
  Trajectory trajectory_;
  Data data_;
  Eigen::VectorXd x_, u_, xdot_, q_, dq_;
};

}  // namespace trellis
