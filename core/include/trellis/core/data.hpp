// trellis/core/data.hpp — the preallocated workspace that goes beside a Model.
//
// Every buffer an algorithm writes is sized here, once; after the first evaluation no algorithm
// allocates (tests/core/test_no_allocation.cpp proves it with Eigen's malloc guard). One Data per
// thread. Results are plain public members, documented with their dimensions.
#pragma once

#include "trellis/core/model.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>

#include <vector>

namespace trellis {

/// Outcome of an evaluation that solves the KKT system [M Aᵀ; A 0].
struct DynamicsStatus {
  enum class Code {
    kOk,
    kRedundantConstraints,   ///< A is rank deficient beyond round-off (rows that depend on the others):
                             ///< q̈ is computed exactly, λ is one choice (minimum norm in the
                             ///< row-normalized coordinates of A M⁻¹ Aᵀ); not ok, the message names the row
    kSingularMassMatrix,     ///< M is not positive definite (a joint moves no mass); no result
    kSingularConstraints,    ///< a degenerate row (its gradient vanishes: e.g. a distance constraint whose
                             ///< points coincide) or a singular or near-singular configuration, judged
                             ///< relative to the row's natural scale: the results are finite but
                             ///< inaccurate (or A q̈ + Ȧ q̇ = 0 has no solution); the message names
                             ///< the constraint, its row and the state
    kNonFinite,              ///< an input or result is NaN/Inf
  };
  Code code = Code::kOk;
  int constraintRank = 0;          ///< numerical rank of A (= nc when full)
  /// In [0, 1]: min of the constraints' kinematic conditioning (‖A_r‖ over its largest possible
  /// value; 0 at a singular configuration) and the reciprocal condition estimate of the
  /// row-normalized A M⁻¹ Aᵀ (0 for redundant rows). 1 without constraints.
  double constraintConditioning = 1.0;
  std::string message;             ///< empty when ok; names the configuration / constraint and the state otherwise
  /// True when q̈, λ (and the linearization) are valid and determined: kOk only.
  bool ok() const { return code == Code::kOk; }
};

/// Kinetic and potential energy, T = ½ q̇ᵀ M q̇, V = gravity + springs.
struct Energy {
  double kinetic = 0.0;
  double potential = 0.0;
  double total() const { return kinetic + potential; }
};

class Data {
 public:
  explicit Data(const Model& model);

  // ---- Results --------------------------------------------------------------------------------
  /// World pose of every frame (model.frames() order).
  std::vector<Eigen::Isometry3d> framePose;
  /// Body velocity of every frame, [v_b; ω_b] in the frame's own axes.
  std::vector<Vector6d> frameVelocity;
  Eigen::MatrixXd M;                  ///< n×n mass matrix ∂²L/∂q̇∂q̇
  Eigen::VectorXd bias;               ///< n: inverse dynamics at q̈ = 0 minus all forces, ID(q,q̇,0) − Q
  Eigen::VectorXd constraintValue;    ///< nc: h(q) (0 for nonholonomic rows)
  Eigen::MatrixXd constraintJacobian; ///< nc×n: A(q)
  Eigen::VectorXd constraintDrift;    ///< nc: Ȧ q̇
  Eigen::VectorXd qdd;                ///< n: forward dynamics q̈
  Eigen::VectorXd lambda;             ///< nc: constraint forces, M q̈ = … + Aᵀ λ
  Eigen::MatrixXd inputMatrix;        ///< n×m: ∂Q/∂u
  Eigen::MatrixXd A;                  ///< 2n×2n: ∂ẋ/∂x, x = [q; q̇]
  Eigen::MatrixXd B;                  ///< 2n×m:  ∂ẋ/∂u
  Eigen::MatrixXd dqdd_dq, dqdd_ddq, dqdd_du;   ///< blocks of A and B (n×n, n×n, n×m)
  Eigen::MatrixXd dlambda_dx;         ///< nc×(2n+m): ∂λ/∂[q; q̇; u]
  Eigen::MatrixXd constraintVelocityJacobian;  ///< nc×n: ∂(A q̇)/∂q
  /// Orthonormal basis (2n×d) of the tangent space of {h(q) = 0, A(q) q̇ = 0} at x, and the
  /// linearization expressed on it: Ar = Tᵀ A T (d×d), Br = Tᵀ B (d×m).
  Eigen::MatrixXd tangentBasis, reducedA, reducedB;
  DynamicsStatus status;

  // ---- Workspace (algorithms only) ------------------------------------------------------------
  std::vector<Eigen::Matrix3d> jointR;   ///< world rotation of each joint body
  std::vector<Eigen::Vector3d> jointP;   ///< world position of each joint body origin
  std::vector<Vector6d> S;               ///< joint motion subspace (world spatial twist)
  std::vector<Vector6d> v, a;            ///< body spatial velocity, acceleration (no gravity)
  std::vector<Vector6d> f;               ///< per body: I(a − g) + v ×* I v − F_ext, then subtree sum
  std::vector<Vector6d> fext;            ///< external wrench on each body
  // world-frame inertia of each body: m, h = m c, I about the world origin
  std::vector<double> wm;
  std::vector<Eigen::Vector3d> wh;
  std::vector<Eigen::Matrix3d> wI;
  std::vector<Eigen::Vector3d> ch;       ///< composite (subtree) inertia for the mass matrix
  std::vector<double> cm;
  std::vector<Eigen::Matrix3d> cI;
  std::vector<Vector6d> Iv, Ia;          ///< I v and I (a − g) per body
  // Subtree sums for the linearization: inertial wrench Σ I(a − g) + v ×* I v, momentum Σ I v,
  // and the 3×3 block B of D = Σ (I crm(v) − crf(v) I) (linearization.cpp: applyD), which make
  // each tangent O(1) per joint pair.
  std::vector<Vector6d> inertialForce, compositeMomentum;
  std::vector<Eigen::Matrix3d> compositeB;
  // Per-joint vectors that reduce each (direction k, joint j) pair of the linearization to one
  // dot product (linearization.cpp): column j = [α; β; γ] with α = S ×* F_ext, β = Ic S,
  // γ = D S + S ×* H.
  Eigen::Matrix<double, 18, Eigen::Dynamic> tangentABG;
  std::vector<Vector6d> tangentWrench;   ///< per body: external wrench tangents of one direction
  std::vector<int> treeRoot;             ///< n: the top-level joint of i's tree
  std::vector<int> tendonFirst;          ///< per tendon: offset of its path in tendonPoint, then the total
  std::vector<int> tendonJointLo, tendonJointHi;  ///< per tendon: lowest and highest joint on its path
  std::vector<Eigen::Vector3d> tendonPoint;       ///< world positions of every tendon path point
  std::vector<int> tendonPointJoint;              ///< joint body of every tendon path point
  /// Per tendon: offset into tendonSegmentPoint, then the total. tendonSegmentPoint lists, by the
  /// index in tendonPoint of its first end, each segment whose ends lie on different bodies (a
  /// segment within one body exerts equal and opposite forces along one line: no net wrench).
  std::vector<int> tendonSegmentStart, tendonSegmentPoint;
  Eigen::VectorXd u;                     ///< inputs of the current evaluation
  Eigen::VectorXd qddZero;
  Eigen::MatrixXd rhsX;                  ///< n×(2n+m): −∂r/∂[x; u]
  Eigen::MatrixXd crhsX;                 ///< nc×(2n+m): −∂c/∂[x; u]
  // The joint tree's structure, fixed at construction (core/src/mass_factor.hpp):
  std::vector<int> treeParent;           ///< n: parent joint (kWorld for a root)
  std::vector<int> runStart;             ///< n: first index of the unbranched run of ancestors ending at i
  std::vector<int> blockStart;           ///< starts of the top-level trees (M is block diagonal over them), then n
  std::vector<int> rowLo, rowHi;         ///< nc: the coordinates row r of A can touch (whole blocks)
  std::vector<int> schurGroupStart;      ///< starts of the groups of rows that share no block, then nc
  std::vector<int> unitInputConfig;      ///< m: c when input k only adds unitInputGain[k]·u_k to Q_c, else −1
  std::vector<double> unitInputGain;
  Eigen::MatrixXd massFactor;            ///< n×n: M = Lᵀ D L, D on the diagonal, L(i, j) at (j, i)
  Eigen::VectorXd massPivotInvSqrt;      ///< n: D^(−1/2)
  Eigen::MatrixXd massInverseFactor;     ///< n×n: rows of L⁻¹ D^(−1/2), stored as columns
  Eigen::MatrixXd massInverse;           ///< n×n, block diagonal M⁻¹ when many right-hand sides are solved
  bool massInverseCurrent = false;       ///< massInverse belongs to the current factor
  // The factor in spatial form (forward dynamics without constraints; mass_factor.hpp):
  std::vector<Vector6d> articulatedU, articulatedWork;          ///< n: U_i = IA_i S_i; solve workspace
  Eigen::VectorXd articulatedPivot;                             ///< n: D_i = S_iᵀ IA_i S_i
  Eigen::Matrix<double, 6, Eigen::Dynamic> articulatedColumns;  ///< 6×n workspace of invertMass
  bool articulatedCurrent = false;                              ///< the articulated factor is the current one
  Eigen::MatrixXd massInverseAt;         ///< n×nc: M⁻¹ Aᵀ
  Eigen::MatrixXd schur;                 ///< nc×nc: D A M⁻¹ Aᵀ D, rows normalized by D
  Eigen::VectorXd constraintScale;       ///< nc: largest possible ‖A_r‖ (see factorizeKkt)
  Eigen::VectorXd schurScale;            ///< nc: D = 1 / constraintScale
  Eigen::LLT<Eigen::MatrixXd> schurLLT;
  Eigen::VectorXd correctionWork;        ///< 2 nc n + nc² + nc: one row group's operands (correctForConstraints)
  Eigen::LDLT<Eigen::MatrixXd> schurLDLT;  ///< pivoted, for rank-deficient Ŝ
  Eigen::VectorXd schurPivotInverse;     ///< 1/D_i of schurLDLT, 0 for the dropped pivots
  Eigen::MatrixXd schurNullBasis;        ///< nc×nc, first schurNullity columns: null space of Ŝ
  int schurNullity = 0;
  bool schurUsesPinv = false;
  Eigen::VectorXd tmpN, tmpC;
  Eigen::MatrixXd tmpNX, tmpCX;
  Eigen::MatrixXd constraintStateJacobian;  ///< rows of the map Φ(x) = [h(q); A q̇]
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> basisQR;
  Eigen::MatrixXd basisQ;
  Eigen::VectorXd basisWorkspace;
  Eigen::MatrixXd basisWorkMatrix;       ///< 2n×2n scratch for A T

 private:
  void describeTree(const Model& model);  ///< fills the tree structure above
};

}  // namespace trellis
