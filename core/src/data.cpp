// Sizes every buffer of the workspace once (see data.hpp).
#include "trellis/core/data.hpp"

#include <algorithm>

namespace trellis {

namespace {
/// The top-level tree (block) that contains joint j, as [first, end); the world is no block.
std::pair<int, int> blockOf(const Model& model, int j) {
  if (j == kWorld) return {model.nq(), 0};  // empty: neutral for min/max
  while (model.joints()[j].parent != kWorld) j = model.joints()[j].parent;
  return {j, model.joints()[j].subtreeEnd};
}
}  // namespace

void Data::describeTree(const Model& model) {
  const int n = model.nq(), nc = model.nc(), m = model.nu();
  treeParent.resize(n);
  runStart.resize(n);
  blockStart.clear();
  for (int i = 0; i < n; ++i) {
    const int p = model.joints()[i].parent;
    treeParent[i] = p;
    runStart[i] = (p != kWorld && p == i - 1) ? runStart[i - 1] : i;
    if (p == kWorld) blockStart.push_back(i);
  }
  treeRoot.resize(n);
  for (int i = 0; i < n; ++i) treeRoot[i] = treeParent[i] == kWorld ? i : treeRoot[treeParent[i]];
  tendonFirst.assign(1, 0);
  tendonJointLo.clear();
  tendonJointHi.clear();
  for (const Tendon& t : model.tendons()) {
    int lo = n, hi = -1;
    for (const BodyPoint& bp : t.path)
      if (bp.joint != kWorld) {
        lo = std::min(lo, bp.joint);
        hi = std::max(hi, bp.joint);
      }
    tendonJointLo.push_back(lo);
    tendonJointHi.push_back(hi);
    tendonFirst.push_back(tendonFirst.back() + static_cast<int>(t.path.size()));
  }
  tendonPoint.assign(static_cast<size_t>(tendonFirst.back()), Eigen::Vector3d::Zero());
  tendonPointJoint.clear();
  tendonSegmentStart.assign(1, 0);
  tendonSegmentPoint.clear();
  for (const Tendon& t : model.tendons()) {
    for (size_t k = 0; k < t.path.size(); ++k) {
      if (k + 1 < t.path.size() && t.path[k].joint != t.path[k + 1].joint)
        tendonSegmentPoint.push_back(static_cast<int>(tendonPointJoint.size()));
      tendonPointJoint.push_back(t.path[k].joint);
    }
    tendonSegmentStart.push_back(static_cast<int>(tendonSegmentPoint.size()));
  }
  blockStart.push_back(n);
  // Row r of A (and column r of M⁻¹Aᵀ) lives on the blocks of the constraint's two bodies.
  rowLo.assign(nc, 0);
  rowHi.assign(nc, 0);
  for (int r = 0; r < nc; ++r) {
    const Constraint& c = model.constraints()[r];
    const auto [a0, a1] = blockOf(model, c.a.joint);
    const auto [b0, b1] = blockOf(model, c.b.joint);
    rowLo[r] = std::min(a0, b0);
    rowHi[r] = std::max(a1, b1);
    if (rowHi[r] <= rowLo[r]) rowLo[r] = rowHi[r] = 0;  // touches no coordinate
  }
  // Groups of consecutive rows: a boundary t is kept when no row before it shares a coordinate
  // with a row after it; A M⁻¹ Aᵀ is then block diagonal over the groups.
  schurGroupStart.assign(1, 0);
  for (int t = 1; t < nc; ++t) {
    bool split = true;
    for (int r = 0; r < t && split; ++r)
      for (int s = t; s < nc && split; ++s)
        split = std::min(rowHi[r], rowHi[s]) <= std::max(rowLo[r], rowLo[s]);
    if (split) schurGroupStart.push_back(t);
  }
  if (nc > 0) schurGroupStart.push_back(nc);
  // Inputs that are generalized forces on one coordinate: their column of B is a column of M⁻¹.
  unitInputConfig.assign(m, -2);
  unitInputGain.assign(m, 0.0);
  for (const ConfigForce& cf : model.configForces()) {
    int& c = unitInputConfig[cf.input];
    c = (c == -2 || c == cf.config) ? cf.config : -1;
    unitInputGain[cf.input] += 1.0;
  }
  for (const BodyWrench& bw : model.bodyWrenches())
    for (int k : bw.input)
      if (k >= 0 && bw.joint != kWorld) unitInputConfig[k] = -1;
  for (const Tendon& t : model.tendons()) unitInputConfig[t.input] = -1;
  for (int& c : unitInputConfig)
    if (c == -2) c = -1;
}

Data::Data(const Model& model)
    // The factorizations are built at their size here (not assigned later); the body factors an
    // identity once because Eigen 3.4's size constructors leave the ComputationInfo flag
    // uninitialized, and moving a Data copies it (UBSan: invalid enum load).
    : schurLLT(model.nc()),
      schurLDLT(model.nc()),
      basisQR(2 * model.nq(), model.nholonomic() + model.nc()) {
  const int n = model.nq(), m = model.nu(), nc = model.nc(), nf = model.nframes();
  const int nh = model.nholonomic();
  const int cols = 2 * n + m;
  schurLLT.compute(Eigen::MatrixXd::Identity(nc, nc));
  schurLDLT.compute(Eigen::MatrixXd::Identity(nc, nc));
  framePose.assign(nf, Eigen::Isometry3d::Identity());
  frameVelocity.assign(nf, Vector6d::Zero());
  M = Eigen::MatrixXd::Zero(n, n);
  bias = Eigen::VectorXd::Zero(n);
  constraintValue = Eigen::VectorXd::Zero(nc);
  constraintJacobian = Eigen::MatrixXd::Zero(nc, n);
  constraintDrift = Eigen::VectorXd::Zero(nc);
  qdd = Eigen::VectorXd::Zero(n);
  lambda = Eigen::VectorXd::Zero(nc);
  inputMatrix = Eigen::MatrixXd::Zero(n, m);
  A = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  A.topRightCorner(n, n).setIdentity();  // constant rows of the linearization
  B = Eigen::MatrixXd::Zero(2 * n, m);
  dqdd_dq = Eigen::MatrixXd::Zero(n, n);
  dqdd_ddq = Eigen::MatrixXd::Zero(n, n);
  dqdd_du = Eigen::MatrixXd::Zero(n, m);
  dlambda_dx = Eigen::MatrixXd::Zero(nc, cols);
  constraintVelocityJacobian = Eigen::MatrixXd::Zero(nc, n);
  tangentBasis = Eigen::MatrixXd::Identity(2 * n, 2 * n);
  reducedA = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  reducedB = Eigen::MatrixXd::Zero(2 * n, m);
  status.constraintRank = nc;

  jointR.assign(n, Eigen::Matrix3d::Identity());
  jointP.assign(n, Eigen::Vector3d::Zero());
  for (auto* vec : {&S, &v, &a, &f, &fext, &Iv, &Ia, &inertialForce, &compositeMomentum,
                    &tangentWrench})
    vec->assign(n, Vector6d::Zero());
  tangentABG = Eigen::Matrix<double, 18, Eigen::Dynamic>::Zero(18, n);
  compositeB.assign(n, Eigen::Matrix3d::Zero());
  wm.assign(n, 0.0);
  wh.assign(n, Eigen::Vector3d::Zero());
  wI.assign(n, Eigen::Matrix3d::Zero());
  cm.assign(n, 0.0);
  ch.assign(n, Eigen::Vector3d::Zero());
  cI.assign(n, Eigen::Matrix3d::Zero());
  u = Eigen::VectorXd::Zero(m);
  qddZero = Eigen::VectorXd::Zero(n);
  rhsX = Eigen::MatrixXd::Zero(n, cols);
  crhsX = Eigen::MatrixXd::Zero(nc, cols);
  massInverse = Eigen::MatrixXd::Zero(n, n);
  massFactor = Eigen::MatrixXd::Zero(n, n);
  massInverseFactor = Eigen::MatrixXd::Zero(n, n);
  massPivotInvSqrt = Eigen::VectorXd::Zero(n);
  articulatedU.assign(n, Vector6d::Zero());
  articulatedWork.assign(n, Vector6d::Zero());
  articulatedPivot = Eigen::VectorXd::Zero(n);
  articulatedColumns = Eigen::Matrix<double, 6, Eigen::Dynamic>::Zero(6, n);
  describeTree(model);
  massInverseAt = Eigen::MatrixXd::Zero(n, nc);
  schur = Eigen::MatrixXd::Zero(nc, nc);
  correctionWork = Eigen::VectorXd::Zero(2 * nc * n + nc * nc + nc);
  constraintScale = Eigen::VectorXd::Ones(nc);
  schurScale = Eigen::VectorXd::Ones(nc);
  schurPivotInverse = Eigen::VectorXd::Zero(nc);
  schurNullBasis = Eigen::MatrixXd::Zero(nc, nc);
  tmpN = Eigen::VectorXd::Zero(n);
  tmpC = Eigen::VectorXd::Zero(nc);
  tmpNX = Eigen::MatrixXd::Zero(n, cols + 1);
  tmpCX = Eigen::MatrixXd::Zero(nc, cols + 1);
  constraintStateJacobian = Eigen::MatrixXd::Zero(nh + nc, 2 * n);
  basisQ = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  basisWorkspace = Eigen::VectorXd::Zero(2 * n);
  basisWorkMatrix = Eigen::MatrixXd::Zero(2 * n, 2 * n);
}

}  // namespace trellis
