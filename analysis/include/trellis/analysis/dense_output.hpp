// trellis/analysis/dense_output.hpp — the dense output of an integration: one polynomial per step.
//
// A linear multistep method (CVODES's BDF and Adams) carries, at the end s_k of every accepted
// step, the derivatives D_k = [y, y', y'', …, y^(q)] of its interpolating polynomial of degree q.
// Stored per step, they give y between the step points at the integrator's own accuracy:
//   y(s) = Σ_{j=0..q} D_k(:, j) (s − s_k)^j / j!,   s ∈ [s_{k−1}, s_k],
// evaluated by Horner's rule. A step with one column (q = 0) is a constant: the initial point, or
// a piecewise-constant record. The Riccati solution (in τ = T − t) and the transported tangent
// basis (in t) are both one DenseOutput.
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <vector>

namespace trellis {

/// The steps of an integration as polynomials (file comment): appended in order of their ends,
/// evaluated anywhere in the span covered.
class DenseOutput {
 public:
  /// Appends the polynomial of a step ending at s (D: dimension × (q+1), column j = d^j y/ds^j at
  /// s). s must not be below the previous step's end; D must have the dimension of the others and
  /// at least one column. Throws std::invalid_argument otherwise.
  void append(double s, Eigen::MatrixXd D);
  /// Removes every step (keeps the memory).
  void clear();
  /// Reserves room for `steps` steps.
  void reserve(std::size_t steps);

  bool empty() const { return ends_.empty(); }          ///< no step stored
  std::size_t size() const { return ends_.size(); }      ///< number of steps
  /// Length of y (0 when empty).
  Eigen::Index dimension() const { return coefficients_.empty() ? 0 : coefficients_[0].rows(); }
  ///@{
  /// The first and last step ends (the span covered; throws std::out_of_range when empty).
  double front() const;
  double back() const;
  ///@}
  /// End of step i and the degree q of its polynomial.
  double end(std::size_t i) const { return ends_[i]; }
  /// The degree q of step i's polynomial (its columns − 1).
  int order(std::size_t i) const { return static_cast<int>(coefficients_[i].cols()) - 1; }
  /// D of step i (dimension × (q+1)).
  const Eigen::MatrixXd& coefficients(std::size_t i) const { return coefficients_[i]; }

  /// The step whose polynomial covers s: the first with s_k ≥ s, the last one beyond back().
  /// Throws std::out_of_range when empty.
  std::size_t locate(double s) const;
  /// y(s) from the covering step's polynomial (out: dimension()). No range check beyond
  /// locate's: s below front() extrapolates the first polynomial, above back() the last one.
  /// Does not allocate.
  void evaluate(double s, Eigen::Ref<Eigen::VectorXd> out) const;

 private:
  std::vector<double> ends_;                  // ascending step ends s_k
  std::vector<Eigen::MatrixXd> coefficients_; // D_k
};

}  // namespace trellis
