// trellis/control/care.hpp — the continuous algebraic Riccati equation (CARE) and its LQR gain.
//
//   AᵀS + SA − (SB + N) R⁻¹ (BᵀS + Nᵀ) + Q = 0,  K = R⁻¹ (BᵀS + Nᵀ),  A − BK Hurwitz.
// Method, checks and failure statuses: algebraic_riccati.hpp.
#pragma once

#include "trellis/control/algebraic_riccati.hpp"

#include <Eigen/Core>

namespace trellis {

/// Continuous algebraic Riccati equation (see the file comment), without / with cross term N.
LqrResult solveCare(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const CareOptions& options = {});
LqrResult solveCare(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const Eigen::MatrixXd& N,
                    const CareOptions& options = {});

}  // namespace trellis
