// algebraic_riccati_common.hpp (private) — what CARE (care.cpp) and DARE (dare.cpp) share: the
// argument checks, the whitened and balanced problem, the scale-invariant residuals, the diagnosis
// of a failed solve and the common ending (S, K, residual, closed loop, status). The method is
// described in trellis/control/algebraic_riccati.hpp.
#pragma once

#include "trellis/control/algebraic_riccati.hpp"
#include "trellis/control/stabilizability.hpp"

#include <Eigen/Core>

#include <complex>
#include <limits>
#include <string>

namespace trellis::detail::are {

using Eigen::Index;
using Eigen::MatrixXcd;
using Eigen::MatrixXd;
using Eigen::VectorXcd;
using Eigen::VectorXd;
using LongDouble = long double;
using MatrixXld = Eigen::Matrix<LongDouble, Eigen::Dynamic, Eigen::Dynamic>;
using Complex = std::complex<double>;

inline constexpr double kEps = std::numeric_limits<double>::epsilon();
/// A Hamiltonian eigenvalue with |Re λ| ≤ this·|λ| (a pencil eigenvalue with ||λ| − 1| ≤ this) is
/// reported as on the boundary: a defective boundary eigenvalue moves by O(√eps) under rounding.
inline constexpr double kBoundaryTolerance = 1e-6;
/// An eigenvalue of A with Re λ ≥ −this·|λ| (|λ| ≥ 1 − this) is treated as not strictly stable.
inline constexpr double kUnstableMargin = 1e-8;

/// Throws std::invalid_argument unless A is n×n (n ≥ 1), B n×m (m ≥ 1), both finite; fn names the caller.
void checkSystem(const MatrixXd& A, const MatrixXd& B, const char* fn);
/// Q: symmetric (indefinite allowed); N: nx×m, finite (empty = no cross term).
void checkStateWeights(const MatrixXd& Q, const MatrixXd& N, Index n, Index m, const char* fn);

/// The problem in whitened inputs (R → I), without cross term, and in balanced states.
struct Prepared {
  VectorXd e;          ///< input scaling, u = E ũ
  MatrixXld L;         ///< E R E = L Lᵀ (long double)
  MatrixXd Bh, Nh;     ///< B E L⁻ᵀ, N E L⁻ᵀ (original states; Nh empty without cross term)
  VectorXd d;          ///< state scaling, x = D z
  MatrixXd A, G, Q, B; ///< balanced reduced: D⁻¹(A − B̂N̂ᵀ)D, D⁻¹B̂B̂ᵀD⁻¹, D(Q − N̂N̂ᵀ)D, D⁻¹B̂
};

/// Whitens the inputs (R → I, extended precision), removes the cross term and balances the states.
Prepared prepare(const MatrixXd& A, const MatrixXd& B, const MatrixXd& Q, const MatrixXd& R,
                 const MatrixXd& N, bool balance);

/// CARE in whitened inputs: Res = AᵀX + XA − F Fᵀ + Q, F = X B̂ + N̂; Kv = Fᵀ.
double careResidual(const MatrixXd& A, const MatrixXd& Bh, const MatrixXd& Nh, const MatrixXd& Q,
                    const MatrixXd& X, MatrixXd* Res = nullptr, MatrixXd* Kv = nullptr);
/// DARE in whitened inputs: Res = AᵀXA − X − Fᵀ W⁻¹ F + Q, W = I + B̂ᵀXB̂, F = B̂ᵀXA + N̂ᵀ;
/// Kv = W⁻¹F.
double dareResidual(const MatrixXd& A, const MatrixXd& Bh, const MatrixXd& Nh, const MatrixXd& Q,
                    const MatrixXd& X, MatrixXd* Res = nullptr, MatrixXd* Kv = nullptr);

/// "a + bi" with the precision the messages use.
std::string formatComplex(Complex z);
/// Re λ ≥ −kUnstableMargin·|λ| (continuous) or |λ| ≥ 1 − kUnstableMargin (discrete).
bool outsideStabilityRegion(Complex lambda, bool discrete);
/// checkStabilizability without the argument checks (stabilizability.cpp).
StabilizabilityCheck stabilizabilityImpl(const MatrixXd& A, const MatrixXd& B, bool discrete,
                                         double tolerance);
/// After a failed solve: sets res.status and res.message to the first true reason (see .cpp).
void diagnoseFailure(LqrResult& res, const Prepared& p, bool discrete, const CareOptions& options,
                     const std::string& fn, const std::string& why);
/// Shared ending: S, K, residual on the original data, closed loop, status.
void finish(LqrResult& res, const Prepared& p, const MatrixXd& A, const MatrixXd& Q, bool discrete,
            const MatrixXd& Xb, const CareOptions& options, const std::string& fn);

}  // namespace trellis::detail::are
