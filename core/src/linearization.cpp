// Exact linearization by tangent Newton-Euler passes (see linearization.hpp for the formulation).
#include "trellis/core/linearization.hpp"

#include "trellis/core/dynamics.hpp"
#include "internal.hpp"
#include "mass_factor.hpp"
#include "constraint_kinds.hpp"
#include "force_elements.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace trellis {
namespace detail {
namespace {

// Both inlined into the tangent pass on purpose: a callback handed by reference to a call that
// is not inlined makes its captures (the pass's running hi, lo) live in memory, which cost the
// passes of free models ~0.4 % more instructions (callgrind, planar 10) for code they never run.

/// The constraint part of forceTangents.
template <class Emit>
inline __attribute__((always_inline)) void constraintForceTangents(const Model& model, const Data& data,
                                                                   const Direction& dir, Emit& emit) {
  const auto& cs = model.constraints();
  for (int r = 0; r < model.nc();) {
    const Constraint& c = cs[r];
    if (!dir.moves(c.a.joint) && !dir.moves(c.b.joint)) {
      ++r;
    } else if (c.type == ConstraintType::kPoint) {
      // Consecutive rows on one point pair: one force f = Σ λ_r e_r, one tangent per body.
      Vector3d f = Vector3d::Zero();
      int e = r;
      for (; e < model.nc() && PointKind::samePair(c, cs[e]); ++e) f[cs[e].axis] += data.lambda[e];
      PointKind::pairWrenchTangents(data, dir, c, f, emit);
      r = e;
    } else if (c.type == ConstraintType::kPointOnPlane) {
      // A contact's rows (normal, two tangents) on one pair: one force at p_b.
      int e = r + 1;
      while (e < model.nc() && PointOnPlaneKind::samePair(c, cs[e])) ++e;
      const auto w = PointOnPlaneKind::contactWrenchTangents(data, dir, &cs[r], &data.lambda[r], e - r);
      emit(c.a.joint, w.a);
      emit(c.b.joint, w.b);
      r = e;
    } else {
      constraintWrenchTangents(data, dir, c, data.lambda[r], emit);
      ++r;
    }
  }
}

/// Tangents of the force elements that move with q (force_elements.hpp) and of the constraint
/// forces at fixed λ; each body wrench tangent δW goes to emit(joint, δW).
template <class Emit>
inline __attribute__((always_inline)) void forceTangents(const Model& model, const Data& data, const Direction& dir,
                                                         const Eigen::VectorXd& u, Emit&& emit) {
  forEachForceElement(model, [&](auto kind, const auto& e, size_t i) {
    decltype(kind)::wrenchTangents(model, data, dir, e, i, u, emit);
  });
  if (model.nc() > 0) constraintForceTangents(model, data, dir, emit);
}

/// The subtree sum D = Σ (I crm(v) − crf(v) I) enters only as D x ± x ×* H (H = [p; L] = Σ I v, the
/// subtree momentum). With I = [[m E, −ĥ], [ĥ, Ī]] and crm(v) = [[ω̂, v̂], [0, ω̂]] each term is
/// P + Pᵀ, P = I crm(v) = [[m ω̂, m v̂ − ĥ ω̂], [ĥ ω̂, ĥ v̂ + Ī ω̂]]; with â b̂ = b aᵀ − (a·b) E and
/// [â, b̂] = (a × b)^, D = [[0, p̂], [−p̂, B]], B = Σ (v hᵀ + h vᵀ − 2 (h·v) E + Ī ω̂ + (Ī ω̂)ᵀ), so
///   D x − x ×* H = [2 p × x_ω; B x_ω + L × x_ω],   D x + x ×* H = [0; 2 x_v × p + B x_ω + x_ω × L].
inline Vector6d dMinusCross(const Vector6d& H, const Eigen::Matrix3d& B, const Vector6d& x) {
  const Vector3d p = lin(H), L = ang(H), xw = ang(x);
  return make(2.0 * p.cross(xw), B * xw + L.cross(xw));
}
inline Vector3d dPlusCrossAngular(const Vector6d& H, const Eigen::Matrix3d& B, const Vector6d& x) {
  const Vector3d p = lin(H), L = ang(H), xw = ang(x);
  return 2.0 * lin(x).cross(p) + B * xw + xw.cross(L);
}

/// Subtree sums used by tangentPass (after the nominal Newton-Euler pass at the solved q̈, λ).
void compositePass(const Model& model, Data& data) {
  auto& ws = detail::workspace(data);
  const auto& joints = model.joints();
  const int n = model.nq();
  for (int i = 0; i < n; ++i) {
    const Vector6d& v = ws.v[i];
    ws.inertialForce[i] = ws.Ia[i] + crossForce(v, ws.Iv[i]);
    ws.compositeMomentum[i] = ws.Iv[i];
    const Vector3d& h = ws.wh[i];
    const Vector3d vl = lin(v);
    Eigen::Matrix3d X;  // Ī ω̂ + v hᵀ; B_i = X + Xᵀ − 2 (h·v) E
    X.noalias() = ws.wI[i] * skew(ang(v));
    X.noalias() += vl * h.transpose();
    Eigen::Matrix3d& B = ws.compositeB[i];
    B = X + X.transpose();
    B.diagonal().array() -= 2.0 * h.dot(vl);
  }
  // Subtree sums; ws.fext is reused for the subtree sum of the external wrenches.
  for (int i = n - 1; i >= 0; --i) {
    const int p = joints[i].parent;
    if (p == kWorld) continue;
    ws.inertialForce[p] += ws.inertialForce[i];
    ws.compositeMomentum[p] += ws.compositeMomentum[i];
    ws.compositeB[p] += ws.compositeB[i];
    ws.fext[p] += ws.fext[i];
  }
  for (int j = 0; j < n; ++j) {
    const Vector6d& S = ws.S[j];
    auto t = ws.tangentABG.col(j);
    t.segment<6>(0) = crossForce(S, ws.fext[j]);
    t.segment<6>(6) = applyInertia(ws.cm[j], ws.ch[j], ws.cI[j], S);
    t.segment<3>(12).setZero();
    t.segment<3>(15) = dPlusCrossAngular(ws.compositeMomentum[j], ws.compositeB[j], S);
  }
}

/// dr(j) += S_j·δW for j = body and its ancestors, δW = ws.tangentWrench[body] (then zeroed): the
/// wrench tangents of one direction when they all act on one body (out of line: the free models'
/// passes never call it).
__attribute__((noinline)) void addAncestorWrenchTangent(const Model& model, DataWorkspace& ws, int body, double* dr) {
  Vector6d& w = ws.tangentWrench[body];
  forAncestorRuns(model.topology(), body, true, [&](int s, int e) {
    for (int j = s; j <= e; ++j) dr[j] += ws.S[j].dot(w);
  });
  w.setZero();
}

/// One state direction, ∂/∂q_k or ∂/∂q̇_k, with q̈ and λ fixed: the columns −∂r (n) of the
/// equations of motion and −∂c (nc) of the constraint accelerations (negated: the right-hand
/// sides of the KKT solve) and, for q_k, ∂(A q̇)/∂q_k.
///
/// The subtree of k moves; with the closed-form body tangents (point_kinematics.hpp) the
/// tangent of its subtree wrench F_j (j in the subtree) is, with Ic, H, D the subtree sums of
/// I, I v and I crm(v) − crf(v) I, w = S_k × v_p and c = S_k × (a_p − g) − w × v_p:
///   ∂/∂q_k:  δF_j = S_k ×* F_j^inertial − Ic_j c + D_j w − w ×* H_j,   δS_j = S_k × S_j;
///   ∂/∂q̇_k:  δF_j = −D_j S_k − 2 Ic_j w + S_k ×* H_j.
/// Ancestors see δF_k; external wrench tangents are carried up their own paths. O(subtree+depth).
template <class ColR, class ColC, class ColH>
void tangentPass(const Model& model, Data& data, const Eigen::VectorXd& u, const Direction& dir, ColR&& dr,
                 ColC&& dc, ColH&& dhdot) {
  auto& ws = detail::workspace(data);
  const auto& joints = model.joints();
  const int k = dir.k;
  const Vector6d g = make(model.gravity(), Vector3d::Zero());
  // With (a × b)·f = −b·(a ×* f) and D symmetric, δτ_j = δS_jᵀ F_j + S_jᵀ δF_j becomes
  //   ∂/∂q_k:  δτ_j = −S_k·α_j − c·β_j + w·γ_j,     ∂/∂q̇_k:  δτ_j = −S_k·γ_j − 2 w·β_j
  // for j in the subtree (external wrench tangents are added below), and S_j·δF_k above it.
  // dr holds −δτ; in the subtree it is one dot product with column j of tangentABG = [α; β; γ].
  dr.setZero();
  Vector6d dFk;
  if (!dir.velocity) {
    const Vector6d c = crossMotion(dir.Sk, dir.aP - g) - crossMotion(dir.w, dir.vP);
    Eigen::Matrix<double, 18, 1> coef;
    coef << dir.Sk, c, -dir.w;
    for (int j = k; j < dir.end; ++j) dr(j) = coef.dot(ws.tangentABG.col(j));
    dFk = crossForce(dir.Sk, ws.inertialForce[k]) - applyInertia(ws.cm[k], ws.ch[k], ws.cI[k], c) +
          dMinusCross(ws.compositeMomentum[k], ws.compositeB[k], dir.w);
  } else {
    Eigen::Matrix<double, 12, 1> coef;  // against [β; γ]
    coef << 2.0 * dir.w, dir.Sk;
    for (int j = k; j < dir.end; ++j) dr(j) = coef.dot(ws.tangentABG.col(j).segment<12>(6));
    dFk = -dMinusCross(ws.compositeMomentum[k], ws.compositeB[k], dir.Sk) -
          2.0 * applyInertia(ws.cm[k], ws.ch[k], ws.cI[k], dir.w);
  }
  for (int j = joints[k].parent; j != kWorld; j = joints[j].parent) dr(j) = -ws.S[j].dot(dFk);

  if (!dir.velocity) {
    // External wrenches enter r with a minus sign; positions do not depend on q̇.
    // The wrench tangents are gathered per body, then carried to the root in one sweep (each
    // joint j sees the sum over its subtree), instead of walking up from every element.
    // With all of them on one body (a closing point on a chain, one fingertip) the sweep is
    // only S_j·δW on that body's ancestors, without the carrying.
    int hi = -1, lo = model.nq(), first = -1;
    bool several = false;
    forceTangents(model, data, dir, u, [&](int joint, const Vector6d& dW) {
      if (joint == kWorld) return;
      ws.tangentWrench[joint] += dW;
      if (first < 0) first = joint;
      else if (joint != first) several = true;
      hi = std::max(hi, joint);
      lo = std::min(lo, model.topology().treeRoot[joint]);
    });
    if (hi >= 0) {
      if (!several) {
        addAncestorWrenchTangent(model, ws, first, &dr(0));
      } else {
        for (int j = hi; j >= lo; --j) {
          Vector6d& w = ws.tangentWrench[j];
          dr(j) += ws.S[j].dot(w);
          if (joints[j].parent != kWorld) ws.tangentWrench[joints[j].parent] += w;
          w.setZero();
        }
      }
    }
  }
  // Forces on coordinates (springs, damping): r contains −Q.
  forEachForceElement(model, [&](auto kind, const auto& e, size_t) {
    decltype(kind)::generalizedForceTangent(dir, e, [&](int i, double dQ) { dr(i) += dQ; });
  });

  constraintTangents(model, data, dir, [&](int r, const ConstraintEval& e) {
    dc(r) = -e.c;
    if (!dir.velocity) dhdot(r) = e.hdot;
  });
}

}  // namespace
}  // namespace detail

DynamicsStatus computeLinearization(const Model& model, Data& data, const Eigen::VectorXd& q,
                                    const Eigen::VectorXd& dq, const Eigen::VectorXd& u) {
  auto& ws = detail::workspace(data);
  const int n = model.nq(), m = model.nu(), nc = model.nc();
  computeDynamics(model, data, q, dq, u);  // and the factor of M that invertMass uses below
  // Near-singular or inconsistent constraints still give finite numbers, flagged by the status.
  if (!detail::solvable(data.status)) return data.status;

  // Nominal pass at the solved q̈ and λ: subtree wrenches F_i, I v, I (a − g).
  detail::updateAccelerations(model, data, dq, data.qdd);
  detail::accumulateExternalWrenches(model, data, u, true, true, &data.lambda);
  detail::inverseDynamicsPass(model, data, ws.tmpN);
  detail::inputMatrixPass(model, data);

  detail::compositePass(model, data);  // (the tendons' path points were stored by the passes above)
  // Columns of −∂r/∂[q, q̇, u] and −∂c/∂[q, q̇, u]; c does not depend on u at fixed q̈.
  for (int k = 0; k < n; ++k) {
    detail::tangentPass(model, data, u, detail::makeDirection(model, data, k, false), ws.rhsX.col(k),
                        ws.crhsX.col(k), data.constraintVelocityJacobian.col(k));
    detail::tangentPass(model, data, u, detail::makeDirection(model, data, k, true), ws.rhsX.col(n + k),
                        ws.crhsX.col(n + k), data.constraintVelocityJacobian.col(k));
  }
  ws.crhsX.rightCols(m).setZero();
  // ∂q̈/∂[q, q̇, u] = M⁻¹ R block by block with the explicit block-diagonal M⁻¹ (its columns are
  // themselves wanted: an input that is a force on one coordinate has M⁻¹ e_c as its column of
  // ∂q̈/∂u), written straight into the results, then corrected for the constraints.
  detail::invertMass(model, data);
  detail::applyMassInverse(model, data, ws.rhsX.leftCols(n), data.dqdd_dq);
  detail::applyMassInverse(model, data, ws.rhsX.middleCols(n, n), data.dqdd_ddq);
  for (int k = 0; k < m;) {
    const int c = model.topology().unitInputConfig[k];
    if (c >= 0) {
      data.dqdd_du.col(k) = model.topology().unitInputGain[k] * ws.massInverse.col(c);
      ++k;
      continue;
    }
    int e = k + 1;  // a run of inputs with general columns ∂Q/∂u_k
    while (e < m && model.topology().unitInputConfig[e] < 0) ++e;
    detail::applyMassInverse(model, data, data.inputMatrix.middleCols(k, e - k), data.dqdd_du.middleCols(k, e - k));
    k = e;
  }
  if (nc > 0) {
    detail::correctForConstraints(model, data, data.dqdd_dq, ws.crhsX.leftCols(n));
    detail::correctForConstraints(model, data, data.dqdd_ddq, ws.crhsX.middleCols(n, n));
    if (m > 0) detail::correctForConstraints(model, data, data.dqdd_du, ws.crhsX.rightCols(m));
  }

  // A sum is NaN or ±Inf if any term is (or if finite terms overflow, which is no result either).
  if (detail::solvable(data.status) &&
      !(std::isfinite(data.dqdd_dq.sum() + data.dqdd_ddq.sum() + data.dqdd_du.sum()) && std::isfinite(ws.crhsX.sum()))) {
    data.status.code = DynamicsStatus::Code::kNonFinite;
    data.status.message = "linearization produced non-finite values";
  }
  if (nc > 0) data.dlambda_dx = ws.crhsX;
  // The top rows of A = [[0, I], ·] and B = [[0], ·] were set when Data was built.
  data.A.bottomLeftCorner(n, n) = data.dqdd_dq;
  data.A.bottomRightCorner(n, n) = data.dqdd_ddq;
  // No inputs: B is 2n×0 with no storage, and a block of it would offset a null pointer (UB).
  if (m > 0) data.B.bottomRows(n) = data.dqdd_du;
  return data.status;
}

ImplicitDynamics::ImplicitDynamics(const Model& model)
    : r(Eigen::VectorXd::Zero(model.nq())),
      c(Eigen::VectorXd::Zero(model.nc())),
      dr_dx(Eigen::MatrixXd::Zero(model.nq(), 2 * model.nq())),
      dc_dx(Eigen::MatrixXd::Zero(model.nc(), 2 * model.nq())) {}

DynamicsStatus computeImplicitDynamics(const Model& model, Data& data, const Eigen::VectorXd& q,
                                       const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd,
                                       const Eigen::VectorXd& u, const Eigen::VectorXd& lambda,
                                       ImplicitDynamics& out) {
  auto& ws = detail::workspace(data);
  using namespace detail;
  const int n = model.nq(), nc = model.nc();
  checkSize(q, n, "computeImplicitDynamics: q");
  checkSize(dq, n, "computeImplicitDynamics: dq");
  checkSize(qdd, n, "computeImplicitDynamics: qdd");
  checkSize(u, model.nu(), "computeImplicitDynamics: u");
  checkSize(lambda, nc, "computeImplicitDynamics: lambda");
  if (out.r.size() != n || out.c.size() != nc || out.dr_dx.rows() != n || out.dr_dx.cols() != 2 * n ||
      out.dc_dx.rows() != nc || out.dc_dx.cols() != 2 * n)
    throw std::invalid_argument("computeImplicitDynamics: out is not sized for this model (ImplicitDynamics(model))");
  data.status = DynamicsStatus{};
  if (!inputsAreFinite(model, data, q, dq, u)) return data.status;
  if (!qdd.allFinite() || !lambda.allFinite()) {
    data.status.code = DynamicsStatus::Code::kNonFinite;
    data.status.message = std::string("computeImplicitDynamics: non-finite ") + (qdd.allFinite() ? "lambda" : "qdd");
    return data.status;
  }
  // The data members at (q, q̇, u), as computeDynamics leaves them (b and Ȧ q̇ at q̈ = 0).
  updateJoints(model, data, q, dq);
  massMatrixPass(model, data);
  ws.qddZero.setZero();
  updateAccelerations(model, data, dq, ws.qddZero);
  accumulateExternalWrenches(model, data, u, true, true, nullptr);
  inverseDynamicsPass(model, data, data.bias);
  ws.tmpN.setZero();
  addConfigurationForces(model, q, dq, u, ws.tmpN);
  data.bias -= ws.tmpN;
  evaluateConstraints(model, data, &data.constraintValue, nullptr, &data.constraintDrift, &data.constraintJacobian);
  // The nominal pass at the given q̈ and λ: r = ID(q, q̇, q̈) − Q_wrenches − Aᵀλ − Q_config.
  data.qdd = qdd;
  data.lambda = lambda;
  updateAccelerations(model, data, dq, data.qdd);
  accumulateExternalWrenches(model, data, u, true, true, nc > 0 ? &data.lambda : nullptr);
  inverseDynamicsPass(model, data, out.r);
  ws.tmpN.setZero();  // (the passes above use it as scratch)
  addConfigurationForces(model, q, dq, u, ws.tmpN);
  out.r -= ws.tmpN;
  inputMatrixPass(model, data);
  out.c = data.constraintDrift;
  if (nc > 0) out.c.noalias() += data.constraintJacobian * qdd;
  compositePass(model, data);
  for (int k = 0; k < n; ++k) {
    tangentPass(model, data, u, makeDirection(model, data, k, false), ws.rhsX.col(k), ws.crhsX.col(k),
                data.constraintVelocityJacobian.col(k));
    tangentPass(model, data, u, makeDirection(model, data, k, true), ws.rhsX.col(n + k), ws.crhsX.col(n + k),
                data.constraintVelocityJacobian.col(k));
  }
  out.dr_dx = -ws.rhsX.leftCols(2 * n);
  if (nc > 0) out.dc_dx = -ws.crhsX.leftCols(2 * n);
  if (!(std::isfinite(out.r.sum() + out.dr_dx.sum()) && std::isfinite(out.c.sum() + out.dc_dx.sum()))) {
    data.status.code = DynamicsStatus::Code::kNonFinite;
    data.status.message = "computeImplicitDynamics: non-finite residual or derivatives";
    appendState(model, q, dq, data.status.message);
  }
  return data.status;
}

int computeConstraintTangentBasis(const Model& model, Data& data) {
  auto& ws = detail::workspace(data);
  const int n = model.nq(), nc = model.nc();
  if (nc == 0) {
    data.tangentBasis.setIdentity(2 * n, 2 * n);
    data.reducedA = data.A;
    data.reducedB = data.B;
    return 2 * n;
  }
  // ∂Φ/∂x with Φ = [h_holonomic(q); A(q) q̇].
  Eigen::MatrixXd& J = ws.constraintStateJacobian;
  J.setZero();
  int row = 0;
  for (int r = 0; r < nc; ++r)
    if (model.constraints()[r].holonomic()) J.row(row++).head(n) = data.constraintJacobian.row(r);
  for (int r = 0; r < nc; ++r, ++row) {
    J.row(row).head(n) = data.constraintVelocityJacobian.row(r);
    J.row(row).tail(n) = data.constraintJacobian.row(r);
  }
  ws.basisQR.compute(J.transpose());
  const int rank = static_cast<int>(ws.basisQR.rank());
  ws.basisQR.householderQ().evalTo(ws.basisQ, ws.basisWorkspace);  // no allocation
  const int d = 2 * n - rank;
  data.tangentBasis = ws.basisQ.rightCols(d);
  Eigen::Ref<Eigen::MatrixXd> AT = ws.basisWorkMatrix.leftCols(d);
  AT.noalias() = data.A * data.tangentBasis;
  data.reducedA.noalias() = data.tangentBasis.transpose() * AT;
  data.reducedB.noalias() = data.tangentBasis.transpose() * data.B;
  return d;
}

}  // namespace trellis
