// trellis/core/trajectory.hpp — a nominal trajectory: knot times, states x = [q; q̇], inputs u.
//
// Layout: N knots t_0 < t_1 < … < t_{N-1}; states() is 2n×N (column k = [q(t_k); q̇(t_k)]),
// inputs() is m×N. CSV form, one row per knot:
//   t, <config names…>, d<config names…>, <input names…>[, rate_<input names…>]
// e.g. `t,x,theta,dx,dtheta,push` or, with input derivatives, `t,x,theta,dx,dtheta,push,rate_push`.
// The optional rate columns u̇_k come last, one per input in the inputs' order, named "rate_" +
// the input name; they cannot be mistaken for a state column (those are the n configuration names
// and "d" + each, before the inputs). An input name must therefore not begin with "rate_": the
// first column after the state columns that does begins the rate block, which must then be
// exactly rate_<input> for every input (else TrajectoryError naming the column).
// A file may end with constraint-force columns, every name beginning with "lambda_" (e.g. a
// contact's force in its frame, lambda_index_n, as the hand's main job writes them): they are for
// people and plots — the dynamics recompute λ from the state and input — and readCsv skips them;
// from the first such column after the states every column must be one, so an input name must not
// begin with "lambda_" either. writeCsv writes none.
//
// Interpolation rule (evaluate), h = t_{k+1} − t_k:
//  - the state is a cubic Hermite spline through the knots using the knot derivatives
//    ẋ_k = [q̇_k; q̈(q_k, q̇_k, u_k)] (computeStateDerivatives evaluates them with the core's forward
//    dynamics, or setStateDerivatives supplies them). On a trajectory that satisfies the dynamics
//    the error is O(h⁴) in the knot spacing h, and the spline is C¹;
//  - the input, by default (no input derivatives), is piecewise linear between knots (C⁰), exact
//    at the knots; its error against a smooth u*(t) is ≤ h² max|ü*| / 8 (second order);
//  - with input derivatives u̇_k (setInputDerivatives, or the rate columns of a file) the input is
//    the cubic Hermite spline through (u_k, u̇_k): C¹, exact for cubics, and when u̇_k = u̇*(t_k)
//    its error is ≤ h⁴ max|u*⁗| / 384 (fourth order). A closed loop need not restart at a knot.
// The linear rule is the meaning of a trajectory file without rate columns for the whole toolkit:
// `trellis optimize` writes what it optimized under it (its Hermite–Simpson midpoint input is the
// knot average), `gains` and `simulate` read by it, and checkConsistency (consistency.hpp) checks
// any file against the rule the file carries.
// Queries outside [t_0, t_{N-1}] throw std::out_of_range.
#pragma once

#include <Eigen/Core>

#include <iosfwd>
#include <stdexcept>
#include <string>
#include <vector>

namespace trellis {

class Model;
class Data;
struct DynamicsStatus;

/// Thrown for an invalid trajectory (file or arrays). The message names the row (1-based data
/// row, and the file line) and the column (1-based, and its header name) when one is at fault.
class TrajectoryError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A nominal trajectory: knot times, states x = [q; q̇] and inputs u, with the interpolation rule of
/// the file comment (cubic Hermite state, linear or cubic input) and its CSV form.
class Trajectory {
 public:
  Trajectory() = default;

  /// times: N (strictly increasing, finite); states: 2n×N; inputs: m×N (m may be 0);
  /// configNames: n, inputNames: m. Throws TrajectoryError naming the first offending row/column.
  Trajectory(std::vector<std::string> configNames, std::vector<std::string> inputNames,
             Eigen::VectorXd times, Eigen::MatrixXd states, Eigen::MatrixXd inputs);

  int nq() const { return static_cast<int>(configNames_.size()); }  ///< n
  int nx() const { return 2 * nq(); }                                ///< 2n
  int nu() const { return static_cast<int>(inputNames_.size()); }   ///< m
  int size() const { return static_cast<int>(times_.size()); }      ///< N knots
  double startTime() const { return times_(0); }                    ///< t_0 (needs N ≥ 1)
  double endTime() const { return times_(times_.size() - 1); }      ///< t_{N−1}

  const Eigen::VectorXd& times() const { return times_; }     ///< N, strictly increasing
  const Eigen::MatrixXd& states() const { return states_; }   ///< 2n×N
  const Eigen::MatrixXd& inputs() const { return inputs_; }   ///< m×N
  const std::vector<std::string>& configNames() const { return configNames_; }  ///< n configuration names
  const std::vector<std::string>& inputNames() const { return inputNames_; }    ///< m input names

  /// Throws TrajectoryError unless the configuration and input names equal the model's (same order).
  void checkCompatible(const Model& model) const;

  /// ẋ_k = [q̇_k; q̈_k] at every knot from computeDynamics. Throws TrajectoryError if the model
  /// does not match or the dynamics fail at a knot (the message names the knot and time).
  void computeStateDerivatives(const Model& model, Data& data);
  /// The same with a failure returned, for callers whose verdict it is: the status of the first
  /// knot whose dynamics fail (index: the knot, t: its time; a non-finite q̈ is kNonFinite), the
  /// derivatives then unchanged. Throws TrajectoryError only when the model does not match.
  DynamicsStatus tryComputeStateDerivatives(const Model& model, Data& data);
  /// Supplies ẋ at the knots directly (2n×N, finite).
  void setStateDerivatives(Eigen::MatrixXd stateDerivatives);
  bool hasStateDerivatives() const { return stateDerivatives_.cols() == times_.size() && size() > 0; }  ///< evaluate() needs them
  const Eigen::MatrixXd& stateDerivatives() const { return stateDerivatives_; }  ///< 2n×N

  /// Supplies u̇ at the knots (m×N, finite): the input becomes the cubic Hermite spline through
  /// (u_k, u̇_k) (file comment). Throws TrajectoryError naming the size or the entry (knot, input).
  void setInputDerivatives(Eigen::MatrixXd inputDerivatives);
  /// Back to the linear input rule.
  void clearInputDerivatives() { inputDerivatives_.resize(0, 0); }
  /// Whether the input follows the cubic rule (input derivatives set), else the linear one.
  bool hasInputDerivatives() const { return inputDerivatives_.cols() == times_.size() && size() > 0 && nu() > 0; }
  const Eigen::MatrixXd& inputDerivatives() const { return inputDerivatives_; }  ///< m×N

  /// x(t) (2n) by cubic Hermite and u(t) (m) by the input rule; see the file comment. x and u are
  /// resized if needed (no allocation when already sized). Throws std::logic_error without state
  /// derivatives, std::out_of_range outside [t_0, t_{N-1}] (a relative slack of 1e-12 is clamped).
  void evaluate(double t, Eigen::VectorXd& x, Eigen::VectorXd& u) const;
  /// The same and the spline's derivative ẋ(t) (2n; at a knot ẋ_k exactly) — what the reference
  /// moves at, to compare with f(x(t), u(t)).
  void evaluate(double t, Eigen::VectorXd& x, Eigen::VectorXd& u, Eigen::VectorXd& xdot) const;
  /// x(t) (2n) and u(t) (m) as new vectors (allocating; evaluate() is the allocation-free form).
  Eigen::VectorXd state(double t) const;
  /// u(t) (m) as a new vector; see state(double).
  Eigen::VectorXd input(double t) const;

  /// Reads the CSV layout above; the number of configurations n is inferred from the header as the
  /// first n with columns n+1..2n equal to "d" + columns 1..n; rate_<input> columns, when present,
  /// become the input derivatives. `source` names the stream in messages.
  static Trajectory readCsv(std::istream& in, const std::string& source = "<stream>");
  /// readCsv on the file at `path`; a file that cannot be opened or read throws, naming the path.
  static Trajectory readCsvFile(const std::string& path);
  /// Writes the CSV layout with 17 significant digits (round trip exact); the rate columns when the
  /// trajectory has input derivatives.
  void writeCsv(std::ostream& out) const;
  /// writeCsv to `path`, atomically (io.hpp); throws FileError.
  void writeCsvFile(const std::string& path) const;

 private:
  int intervalIndex(double& t) const;
  template <bool kWithDerivative>
  void interpolate(double t, Eigen::VectorXd& x, Eigen::VectorXd& u, Eigen::VectorXd* xdot) const;

  std::vector<std::string> configNames_, inputNames_;
  Eigen::VectorXd times_;
  Eigen::MatrixXd states_, inputs_, stateDerivatives_, inputDerivatives_;
};

}  // namespace trellis
