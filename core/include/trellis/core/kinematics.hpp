// trellis/core/kinematics.hpp — frame poses and body velocities (paper Sec. II-A).
#pragma once

#include "trellis/core/data.hpp"

namespace trellis {

/// Joint placements, motion subspaces and spatial velocities of every joint body, then the world
/// pose g_s,k(q) and body velocity v_k^b(q, q̇) = [v_b; ω_b] (frame axes) of every frame:
/// data.framePose, data.frameVelocity. q, dq: n-vectors. O(frames). Throws std::invalid_argument
/// on a size mismatch.
void computeKinematics(const Model& model, Data& data, const Eigen::VectorXd& q,
                       const Eigen::VectorXd& dq);

}  // namespace trellis
