// Mass matrix (composite rigid bodies), Newton-Euler bias forces, constraints and the KKT solve.
#include "trellis/core/dynamics.hpp"

#include "internal.hpp"
#include "mass_factor.hpp"
#include "packs.hpp"
#include "constraint_kinds.hpp"
#include "force_elements.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <type_traits>
#include <string>

namespace trellis {

std::string DynamicsStatus::describe() const {
  std::string line = Status<DynamicsCode>::describe();
  if (constraintRank > 0 || !ok())
    line += " (constraint rank " + std::to_string(constraintRank) + ", conditioning " +
            formatStatusNumber(constraintConditioning) + ")";
  return line;
}

std::string DynamicsStatus::json() const {
  detail::ReportJson j = detail::statusJson(static_cast<const Status<DynamicsCode>&>(*this));
  j["constraint_rank"] = constraintRank;
  j["constraint_conditioning"] = detail::toJson(constraintConditioning);
  return j.dump();
}
namespace detail {

using namespace spatial;

void updateAccelerations(const Model& model, Data& data, const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd) {
  auto& ws = detail::workspace(data);
  const auto& joints = model.joints();
  if (&qdd != &ws.qddOfA) ws.qddOfA = qdd;
  for (int i = 0; i < model.nq(); ++i) {
    const int p = joints[i].parent;
    // a_i = a_p + S_i q̈_i + Ṡ_i q̇_i with Ṡ_i = v_i × S_i (S_i moves with body i).
    ws.a[i] = ws.S[i] * qdd[i] + crossMotion(ws.v[i], ws.S[i]) * dq[i];
    if (p != kWorld) ws.a[i] += ws.a[p];
  }
}

namespace {

/// x as printf's "%.6g" (std::to_chars with a precision is specified as printf's conversion),
/// without printf's cost: a redundant or degenerate row is reported at every call, with the state.
void appendNumber(std::string& out, double x) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, x, std::chars_format::general, 6);
  out.append(buf, res.ptr);
}
std::string formatNumber(double x) {
  std::string s;
  appendNumber(s, x);
  return s;
}

}  // namespace

void accumulateExternalWrenches(const Model& model, Data& data, const Eigen::VectorXd& u,
                                bool conservative, bool nonConservative, const Eigen::VectorXd* lambda) {
  auto& ws = detail::workspace(data);
  for (auto& w : ws.fext) w.setZero();
  const auto add = [&](int joint, const Vector6d& w) { addBodyWrench(ws, joint, w); };
  forEachForceElement(model, [&](auto kind, const auto& e, size_t i) {
    if (decltype(kind)::conservative ? conservative : nonConservative) decltype(kind)::wrenches(model, data, e, i, u, add);
  });
  if (lambda) {
    const auto& cs = model.constraints();
    for (int r = 0; r < model.nc(); ++r) addConstraintWrenches(data, cs[r], (*lambda)[r]);
  }
}

void inverseDynamicsPass(const Model& model, Data& data, Eigen::VectorXd& tau) {
  auto& ws = detail::workspace(data);
  const auto& joints = model.joints();
  const int n = model.nq();
  const Vector6d g = make(model.gravity(), Vector3d::Zero());
  for (int i = 0; i < n; ++i) {
    ws.Ia[i] = applyInertia(ws.wm[i], ws.wh[i], ws.wI[i], ws.a[i] - g);
    ws.Iv[i] = applyInertia(ws.wm[i], ws.wh[i], ws.wI[i], ws.v[i]);
    ws.f[i] = ws.Ia[i] + crossForce(ws.v[i], ws.Iv[i]) - ws.fext[i];
  }
  for (int i = n - 1; i >= 0; --i) {
    tau[i] = ws.S[i].dot(ws.f[i]);
    if (joints[i].parent != kWorld) ws.f[joints[i].parent] += ws.f[i];
  }
}

void addConfigurationForces(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                            const Eigen::VectorXd& u, Eigen::VectorXd& Q) {
  forEachForceElement(model, [&](auto kind, const auto& e, size_t) { decltype(kind)::generalizedForce(q, dq, u, e, Q); });
}

namespace {
/// evaluateConstraints for the consecutive rows from row r on one pair of points (Kind::samePair;
/// at most maxRows of them): the points and their gradients once for all rows; row k's scale is
/// Kind's row factor (1 for a point row, ‖n_a,k‖ for a point-on-plane row) times the pair's
/// ‖Σ_sides ‖∂p_b/∂q_j‖‖. Returns the row after them.
template <class Kind>
inline int evaluatePairRows(const Model& model, Data& data, int r, int maxRows, Eigen::VectorXd* h,
                            Eigen::VectorXd* hdot, Eigen::VectorXd* c, Eigen::MatrixXd* A) {
  auto& ws = detail::workspace(data);
  const auto& cs = model.constraints();
  int end = r + 1;
  while (end < model.nc() && end - r < maxRows && Kind::samePair(cs[r], cs[end])) ++end;
  Kind::pairValues(data, &cs[r], end - r, [&](int k, const ConstraintEval& e) {
    if (h) (*h)[r + k] = e.h;
    if (hdot) (*hdot)[r + k] = e.hdot;
    if (c) (*c)[r + k] = e.c;
  });
  if (A) {
    ws.tmpN.setZero();
    Kind::addPairJacobianRows(model, data, &cs[r], end - r, r, *A, ws.tmpN);
    const double scale = ws.tmpN.norm();
    for (int k = r; k < end; ++k)
      ws.constraintScale[k] = std::is_same_v<Kind, PointOnPlaneKind> ? cs[k].direction.norm() * scale : scale;
  }
  return end;
}
/// The contact rows (up to three point-on-plane rows on one pair) out of line: inlined, they cost
/// the models without contacts ~100 instructions per call (callgrind, planar 20-chain).
__attribute__((noinline)) int evaluateContactRows(const Model& model, Data& data, int r, Eigen::VectorXd* h,
                                                  Eigen::VectorXd* hdot, Eigen::VectorXd* c, Eigen::MatrixXd* A) {
  return evaluatePairRows<PointOnPlaneKind>(model, data, r, PointOnPlaneKind::kContactRows, h, hdot, c, A);
}
}  // namespace

void evaluateConstraints(const Model& model, Data& data, Eigen::VectorXd* h, Eigen::VectorXd* hdot,
                         Eigen::VectorXd* c, Eigen::MatrixXd* A) {
  auto& ws = detail::workspace(data);
  const auto& cs = model.constraints();
  if (A) A->setZero();
  for (int r = 0; r < model.nc(); ++r) {
    if (cs[r].type == ConstraintType::kPoint) {
      // Consecutive rows on one point pair: the points and their gradients once for all rows.
      r = evaluatePairRows<PointKind>(model, data, r, model.nc(), h, hdot, c, A) - 1;
      continue;
    }
    if (cs[r].type == ConstraintType::kPointOnPlane) {
      r = evaluateContactRows(model, data, r, h, hdot, c, A) - 1;
      continue;
    }
    const ConstraintEval e = evaluateConstraint(data, cs[r]);
    if (h) (*h)[r] = e.h;
    if (hdot) (*hdot)[r] = e.hdot;
    if (c) (*c)[r] = e.c;
    if (A) {
      // Kinematic conditioning of the row: ‖A_r‖ over the norm it would have if every joint moved
      // the constraint's points along its gradient; → 0 at singular configurations.
      ws.tmpN.setZero();
      addConstraintJacobianRow(model, data, cs[r], A->row(r), &ws.tmpN);
      ws.constraintScale[r] = ws.tmpN.norm();
    }
  }
}

namespace {
/// out(k, l) = a_k · u_l over the coordinate ranges cut[0 … nCut) for the K columns a_k = a + k lda
/// and the L columns u_l = u + l ldu, two coordinates per step: the K + L columns share their
/// loads (a contact's 3 rows against another's in 9 running sums).
template <int K, int L>
void crossDots(const double* a, Eigen::Index lda, const double* u, Eigen::Index ldu, const int (*cut)[2], int nCut,
               double (*out)[3]) {
  Pack acc[K][L];
  double tail[K][L];
  for (int k = 0; k < K; ++k)
    for (int l = 0; l < L; ++l) {
      acc[k][l] = Pack::Zero();
      tail[k][l] = 0.0;
    }
  for (int c = 0; c < nCut; ++c) {
    int i = cut[c][0];
    for (; i + 1 < cut[c][1]; i += 2) {
      Pack ak[K];
      for (int k = 0; k < K; ++k) ak[k] = loadPack(a + k * lda + i);
      for (int l = 0; l < L; ++l) {
        const Pack ul = loadPack(u + l * ldu + i);
        for (int k = 0; k < K; ++k) acc[k][l] += ak[k] * ul;
      }
    }
    if (i < cut[c][1])
      for (int k = 0; k < K; ++k)
        for (int l = 0; l < L; ++l) tail[k][l] += a[k * lda + i] * u[l * ldu + i];
  }
  for (int k = 0; k < K; ++k)
    for (int l = 0; l < L; ++l) out[k][l] = acc[k][l][0] + acc[k][l][1] + tail[k][l];
}
/// crossDots for K, L in 1 … 3 at run time.
void crossDots(int k, int l, const double* a, Eigen::Index lda, const double* u, Eigen::Index ldu, const int (*cut)[2],
               int nCut, double (*out)[3]) {
  switch (3 * (k - 1) + l - 1) {
    case 0: crossDots<1, 1>(a, lda, u, ldu, cut, nCut, out); break;
    case 1: crossDots<1, 2>(a, lda, u, ldu, cut, nCut, out); break;
    case 2: crossDots<1, 3>(a, lda, u, ldu, cut, nCut, out); break;
    case 3: crossDots<2, 1>(a, lda, u, ldu, cut, nCut, out); break;
    case 4: crossDots<2, 2>(a, lda, u, ldu, cut, nCut, out); break;
    case 5: crossDots<2, 3>(a, lda, u, ldu, cut, nCut, out); break;
    case 6: crossDots<3, 1>(a, lda, u, ldu, cut, nCut, out); break;
    case 7: crossDots<3, 2>(a, lda, u, ldu, cut, nCut, out); break;
    default: crossDots<3, 3>(a, lda, u, ldu, cut, nCut, out); break;
  }
}
/// S = L Lᵀ for the symmetric positive definite S (its lower triangle read), L into the lower
/// triangle of F and Lᵀ into its strict upper one (each row of L then contiguous too: the run
/// kernel's forward substitution reads it in place), left-looking column by column,
/// two earlier columns per pass: L(k:, k) = (S(k:, k) − Σ_{t<k} L(k, t) L(k:, t)) / L(k, k).
/// False at a pivot not above 0 (or NaN): S is not numerically positive definite. Eigen's LLT
/// spent ~6× the instructions on the hand with a ball's 15 rows (the set-up of its blocked and
/// matrix–vector kernels per column, and an l1 norm only its rcond() reads).
bool choleskyLower(const Eigen::MatrixXd& S, Eigen::MatrixXd& F) {
  const int n = static_cast<int>(S.rows());
  for (int k = 0; k < n; ++k) {
    double* y = &F(k, k);
    const double* s = &S(k, k);
    const int len = n - k;
    int i = 0;
    for (; i + 1 < len; i += 2) storePack(y + i, loadPack(s + i));
    if (i < len) y[i] = s[i];
    int t = 0;
    for (; t + 1 < k; t += 2) subtractScaled2(y, &F(k, t), F(k, t), &F(k, t + 1), F(k, t + 1), len);
    if (t < k) subtractScaled(y, &F(k, t), F(k, t), len);
    const double d = y[0];
    if (!(d > 0.0)) return false;
    const double l = std::sqrt(d), r = 1.0 / l;
    const Pack rv = Pack::Constant(r);
    for (i = 1; i + 1 < len; i += 2) storePack(y + i, loadPack(y + i) * rv);
    if (i < len) y[i] *= r;
    y[0] = l;
    for (i = 1; i < len; ++i) F(k, k + i) = y[i];
  }
  return true;
}
}  // namespace

void factorizeKkt(const Model& model, Data& data) {
  auto& ws = detail::workspace(data);
  DynamicsStatus& st = data.status;
  st.code = DynamicsStatus::Code::kOk;
  st.message.clear();
  const int n = model.nq(), nc = model.nc();
  st.constraintRank = nc;
  st.constraintConditioning = 1.0;
  ws.schurUsesPinv = false;
  ws.zeroRowHolds = false;
  if (!std::isfinite(data.M.sum())) {  // NaN or ±Inf if any entry is
    st.code = DynamicsStatus::Code::kNonFinite;
    st.message = "mass matrix has non-finite entries";
    return;
  }
  if (n == 0) return;  // nothing moves: q̈ and the linearization are empty
  const double scale = std::max(data.M.diagonal().maxCoeff(), std::numeric_limits<double>::min());
  // The tree factor M = Lᵀ D L (mass_factor.hpp); a pivot D_i ≤ 1e-14 max M_ii means M is
  // singular to working precision.
  if (factorMass(model, data, 1e-14 * scale) >= 0) {
    st.code = DynamicsStatus::Code::kSingularMassMatrix;
    st.message = "mass matrix is not positive definite";
    for (int i = 0; i < n; ++i)
      if (data.M(i, i) <= 1e-14 * scale) {
        st.message += ": configuration '" + model.configNames()[i] + "' moves no mass or inertia";
        break;
      }
    return;
  }
  if (nc == 0) return;
  // Two separate questions. (1) Is a row degenerate, or close to it? Its kinematic conditioning
  // κ_r = ‖A_r‖ / s_r compares it with the norm it has when its gradients have their natural size
  // (s_r from addConstraintJacobianRow: e.g. 2ℓ for a distance ℓ, 1 for a point axis), so it is
  // independent of the units and scale of h and → 0 both at a singular configuration and when the
  // gradient itself vanishes (a distance constraint whose points coincide). s_r = 0: no joint
  // moves the row's points at all. (2) Are the rows dependent? The Schur complement scaled to
  // unit diagonal, Ŝ = D A M⁻¹ Aᵀ D, answers that independently of how each h is scaled.
  // Aᵀ, contiguous (ws.jacobianT: zero off each row's segments, which the model fixes).
  const ModelTopology& topo = model.topology();
  for (int r = 0; r < nc; ++r) {
    auto at = ws.jacobianT.col(r);
    forRowSegments(topo, ws, r, [&](int lo, int hi) {
      at.segment(lo, hi - lo) = data.constraintJacobian.row(r).segment(lo, hi - lo).transpose();
    });
  }
  double kinematic = 1.0;
  int worstRow = 0;
  for (int r = 0; r < nc; ++r) {
    const double s = ws.constraintScale[r];
    const double k = s > 0 ? ws.jacobianT.col(r).norm() / s : 0.0;  // ‖A_r‖
    if (k < kinematic) {
      kinematic = k;
      worstRow = r;
    }
  }
  // Relative errors of the constraint forces and their derivatives grow like eps / κ²; below
  // κ = 1e-5 they may exceed 1e-6 and the row is reported as degenerate (finite results, no ok).
  const auto reportDegenerate = [&] {
    st.code = DynamicsStatus::Code::kSingularConstraints;
    // An exactly zero row that holds (h_r = 0 and Ȧ_r q̇ = 0: it constrains nothing at this state,
    // 0·q̈ = 0), when every zero row holds, is dropped exactly: q̈ and the linearization are the
    // other rows', λ_r = 0. Its report does not depend on the state, so it is formatted once per
    // row and copied afterwards.
    const auto zeroRowsHold = [&] {
      for (int r = 0; r < nc; ++r)
        if (data.constraintJacobian.row(r).squaredNorm() == 0.0 &&
            (data.constraintValue[r] != 0.0 || data.constraintDrift[r] != 0.0))
          return false;
      return true;
    };
    if (kinematic == 0.0 && data.constraintJacobian.row(worstRow).squaredNorm() == 0.0 && zeroRowsHold()) {
      if (ws.zeroRowMessageRow != worstRow) {
        ws.zeroRowMessage = "degenerate constraint row " + std::to_string(worstRow) + " (" +
                            model.constraints()[worstRow].name +
                            "): its gradient is zero and the row holds (h = 0, Ȧ q̇ = 0), so it constrains nothing "
                            "here; it is dropped (its constraint force is undetermined, λ = 0 is reported) and q̈ "
                            "and the linearization are those of the other rows";
        ws.zeroRowMessageRow = worstRow;
      }
      st.message = ws.zeroRowMessage;
      ws.zeroRowHolds = true;
      return;
    }
    st.message = "degenerate constraint row " + std::to_string(worstRow) + " (" + model.constraints()[worstRow].name +
                 "): |A_row| = " + formatNumber(data.constraintJacobian.row(worstRow).norm()) +
                 (ws.constraintScale[worstRow] > 0
                      ? " is " + formatNumber(kinematic) + " of its natural scale " +
                            formatNumber(ws.constraintScale[worstRow])
                      : std::string(" and no configuration variable moves its points")) +
                 " (its gradient vanishes or the configuration is singular; the constraint force is undetermined)";
  };
  // M⁻¹ Aᵀ by tree solves inside the blocks each run of rows on the same segments touches (the
  // rows of a run in one sweep: solveMassColumns; a contact between a digit and a free ball
  // solves on those two blocks only); then A M⁻¹ Aᵀ over the segments two rows share, whose
  // entries between groups of rows on disjoint blocks are exactly zero.
  for (size_t b = 0; b + 1 < ws.rowRunStart.size(); ++b) {
    const int b0 = ws.rowRunStart[b], b1 = ws.rowRunStart[b + 1];
    for (int r = b0; r < b1; ++r) ws.massInverseAt.col(r) = ws.jacobianT.col(r);
    forRowSegments(topo, ws, b0, [&](int lo, int hi) {
      solveMassColumns(model, data, ws.massInverseAt.col(b0).data(), ws.massInverseAt.outerStride(), b1 - b0, lo, hi);
    });
  }
  // A M⁻¹ Aᵀ(r, s) = A_r · (M⁻¹Aᵀ)_s over the segments the two rows share, run pair by run pair
  // (the rows of a run share their segments: the intersections once per pair of runs, 15 for the
  // hand's 5 contacts instead of 120 row pairs), up to 3 rows against 3 in one pass (crossDots),
  // on the contiguous copy Aᵀ. Only the lower triangle s ≤ r: the scaling below mirrors it.
  ws.schur.setZero();
  const double* At = ws.jacobianT.data();
  const double* Ud = ws.massInverseAt.data();
  const Eigen::Index ld = ws.jacobianT.outerStride(), ldU = ws.massInverseAt.outerStride();
  for (size_t g = 0; g + 1 < topo.rowGroupStart.size(); ++g) {
    const int g0 = topo.rowGroupStart[g], g1 = topo.rowGroupStart[g + 1];
    size_t first = 0;  // the group's first run
    while (ws.rowRunStart[first] < g0) ++first;
    for (size_t R = first; ws.rowRunStart[R] < g1; ++R) {
      for (size_t S = first; S <= R; ++S) {
        int cut[4][2], nCut = 0;
        forRowSegments(topo, ws, ws.rowRunStart[R], [&](int rlo, int rhi) {
          forRowSegments(topo, ws, ws.rowRunStart[S], [&](int slo, int shi) {
            const int lo = std::max(rlo, slo), hi = std::min(rhi, shi);
            if (hi > lo) {
              cut[nCut][0] = lo;
              cut[nCut++][1] = hi;
            }
          });
        });
        const int rEnd = ws.rowRunStart[R + 1], sEnd = ws.rowRunStart[S + 1];
        for (int r = ws.rowRunStart[R]; r < rEnd; r += 3)
          for (int s = ws.rowRunStart[S]; s < sEnd && (R != S || s <= r); s += 3) {
            const int nr = std::min(3, rEnd - r), ns = std::min(3, sEnd - s);
            double out[3][3];
            crossDots(nr, ns, At + r * ld, ld, Ud + s * ldU, ldU, cut, nCut, out);
            for (int k = 0; k < nr; ++k)
              for (int l = 0; l < ns && s + l <= r + k; ++l) ws.schur(r + k, s + l) = out[k][l];
          }
      }
    }
  }
  // A zero row of A (A M⁻¹ Aᵀ has a zero there exactly then: M⁻¹ is definite) says nothing about
  // q̈ and leaves its λ free: it is dropped here by a zero scale D_r and a unit pivot in Ŝ, so
  // that the Cholesky path below solves the other rows and the correction gives λ_r = 0 — the
  // minimum-norm choice the pivoted path makes, at the cost of the regular path (the z row of a
  // point on a planar chain; the redundant-row path cost 2–3× the model without the row).
  int zeroRows = 0;
  for (int r = 0; r < nc; ++r) {
    const double s = ws.schur(r, r);
    ws.schurScale[r] = s > 0 ? 1.0 / std::sqrt(s) : s == 0.0 ? 0.0 : 1.0;
    zeroRows += s == 0.0;
  }
  for (int k = 0; k < nc; ++k) {
    double* col = &ws.schur(0, k);
    const double dk = ws.schurScale[k];
    for (int i = k; i < nc; ++i) ws.schur(k, i) = col[i] = ws.schurScale[i] * col[i] * dk;
  }
  if (zeroRows > 0)
    for (int r = 0; r < nc; ++r)
      if (ws.schurScale[r] == 0.0) ws.schur(r, r) = 1.0;
  const bool definite = choleskyLower(ws.schur, ws.schurFactor);
  const double sScale = ws.schur.diagonal().maxCoeff();
  if (definite && sScale > 0) {
    // (min L_ii / max L_ii)² tracks λ_min/λ_max of Ŝ.
    const auto diag = ws.schurFactor.diagonal();
    const double ratio = diag.minCoeff() / diag.maxCoeff();
    const double rcond = ratio * ratio;
    st.constraintConditioning = std::min(kinematic, rcond);
    // κ_r = 0 only for a zero row (‖A_r‖ = 0), which was dropped above.
    if (rcond > 1e-13 && (kinematic > 0 || zeroRows > 0)) {
      st.constraintRank = nc - zeroRows;
      if (kinematic < 1e-5) reportDegenerate();
      return;
    }
  }
  // Rank-deficient Ŝ (redundant or degenerate rows): pivoted LDLᵀ, dropping the pivots below
  // 1e-12 (Ŝ has unit diagonal). q̈ stays exact when the rows are consistent; λ is one valid choice.
  ws.schurLDLT.compute(ws.schur);
  const auto D = ws.schurLDLT.vectorD();
  const double tol = 1e-12 * std::max(1.0, D.cwiseAbs().maxCoeff());
  int rank = 0, dropped = -1;
  for (int k = 0; k < nc; ++k) {
    if (D[k] > tol) {
      ws.schurPivotInverse[k] = 1.0 / D[k];
      ++rank;
    } else {
      ws.schurPivotInverse[k] = 0.0;
      if (dropped < 0) dropped = k;
    }
  }
  // Orthonormal basis of null(Ŝ): x = Pᵀ L⁻ᵀ e_k for each dropped pivot k (then Ŝ x = 0), so that
  // solveKkt can remove that component and return the minimum-norm λ̂.
  int nullity = 0;
  for (int k = 0; k < nc; ++k) {
    if (ws.schurPivotInverse[k] != 0.0) continue;
    auto x = ws.schurNullBasis.col(nullity);
    x.setZero();
    x[k] = 1.0;
    ws.schurLDLT.matrixU().solveInPlace(x);
    x = ws.schurLDLT.transpositionsP().transpose() * x;
    for (int j = 0; j < nullity; ++j) x -= ws.schurNullBasis.col(j).dot(x) * ws.schurNullBasis.col(j);
    const double norm = x.norm();
    if (norm > 0) {
      x /= norm;
      ++nullity;
    }
  }
  ws.schurNullity = nullity;
  ws.schurUsesPinv = true;
  st.constraintRank = rank - zeroRows;  // the dropped zero rows have unit pivots
  st.constraintConditioning = 0.0;
  st.code = DynamicsStatus::Code::kRedundantConstraints;
  // Which constraint the first dropped pivot belongs to: undo the row swaps (applied in order
  // i = 0, 1, … as swap(i, indices[i])) for that one position.
  int worst = std::max(dropped, 0);
  const auto& swaps = ws.schurLDLT.transpositionsP().indices();
  for (int i = nc - 1; i >= 0; --i) {
    if (worst == i) worst = swaps[i];
    else if (worst == swaps[i]) worst = i;
  }
  if (kinematic < 1e-5) {
    reportDegenerate();
    return;
  }
  st.message = "constraint Jacobian has rank " + std::to_string(rank) + " < " + std::to_string(nc) +
               " rows: row " + std::to_string(worst) + " (" + model.constraints()[worst].name +
               ") depends on the others (redundant constraints: q̈ is determined, the constraint forces are not)";
}

void solveMass(const Model& model, Data& data, Eigen::Ref<Eigen::MatrixXd> X) {
  auto& ws = detail::workspace(data);
  if (ws.massInverseCurrent && X.cols() > 1) {
    applyMassInverse(model, data, X);
    return;
  }
  for (Eigen::Index c = 0; c < X.cols(); ++c) solveMassVector(model, data, X.col(c), 0, model.nq());
}

namespace {

/// One row group's operands for correctForConstraints: A_g row by row (row r's entries on the
/// group's coordinates at a + r len), (M⁻¹Aᵀ)_g column by column (at u + r uStride, the
/// workspace's own columns), the Cholesky factor of Ŝ_g (row-major, 1 / L_rr on its diagonal)
/// and its scaling D_g.
struct GroupColumns {
  int ng, len;
  const double *a, *u, *l, *d;
  Eigen::Index uStride;
  double* t;                ///< ng entries of workspace
  double* x;                ///< X on the group's coordinates, column 0
  Eigen::Index xStride;
  double* lambda;           ///< C on the group's rows, column 0; overwritten with Λ
  Eigen::Index lStride, cols;
};

/// For every column: t = C_g − A_g X, Λ_g = (A M⁻¹ Aᵀ)_g⁻¹ t, X += (M⁻¹Aᵀ)_g Λ_g. NG: the row count
/// when fixed at compile time (the rows then share each pass over X, two coordinates per
/// step), 0 for g.ng.
template <int NG>
void correctGroupColumns(const GroupColumns& g) {
  const int ng = NG > 0 ? NG : g.ng;
  double local[NG > 0 ? NG : 1];  // fixed sizes: t stays in registers
  double* t = NG > 0 ? local : g.t;
  double* x = g.x;
  double* lam = g.lambda;
  const int len = g.len, pairs = len & ~1;
  for (Eigen::Index c = 0; c < g.cols; ++c, x += g.xStride, lam += g.lStride) {
    if constexpr (NG > 0) {
      Pack s[NG];
      for (int r = 0; r < NG; ++r) s[r] = Pack::Zero();
      for (int i = 0; i < pairs; i += 2) {
        const Pack xi = loadPack(x + i);
        for (int r = 0; r < NG; ++r) s[r] += loadPack(g.a + r * len + i) * xi;
      }
      for (int r = 0; r < NG; ++r) {
        double v = lam[r] - (s[r][0] + s[r][1]);
        if (pairs < len) v -= g.a[r * len + pairs] * x[pairs];
        t[r] = v;
      }
    } else {
      for (int r = 0; r < ng; ++r) {
        double v = lam[r];
        for (int i = 0; i < len; ++i) v -= g.a[r * len + i] * x[i];
        t[r] = v;
      }
    }
    // Λ = D L⁻ᵀ L⁻¹ D t: the substitutions of the group's Cholesky factor, whose diagonal holds
    // 1 / L_rr here (a product instead of a division per row and column; an explicit inverse of
    // the whole factor was cheaper still but less accurate: the hand's closed-loop error floor
    // rose from 5e-8 to 1.2e-7).
    for (int r = 0; r < ng; ++r) {
      double v = t[r] * g.d[r];
      for (int q = 0; q < r; ++q) v -= g.l[r * ng + q] * t[q];
      t[r] = v * g.l[r * ng + r];
    }
    for (int r = ng - 1; r >= 0; --r) {
      double v = t[r];
      for (int q = r + 1; q < ng; ++q) v -= g.l[q * ng + r] * t[q];
      t[r] = v * g.l[r * ng + r];
      lam[r] = t[r] * g.d[r];
    }
    if constexpr (NG > 0) {
      Pack lr[NG];
      for (int r = 0; r < NG; ++r) lr[r] = Pack::Constant(lam[r]);
      for (int i = 0; i < pairs; i += 2) {
        Pack xi = loadPack(x + i);
        for (int r = 0; r < NG; ++r) xi += loadPack(g.u + r * g.uStride + i) * lr[r];
        Eigen::Map<Pack>(x + i) = xi;
      }
      if (pairs < len)
        for (int r = 0; r < NG; ++r) x[pairs] += g.u[r * g.uStride + pairs] * lam[r];
    } else {
      for (int r = 0; r < ng; ++r)
        for (int i = 0; i < len; ++i) x[i] += g.u[r * g.uStride + i] * lam[r];
    }
  }
}

/// s_k += a_k · x over len entries for the NB rows a_k = a + k w (the rows share each load of x).
template <int NB>
inline void runDots(const double* a, int w, const double* x, int len, double* s) {
  Pack acc[NB];
  for (int k = 0; k < NB; ++k) acc[k] = Pack::Zero();
  const int pairs = len & ~1;
  for (int i = 0; i < pairs; i += 2) {
    const Pack xi = loadPack(x + i);
    for (int k = 0; k < NB; ++k) acc[k] += loadPack(a + k * w + i) * xi;
  }
  for (int k = 0; k < NB; ++k) {
    double v = acc[k][0] + acc[k][1];
    if (pairs < len) v += a[k * w + pairs] * x[pairs];
    s[k] += v;
  }
}
/// x += Σ_k u_k λ_k over len entries for the NB columns u_k = u + k stride.
template <int NB>
inline void runUpdates(const double* u, Eigen::Index stride, const double* lam, double* x, int len) {
  Pack lr[NB];
  for (int k = 0; k < NB; ++k) lr[k] = Pack::Constant(lam[k]);
  const int pairs = len & ~1;
  for (int i = 0; i < pairs; i += 2) {
    Pack xi = loadPack(x + i);
    for (int k = 0; k < NB; ++k) xi += loadPack(u + k * stride + i) * lr[k];
    Eigen::Map<Pack>(x + i) = xi;
  }
  if (pairs < len)
    for (int k = 0; k < NB; ++k) x[pairs] += u[k * stride + pairs] * lam[k];
}
/// runDots / runUpdates over a run's rows in threes (a contact's three rows), then the rest.
template <class F>
inline void inThrees(int count, F&& f) {
  int k = 0;
  for (; k + 3 <= count; k += 3) f(std::integral_constant<int, 3>{}, k);
  if (count - k == 2) f(std::integral_constant<int, 2>{}, k);
  if (count - k == 1) f(std::integral_constant<int, 1>{}, k);
}

/// One row group's operands for the run kernel (correctRunColumns), all read in place: row r of
/// A_g is column g0 + r of Aᵀ (ws.jacobianT, at a + r aStride), column r of (M⁻¹Aᵀ)_g at
/// u + r uStride, the group's block of the Cholesky factor of Ŝ at f (column stride fStride: row
/// r of L in the strict upper triangle of column r, column r below its diagonal; choleskyLower),
/// 1 / L_rr at lInv.
struct RunColumns {
  int ng;
  const double *a, *u, *f, *lInv, *d;
  Eigen::Index aStride, uStride, fStride;
  double* t;                ///< ng entries of workspace
  double* x;                ///< X, column 0 (coordinate 0)
  Eigen::Index xStride;
  double* lambda;           ///< C on the group's rows, column 0; overwritten with Λ
  Eigen::Index lStride, cols;
};

/// correctGroupColumns for a group whose rows live on different segments (loops across the tree: each
/// contact row on one digit's block and the free ball's, not on the other digits'): the group's
/// rows in runs on the same segments (DataWorkspace::rowRunStart), A, M⁻¹Aᵀ and X read in place
/// on those segments only (RowRun, data_workspace.hpp). Same operations as correctGroupColumns
/// without the zeros.
void correctRunColumns(const RunColumns& g, const RowRun* runs, int nRuns) {
  const int ng = g.ng;
  double* t = g.t;
  double* x = g.x;
  double* lam = g.lambda;
  for (Eigen::Index c = 0; c < g.cols; ++c, x += g.xStride, lam += g.lStride) {
    for (int b = 0; b < nRuns; ++b) {
      const RowRun& run = runs[b];
      double* tb = t + run.first;
      for (int k = 0; k < run.count; ++k) tb[k] = 0.0;
      inThrees(run.count, [&](auto nb, int k) {
        const double* a = g.a + (run.first + k) * g.aStride;
        runDots<decltype(nb)::value>(a + run.lo[0], g.aStride, x + run.lo[0], run.len[0], tb + k);
        runDots<decltype(nb)::value>(a + run.lo[1], g.aStride, x + run.lo[1], run.len[1], tb + k);
      });
      for (int k = 0; k < run.count; ++k) tb[k] = lam[run.first + k] - tb[k];
    }
    // Λ = D L⁻ᵀ L⁻¹ D t, as in correctGroupColumns; each substitution step a contiguous dot
    // product (a row of L, then a column; a group of 15 rows: 105 terms each way).
    for (int r = 0; r < ng; ++r) t[r] = (t[r] * g.d[r] - dotRun(g.f + r * g.fStride, t, r)) * g.lInv[r];
    for (int r = ng - 1; r >= 0; --r) {
      t[r] = (t[r] - dotRun(g.f + r * g.fStride + r + 1, t + r + 1, ng - r - 1)) * g.lInv[r];
      lam[r] = t[r] * g.d[r];
    }
    for (int b = 0; b < nRuns; ++b) {
      const RowRun& run = runs[b];
      inThrees(run.count, [&](auto nb, int k) {
        const double* u = g.u + (run.first + k) * g.uStride;
        const double* l = lam + run.first + k;
        runUpdates<decltype(nb)::value>(u + run.lo[0], g.uStride, l, x + run.lo[0], run.len[0]);
        runUpdates<decltype(nb)::value>(u + run.lo[1], g.uStride, l, x + run.lo[1], run.len[1]);
      });
    }
  }
}

/// correctForConstraints' Cholesky path for the rows g0 … g1 − 1 of one group, in runs.
void correctGroupInRuns(const Model& model, Data& data, double* X, Eigen::Index xStride, Eigen::Index cols,
                        double* Lambda, Eigen::Index lStride, int g0, int g1) {
  auto& ws = detail::workspace(data);
  const ModelTopology& topo = model.topology();
  const Eigen::MatrixXd &At = ws.jacobianT, &U = ws.massInverseAt, &F = ws.schurFactor;
  const int ng = g1 - g0;
  double* t = ws.correctionWork.data();  // t (ng), then 1 / L_rr (ng)
  double* lInv = t + ng;
  for (int r = 0; r < ng; ++r) lInv[r] = 1.0 / F(g0 + r, g0 + r);
  RowRun* runs = ws.correctionRuns.data();
  int nRuns = 0;
  for (size_t b = 0; b + 1 < ws.rowRunStart.size(); ++b) {
    const int b0 = ws.rowRunStart[b], b1 = ws.rowRunStart[b + 1];
    if (b0 < g0 || b0 >= g1) continue;
    RowRun& run = runs[nRuns++];
    run = RowRun{b0 - g0, b1 - b0, {0, 0}, {0, 0}};
    int s = 0;
    forRowSegments(topo, ws, b0, [&](int lo, int hi) {
      run.lo[s] = lo;
      run.len[s++] = hi - lo;
    });
  }
  const RunColumns g{ng, At.data() + g0 * At.outerStride(), U.data() + g0 * U.outerStride(), &F(g0, g0), lInv,
                     ws.schurScale.data() + g0, At.outerStride(), U.outerStride(), F.outerStride(), t, X, xStride,
                     Lambda + g0, lStride, cols};
  correctRunColumns(g, runs, nRuns);
}

/// correctGroupInRuns for every group that takes the run kernel (DataWorkspace::groupInRuns).
/// Apart from the hull kernels' loop and out of line: a call inside that loop cost hand.json's
/// correction +800 instructions per linearization (callgrind), for groups it never has.
__attribute__((noinline)) void correctGroupsInRuns(const Model& model, Data& data, double* X, Eigen::Index xStride,
                                                   Eigen::Index cols, double* Lambda, Eigen::Index lStride) {
  const auto& ws = detail::workspace(data);
  const auto& starts = model.topology().rowGroupStart;
  for (size_t g = 0; g + 1 < starts.size(); ++g)
    if (ws.groupInRuns[g]) correctGroupInRuns(model, data, X, xStride, cols, Lambda, lStride, starts[g], starts[g + 1]);
}

}  // namespace

void correctForConstraints(const Model& model, Data& data, Eigen::Ref<Eigen::MatrixXd> X,
                           Eigen::Ref<Eigen::MatrixXd> Lambda) {
  auto& ws = detail::workspace(data);
  const int nc = model.nc();
  if (nc == 0) return;
  if (!ws.schurUsesPinv) {
    // Group by group (rows g0…g1 on the coordinates [lo, hi) of their blocks) and column by
    // column: Λ = (A M⁻¹ Aᵀ)⁻¹ (C − A X), X += M⁻¹Aᵀ Λ, with the group's block of the Cholesky
    // factor of Ŝ; every operand is a few contiguous numbers (a digit: 3 rows on 4 coordinates).
    const bool runGroups = ws.anyGroupInRuns && ws.correctInRuns;
    if (runGroups) correctGroupsInRuns(model, data, X.data(), X.outerStride(), X.cols(), Lambda.data(), Lambda.outerStride());
    const Eigen::MatrixXd &A = data.constraintJacobian, &U = ws.massInverseAt, &LL = ws.schurFactor;
    for (size_t g = 0; g + 1 < model.topology().rowGroupStart.size(); ++g) {
      const int g0 = model.topology().rowGroupStart[g], g1 = model.topology().rowGroupStart[g + 1], ng = g1 - g0;
      int lo = model.nq(), hi = 0;
      for (int r = g0; r < g1; ++r)
        if (model.topology().rowHi[r] > model.topology().rowLo[r]) {
          lo = std::min(lo, model.topology().rowLo[r]);
          hi = std::max(hi, model.topology().rowHi[r]);
        }
      if (hi <= lo) lo = hi = 0;  // rows that touch no coordinate: Λ = (A M⁻¹ Aᵀ)⁻¹ C
      // A copy of the group's rows of A, each contiguous on the group's coordinates (M⁻¹Aᵀ is
      // read in place: its columns are), and of its Cholesky factor; then the column loop with
      // the row count fixed at compile time for the usual groups.
      const int len = hi - lo;
      if (runGroups && ws.groupInRuns[g]) continue;  // done above
      double* ag = ws.correctionWork.data();  // A_g
      double* sg = ag + ng * len;               // the group's Cholesky factor
      for (int r = 0; r < ng; ++r)
        for (int i = 0; i < len; ++i) ag[r * len + i] = A(g0 + r, lo + i);
      for (int r = 0; r < ng; ++r)
        for (int t = 0; t < ng; ++t) sg[r * ng + t] = t < r ? LL(g0 + r, g0 + t) : t == r ? 1.0 / LL(g0 + r, g0 + r) : 0.0;
      GroupColumns cols{ng, len, ag, U.data() + lo + g0 * U.outerStride(), sg, ws.schurScale.data() + g0,
                        U.outerStride(), sg + ng * ng, X.data() + lo, X.outerStride(), Lambda.data() + g0,
                        Lambda.outerStride(), X.cols()};
      switch (ng) {
        case 1: correctGroupColumns<1>(cols); break;
        case 2: correctGroupColumns<2>(cols); break;
        case 3: correctGroupColumns<3>(cols); break;
        default: correctGroupColumns<0>(cols); break;
      }
    }
    return;
  }
  // Rank-deficient Ŝ: the pivoted LDLᵀ on all rows at once.
  // C − A M⁻¹ R, each row of A over the coordinates it touches.
  for (int r = 0; r < nc; ++r) {
    const int lo = model.topology().rowLo[r], len = model.topology().rowHi[r] - lo;
    if (len > 0) Lambda.row(r) -= data.constraintJacobian.row(r).segment(lo, len).lazyProduct(X.middleRows(lo, len));
  }
  // (A M⁻¹ Aᵀ)⁺ = D Ŝ⁺ D with the row-normalized Ŝ of factorizeKkt.
  Lambda = ws.schurScale.asDiagonal() * Lambda;
  Lambda = ws.schurLDLT.transpositionsP() * Lambda;
  ws.schurLDLT.matrixL().solveInPlace(Lambda);
  Lambda = ws.schurPivotInverse.asDiagonal() * Lambda;
  ws.schurLDLT.matrixU().solveInPlace(Lambda);
  Lambda = ws.schurLDLT.transpositionsP().transpose() * Lambda;
  // Minimum norm: remove the null-space component, Λ −= N (Nᵀ Λ).
  const auto N = ws.schurNullBasis.leftCols(ws.schurNullity);
  Eigen::Ref<Eigen::MatrixXd> t = ws.tmpCX.topLeftCorner(ws.schurNullity, Lambda.cols());
  t.noalias() = N.transpose() * Lambda;
  Lambda.noalias() -= N * t;
  Lambda = ws.schurScale.asDiagonal() * Lambda;
  // M⁻¹ (R + Aᵀ Λ): one rank-1 update per row, on the blocks of that row.
  for (int r = 0; r < nc; ++r) {
    const int lo = model.topology().rowLo[r], len = model.topology().rowHi[r] - lo;
    if (len > 0) X.middleRows(lo, len).noalias() += ws.massInverseAt.col(r).segment(lo, len) * Lambda.row(r);
  }
}

void solveKkt(const Model& model, Data& data, Eigen::Ref<Eigen::MatrixXd> X, Eigen::Ref<Eigen::MatrixXd> Lambda) {
  solveMass(model, data, X);  // X = M⁻¹ R
  correctForConstraints(model, data, X, Lambda);
}

void inputMatrixPass(const Model& model, Data& data) {
  Eigen::MatrixXd& Bq = data.inputMatrix;
  Bq.setZero();
  forEachForceElement(model, [&](auto kind, const auto& e, size_t i) { decltype(kind)::addInputColumns(model, data, e, i, Bq); });
}

void massMatrixPass(const Model& model, Data& data) {
  auto& ws = detail::workspace(data);
  const auto& joints = model.joints();
  const int n = model.nq();
  for (int i = 0; i < n; ++i) {
    ws.cm[i] = ws.wm[i];
    ws.ch[i] = ws.wh[i];
    ws.cI[i] = ws.wI[i];
  }
  for (int i = n - 1; i >= 0; --i) {
    const int p = joints[i].parent;
    if (p == kWorld) continue;
    ws.cm[p] += ws.cm[i];
    ws.ch[p] += ws.ch[i];
    ws.cI[p] += ws.cI[i];
  }
  // M(j, i) = S_jᵀ Ic_i S_i for j = i and its ancestors, walked as runs of consecutive indices.
  for (int i = 0; i < n; ++i) {
    const Vector6d F = applyInertia(ws.cm[i], ws.ch[i], ws.cI[i], ws.S[i]);
    double* col = &data.M(0, i);
    forAncestorRuns(model.topology(), i, true, [&](int s, int e) {
      for (int j = s; j <= e; ++j) data.M(i, j) = col[j] = ws.S[j].dot(F);
    });
  }
}

bool nonFinite(const Eigen::VectorXd& x, const char* name, const std::vector<std::string>& names, DynamicsStatus& st) {
  for (int i = 0; i < x.size(); ++i)
    if (!std::isfinite(x[i])) {
      st.code = DynamicsStatus::Code::kNonFinite;
      st.message = std::string(name) + "[" + std::to_string(i) + "] ('" + names[i] + "') is not finite";
      return true;
    }
  return false;
}

void appendState(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq, std::string& message) {
  // The first coordinates by name (a message, not a state file: long states are cut).
  constexpr int kShown = 12;
  const int n = model.nq();
  for (int pass = 0; pass < 2; ++pass) {
    const Eigen::VectorXd& x = pass == 0 ? q : dq;
    message += pass == 0 ? " at q = (" : ", dq = (";
    for (int i = 0; i < std::min(n, kShown); ++i) {
      if (i) message += ", ";
      message += model.configNames()[i];
      message += '=';
      appendNumber(message, x[i]);
    }
    if (n > kShown) message += ", … " + std::to_string(n - kShown) + " more";
    message += ")";
  }
}

bool inputsAreFinite(const Model& model, Data& data, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                     const Eigen::VectorXd& u) {
  return !(nonFinite(q, "q", model.configNames(), data.status) ||
           nonFinite(dq, "dq", model.configNames(), data.status) ||
           nonFinite(u, "u", model.inputNames(), data.status));
}

}  // namespace detail

void computeMassMatrix(const Model& model, Data& data, const Eigen::VectorXd& q) {
  auto& ws = detail::workspace(data);
  detail::checkSize(q, model.nq(), "computeMassMatrix: q");
  ws.tmpN.setZero();
  detail::updateJoints(model, data, q, ws.tmpN);
  detail::massMatrixPass(model, data);
}

void computeConstraints(const Model& model, Data& data, const Eigen::VectorXd& q, const Eigen::VectorXd& dq) {
  auto& ws = detail::workspace(data);
  detail::checkSize(q, model.nq(), "computeConstraints: q");
  detail::checkSize(dq, model.nq(), "computeConstraints: dq");
  detail::updateJoints(model, data, q, dq);
  ws.qddZero.setZero();
  detail::updateAccelerations(model, data, dq, ws.qddZero);
  detail::evaluateConstraints(model, data, &data.constraintValue, nullptr, &data.constraintDrift,
                              &data.constraintJacobian);
}

void computeInputMatrix(const Model& model, Data& data, const Eigen::VectorXd& q) {
  auto& ws = detail::workspace(data);
  detail::checkSize(q, model.nq(), "computeInputMatrix: q");
  ws.tmpN.setZero();
  detail::updateJoints(model, data, q, ws.tmpN);
  detail::inputMatrixPass(model, data);
}

DynamicsStatus computeDynamics(const Model& model, Data& data, const Eigen::VectorXd& q,
                               const Eigen::VectorXd& dq, const Eigen::VectorXd& u) {
  auto& ws = detail::workspace(data);
  using namespace detail;
  const int n = model.nq();
  checkSize(q, n, "computeDynamics: q");
  checkSize(dq, n, "computeDynamics: dq");
  checkSize(u, model.nu(), "computeDynamics: u");
  if (!inputsAreFinite(model, data, q, dq, u)) return data.status;
  updateJoints(model, data, q, dq);
  massMatrixPass(model, data);
  ws.qddZero.setZero();
  updateAccelerations(model, data, dq, ws.qddZero);
  accumulateExternalWrenches(model, data, u, true, true, nullptr);
  inverseDynamicsPass(model, data, data.bias);  // ID(q, q̇, 0) − Q_wrenches
  ws.tmpN.setZero();
  addConfigurationForces(model, q, dq, u, ws.tmpN);
  data.bias -= ws.tmpN;
  evaluateConstraints(model, data, &data.constraintValue, nullptr, &data.constraintDrift, &data.constraintJacobian);
  if (model.nc() == 0 && n > 0 && blocksAreChains(model) && std::isfinite(data.M.sum())) {
    // No constraints, chains: M q̈ = −b by the articulated factor (mass_factor.hpp), O(n) instead
    // of the dense factor's O(n³), and the linearization's M⁻¹ from it in O(n²). (Branched trees
    // keep the tree factor, cheap there, so that q̈ is the same computation in both.) The pivot
    // test is factorizeKkt's; a failing one takes the KKT path below, which reports it.
    const double scale = std::max(data.M.diagonal().maxCoeff(), std::numeric_limits<double>::min());
    if (factorArticulated(model, data, 1e-14 * scale) < 0) {
      DynamicsStatus& st = data.status;
      st.code = DynamicsStatus::Code::kOk;
      st.message.clear();
      st.constraintRank = 0;
      st.constraintConditioning = 1.0;
      ws.schurUsesPinv = false;
      ws.massInverseCurrent = false;  // the tree factor was not updated
      ws.articulatedCurrent = true;
      data.qdd = -data.bias;
      solveArticulated(model, data, data.qdd);
      if (!data.qdd.allFinite()) {
        st.code = DynamicsStatus::Code::kNonFinite;
        st.message = "forward dynamics produced non-finite values";
        appendState(model, q, dq, st.message);
      }
      return st;
    }
  }
  factorizeKkt(model, data);
  if (!solvable(data.status)) {
    appendState(model, q, dq, data.status.message);
    return data.status;
  }
  data.qdd = -data.bias;
  data.lambda = -data.constraintDrift;
  solveKkt(model, data, data.qdd, data.lambda);
  if (data.status.code == DynamicsStatus::Code::kRedundantConstraints) {
    // The pseudo-inverse solves consistent redundant rows exactly; inconsistent ones are not.
    ws.tmpC.noalias() = data.constraintJacobian * data.qdd;
    ws.tmpC += data.constraintDrift;
    double scale = 1.0 + data.constraintDrift.cwiseAbs().maxCoeff();
    for (int r = 0; r < model.nc(); ++r)
      scale = std::max(scale, data.constraintJacobian.row(r).cwiseAbs().dot(data.qdd.cwiseAbs()));
    int worst = 0;
    if (ws.tmpC.cwiseAbs().maxCoeff(&worst) > 1e-8 * scale) {
      data.status.code = DynamicsStatus::Code::kSingularConstraints;
      data.status.message = "constraints are singular and inconsistent at this state: A q̈ + Ȧ q̇ = " +
                            std::to_string(ws.tmpC[worst]) + " on " + model.constraints()[worst].name;
    }
  }
  if (!(data.qdd.allFinite() && data.lambda.allFinite())) {
    data.status.code = DynamicsStatus::Code::kNonFinite;
    data.status.message = "forward dynamics produced non-finite values";
  }
  // The state goes into every failure's message, except the report of a zero row that holds
  // (factorizeKkt: the report is the same at every state, and such a row is met at every call).
  const bool stateFree = ws.zeroRowHolds && data.status.code == DynamicsStatus::Code::kSingularConstraints;
  if (!data.status.ok() && !stateFree) appendState(model, q, dq, data.status.message);
  return data.status;
}

Energy computeEnergy(const Model& model, Data& data, const Eigen::VectorXd& q, const Eigen::VectorXd& dq) {
  auto& ws = detail::workspace(data);
  detail::checkSize(q, model.nq(), "computeEnergy: q");
  detail::checkSize(dq, model.nq(), "computeEnergy: dq");
  detail::updateJoints(model, data, q, dq);
  Energy e;
  for (int i = 0; i < model.nq(); ++i) {
    e.kinetic += 0.5 * ws.v[i].dot(spatial::applyInertia(ws.wm[i], ws.wh[i], ws.wI[i], ws.v[i]));
    e.potential -= model.gravity().dot(ws.wh[i]);  // V = −m g·c
  }
  detail::forEachForceElement(model, [&](auto kind, const auto& el, size_t) {
    if constexpr (decltype(kind)::conservative) e.potential += decltype(kind)::potential(data, q, el);
  });
  return e;
}

double computeNonConservativePower(const Model& model, Data& data, const Eigen::VectorXd& q,
                                   const Eigen::VectorXd& dq, const Eigen::VectorXd& u) {
  auto& ws = detail::workspace(data);
  detail::checkSize(q, model.nq(), "computeNonConservativePower: q");
  detail::checkSize(dq, model.nq(), "computeNonConservativePower: dq");
  detail::checkSize(u, model.nu(), "computeNonConservativePower: u");
  detail::updateJoints(model, data, q, dq);
  detail::accumulateExternalWrenches(model, data, u, false, true, nullptr);
  double power = 0.0;
  for (int i = 0; i < model.nq(); ++i) power += ws.fext[i].dot(ws.v[i]);
  // Non-conservative generalized forces on coordinates (inputs, damping): Q_nc · q̇.
  ws.tmpN.setZero();
  detail::forEachForceElement(model, [&](auto kind, const auto& e, size_t) {
    if constexpr (!decltype(kind)::conservative) decltype(kind)::generalizedForce(q, dq, u, e, ws.tmpN);
  });
  return power + ws.tmpN.dot(dq);
}

}  // namespace trellis
