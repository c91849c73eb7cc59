// Sizes every result and every buffer of the workspace once (see data.hpp, data_workspace.hpp).
#include "data_workspace.hpp"
#include "mass_factor.hpp"

#include <algorithm>
#include <utility>

namespace trellis {

namespace detail {

DataWorkspace::DataWorkspace(const Model& model)
    // The factorizations are built at their size here (not assigned later); the body factors an
    // identity once because Eigen 3.4's size constructors leave the ComputationInfo flag
    // uninitialized, and copying a Data copies it (UBSan: invalid enum load).
    : schurLDLT(model.nc()),
      basisQR(2 * model.nq(), model.nholonomic() + model.nc()) {
  const int n = model.nq(), m = model.nu(), nc = model.nc();
  const int nh = model.nholonomic();
  const int cols = 2 * n + m;
  schurFactor = Eigen::MatrixXd::Identity(nc, nc);
  schurLDLT.compute(Eigen::MatrixXd::Identity(nc, nc));
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
  tendonPoint.assign(static_cast<size_t>(model.topology().tendonFirst.back()), Eigen::Vector3d::Zero());
  u = Eigen::VectorXd::Zero(m);
  qddZero = Eigen::VectorXd::Zero(n);
  q = Eigen::VectorXd::Zero(n);
  dq = Eigen::VectorXd::Zero(n);
  qddOfA = Eigen::VectorXd::Zero(n);
  rhsX = Eigen::MatrixXd::Zero(n, cols);
  crhsX = Eigen::MatrixXd::Zero(nc, cols);
  massInverse = Eigen::MatrixXd::Zero(n, n);
  massFactor = Eigen::MatrixXd::Zero(n, n);
  massInverseFactor = Eigen::MatrixXd::Zero(n, n);
  massPivotInvSqrt = Eigen::VectorXd::Zero(n);
  articulatedU.assign(n, Vector6d::Zero());
  articulatedWork.assign(n, Vector6d::Zero());
  articulatedPivot = Eigen::VectorXd::Zero(n);
  articulatedModel = suitsArticulatedFactor(model);
  articulatedColumns = Eigen::Matrix<double, 6, Eigen::Dynamic>::Zero(6, n);
  massInverseAt = Eigen::MatrixXd::Zero(n, nc);
  jacobianT = Eigen::MatrixXd::Zero(n, nc);
  schur = Eigen::MatrixXd::Zero(nc, nc);
  correctionWork = Eigen::VectorXd::Zero(2 * nc * n + 2 * nc * nc + nc);
  correctionRuns.assign(static_cast<size_t>(nc), RowRun{});
  // The rows' segments: a row between two non-empty blocks apart skips the blocks between them.
  const ModelTopology& topo = model.topology();
  const auto blockOf = [&](int j) {  // [first, end) of j's top-level tree; empty for the world
    if (j == kWorld) return std::pair<int, int>(n, 0);
    const int root = topo.treeRoot[static_cast<size_t>(j)];
    return std::pair<int, int>(root, model.joints()[static_cast<size_t>(root)].subtreeEnd);
  };
  rowGapLo.assign(static_cast<size_t>(nc), 0);
  rowGapHi.assign(static_cast<size_t>(nc), 0);
  for (int r = 0; r < nc; ++r) {
    const size_t i = static_cast<size_t>(r);
    const auto [a0, a1] = blockOf(model.constraints()[i].a.joint);
    const auto [b0, b1] = blockOf(model.constraints()[i].b.joint);
    rowGapLo[i] = rowGapHi[i] = topo.rowHi[i];
    if (a1 > a0 && b1 > b0 && (a1 < b0 || b1 < a0)) {
      rowGapLo[i] = std::min(a1, b1);
      rowGapHi[i] = std::max(a0, b0);
    }
  }
  // Runs of rows on the same segments, broken at every group start.
  rowRunStart.assign(1, 0);
  for (int r = 1, g = 1; r < nc; ++r) {
    const size_t i = static_cast<size_t>(r);
    const bool groupStart = topo.rowGroupStart[static_cast<size_t>(g)] == r;
    g += groupStart;
    if (groupStart || topo.rowLo[i] != topo.rowLo[i - 1] || topo.rowHi[i] != topo.rowHi[i - 1] ||
        rowGapLo[i] != rowGapLo[i - 1] || rowGapHi[i] != rowGapHi[i - 1])
      rowRunStart.push_back(r);
  }
  if (nc > 0) rowRunStart.push_back(nc);
  // Groups whose rows do not all cover the group's coordinate range [lo, hi) take the run kernel.
  groupInRuns.assign(topo.rowGroupStart.empty() ? 0 : topo.rowGroupStart.size() - 1, 0);
  for (size_t g = 0; g < groupInRuns.size(); ++g) {
    const int g0 = topo.rowGroupStart[g], g1 = topo.rowGroupStart[g + 1];
    int lo = n, hi = 0;
    for (int r = g0; r < g1; ++r)
      if (topo.rowHi[static_cast<size_t>(r)] > topo.rowLo[static_cast<size_t>(r)]) {
        lo = std::min(lo, topo.rowLo[static_cast<size_t>(r)]);
        hi = std::max(hi, topo.rowHi[static_cast<size_t>(r)]);
      }
    if (hi <= lo) lo = hi = 0;
    for (int r = g0; r < g1; ++r) {
      const size_t i = static_cast<size_t>(r);
      if (topo.rowLo[i] != lo || topo.rowHi[i] != hi || rowGapLo[i] != hi) groupInRuns[g] = 1;
    }
    anyGroupInRuns |= groupInRuns[g] != 0;
  }
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

}  // namespace detail

Data::Data(const Model& model) : work_(std::make_unique<detail::DataWorkspace>(model)) {
  const int n = model.nq(), m = model.nu(), nc = model.nc(), nf = model.nframes();
  const int cols = 2 * n + m;
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
}

// The workspace is copied with the results: a copy continues from the same state (e.g. the
// factor that invertMass reuses), exactly as the members of one object did.
Data::Data(const Data& other)
    : framePose(other.framePose), frameVelocity(other.frameVelocity), M(other.M), bias(other.bias),
      constraintValue(other.constraintValue), constraintJacobian(other.constraintJacobian),
      constraintDrift(other.constraintDrift), qdd(other.qdd), lambda(other.lambda),
      inputMatrix(other.inputMatrix), A(other.A), B(other.B), dqdd_dq(other.dqdd_dq),
      dqdd_ddq(other.dqdd_ddq), dqdd_du(other.dqdd_du), dlambda_dx(other.dlambda_dx),
      constraintVelocityJacobian(other.constraintVelocityJacobian), tangentBasis(other.tangentBasis),
      reducedA(other.reducedA), reducedB(other.reducedB), status(other.status),
      work_(std::make_unique<detail::DataWorkspace>(*other.work_)) {}

Data& Data::operator=(const Data& other) {
  if (this != &other) *this = Data(other);
  return *this;
}

Data::Data(Data&& other) noexcept = default;
Data& Data::operator=(Data&& other) noexcept = default;
Data::~Data() = default;

}  // namespace trellis
