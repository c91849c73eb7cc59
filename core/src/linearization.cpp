// Exact linearization by tangent Newton-Euler passes (see linearization.hpp for the formulation).
#include "trellis/core/linearization.hpp"

#include "trellis/core/dynamics.hpp"
#include "internal.hpp"
#include "point_kinematics.hpp"

namespace trellis {
namespace detail {
namespace {

/// Tangents of the force elements that move with q (springs, tendons, body wrenches, constraint
/// forces at fixed λ) for the current body tangents; only elements touching [first, last) move.
void forceTangents(const Model& model, Data& data, const Eigen::VectorXd& u, int first, int last) {
  auto moves = [&](int joint) { return joint >= first && joint < last; };
  auto segment = [&](const BodyPoint& a, const BodyPoint& b, auto tauOfL, auto dtauOfL) {
    if (!moves(a.joint) && !moves(b.joint)) return;
    const PointKin ka{pointPosition(data, a)}, kb{pointPosition(data, b)};
    const Vector3d dpa = pointTangent(data, a.joint, ka).p, dpb = pointTangent(data, b.joint, kb).p;
    const Vector3d d = kb.p - ka.p, dd = dpb - dpa;
    const double L = d.norm();
    const double tau = tauOfL(L), dL = d.dot(dd) / L;
    const Vector3d f = tau * d, df = dtauOfL(L) * dL * d + tau * dd;
    addBodyWrenchTangent(data, a.joint, forceAtTangent(ka.p, dpa, f, df));
    addBodyWrenchTangent(data, b.joint, forceAtTangent(kb.p, dpb, -f, -df));
  };
  for (const LinearSpring& s : model.linearSprings())
    segment(s.a, s.b, [&](double L) { return springTensionPerLength(s, L); },
            [&](double L) { return springTensionPerLengthDerivative(s, L); });
  for (const Tendon& t : model.tendons()) {
    const double T = u[t.input];
    for (size_t k = 0; k + 1 < t.path.size(); ++k)
      segment(t.path[k], t.path[k + 1], [&](double L) { return T / L; }, [&](double L) { return -T / (L * L); });
  }
  for (const BodyWrench& bw : model.bodyWrenches()) {
    if (!moves(bw.joint)) continue;
    Vector6d w;
    for (int k = 0; k < 6; ++k) w[k] = bw.input[k] >= 0 ? u[bw.input[k]] : bw.constant[k];
    // A wrench fixed in a body is carried along rigidly: δW = δθ ×* W.
    addBodyWrenchTangent(data, bw.joint, crossForce(data.dTheta[bw.joint], bodyWrenchWorld(data, bw, w)));
  }
  const auto& cs = model.constraints();
  for (int r = 0; r < model.nc(); ++r)
    if (moves(cs[r].a.joint) || moves(cs[r].b.joint)) addConstraintWrenchTangents(data, cs[r], data.lambda[r]);
}

/// One state direction: x_dir = q_k (velocity = false) or q̇_k (velocity = true). Writes the
/// column ∂r/∂x_dir into `dr` (n), ∂c/∂x_dir into `dc` (nc) and, for q_k, ∂(A q̇)/∂q_k into
/// `dhdot` (nc). Body tangents are nonzero only on the subtree of joint k.
template <class ColR, class ColC, class ColH>
void tangentPass(const Model& model, Data& data, const Eigen::VectorXd& dq, const Eigen::VectorXd& u, int k,
                 bool velocity, ColR&& dr, ColC&& dc, ColH&& dhdot) {
  const auto& joints = model.joints();
  const int n = model.nq();
  const int end = joints[k].subtreeEnd;
  const Vector6d g = make(model.gravity(), Vector3d::Zero());

  // Forward: δθ, δS, δv, δa on the subtree (zero elsewhere).
  for (int i = k; i < end; ++i) {
    const int p = joints[i].parent;
    const bool root = (i == k);
    const Vector6d dvParent = root ? Vector6d::Zero() : data.dv[p];
    const Vector6d daParent = root ? Vector6d::Zero() : data.da[p];
    if (!velocity) {
      // The subtree turns rigidly with q_k: δθ_i = S_k, δS_i = S_k × S_i.
      data.dTheta[i] = data.S[k];
      data.dS[i] = crossMotion(data.S[k], data.S[i]);
      data.dv[i] = dvParent + data.dS[i] * dq[i];
      data.da[i] = daParent + data.dS[i] * data.qdd[i] + crossMotion(data.dv[i], data.S[i]) * dq[i] +
                   crossMotion(data.v[i], data.dS[i]) * dq[i];
    } else {
      data.dv[i] = root ? Vector6d(data.S[k]) : dvParent;
      data.da[i] = daParent + crossMotion(data.dv[i], data.S[i]) * dq[i];
      if (root) data.da[i] += crossMotion(data.v[i], data.S[i]);
    }
  }

  // External wrench tangents (positions do not depend on q̇).
  for (auto& w : data.dfext) w.setZero();
  if (!velocity) forceTangents(model, data, u, k, end);

  // Inertial wrench tangents on the subtree: δ(I x) = δθ ×* (I x) − I (δθ × x) + I δx.
  for (int i = 0; i < n; ++i) data.df[i] = -data.dfext[i];
  for (int i = k; i < end; ++i) {
    const double m = data.wm[i];
    const Vector3d& h = data.wh[i];
    const Eigen::Matrix3d& I = data.wI[i];
    const Vector6d& v = data.v[i];
    Vector6d df = applyInertia(m, h, I, data.da[i]) + crossForce(data.dv[i], data.Iv[i]);
    Vector6d dIv = applyInertia(m, h, I, data.dv[i]);
    if (!velocity) {
      const Vector6d& th = data.dTheta[i];
      df += crossForce(th, data.Ia[i]) - applyInertia(m, h, I, crossMotion(th, data.a[i] - g));
      dIv += crossForce(th, data.Iv[i]) - applyInertia(m, h, I, crossMotion(th, v));
    }
    data.df[i] += df + crossForce(v, dIv);
  }

  // Backward: δτ_i = δS_iᵀ F_i + S_iᵀ δF_i.
  for (int i = n - 1; i >= 0; --i) {
    dr(i) = data.S[i].dot(data.df[i]);
    if (!velocity && i >= k && i < end) dr(i) += data.dS[i].dot(data.f[i]);
    if (joints[i].parent != kWorld) data.df[joints[i].parent] += data.df[i];
  }
  // Configuration-level elements: r contains −Q_config.
  if (!velocity) {
    for (const ConfigSpring& s : model.configSprings())
      if (s.config == k) dr(k) += s.k;
  } else {
    dr(k) += model.damping()[k];
  }

  // Constraint residual tangents.
  const auto& cs = model.constraints();
  for (int r = 0; r < model.nc(); ++r) {
    const Constraint& c = cs[r];
    const bool touched = (c.a.joint >= k && c.a.joint < end) || (c.b.joint >= k && c.b.joint < end);
    if (!touched) {
      dc(r) = 0.0;
      if (!velocity) dhdot(r) = 0.0;
      continue;
    }
    const ConstraintEval e = constraintTangent(data, c);
    dc(r) = e.c;
    if (!velocity) dhdot(r) = e.hdot;
  }

  // Leave the tangents zero outside the next direction's subtree.
  for (int i = k; i < end; ++i) {
    data.dTheta[i].setZero();
    data.dS[i].setZero();
    data.dv[i].setZero();
    data.da[i].setZero();
  }
}

}  // namespace
}  // namespace detail

DynamicsStatus computeLinearization(const Model& model, Data& data, const Eigen::VectorXd& q,
                                    const Eigen::VectorXd& dq, const Eigen::VectorXd& u) {
  const int n = model.nq(), m = model.nu(), nc = model.nc();
  computeDynamics(model, data, q, dq, u);
  if (!data.status.ok()) return data.status;

  // Nominal pass at the solved q̈ and λ: subtree wrenches F_i, I v, I (a − g).
  detail::updateAccelerations(model, data, dq, data.qdd);
  detail::accumulateExternalWrenches(model, data, u, true, true, &data.lambda);
  detail::inverseDynamicsPass(model, data, data.tmpN);
  detail::inputMatrixPass(model, data);

  for (int i = 0; i < n; ++i) {
    data.dTheta[i].setZero();
    data.dS[i].setZero();
    data.dv[i].setZero();
    data.da[i].setZero();
  }
  // Columns of −∂r/∂[q, q̇, u] and −∂c/∂[q, q̇, u]; c does not depend on u at fixed q̈.
  for (int k = 0; k < n; ++k) {
    detail::tangentPass(model, data, dq, u, k, false, data.rhsX.col(k), data.crhsX.col(k),
                        data.constraintVelocityJacobian.col(k));
    detail::tangentPass(model, data, dq, u, k, true, data.rhsX.col(n + k), data.crhsX.col(n + k),
                        data.constraintVelocityJacobian.col(k));
  }
  data.rhsX.leftCols(2 * n) *= -1.0;
  data.crhsX.leftCols(2 * n) *= -1.0;
  data.rhsX.rightCols(m) = data.inputMatrix;
  data.crhsX.rightCols(m).setZero();
  detail::solveKkt(model, data, data.rhsX, data.crhsX);

  data.dqdd_dq = data.rhsX.leftCols(n);
  data.dqdd_ddq = data.rhsX.middleCols(n, n);
  data.dqdd_du = data.rhsX.rightCols(m);
  if (nc > 0) data.dlambda_dx = data.crhsX;
  data.A.setZero();
  data.A.topRightCorner(n, n).setIdentity();
  data.A.bottomLeftCorner(n, n) = data.dqdd_dq;
  data.A.bottomRightCorner(n, n) = data.dqdd_ddq;
  data.B.topRows(n).setZero();
  data.B.bottomRows(n) = data.dqdd_du;
  if (!(data.A.allFinite() && data.B.allFinite())) {
    data.status.code = DynamicsStatus::Code::kNonFinite;
    data.status.message = "linearization produced non-finite values";
  }
  return data.status;
}

int computeConstraintTangentBasis(const Model& model, Data& data) {
  const int n = model.nq(), nc = model.nc();
  if (nc == 0) {
    data.tangentBasis.setIdentity(2 * n, 2 * n);
    data.reducedA = data.A;
    data.reducedB = data.B;
    return 2 * n;
  }
  // ∂Φ/∂x with Φ = [h_holonomic(q); A(q) q̇].
  Eigen::MatrixXd& J = data.constraintStateJacobian;
  J.setZero();
  int row = 0;
  for (int r = 0; r < nc; ++r)
    if (model.constraints()[r].holonomic()) J.row(row++).head(n) = data.constraintJacobian.row(r);
  for (int r = 0; r < nc; ++r, ++row) {
    J.row(row).head(n) = data.constraintVelocityJacobian.row(r);
    J.row(row).tail(n) = data.constraintJacobian.row(r);
  }
  data.basisQR.compute(J.transpose());
  const int rank = static_cast<int>(data.basisQR.rank());
  data.basisQ = data.basisQR.matrixQ();
  const int d = 2 * n - rank;
  data.tangentBasis = data.basisQ.rightCols(d);
  data.reducedA.noalias() = data.tangentBasis.transpose() * data.A * data.tangentBasis;
  data.reducedB.noalias() = data.tangentBasis.transpose() * data.B;
  return d;
}

}  // namespace trellis
