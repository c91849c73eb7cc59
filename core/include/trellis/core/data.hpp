// trellis/core/data.hpp — the results of the algorithms, beside a Model.
//
// A Data holds what a user reads after an evaluation (poses, M, q̈, λ, the linearization, the
// status), each documented with its dimensions; the scratch every algorithm writes lives in a
// private workspace (core/src/data_workspace.hpp) that the Data owns. Everything is sized once, at
// construction, from the Model; after the first evaluation no algorithm allocates
// (tests/core/no_malloc proves it with Eigen's malloc guard). One Data per thread, used only with
// the Model it was built for (the algorithms read that Model's topology and this Data's buffers).
// A moved-from Data may only be assigned to or destroyed.
// n = model.nq(), m = model.nu(), nc = model.nc(), nf = model.nframes().
#pragma once

#include "trellis/core/model.hpp"
#include "trellis/core/status.hpp"

#include <memory>
#include <string>
#include <vector>

namespace trellis {

/// Outcome codes of an evaluation that solves the KKT system [M Aᵀ; A 0] (computeDynamics,
/// computeLinearization); success is kOk only.
enum class DynamicsCode {
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

/// Names: ok, redundant_constraints, singular_mass_matrix, singular_constraints, non_finite.
inline EnumNameTable<DynamicsCode> enumNames(DynamicsCode) {
  static constexpr EnumName<DynamicsCode> table[] = {
      {DynamicsCode::kOk, "ok"},
      {DynamicsCode::kRedundantConstraints, "redundant_constraints"},
      {DynamicsCode::kSingularMassMatrix, "singular_mass_matrix"},
      {DynamicsCode::kSingularConstraints, "singular_constraints"},
      {DynamicsCode::kNonFinite, "non_finite"}};
  return table;
}

/// The status of the last evaluation (Status<DynamicsCode>: code, message naming the constraint
/// and the state; t and index unused) with the constraints' rank and conditioning beside it.
/// ok() is true when q̈, λ (and the linearization) are valid and determined: kOk only.
struct DynamicsStatus : Status<DynamicsCode> {
  using Code = DynamicsCode;       ///< DynamicsStatus::Code::kOk reads as before
  int constraintRank = 0;          ///< numerical rank of A (= nc when full)
  /// In [0, 1]: min of the constraints' kinematic conditioning (‖A_r‖ over its largest possible
  /// value; 0 at a singular configuration) and the reciprocal condition estimate of the
  /// row-normalized A M⁻¹ Aᵀ (0 for redundant rows). 1 without constraints.
  double constraintConditioning = 1.0;
  /// One line: Status::describe(), then the rank and conditioning when constraints exist.
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "constraint_rank", "constraint_conditioning"}.
  std::string json() const;
};

/// Kinetic and potential energy, T = ½ q̇ᵀ M q̇, V = gravity + springs.
struct Energy {
  double kinetic = 0.0;    ///< T = ½ q̇ᵀ M(q) q̇ [J]
  double potential = 0.0;  ///< V: gravity, linear and configuration springs [J]
  double total() const { return kinetic + potential; }  ///< T + V [J]
};

class Data;

namespace detail {
struct DataWorkspace;  // core/src/data_workspace.hpp: the algorithms' scratch
inline DataWorkspace& workspace(Data& data);  // defined in data_workspace.hpp
inline const DataWorkspace& workspace(const Data& data);
}  // namespace detail

/// The workspace of one Model: every result the algorithms write (named members below) and their
/// scratch buffers, sized once; one per thread. The algorithms take (model, data, ...) and do not
/// allocate. A Data belongs to the model it was made for (same sizes); using it with another throws.
class Data {
 public:
  /// Sizes every result and every scratch buffer for `model` (allocates; the algorithms do not).
  explicit Data(const Model& model);
  ///@{
  /// Copies and moves carry the results and the scratch (a deep copy: the copy is independent,
  /// e.g. one per thread made from a prototype).
  Data(const Data& other);
  Data(Data&& other) noexcept;
  Data& operator=(const Data& other);
  Data& operator=(Data&& other) noexcept;
  ///@}
  ~Data();

  /// World pose of every frame (nf, model.frames() order): updateFramePoses, computeDynamics.
  std::vector<Eigen::Isometry3d> framePose;
  /// Body velocity of every frame (nf), [v_b; ω_b] in the frame's own axes: updateFrameVelocities.
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
  Eigen::MatrixXd dqdd_dq;            ///< n×n: ∂q̈/∂q (the lower-left block of A)
  Eigen::MatrixXd dqdd_ddq;           ///< n×n: ∂q̈/∂q̇ (the lower-right block of A)
  Eigen::MatrixXd dqdd_du;            ///< n×m: ∂q̈/∂u (the lower block of B)
  Eigen::MatrixXd dlambda_dx;         ///< nc×(2n+m): ∂λ/∂[q; q̇; u]
  Eigen::MatrixXd constraintVelocityJacobian;  ///< nc×n: ∂(A q̇)/∂q
  /// 2n×d: orthonormal basis T of the tangent space of {h(q) = 0, A(q) q̇ = 0} at x
  /// (computeTangentBasis; d = 2n − rank, identity without constraints).
  Eigen::MatrixXd tangentBasis;
  Eigen::MatrixXd reducedA;           ///< d×d: Tᵀ A T, the linearization on the tangent space
  Eigen::MatrixXd reducedB;           ///< d×m: Tᵀ B
  DynamicsStatus status;              ///< outcome of the last computeDynamics / computeLinearization

 private:
  friend detail::DataWorkspace& detail::workspace(Data& data);
  friend const detail::DataWorkspace& detail::workspace(const Data& data);
  std::unique_ptr<detail::DataWorkspace> work_;  ///< never null
};

}  // namespace trellis
