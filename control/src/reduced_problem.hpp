// reduced_problem.hpp (private) — the LQR problem on the constraint tangent space along a
// transported basis T(t): Ar = TᵀAT, Br = TᵀB (ReducedLinearization) and Qr(t) = TᵀQ(t)T, R as
// given. One evaluator serves the linearization and the Q callback (its cache gives one dynamics
// evaluation per t). The callbacks hold the evaluator, and through it the model, only while they
// live: a solver's result keeps none of them. Used by solveManifoldRiccati (continuous) and
// solveTvlqr (sampled).
#pragma once

#include "trellis/control/manifold_lqr.hpp"
#include "trellis/control/riccati.hpp"

#include <memory>

namespace trellis::detail {

struct ReducedProblem {
  LinearizationCallback linearization;  ///< (Ar, Br) at t
  LqrWeights weights;                   ///< Qfun = TᵀQT (exactly symmetric; a constant Q when T = I
                                        ///< and Q is), R / Rfun as given; no Qf
  std::shared_ptr<ReducedLinearization> evaluator;  ///< the callbacks' evaluator (T(t), counts)
  /// Qfr = Tᵀ Qf T at t (symmetrized), from the evaluator; a failure of the reduced linearization
  /// at t is the returned status (Qfr then untouched).
  ReferenceStatus reducedTerminal(const Eigen::MatrixXd& Qf, double t, Eigen::MatrixXd& Qfr) const;
};

/// `weights` in the full state (Q, Qfun nx×nx); the model must outlive the returned callbacks.
ReducedProblem makeReducedProblem(const Model& model, const TangentBasisTrajectory& basis,
                                  const LqrWeights& weights);

}  // namespace trellis::detail
