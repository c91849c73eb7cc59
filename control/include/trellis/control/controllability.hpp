// trellis/control/controllability.hpp — controllability of a linearization at a point.
//
// For ẋ = A x + B u (A d×d, B d×m) the Krylov matrix C = [B, Â B, Â² B, …, Â^{d−1} B] with
// Â = A / α, α = max(1, ‖A‖_F), has the rank of the controllability matrix (the scaling only
// changes the singular values, and keeps the powers of A from overflowing); the pair is
// controllable when rank C = d. On a constrained system the state is first reduced to the tangent
// space of the constraint manifold (core's computeConstraintTangentBasis: Ar = TᵀAT, Br = TᵀB),
// where the directions that leave the manifold — which no input can steer — are gone.
#pragma once

#include <Eigen/Core>

namespace trellis {

class Model;
class Data;

struct ControllabilityReport {
  int dimension = 0;                  ///< d, the (reduced) state dimension
  int rank = 0;                       ///< numerical rank of C (σ_i > tolerance·σ_max)
  double smallestSingularValue = 0.0; ///< σ_d of C (0 if C has fewer than d columns)
  double largestSingularValue = 0.0;
  double scale = 1.0;                 ///< α used for Â = A/α
  Eigen::VectorXd singularValues;     ///< of C, descending
  bool controllable() const { return rank == dimension; }
};

/// Throws std::invalid_argument on inconsistent sizes.
ControllabilityReport computeControllability(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B,
                                             double relativeTolerance = 1e-10);

/// computeLinearization at x = [q; q̇], u, reduction to the constraint tangent space, then the
/// report above. Throws std::runtime_error if the dynamics fail at that point.
ControllabilityReport computeControllabilityAt(const Model& model, Data& data,
                                               const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                                               const Eigen::VectorXd& u,
                                               double relativeTolerance = 1e-10);

}  // namespace trellis
