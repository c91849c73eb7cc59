// trellis/control/dare.hpp — the discrete algebraic Riccati equation (DARE) and its LQR gain.
//
//   S = AdᵀS Ad − (AdᵀS Bd + N)(R + BdᵀS Bd)⁻¹(BdᵀS Ad + Nᵀ) + Q,
//   K = (R + BdᵀS Bd)⁻¹ (BdᵀS Ad + Nᵀ),  Ad − Bd K Schur stable.
// Method, checks and failure statuses: algebraic_riccati.hpp.
#pragma once

#include "trellis/control/algebraic_riccati.hpp"

#include <Eigen/Core>

namespace trellis {

/// Discrete algebraic Riccati equation (see the file comment), without / with cross term N.
LqrResult solveDare(const Eigen::MatrixXd& Ad, const Eigen::MatrixXd& Bd, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const CareOptions& options = {});
LqrResult solveDare(const Eigen::MatrixXd& Ad, const Eigen::MatrixXd& Bd, const Eigen::MatrixXd& Q,
                    const Eigen::MatrixXd& R, const Eigen::MatrixXd& N,
                    const CareOptions& options = {});

}  // namespace trellis
