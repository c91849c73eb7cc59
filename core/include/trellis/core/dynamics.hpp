// trellis/core/dynamics.hpp — mass matrix, constraints, forward dynamics (paper Eq. (3), (5)).
//
// The Euler-Lagrange equations with constraint forces,
//   M(q) q̈ = Q(q, q̇, u) + ∂L/∂q − (∂²L/∂q∂q̇) q̇ + Aᵀ λ,     A q̈ + Ȧ q̇ = 0,
// are evaluated with a recursive Newton-Euler pass over the joint tree (the same quantities as the
// Lagrangian terms, O(n)) and a composite-rigid-body pass for M, then solved as the KKT system
// [M Aᵀ; A 0] [q̈; −λ] = [Q − b; −Ȧ q̇] by a Cholesky factor of M and of A M⁻¹ Aᵀ — or, without
// constraints on a model whose trees are chains, M q̈ = Q − b by the articulated-body recursion
// in O(n).
#pragma once

#include "trellis/core/data.hpp"

namespace trellis {

/// data.M (n×n, symmetric positive semidefinite). Needs computeKinematics at q first; this
/// function calls it when `q` is given.
void computeMassMatrix(const Model& model, Data& data, const Eigen::VectorXd& q);

/// data.constraintValue h(q) (nc), data.constraintJacobian A(q) (nc×n) and data.constraintDrift
/// Ȧ q̇ (nc). Nonholonomic rows have h = 0.
void computeConstraints(const Model& model, Data& data, const Eigen::VectorXd& q,
                        const Eigen::VectorXd& dq);

/// data.inputMatrix ∂Q/∂u (n×m) at q.
void computeInputMatrix(const Model& model, Data& data, const Eigen::VectorXd& q);

/// Forward dynamics: data.qdd, data.lambda, and on the way data.M, data.bias and the constraint
/// quantities. u: m-vector. Numerical failure is returned (and kept in data.status), never thrown;
/// size mismatches throw std::invalid_argument.
DynamicsStatus computeDynamics(const Model& model, Data& data, const Eigen::VectorXd& q,
                               const Eigen::VectorXd& dq, const Eigen::VectorXd& u);

/// Kinetic energy ½ q̇ᵀ M q̇ and potential energy (gravity, linear and configuration springs).
Energy computeEnergy(const Model& model, Data& data, const Eigen::VectorXd& q,
                     const Eigen::VectorXd& dq);

/// Power of the non-conservative generalized forces, Q_ncᵀ q̇ (inputs, damping, wrenches, tendons).
double computeNonConservativePower(const Model& model, Data& data, const Eigen::VectorXd& q,
                                   const Eigen::VectorXd& dq, const Eigen::VectorXd& u);

}  // namespace trellis
