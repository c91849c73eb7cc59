// tests/core/test_hand_ball_scene.cpp — the hand holding a FREE ball (issue 26;
// examples/scenes/hand_ball.json, written by examples/hand/make_hand_scene.py --free-ball): the
// sizes (26 coordinates, 23 tendons, 15 sticking-contact rows), the stored grasp on the manifold,
// the energy balance of hand + ball, the linearization (q̈ and λ) against central differences, and
// λ read as the pads' forces on the ball in each contact frame (normal n, tangents t1, t2), checked
// against two independent paths: the point forces of constraint_forces.hpp projected on the
// contact frame, and Newton's law for the ball's centre, m c̈ = m g + Σ contact forces.
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/linearization_checks.hpp"

#include <trellis/core.hpp>
#include <trellis/core/constraint_forces.hpp>

#include <Eigen/SVD>

#include <random>
#include <string>

using namespace trellis;

namespace {

Scene loadHandBall() {
  return loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand_ball.json");
}

const char* const kDigits[] = {"index", "middle", "ring", "little", "thumb"};  // constraint row order

/// A state on the constraint manifold at the stored grasp: q̇ = the projection of a random velocity
/// on the null space of A (so A q̇ = 0 to rounding), tensions of a few N.
struct BallState {
  Eigen::VectorXd q, dq, u;
};
BallState consistentState(const Scene& s, std::mt19937& rng, double speed) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const Model& m = s.model;
  Data data(m);
  computeConstraints(m, data, s.q, Eigen::VectorXd::Zero(m.nq()));
  Eigen::VectorXd v(m.nq());
  for (int i = 0; i < m.nq(); ++i) v(i) = speed * unit(rng);
  const Eigen::MatrixXd& A = data.constraintJacobian;
  const Eigen::VectorXd dq = v - A.transpose() * (A * A.transpose()).ldlt().solve(A * v);
  Eigen::VectorXd u(m.nu());
  for (int i = 0; i < m.nu(); ++i) u(i) = 3.0 + 2.0 * unit(rng);
  return {s.q, dq, u};
}

}  // namespace

TEST_CASE("The free-ball hand scene: 26 coordinates, 23 tendons, 15 contact rows, on the manifold",
          "[hand][ball][scene]") {
  const Scene s = loadHandBall();
  const Model& m = s.model;
  CHECK(m.nq() == 26);
  CHECK(m.nu() == 23);
  CHECK(m.nc() == 15);
  CHECK(m.nholonomic() == 15);
  for (const char* name : {"ball_x", "ball_y", "ball_z", "ball_yaw", "ball_pitch", "ball_roll"})
    CHECK(s.q(m.configIndex(name)) == 0.0);
  Data data(m);
  computeConstraints(m, data, s.q, s.dq);
  // As hand.json (test_hand_scene.cpp): the pads are solved to ~1e-17 m, positions of 0.2 m.
  CHECK(data.constraintValue.cwiseAbs().maxCoeff() < 1e-13);
  // Rank 15 with margin, and a 2·(26 − 15) = 22-dimensional tangent space of the state.
  REQUIRE(computeLinearization(m, data, s.q, s.dq, Eigen::VectorXd::Zero(m.nu())).ok());
  CHECK(data.status.constraintRank == 15);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(data.constraintJacobian);
  CHECK(svd.singularValues()(14) / svd.singularValues()(0) > 1e-3);
  CHECK(computeConstraintTangentBasis(m, data) == 22);
  // The ball's mass and inertia as documented: 80 g, 2/5 m r² about its centre. The ball's
  // translations are the last body's: M restricted to ball_x..z is m I (the ball's own translational
  // inertia, its centre of mass at the joint origin).
  const int bx = m.configIndex("ball_x");
  CHECK(data.M.block(bx, bx, 3, 3).isApprox(0.080 * Eigen::Matrix3d::Identity(), 1e-14));
  const int yaw = m.configIndex("ball_yaw");
  CHECK(data.M(yaw, yaw) == Approx(0.4 * 0.080 * 0.035 * 0.035).epsilon(1e-12));
}

TEST_CASE("The free ball and the hand keep the energy balance dE/dt = Q_nc·q̇",
          "[hand][ball][energy]") {
  const Scene s = loadHandBall();
  const Model& m = s.model;
  Data data(m);
  std::mt19937 rng(2601);
  const BallState st = consistentState(s, rng, 0.5);
  REQUIRE(computeDynamics(m, data, st.q, st.dq, st.u).ok());
  const Eigen::VectorXd qdd = data.qdd;
  // dE/dt along the motion (q̇, q̈) by one central difference of E(q, q̇) — an independent path
  // (energies from M and the potentials; q̈ from the constrained dynamics). Constraint forces do no
  // work at a consistent state (A q̇ = 0).
  const test::VectorFunction energy = [&](const Eigen::VectorXd& x) {
    return Eigen::VectorXd::Constant(1, computeEnergy(m, data, x.head(m.nq()), x.tail(m.nq())).total());
  };
  Eigen::VectorXd x(2 * m.nq()), f(2 * m.nq());
  x << st.q, st.dq;
  f << st.dq, qdd;
  const double dEdt = test::centralDifferenceDirectional(energy, x, f)(0);
  const double power = computeNonConservativePower(m, data, st.q, st.dq, st.u);
  // The tendon power alone sets the scale: Σ |u_j (B q̇)_j|. The difference's error is
  // ~eps^(2/3) relative to the terms of E that vary (≈1e-10); 1e-6 of the scale leaves a margin and
  // a missing force (gravity on the ball: m g ż ~ 0.8·0.1 W) shows at ≥ 1e-2.
  computeInputMatrix(m, data, st.q);
  const double scale = (st.u.asDiagonal() * (data.inputMatrix.transpose() * st.dq)).cwiseAbs().sum();
  INFO("dE/dt = " << dEdt << ", Q_nc·q̇ = " << power << ", scale " << scale);
  CHECK(std::abs(dEdt - power) <= 1e-6 * scale);
}

TEST_CASE("The free-ball hand's linearization (q̈ and λ) agrees with central differences",
          "[hand][ball][linearization][fd]") {
  const Scene s = loadHandBall();
  std::mt19937 rng(2602);
  const BallState st = consistentState(s, rng, 0.5);
  // Same reasoning as the fixed-ball hand (test_hand_scene.cpp): small inertias give q̈ ~ 1e4, the
  // fourth-order stencil keeps the rounding near 1e-7 column-relative; the check covers dλ/d[x; u]
  // (the contact forces' exact derivatives the optimizer's cone rows use).
  test::checkLinearizationAgainstFd(s.model, test::State{st.q, st.dq, st.u}, test::kFdTolerance, 1.0,
                                    test::Stencil::kFourthOrder);
}

TEST_CASE("λ of the free-ball hand is each pad's force on the ball in its contact frame",
          "[hand][ball][contact]") {
  const Scene s = loadHandBall();
  const Model& m = s.model;
  Data data(m);
  std::mt19937 rng(2603);
  BallState st = consistentState(s, rng, 0.3);
  // Turn the ball away from the grasp (the frame must follow the ball, not the palm): the contact
  // rows are then off the manifold, which changes λ but not what the rows mean.
  st.q(m.configIndex("ball_yaw")) = 0.2;
  st.q(m.configIndex("ball_pitch")) = -0.1;
  st.q(m.configIndex("ball_roll")) = 0.15;
  REQUIRE(computeDynamics(m, data, st.q, st.dq, st.u).ok());
  computeKinematics(m, data, st.q, st.dq);  // every frame's pose (the contact frames included)
  const Eigen::Matrix3d R = data.framePose[m.frameIndex("ball")].linear();
  const std::vector<ConstraintPointForce> forces = computeConstraintPointForces(m, data, data.lambda);
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  const int ballJoint = m.frames()[m.frameIndex("ball")].joint;
  for (int d = 0; d < 5; ++d) {
    INFO(kDigits[d]);
    Eigen::Vector3d onBall = Eigen::Vector3d::Zero();
    for (const ConstraintPointForce& f : forces)
      if (f.row / 3 == d && f.joint == ballJoint) onBall += f.force;
    total += onBall;
    // The contact frame in world axes: the rows' directions (ball axes) turned by R.
    Eigen::Matrix3d frame;
    for (int k = 0; k < 3; ++k) frame.col(k) = R * m.constraints()[3 * d + k].direction;
    CHECK((frame.transpose() * frame - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-14);
    // The inward normal points from the contact point to the centre; the contact point lies on the
    // ball (radius 35 mm) to the grasp program's tolerance (its pads on the sphere to ~1e-9 m).
    const Eigen::Vector3d r = data.framePose[m.frameIndex(std::string("ball_contact_") + kDigits[d])].translation() -
                              data.framePose[m.frameIndex("ball")].translation();
    CHECK(std::abs(r.norm() - 0.035) < 1e-9);
    CHECK((frame.col(0) + r.normalized()).norm() < 1e-12);
    // λ_(n, t1, t2) are the components of the pad's force on the ball in that frame.
    const Eigen::Vector3d inFrame = frame.transpose() * onBall;
    INFO("lambda " << data.lambda.segment<3>(3 * d).transpose() << ", in frame " << inFrame.transpose());
    CHECK(data.lambda.segment<3>(3 * d).norm() > 1e-3);  // a real force, not a vacuous comparison
    CHECK((inFrame - data.lambda.segment<3>(3 * d)).cwiseAbs().maxCoeff() <=
          1e-12 * data.lambda.segment<3>(3 * d).norm());
  }
  // Newton for the ball's centre (its translations are world translations of the centre):
  // m c̈ = m g + Σ pad forces, an identity between the constraint forces and q̈.
  const Eigen::Vector3d cdd = data.qdd.segment<3>(m.configIndex("ball_x"));
  const Eigen::Vector3d residual = 0.080 * cdd - (0.080 * Eigen::Vector3d(0.0, 0.0, -9.81) + total);
  INFO("residual " << residual.transpose() << ", total " << total.transpose());
  CHECK(residual.norm() <= 1e-10 * (total.norm() + 0.080 * 9.81));
}
