// tests/support/random_state.hpp — seeded random states, rotations, inertias, and consistent
// states of constrained systems. Every generator takes a std::mt19937 the test seeds explicitly;
// numbers are drawn with our own mapping of the engine's 32-bit output (std::mt19937 is specified
// bit for bit, std::uniform_real_distribution is not), so a seed means the same state everywhere.
#pragma once

#include <trellis/core.hpp>

#include <Eigen/Core>

#include <random>

namespace trellis::test {

/// Uniform in [lo, hi].
double uniform(std::mt19937& rng, double lo, double hi);
Eigen::VectorXd uniformVector(std::mt19937& rng, Eigen::Index n, double lo, double hi);

/// A uniformly random rotation (from a normalized random quaternion).
Eigen::Matrix3d randomRotation(std::mt19937& rng);

/// A random, physically valid inertia tensor: R diag(a, b, c) Rᵀ with principal moments in
/// [lo, hi] that satisfy the triangle inequality, and a random R (so every entry is nonzero).
Eigen::Matrix3d randomInertia(std::mt19937& rng, double lo = 0.05, double hi = 0.2);

/// A random rigid transform: random rotation, translation with entries in [−t, t].
Eigen::Matrix4d randomSE3(std::mt19937& rng, double t = 0.5);

struct State {
  Eigen::VectorXd q, dq, u;
};

/// q ∈ [−qRange, qRange]^n, q̇ ∈ [−dqRange, dqRange]^n, u ∈ [−uRange, uRange]^m.
State randomState(const Model& model, std::mt19937& rng, double qRange = 1.2, double dqRange = 1.0,
                  double uRange = 1.0);

/// Moves q onto h(q) = 0 (holonomic rows) by Gauss-Newton with the minimum-norm step, then
/// projects q̇ onto the null space of A(q) (all rows, holonomic and not). Returns true when
/// ‖h‖∞ ≤ 1e-13 and ‖A q̇‖∞ ≤ 1e-13 · max(1, ‖q̇‖∞) were reached.
bool projectToConstraints(const Model& model, Eigen::VectorXd& q, Eigen::VectorXd& dq);

/// A random state (as randomState) projected to the constraint manifold; retries with new draws
/// until the projection converges (throws std::runtime_error after 20 tries).
State randomConsistentState(const Model& model, std::mt19937& rng, double qRange = 1.2,
                            double dqRange = 1.0, double uRange = 1.0);

}  // namespace trellis::test
