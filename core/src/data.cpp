// Sizes every buffer of the workspace once (see data.hpp).
#include "trellis/core/data.hpp"

namespace trellis {

Data::Data(const Model& model)
    // The factorizations are built at their size here (not assigned later) so that every member,
    // including their status flags, is initialized.
    : massLLT(model.nq()),
      schurLLT(model.nc()),
      schurLDLT(model.nc()),
      basisQR(2 * model.nq(), model.nholonomic() + model.nc()) {
  const int n = model.nq(), m = model.nu(), nc = model.nc(), nf = model.nframes();
  const int nh = model.nholonomic();
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

  jointR.assign(n, Eigen::Matrix3d::Identity());
  jointP.assign(n, Eigen::Vector3d::Zero());
  for (auto* vec : {&S, &v, &a, &f, &fext, &Iv, &Ia, &inertialForce, &compositeMomentum,
                    &tangentAlpha, &tangentBeta, &tangentGamma})
    vec->assign(n, Vector6d::Zero());
  compositeD.assign(n, Eigen::Matrix<double, 6, 6>::Zero());
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
  Y = Eigen::MatrixXd::Zero(n, nc);
  massInverseAt = Eigen::MatrixXd::Zero(n, nc);
  schur = Eigen::MatrixXd::Zero(nc, nc);
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
