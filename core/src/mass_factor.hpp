// Internal: the mass matrix factored along the joint tree (Featherstone, RBDA §6.5, "LTDL").
//
// M(i, j) ≠ 0 only when one of i, j is an ancestor of the other, so M = Lᵀ D L with L unit lower
// triangular and L(i, j) ≠ 0 only for j an ancestor of i: eliminating from the leaves creates no
// fill-in. Factor O(Σ dᵢ²), one solve O(Σ dᵢ) (dᵢ the depth of joint i), against n³/6 and n² for a
// dense Cholesky factor — on a hand of five 4-joint digits 50 against 200 per solve. The joints of
// different top-level trees never share an ancestor: M is block diagonal over those trees and every
// loop below stays inside one block.
//
// Ancestor sets are walked as contiguous runs: in pre-order an unbranched stretch of the tree is a
// run of consecutive indices [runStart(i), i], so every inner loop is a vectorized segment
// operation (one run for a chain, one per digit for a hand).
//
// Storage (ws.massFactor, n×n): D on the diagonal and L(i, j) at (j, i) — column i holds row i
// of L, so that each run is contiguous in memory. Entries off the ancestor pattern stay exactly 0.
//
// An unbranched block of 12 or more joints (a long chain) has nothing for the tree to skip; there
// the block is factored by Eigen's dense Cholesky M_b = L Lᵀ (lower triangle of the same storage),
// whose blocked kernels do the same O(n³) work in fewer instructions (callgrind, chains of 10–40).
#pragma once

#include "internal.hpp"

namespace trellis::detail {

/// Calls f(first, last) for the runs [first, last] of consecutive indices that make up the
/// ancestors of joint i (with `self`, i included), nearest run first.
template <class F>
inline void forAncestorRuns(const ModelTopology& topo, int i, bool self, F&& f) {
  int t = self ? i : topo.parent[static_cast<size_t>(i)];
  while (t != kWorld) {
    const int s = topo.runStart[static_cast<size_t>(t)];
    f(s, t);
    t = topo.parent[static_cast<size_t>(s)];
  }
}

/// Whether factorMass takes the articulated factor for this model: every block a chain, the
/// longest of at least 8 joints (decided once per model: ws.articulatedModel).
bool suitsArticulatedFactor(const Model& model);

/// Factors M: the articulated factor (factorArticulated, ws.articulatedCurrent) when
/// ws.articulatedModel (suitsArticulatedFactor), else data.M into ws.massFactor. Returns −1 on
/// success, else the joint whose pivot Dᵢ is not above tol (then the factor is unusable). Both
/// factors have the same pivots Dᵢ.
int factorMass(const Model& model, Data& data, double tol);

/// x ← M⁻¹ x on the coordinates [lo, hi), a union of whole blocks (x is 0 elsewhere or ignored).
void solveMassVector(const Model& model, Data& data, Eigen::Ref<Eigen::VectorXd> x, int lo, int hi);

/// The same for `cols` columns x + c stride (each n long) at once; with the articulated factor
/// the columns share one sweep (the rows of a constraint group: M⁻¹Aᵀ in factorizeKkt).
void solveMassColumns(const Model& model, Data& data, double* x, Eigen::Index stride, int cols, int lo, int hi);

/// ws.massInverse = M⁻¹ (block diagonal, zero between blocks) from the current factor: the tree
/// factor, M⁻¹ = W D⁻¹ Wᵀ with W = L⁻¹, which keeps the ancestor pattern of L, O(Σ per block
/// n_b³/3); or, when ws.articulatedCurrent (only used when blocksAreChains), the articulated
/// factor, O(Σ n_b²) (invertChainArticulated in mass_factor.cpp).
void invertMass(const Model& model, Data& data);

/// Whether every top-level tree is unbranched (a chain).
bool blocksAreChains(const Model& model);

/// X ← M⁻¹ X for many columns, block by block with ws.massInverse (invertMass first).
void applyMassInverse(const Model& model, Data& data, Eigen::Ref<Eigen::MatrixXd> X);

/// X = M⁻¹ R (X and R distinct, same shape), block by block with ws.massInverse.
void applyMassInverse(const Model& model, Data& data, const Eigen::Ref<const Eigen::MatrixXd>& R, Eigen::Ref<Eigen::MatrixXd> X);

// The same factor in spatial form (forward dynamics without constraints, and M⁻¹ of chains for
// the linearization: invertMass). Articulated-body inertias from the leaves (Featherstone, RBDA §7.3, at
// zero velocity): IA_i = I_i + Σ_children (IA_c − U_c U_cᵀ / D_c), U_i = IA_i S_i, D_i = S_iᵀ U_i.
// The D_i are the pivots of M = Lᵀ D L above; the work is O(n) 6×6 products instead of the
// factor's O(Σ dᵢ²) (M itself is still formed: data.M is a result of computeDynamics). Used for
// every model whose trees are all chains without constraints (computeDynamics), and with
// constraints when a chain has 8 joints or more (factorMass; M⁻¹Aᵀ of a group of constraint rows
// is then one articulated sweep, solveMassColumns).

/// Fills ws.articulatedU, articulatedPivot from the world inertias (needs updateJoints), for a
/// model whose blocks are chains (blocksAreChains). Returns −1 on success, else the joint whose
/// pivot D_i is not above tol.
int factorArticulated(const Model& model, Data& data, double tol);

/// x ← M⁻¹ x with the articulated factor: from the leaves u_i = x_i − S_i·p_i with
/// p_parent += p_i + U_i u_i / D_i, then from the roots x_i = (u_i − U_i·a_parent) / D_i,
/// a_i = a_parent + S_i x_i.
void solveArticulated(const Model& model, Data& data, Eigen::VectorXd& x);

}  // namespace trellis::detail
