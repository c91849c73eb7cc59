// Internal: the scratch of the algorithms, owned by a Data (data.hpp) and sized once from the
// Model (data.cpp). Not installed: users read the results in Data; the algorithms reach this with
// detail::workspace(data). The tree's structure (parents, runs, blocks, row groups, tendon paths)
// is not here: it is fixed by the Model and computed once in ModelBuilder::finalize
// (model.topology()). n = nq, m = nu, nc constraint rows, nh holonomic rows.
#pragma once

#include "trellis/core/data.hpp"

#include <Eigen/Cholesky>
#include <Eigen/QR>

#include <vector>

namespace trellis::detail {

/// Consecutive rows of one constraint group that live on the same coordinate segments
/// (DataWorkspace::rowRunStart), as correctForConstraints walks them.
struct RowRun {
  int first, count;   ///< the group's rows first … first + count − 1 (relative to the group)
  int lo[2], len[2];  ///< the two coordinate segments of the rows (len 0: none)
};

struct DataWorkspace {
  explicit DataWorkspace(const Model& model);

  // ---- Kinematics and forces, per joint body (kinematics.cpp, dynamics.cpp) --------------------
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
  std::vector<Eigen::Vector3d> tendonPoint;  ///< world positions of every tendon path point
  Eigen::VectorXd u;                     ///< inputs of the current evaluation
  Eigen::VectorXd qddZero;
  ///@{
  /// The coordinates of the current kinematics (set with ws.jointR, ws.v) and the q̈ that ws.a was
  /// computed with (updateAccelerations): what a coordinate coupling's row reads.
  Eigen::VectorXd q, dq, qddOfA;
  ///@}

  // ---- Linearization (linearization.cpp) -------------------------------------------------------
  // Subtree sums: inertial wrench Σ I(a − g) + v ×* I v, momentum Σ I v, and the 3×3 block B of
  // D = Σ (I crm(v) − crf(v) I) (linearization.cpp: applyD), which make each tangent O(1) per
  // joint pair.
  std::vector<Vector6d> inertialForce, compositeMomentum;
  std::vector<Eigen::Matrix3d> compositeB;
  // Per-joint vectors that reduce each (direction k, joint j) pair of the linearization to one
  // dot product: column j = [α; β; γ] with α = S ×* F_ext, β = Ic S, γ = D S + S ×* H.
  Eigen::Matrix<double, 18, Eigen::Dynamic> tangentABG;
  std::vector<Vector6d> tangentWrench;   ///< per body: external wrench tangents of one direction
  Eigen::MatrixXd rhsX;                  ///< n×(2n+m): −∂r/∂[x; u]
  Eigen::MatrixXd crhsX;                 ///< nc×(2n+m): −∂c/∂[x; u]

  // ---- The mass matrix factored along the tree (mass_factor.hpp) -------------------------------
  Eigen::MatrixXd massFactor;            ///< n×n: M = Lᵀ D L, D on the diagonal, L(i, j) at (j, i)
  Eigen::VectorXd massPivotInvSqrt;      ///< n: D^(−1/2)
  Eigen::MatrixXd massInverseFactor;     ///< n×n: rows of L⁻¹ D^(−1/2), stored as columns
  Eigen::MatrixXd massInverse;           ///< n×n, block diagonal M⁻¹ when many right-hand sides are solved
  bool massInverseCurrent = false;       ///< massInverse belongs to the current factor
  // The factor in spatial form (forward dynamics without constraints):
  std::vector<Vector6d> articulatedU, articulatedWork;          ///< n: U_i = IA_i S_i; solve workspace
  Eigen::VectorXd articulatedPivot;                             ///< n: D_i = S_iᵀ IA_i S_i
  Eigen::Matrix<double, 6, Eigen::Dynamic> articulatedColumns;  ///< 6×n workspace of invertMass
  bool articulatedCurrent = false;                              ///< the articulated factor is the current one
  bool articulatedModel = false;  ///< factorMass takes the articulated factor (suitsArticulatedFactor, fixed by the model)

  // ---- The KKT system [M Aᵀ; A 0] (dynamics.cpp) ----------------------------------------------
  Eigen::MatrixXd massInverseAt;         ///< n×nc: M⁻¹ Aᵀ
  Eigen::MatrixXd jacobianT;             ///< n×nc: Aᵀ on each row's segments, 0 elsewhere (factorizeKkt)
  Eigen::MatrixXd schur;                 ///< nc×nc: D A M⁻¹ Aᵀ D, rows normalized by D
  Eigen::VectorXd constraintScale;       ///< nc: largest possible ‖A_r‖ (see factorizeKkt)
  Eigen::VectorXd schurScale;            ///< nc: D = 1 / constraintScale
  Eigen::MatrixXd schurFactor;           ///< nc×nc: Ŝ = L Lᵀ, L in the lower triangle, Lᵀ in the strict upper (factorizeKkt)
  Eigen::VectorXd correctionWork;        ///< ≥ nc n + 2 nc² + nc: one row group's operands (correctForConstraints)
  std::vector<RowRun> correctionRuns;    ///< nc: one group's runs of rows (correctForConstraints)
  /// nc: the coordinates [rowGapLo[r], rowGapHi[r]) inside the range [rowLo[r], rowHi[r]) of
  /// ModelTopology that row r cannot touch: the blocks between its two bodies' blocks (a loop
  /// across two top-level trees, e.g. a digit and a free ball); both rowHi[r] when there are none.
  /// Row r lives on [rowLo, rowGapLo) and [rowGapHi, rowHi) (forRowSegments). Fixed by the model.
  std::vector<int> rowGapLo, rowGapHi;
  /// Starts of the runs of consecutive rows of one group that live on the same segments (the rows
  /// of one contact: one digit and the ball), then nc ({0} when nc = 0); each group is a union of
  /// whole runs. Fixed by the model.
  std::vector<int> rowRunStart;
  /// Per row group of ModelTopology: 1 when its rows do not all cover the group's coordinate
  /// range (rows on different segments), so that correctForConstraints takes the run kernel.
  /// Fixed by the model.
  std::vector<unsigned char> groupInRuns;
  bool anyGroupInRuns = false;           ///< some groupInRuns[g] is 1
  bool correctInRuns = true;             ///< false: every group takes the hull kernels (tests compare both)
  Eigen::LDLT<Eigen::MatrixXd> schurLDLT;  ///< pivoted, for rank-deficient Ŝ
  Eigen::VectorXd schurPivotInverse;     ///< 1/D_i of schurLDLT, 0 for the dropped pivots
  Eigen::MatrixXd schurNullBasis;        ///< nc×nc, first schurNullity columns: null space of Ŝ
  int schurNullity = 0;
  bool schurUsesPinv = false;
  /// The last evaluation's degenerate row was an exact zero row that holds (h_r = 0, Ȧ_r q̇ = 0):
  /// its message (below) names the row without the state, so computeDynamics appends none.
  bool zeroRowHolds = false;
  /// The message of that report for row zeroRowMessageRow, formatted at its first report and
  /// copied (no formatting, no allocation) at every later one — the z row of a point on a planar
  /// chain is reported at every call, and formatting it was a quarter of the call (issue 25).
  std::string zeroRowMessage;
  int zeroRowMessageRow = -1;
  Eigen::VectorXd tmpN, tmpC;            ///< n, nc: one right-hand side of solveKkt
  Eigen::MatrixXd tmpNX, tmpCX;          ///< n×(2n+m+1), nc×(2n+m+1): many right-hand sides

  // ---- The tangent basis (linearization.cpp: computeTangentBasis) -----------------------------
  Eigen::MatrixXd constraintStateJacobian;  ///< (nh+nc)×2n: rows of the map Φ(x) = [h(q); A q̇]
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> basisQR;
  Eigen::MatrixXd basisQ;                ///< 2n×2n
  Eigen::VectorXd basisWorkspace;        ///< 2n
  Eigen::MatrixXd basisWorkMatrix;       ///< 2n×2n scratch for A T
};

inline DataWorkspace& workspace(Data& data) { return *data.work_; }
inline const DataWorkspace& workspace(const Data& data) { return *data.work_; }

}  // namespace trellis::detail
