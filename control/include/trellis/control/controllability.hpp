// trellis/control/controllability.hpp — controllability of a linearization at a point.
//
// For ẋ = A x + B u (A d×d, B d×m) the Krylov matrix C = [B, Â B, Â² B, …, Â^{d−1} B] with
// Â = A / α, α = max(1, ‖A‖_F), has the rank of the controllability matrix (the scaling only
// changes the singular values, and keeps the powers of A from overflowing); the pair is
// controllable when rank C = d. On a constrained system the state is first reduced to the tangent
// space of the constraint manifold (core's computeConstraintTangentBasis: Ar = TᵀAT, Br = TᵀB),
// where the directions that leave the manifold — which no input can steer — are gone.
//
// Along a trajectory the reduced reachability Gramian on [t0, t1],
//   W(t0, t1) = ∫_{t0}^{t1} Φr(t1, τ) Br(τ) Br(τ)ᵀ Φr(t1, τ)ᵀ dτ    (d×d, in the basis T(t1)),
// with Φr the transition matrix of ż = Ar(t) z and Ar = TᵀAT, Br = TᵀB on the parallel-transported
// tangent basis T(t) of manifold_lqr.hpp, solves Ẇ = Ar W + W Arᵀ + Br Brᵀ, W(t0) = 0. The
// time-varying system is controllable on [t0, t1] iff W is positive definite; λ_min(W) measures
// the least energy-efficient direction (reaching z from 0 needs ∫|u|² ≥ zᵀ W⁻¹ z).
#pragma once

#include "trellis/control/manifold_lqr.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace trellis {

class Model;
class Data;
class Trajectory;

/// Outcome codes of the controllability queries (status.t: the time, status.index: the knot).
enum class ControllabilityCode {
  kOk,
  kLinearizationFailed,  ///< the dynamics failed at the point (singular M or constraints)
  kTransportFailure,     ///< Gramian: the tangent basis does not reach t1
  kIntegratorFailure,    ///< Gramian: CVODES stopped on the Lyapunov equation
  kNotComputed,          ///< a default-constructed Gramian report
};

/// Names: ok, linearization_failed, transport_failure, integrator_failure, not_computed.
inline EnumNameTable<ControllabilityCode> enumNames(ControllabilityCode) {
  static constexpr EnumName<ControllabilityCode> table[] = {
      {ControllabilityCode::kOk, "ok"},
      {ControllabilityCode::kLinearizationFailed, "linearization_failed"},
      {ControllabilityCode::kTransportFailure, "transport_failure"},
      {ControllabilityCode::kIntegratorFailure, "integrator_failure"},
      {ControllabilityCode::kNotComputed, "not_computed"}};
  return table;
}

/// The rank of the Krylov matrix C = [B, ÂB, …, Â^{d−1}B] of a (reduced) linearization, Â = A/α,
/// α = max(1, ‖A‖_F) (file comment), with its singular values.
struct ControllabilityReport {
  int dimension = 0;                  ///< d, the (reduced) state dimension
  int rank = 0;                       ///< numerical rank of C (σ_i > tolerance·σ_max)
  double smallestSingularValue = 0.0; ///< σ_d of C (0 if C has fewer than d columns)
  double largestSingularValue = 0.0;  ///< σ_1 of C
  double scale = 1.0;                 ///< α used for Â = A/α
  Eigen::VectorXd singularValues;     ///< of C, descending
  /// kLinearizationFailed when the dynamics failed at the point; the message names the cause
  /// (and, along a trajectory, t and index name the knot).
  Status<ControllabilityCode> status;
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  bool controllable() const { return ok() && rank == dimension; }  ///< ok and rank C = d
  /// One line: the status, then rank of dimension and the extreme singular values.
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "dimension", "rank", "controllable",
  /// "smallest_singular_value", "largest_singular_value", "scale", "singular_values"}.
  std::string json() const;
};

/// Throws std::invalid_argument on inconsistent sizes.
ControllabilityReport computeControllability(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B,
                                             double relativeTolerance = 1e-10);

/// computeLinearization at x = [q; q̇], u, reduction to the constraint tangent space, then the
/// report above. Throws std::invalid_argument for sizes; if the dynamics fail at that point the
/// report's status is kLinearizationFailed (rank 0).
ControllabilityReport computeControllabilityAt(const Model& model, Data& data,
                                               const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                               const Eigen::VectorXd& u,
                                               double relativeTolerance = 1e-10);

/// computeControllabilityAt at every knot (x_k, u_k) of the trajectory (which must match the model).
/// A knot where the dynamics fail gets kLinearizationFailed, with t and index naming the knot.
std::vector<ControllabilityReport> controllabilityAtKnots(const Model& model,
                                                          const Trajectory& trajectory,
                                                          double relativeTolerance = 1e-10);

/// The reduced reachability Gramian W(t0, t1) along a trajectory (file comment: Ẇ = Ar W + W Arᵀ +
/// Br Brᵀ, W(t0) = 0, integrated by CVODES), its eigenvalues and the integrator's work.
struct GramianReport {
  Eigen::MatrixXd W;                  ///< d×d reduced reachability Gramian (symmetric PSD)
  ///@{
  /// The smallest and largest eigenvalue of W.
  double minEigenvalue = 0.0, maxEigenvalue = 0.0;
  ///@}
  /// Not ok on numerical failure: the message gives the time and the cause.
  Status<ControllabilityCode> status{ControllabilityCode::kNotComputed, "not computed"};
  int dimension = 0;                  ///< d
  long steps = 0;                     ///< CVODES steps of the Lyapunov equation
  long linearizations = 0;            ///< dynamics evaluations for it (one per distinct t)
  long differenceQuotientEvaluations = 0;  ///< 0: only the exact Lyapunov products were used
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// ok and λ_min(W) > relTol · λ_max(W).
  bool controllable(double relTol = 1e-10) const {
    return ok() && dimension > 0 && minEigenvalue > relTol * maxEigenvalue;
  }
  /// One line: the status, then λ_min (or "unresolved" when below 1e-10 λ_max: see controllable()),
  /// λ_max and the steps.
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "dimension", "min_eigenvalue", "max_eigenvalue",
  /// "steps", "linearizations"}.
  std::string json() const;
};

/// How the Gramian is integrated. The defaults serve a summary that prints λ_min and λ_max to
/// two or three digits. The integration error of the linear Lyapunov equation is itself close to
/// the Gramian of a slightly perturbed system, so λ_min is far better resolved than the per-entry
/// bound rtol·max|W_ij| suggests: on the hanging 20-link chain (bench/manifold_bench.cpp,
/// λ_min/λ_max = 2e-8) rtol 1e-4 and 1e-12 give the same λ_min and λ_max to six digits, in 606
/// and 14020 steps; on the hand's manifold Gramian rtol 1e-5 moves λ_min by 1.8e-3 relative
/// from rtol 1e-8 (346 steps instead of 3926). Default rtol 1e-5, atol 1e-14; tighten both for
/// more digits.
struct GramianOptions {
  TangentTransportOptions transport;  ///< for the basis (constrained scenes)
  double rtol = 1e-5;                 ///< CVODES relative tolerance on each entry of W (> 0)
  double atol = 1e-14;                ///< absolute tolerance on each entry of W (> 0)
  void validate() const;              ///< throws std::invalid_argument naming the field
};

/// The Gramian above along the trajectory (which needs state derivatives), for
/// reference.startTime() ≤ t0 < t1 ≤ reference.endTime(): CVODES BDF on the packed d(d+1)/2
/// entries, Newton by GMRES on the exact Lyapunov product E ↦ Ar E + E Arᵀ, preconditioned by the
/// exact Newton-matrix solve (complex Schur form of Ar, Bartels–Stewart: O(d³), no dense
/// N×N matrix). The basis is transported over the whole trajectory first (transportTangentBasis).
/// Throws std::invalid_argument / TrajectoryError for bad input; numerical failure is in the report.
GramianReport computeControllabilityGramian(const Model& model, const Trajectory& reference,
                                            double t0, double t1, const GramianOptions& options);

/// The same with the transport's options, and its rtol/atol for W as well (the earlier signature).
GramianReport computeControllabilityGramian(const Model& model, const Trajectory& reference,
                                            double t0, double t1,
                                            const TangentTransportOptions& options = {});

}  // namespace trellis
