// Internal passes shared by dynamics.cpp and linearization.cpp. Not installed.
#pragma once

#include "spatial.hpp"
#include "data_workspace.hpp"

namespace trellis::detail {

/// Throws std::invalid_argument unless v has `expected` entries.
void checkSize(const Eigen::VectorXd& v, int expected, const char* what);

/// Joint poses, motion subspaces S, spatial velocities v and world inertias, O(n).
void updateJoints(const Model& model, Data& data, const Eigen::VectorXd& q, const Eigen::VectorXd& dq);

/// Spatial accelerations a_i = a_parent + S_i q̈_i + v_i × S_i q̇_i (no gravity), O(n).
void updateAccelerations(const Model& model, Data& data, const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd);

/// ws.fext: wrenches of springs, tendons and body wrenches at inputs u (conservative and not,
/// selected by the flags), plus, with lambda non-null, the constraint forces Aᵀλ.
void accumulateExternalWrenches(const Model& model, Data& data, const Eigen::VectorXd& u,
                                bool conservative, bool nonConservative, const Eigen::VectorXd* lambda);

/// Newton-Euler backward pass: tau = Σ S_iᵀ F_i with f_i = I(a − g) + v ×* I v − fext; leaves the
/// subtree wrenches in ws.f. Uses ws.a as set by updateAccelerations.
void inverseDynamicsPass(const Model& model, Data& data, Eigen::VectorXd& tau);

/// Generalized forces of the configuration-level elements (config springs, config forces,
/// damping) added to Q.
void addConfigurationForces(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                            const Eigen::VectorXd& u, Eigen::VectorXd& Q);

/// h, A q̇ and c = A q̈ + Ȧ q̇ (with the current accelerations) of every constraint, and A.
void evaluateConstraints(const Model& model, Data& data, Eigen::VectorXd* h, Eigen::VectorXd* hdot,
                         Eigen::VectorXd* c, Eigen::MatrixXd* A);

/// data.M by composite rigid bodies (needs updateJoints).
void massMatrixPass(const Model& model, Data& data);

/// data.inputMatrix = ∂Q/∂u (needs updateJoints).
void inputMatrixPass(const Model& model, Data& data);

/// False (and data.status set to kNonFinite naming the entry) if q, dq or u has NaN/Inf.
bool inputsAreFinite(const Model& model, Data& data, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                     const Eigen::VectorXd& u);

/// Appends " at q = (name=value, …), dq = (…)" to a status message (the first coordinates).
void appendState(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq, std::string& message);

/// f(lo, hi) for the (at most two) coordinate ranges row r of A lives on: [rowLo, rowGapLo) and
/// [rowGapHi, rowHi) (ModelTopology, DataWorkspace), each a union of whole blocks; A is exactly 0
/// elsewhere, and so is column r of M⁻¹Aᵀ (M⁻¹ is block diagonal).
template <class F>
inline void forRowSegments(const ModelTopology& t, const DataWorkspace& ws, int r, F&& f) {
  const size_t i = static_cast<size_t>(r);
  if (ws.rowGapLo[i] > t.rowLo[i]) f(t.rowLo[i], ws.rowGapLo[i]);
  if (t.rowHi[i] > ws.rowGapHi[i]) f(ws.rowGapHi[i], t.rowHi[i]);
}

/// Factorizes [M Aᵀ; A 0] from data.M and data.constraintJacobian; fills data.status.
void factorizeKkt(const Model& model, Data& data);

/// Whether the KKT factorization can be used at all (it can, with a status that is not ok, for
/// redundant and degenerate or near-singular constraints; not for a singular M or non-finite input).
inline bool solvable(const DynamicsStatus& s) {
  return s.code != DynamicsStatus::Code::kSingularMassMatrix && s.code != DynamicsStatus::Code::kNonFinite;
}

/// Solves M X = R + Aᵀ Λ, A X = C for X (n×p) and Λ (nc×p) with the current factorization.
/// X may alias R; Λ may alias C. Workspace: ws.tmpN/tmpC (p = 1) or ws.tmpNX/tmpCX.
void solveKkt(const Model& model, Data& data, Eigen::Ref<Eigen::MatrixXd> X, Eigen::Ref<Eigen::MatrixXd> Lambda);

/// X ← M⁻¹ X through the tree factor (column by column), or with ws.massInverse when it is
/// current and X has several columns.
void solveMass(const Model& model, Data& data, Eigen::Ref<Eigen::MatrixXd> X);

/// The second half of solveKkt: given X = M⁻¹ R and Λ = C, returns the KKT solution in (X, Λ).
void correctForConstraints(const Model& model, Data& data, Eigen::Ref<Eigen::MatrixXd> X,
                           Eigen::Ref<Eigen::MatrixXd> Lambda);

}  // namespace trellis::detail
