// bench/finite_differences.hpp — the numerical baseline the exact linearization is measured against.
//
// J = ∂q̈/∂z with z = [q; q̇; u] (n × (2n+m)) is the nontrivial part of the linearization:
// A = [[0, I], [J_q, J_q̇]], B = [[0], [J_u]]. It is estimated from the project's own
// computeDynamics, so the comparison is between two ways of differentiating the same function.
// The differences themselves are the core's (trellis/core/numdiff.hpp); this file only adds the
// benchmark's Richardson reference and error measures.
#pragma once

#include "trellis/core/data.hpp"
#include "trellis/core/numdiff.hpp"

#include <Eigen/Core>

namespace trellis::bench {

/// Preallocated buffers for centralDifferences (no allocation inside the timed loop).
struct FdWorkspace {
  explicit FdWorkspace(const Model& model);
  NumDiffWorkspace numdiff;   ///< the core's buffers
  Eigen::MatrixXd coarse;     ///< Richardson extrapolation: the estimate at step 2h
};

/// Central differences (trellis::differenceDynamics, DifferenceScheme::kCentral), column j:
/// (q̈(z + h_j e_j) − q̈(z − h_j e_j)) / (z_j⁺ − z_j⁻) with h_j = relStep · max(1, |z_j|). 2(2n+m)
/// evaluations of computeDynamics. J: n × (2n+m), resized by the caller. Returns false if any
/// evaluation failed (data.status then says why).
bool centralDifferences(const Model& model, Data& data, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& dq, const Eigen::VectorXd& u, double relStep,
                        FdWorkspace& ws, Eigen::MatrixXd& J);

/// One Richardson step on central differences, (4 D(h/2) − D(h)) / 3: truncation error O(h⁴),
/// rounding error O(ε/h). With h ≈ ε^(1/5) the estimate is good to roughly ε^(4/5) ≈ 3e-13
/// relative — a reference tight enough to measure the exact result's own error against.
bool richardsonDifferences(const Model& model, Data& data, const Eigen::VectorXd& q,
                           const Eigen::VectorXd& dq, const Eigen::VectorXd& u, double relStep,
                           FdWorkspace& ws, Eigen::MatrixXd& J);

/// The error measure used throughout: max|J − ref| / max(1, max|ref|).
double maxRelativeError(const Eigen::MatrixXd& J, const Eigen::MatrixXd& ref);

/// The same measure column by column, worst column: max_j max_i|J_ij − ref_ij| / max(1, max_i|ref_ij|).
/// Resolves columns whose scale is far below the largest entry (in the hand, a light finger's
/// columns beside a heavy one's), which the global measure hides.
double maxColumnRelativeError(const Eigen::MatrixXd& J, const Eigen::MatrixXd& ref);

}  // namespace trellis::bench
