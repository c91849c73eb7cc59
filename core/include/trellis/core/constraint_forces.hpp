// trellis/core/constraint_forces.hpp — the constraint forces Aᵀλ as forces at points of the bodies
// (what a viewer draws as arrows, what a contact model would read).
#pragma once

#include "trellis/core/model.hpp"

#include <Eigen/Core>

#include <vector>

namespace trellis {

class Data;

/// The force one constraint row exerts on one body, at one point.
struct ConstraintPointForce {
  int row = 0;                                         ///< constraint row r (index into Model::constraints())
  int joint = kWorld;                                  ///< the body it acts on (kWorld: the world)
  /// Which of the constraint's points it acts at: 0 its first point a, 1 its second point b (for
  /// the plane body of a point on a plane: 1, the point body's point).
  int side = 0;
  /// Where it acts, world coordinates [m]: a point of body `joint` (for the plane body of a point
  /// on a plane, its material point that coincides with the point body's point).
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d force = Eigen::Vector3d::Zero();     ///< λ_r g, world coordinates [N when λ is in N per unit of h]
};

/// The constraint forces Aᵀλ split into point forces: row r of A is Σ gᵀ ∂p/∂q over its points p,
/// so Aᵀλ = Σ_r Σ_points (∂p/∂q)ᵀ λ_r g, the force λ_r g at p on that point's body. Per kind (p_a,
/// p_b the constraint's two points, world coordinates):
///   distance  h = ‖p_a − p_b‖² − ℓ²  →  λ 2(p_a − p_b) at p_a, −λ 2(p_a − p_b) at p_b;
///   point     h = e·(p_a − p_b)      →  λ e at p_a, −λ e at p_b;
///   point on plane, normal n = R_a n_a →  λ n on the plane body a and −λ n on the point body b,
///                                         both at p_b;
///   knife edge (e = R_a e_a)          →  λ e at p_a.
/// Forces on the world are listed too (joint = kWorld). Rows come in order, each row's forces in
/// the order above (the first is the force on the constraint's first body).
///
/// `data` must hold the kinematics at the configuration (after computeKinematics, computeDynamics
/// or computeLinearization); lambda: nc (e.g. data.lambda). Throws std::invalid_argument for a
/// lambda of the wrong size. Allocates the result.
std::vector<ConstraintPointForce> computeConstraintPointForces(const Model& model, const Data& data,
                                                               const Eigen::VectorXd& lambda);

}  // namespace trellis
