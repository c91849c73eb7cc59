// tests/core/test_urdf.cpp — URDF import (trellis/core/urdf.hpp): the real robots of
// tests/data/robots (structure, M symmetric positive definite, linearization against central
// differences, B = [0; M⁻¹], energy balance), the same robots written as a scene or built in C++
// (A, B equal to 1e-14), scenes that include a URDF, compound joints, and the refusals.
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/linearization_checks.hpp"
#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>
#include <trellis/core/urdf.hpp>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>

using namespace trellis;
using namespace trellis::test;

namespace {

std::string robotPath(const std::string& file) { return std::string(TRELLIS_SOURCE_DIR) + "/tests/data/robots/" + file; }

struct RobotCase {
  const char* file;
  int nq;
  int nframes;  ///< links + "<link>:inertial" frames
  double uRange;  ///< inputs of the random states: torques the robot's scale makes sensible
};
// Link counts from tests/data/robots/README.md; the inertial frames are the links (not the root)
// whose <inertial> origin is not the identity. Input ranges: the Leap hand's phalanges weigh
// 10–40 g with inertias near 1e-5 kg m², so 1 N m would give q̈ ~ 1e5 rad/s² and central
// differences (of q̈ and of the energy) that lose five digits to rounding; 1e-3 N m is its scale.
const RobotCase kRobots[] = {
    {"double_pendulum_continuous.urdf", 2, 3 + 2, 0.1},
    {"panda.urdf", 9, 13 + 7 + 1, 1.0},
    {"solo12.urdf", 12, 17 + 16, 1.0},
    {"leap_hand_right.urdf", 16, 22, 1e-3},
};

/// dE/dt (central difference along the motion) against the non-conservative power.
void checkEnergyBalance(const Model& model, const State& s) {
  const int n = model.nq();
  Data data(model), work(model);
  REQUIRE(computeDynamics(model, data, s.q, s.dq, s.u).ok());
  Eigen::VectorXd x(2 * n), xdot(2 * n);
  x << s.q, s.dq;
  xdot << s.dq, data.qdd;
  const VectorFunction energy = [&](const Eigen::VectorXd& xx) {
    return Eigen::VectorXd::Constant(1, computeEnergy(model, work, xx.head(n), xx.tail(n)).total());
  };
  const double dEdt = centralDifferenceDirectional(energy, x, xdot)[0];
  const double power = computeNonConservativePower(model, work, s.q, s.dq, s.u);
  const Energy E = computeEnergy(model, work, s.q, s.dq);
  const double scale = std::max({1.0, std::abs(E.kinetic), std::abs(E.potential), std::abs(power)});
  INFO("dE/dt = " << dEdt << ", power = " << power);
  // Central difference error ~eps^(2/3) relative; 1e-7 leaves three orders (test_identities).
  CHECK(std::abs(dEdt - power) <= 1e-7 * scale);
}

void checkSameLinearization(const Model& expected, const Model& got, const State& s, double tol = 1e-14) {
  Data d1(expected), d2(got);
  REQUIRE(computeLinearization(expected, d1, s.q, s.dq, s.u).ok());
  REQUIRE(computeLinearization(got, d2, s.q, s.dq, s.u).ok());
  TRELLIS_CHECK_MATRIX(d1.A, d2.A, tol, Scale::kMatrix);
  TRELLIS_CHECK_MATRIX(d1.B, d2.B, tol, Scale::kMatrix);
}

Eigen::Matrix4d translation(double x, double y, double z) {
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  g.topRightCorner<3, 1>() << x, y, z;
  return g;
}
Eigen::Matrix4d rotationX(double angle) {
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  g.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitX()).toRotationMatrix();
  return g;
}
Mass mass(double m, double ixx, double ixy, double ixz, double iyy, double iyz, double izz) {
  Mass r;
  r.m = m;
  r.inertia << ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz;
  return r;
}

}  // namespace

TEST_CASE("URDF robots load with links as frames and one input per joint", "[urdf]") {
  for (const RobotCase& r : kRobots) {
    SECTION(r.file) {
      const Scene scene = loadScene(robotPath(r.file));  // through the scene loader, as the CLI does
      const Model& m = scene.model;
      CHECK(m.nq() == r.nq);
      CHECK(m.nu() == r.nq);
      CHECK(m.inputNames() == m.configNames());
      CHECK(m.nframes() == r.nframes);
      CHECK(m.gravity() == Eigen::Vector3d(0, 0, -9.81));
      CHECK(m.nc() == 0);
      CHECK(scene.q.size() == r.nq);
    }
  }
  SECTION("names") {
    const Model m = loadUrdf(robotPath("leap_hand_right.urdf")).model;
    CHECK(m.configIndex("0") >= 0);  // joint names that are numbers
    CHECK(m.configIndex("15") >= 0);
    const Model p = loadUrdf(robotPath("panda.urdf")).model;
    CHECK(p.frameIndex("panda_hand_tcp") >= 0);
    CHECK(p.frameIndex("panda_link0") >= 0);
    CHECK(p.damping()[p.configIndex("panda_joint3")] == 0.003);
    CHECK(p.damping()[p.configIndex("panda_finger_joint2")] == 0.3);
  }
  SECTION("inputs off, other gravity") {
    UrdfOptions o;
    o.jointInputs = false;
    o.gravity = Eigen::Vector3d(0, -9.81, 0);
    const Model m = loadUrdf(robotPath("panda.urdf"), o).model;
    CHECK(m.nu() == 0);
    CHECK(m.gravity() == Eigen::Vector3d(0, -9.81, 0));
  }
  SECTION("joint limits are kept as metadata") {
    std::ifstream f(robotPath("panda.urdf"));
    const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    const UrdfImport robot = importUrdf(text, "panda.urdf");
    REQUIRE(robot.joints.size() == 9);
    CHECK(robot.joints[0].name == "panda_joint1");
    CHECK(robot.joints[0].hasLimits);
    CHECK(robot.joints[0].upper == 2.8973);
    CHECK(robot.joints[0].effort == 87.0);
  }
}

TEST_CASE("URDF robots: M SPD, linearization vs central differences, B = [0; M^-1], energy balance",
          "[urdf][linearization][fd]") {
  for (const RobotCase& r : kRobots) {
    SECTION(r.file) {
      const Model model = loadScene(robotPath(r.file)).model;
      std::mt19937 rng(900 + static_cast<std::uint32_t>(r.nq));
      for (int k = 0; k < 2; ++k) {
        const State s = randomState(model, rng, 1.2, 1.0, r.uRange);
        INFO("random state #" << k);
        checkLinearizationAgainstFd(model, s);
        Data data(model);
        REQUIRE(computeLinearization(model, data, s.q, s.dq, s.u).ok());
        const Eigen::MatrixXd M = data.M;
        CHECK((M - M.transpose()).cwiseAbs().maxCoeff() <= 1e-14 * M.cwiseAbs().maxCoeff());
        CHECK(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(M).eigenvalues().minCoeff() > 0.0);
        // Default inputs: ∂Q/∂u = I, so B = [0; M⁻¹] (relative to M⁻¹'s scale: rounding only).
        const int n = model.nq();
        const Eigen::MatrixXd Minv = M.llt().solve(Eigen::MatrixXd::Identity(n, n));
        CHECK(data.B.topRows(n).isZero(0.0));
        const double scale = Minv.cwiseAbs().maxCoeff();
        CHECK((data.B.bottomRows(n) - Minv).cwiseAbs().maxCoeff() <= 1e-10 * scale);
        checkEnergyBalance(model, s);
      }
    }
  }
}

TEST_CASE("URDF double pendulum equals the same system as a scene and in C++", "[urdf][equivalence]") {
  const Model urdf = loadScene(robotPath("double_pendulum_continuous.urdf")).model;
  // Built by hand from the file's numbers with primitives (rx joints, tx/tz placements).
  ModelBuilder b;
  b.addFrame("base_link", "world", Transform::constSE3(Eigen::Matrix4d::Identity()));
  b.addFrame("o1", "base_link", Transform::constSE3(translation(0.0060872, 0, 0.035)));
  b.addFrame("link1", "o1", Transform::rx("joint1"));
  b.addFrame("c1", "link1", Transform::constSE3(translation(0.0086107, 2.1727E-06, 0.036012)),
             mass(0.26703, 0.00040827, 1.2675E-09, 1.8738E-05, 0.00038791, 3.5443E-08, 3.6421E-05));
  b.addFrame("o2", "link1", Transform::constSE3(translation(0.023, 0, 0.1)));
  b.addFrame("link2", "o2", Transform::rx("joint2"));
  b.addFrame("c2", "link2", Transform::constSE3(translation(-0.0050107, 1.9371E-10, 0.10088)),
             mass(0.33238, 0.0011753, -3.854E-13, -2.9304E-08, 0.0011666, -5.2365E-12, 1.4553E-05));
  b.addDamping(0.0, {{"joint1", 0.05}, {"joint2", 0.05}});
  b.addConfigForce("joint1", "joint1");
  b.addConfigForce("joint2", "joint2");
  b.addGravity(Eigen::Vector3d(0, 0, -9.81));
  const Model cpp = b.finalize();
  const Scene scene = parseScene(R"({"frames": [{"name": "base_link", "type": "tx", "value": 0, "children": [
      {"name": "o1x", "type": "tx", "value": 0.0060872, "children": [{"name": "o1", "type": "tz", "value": 0.035, "children": [
        {"name": "link1", "type": "rx", "config": "joint1", "children": [
          {"name": "c1", "type": "t_axis", "axis": [1, 0, 0], "value": 0, "origin": {"xyz": [0.0086107, 2.1727E-06, 0.036012]},
           "mass": {"m": 0.26703, "inertia": [0.00040827, 0.00038791, 3.6421E-05, 1.2675E-09, 1.8738E-05, 3.5443E-08]}},
          {"name": "o2", "type": "t_axis", "axis": [1, 0, 0], "value": 0, "origin": {"xyz": [0.023, 0, 0.1]}, "children": [
            {"name": "link2", "type": "rx", "config": "joint2", "children": [
              {"name": "c2", "type": "t_axis", "axis": [1, 0, 0], "value": 0, "origin": {"xyz": [-0.0050107, 1.9371E-10, 0.10088]},
               "mass": {"m": 0.33238, "inertia": [0.0011753, 0.0011666, 1.4553E-05, -3.854E-13, -2.9304E-08, -5.2365E-12]}}]}]}]}]}]}]}],
    "potentials": [{"type": "gravity", "g": [0, 0, -9.81]}],
    "forces": [{"type": "damping", "coefficients": {"joint1": 0.05, "joint2": 0.05}},
               {"type": "config_force", "config": "joint1", "input": "joint1"},
               {"type": "config_force", "config": "joint2", "input": "joint2"}]})");
  std::mt19937 rng(31);
  for (int k = 0; k < 3; ++k) {
    const State s = randomState(urdf, rng, 3.0, 2.0, 1.0);
    checkSameLinearization(cpp, urdf, s);
    checkSameLinearization(scene.model, urdf, s);
  }
}

TEST_CASE("URDF panda equals the arm built in C++ from primitives", "[urdf][equivalence]") {
  const Model urdf = loadUrdf(robotPath("panda.urdf")).model;
  // Transcribed from panda.urdf: joint origins (xyz, roll), link inertials (COM offset, mass,
  // inertia). Every arm axis is z; origin rotations are about x only (Rx(±π/2)).
  struct ArmJoint {
    double x, y, z, roll;
  };
  const ArmJoint joints[7] = {{0, 0, 0.333, 0},       {0, 0, 0, -std::numbers::pi / 2},
                              {0, -0.316, 0, std::numbers::pi / 2}, {0.0825, 0, 0, std::numbers::pi / 2},
                              {-0.0825, 0.384, 0, -std::numbers::pi / 2}, {0, 0, 0, std::numbers::pi / 2},
                              {0.088, 0, 0, std::numbers::pi / 2}};
  struct Inertial {
    double cx, cy, cz;
    Mass m;
  };
  const Inertial links[7] = {
      {0.003875, 0.002081, -0.04762, mass(4.970684, 0.70337, -0.000139, 0.006772, 0.70661, 0.019169, 0.009117)},
      {-0.003141, -0.02872, 0.003495, mass(0.646926, 0.007962, -0.003925, 0.010254, 0.02811, 0.000704, 0.025995)},
      {2.7518e-02, 3.9252e-02, -6.6502e-02, mass(3.228604, 0.037242, -0.004761, -0.011396, 0.036155, -0.012805, 0.01083)},
      {-5.317e-02, 1.04419e-01, 2.7454e-02, mass(3.587895, 0.025853, 0.007796, -0.001332, 0.019552, 0.008641, 0.028323)},
      {-1.1953e-02, 4.1065e-02, -3.8437e-02, mass(1.225946, 0.035549, -0.002117, -0.004037, 0.029474, 0.000229, 0.008627)},
      {6.0149e-02, -1.4117e-02, -1.0517e-02, mass(1.666555, 0.001964, 0.000109, -0.001158, 0.004354, 0.000341, 0.005433)},
      {1.0517e-02, -4.252e-03, 6.1597e-02, mass(0.735522, 0.012516, -0.000428, -0.001196, 0.010027, -0.000741, 0.004815)}};
  ModelBuilder b;
  std::string parent = "panda_link0";
  b.addFrame(parent, "world", Transform::constSE3(Eigen::Matrix4d::Identity()));
  std::map<std::string, double> damping;
  for (int i = 0; i < 7; ++i) {
    const std::string k = std::to_string(i + 1), link = "panda_link" + k, joint = "panda_joint" + k;
    const ArmJoint& j = joints[i];
    b.addFrame(link + "_origin", parent, Transform::constSE3(translation(j.x, j.y, j.z) * rotationX(j.roll)));
    b.addFrame(link, link + "_origin", Transform::rz(joint));
    b.addFrame(link + "_com", link, Transform::constSE3(translation(links[i].cx, links[i].cy, links[i].cz)), links[i].m);
    damping[joint] = 0.003;
    parent = link;
  }
  b.addFrame("panda_link8", "panda_link7", Transform::tz(0.107));
  b.addFrame("panda_hand", "panda_link8", Transform::rz(-std::numbers::pi / 4));
  b.addFrame("panda_hand_com", "panda_hand", Transform::constSE3(translation(-0.01, 0, 0.03)),
             mass(0.73, 0.001, 0, 0, 0.0025, 0, 0.0017));
  const Mass finger = mass(0.015, 2.3749999999999997e-06, 0, 0, 2.3749999999999997e-06, 0, 7.5e-07);
  b.addFrame("finger_origin", "panda_hand", Transform::tz(0.0584));
  b.addFrame("panda_leftfinger", "finger_origin", Transform::ty("panda_finger_joint1"), finger);
  // axis (0, −1, 0): a translation along y of a frame turned by π about z, turned back.
  b.addFrame("flip", "finger_origin", Transform::rz(std::numbers::pi));
  b.addFrame("right_slide", "flip", Transform::ty("panda_finger_joint2"));
  b.addFrame("panda_rightfinger", "right_slide", Transform::rz(-std::numbers::pi), finger);
  damping["panda_finger_joint1"] = damping["panda_finger_joint2"] = 0.3;
  b.addDamping(0.0, damping);
  for (const auto& [joint, d] : damping) b.addConfigForce(joint, joint);
  b.addGravity(Eigen::Vector3d(0, 0, -9.81));
  const Model cpp = b.finalize();
  REQUIRE(cpp.configNames() == urdf.configNames());
  // Inputs are in another order (map order): compare B column by column through the names.
  std::mt19937 rng(41);
  for (int k = 0; k < 3; ++k) {
    State s = randomState(urdf, rng, 1.5, 1.5, 1.0);
    State sc = s;
    for (int i = 0; i < urdf.nu(); ++i) sc.u[cpp.inputIndex(urdf.inputNames()[i])] = s.u[i];
    Data d1(cpp), d2(urdf);
    REQUIRE(computeLinearization(cpp, d1, sc.q, sc.dq, sc.u).ok());
    REQUIRE(computeLinearization(urdf, d2, s.q, s.dq, s.u).ok());
    TRELLIS_CHECK_MATRIX(d1.A, d2.A, 1e-14, Scale::kMatrix);
    Eigen::MatrixXd B1(d2.B.rows(), d2.B.cols());
    for (int i = 0; i < urdf.nu(); ++i) B1.col(i) = d1.B.col(cpp.inputIndex(urdf.inputNames()[i]));
    TRELLIS_CHECK_MATRIX(B1, d2.B, 1e-14, Scale::kMatrix);
  }
}

TEST_CASE("A scene can start from a URDF and add constraints, forces and state", "[urdf][scene]") {
  const auto dir = std::filesystem::temp_directory_path() / "trellis_test_urdf_include";
  std::filesystem::create_directories(dir);
  const std::string rel = std::filesystem::relative(robotPath("double_pendulum_continuous.urdf"), dir).string();
  const auto write = [&](const std::string& text) {
    const auto path = dir / "scene.json";
    std::ofstream(path) << text;
    return path.string();
  };
  SECTION("closed chain, spring, wrench, state; relative path") {
    const Scene scene = loadScene(write(R"({"urdf": ")" + rel + R"(",
      "frames": [{"name": "anchor", "type": "t_axis", "axis": [0, 0, 1], "value": 0.2},
                 {"name": "tip", "parent": "link2", "type": "tz", "value": 0.2}],
      "constraints": [{"type": "distance", "frame1": "tip", "frame2": "anchor", "distance": 0.25}],
      "potentials": [{"type": "linear_spring", "frame1": "link1", "frame2": "anchor", "k": 3, "x0": 0.1}],
      "forces": [{"type": "body_wrench", "frame": "link2", "wrench": [0, "push", 0, 0, 0, 0]}],
      "state": {"q": {"joint1": 0.3}, "u": {"push": 0.5}}})"));
    const Model& m = scene.model;
    CHECK(m.nq() == 2);
    CHECK(m.nc() == 1);
    CHECK(m.nu() == 3);
    CHECK(scene.q[m.configIndex("joint1")] == 0.3);
    CHECK(scene.u[m.inputIndex("push")] == 0.5);
    std::mt19937 rng(51);
    checkLinearizationAgainstFd(m, randomState(m, rng));
  }
  SECTION("options: no joint inputs, zero gravity") {
    const Scene scene = loadScene(write(R"({"urdf": ")" + rel + R"(", "urdf_options": {"joint_inputs": false, "gravity": [0, 0, 0]}})"));
    CHECK(scene.model.nu() == 0);
    CHECK(scene.model.gravity().isZero(0.0));
  }
  SECTION("errors name the include") {
    CHECK_THROWS_WITH(loadScene(write(R"({"urdf": "missing.urdf"})")),
                      Catch::Contains("field 'urdf': \"missing.urdf\" cannot be read") &&
                          Catch::Contains("No such file or directory"));
    CHECK_THROWS_WITH(loadScene(write(R"({"urdf": ")" + rel + R"(", "urdf_options": {"inputs": false}})")),
                      Catch::Contains("urdf_options: field 'inputs': unknown option"));
    CHECK_THROWS_WITH(loadScene(write(R"({"urdf": ")" + rel + R"(", "constraints": [{"type": "distance", "frame1": "link9", "frame2": "world", "distance": 1}]})")),
                      Catch::Contains("field 'frame1': unknown frame \"link9\""));
    CHECK_THROWS_WITH(loadScene(write(R"({"frames": [{"name": "a", "parent": "nope", "type": "tx", "value": 1}]})")),
                      Catch::Contains("frame 'a': field 'parent': unknown frame \"nope\""));
  }
  std::filesystem::remove_all(dir);
}

namespace {

const char* kHeader = "<?xml version=\"1.0\"?>\n<robot name=\"r\">\n";

std::string robot(const std::string& body) { return std::string(kHeader) + body + "</robot>\n"; }

const char* kTwoLinks = R"(  <link name="a"/>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
)";

}  // namespace

TEST_CASE("URDF compound joints: planar and floating as primitive sequences", "[urdf][joints]") {
  SECTION("planar: translations along two unit vectors normal to the axis, then the rotation") {
    const Scene s = parseScene(robot(std::string(kTwoLinks) + R"(
  <link name="c"><inertial><origin xyz="0.2 0 0"/><mass value="0.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/></inertial></link>
  <joint name="p" type="planar"><parent link="a"/><child link="b"/><origin xyz="0 0 1" rpy="0.3 0 0"/><axis xyz="0 0.6 0.8"/></joint>
  <joint name="h" type="revolute"><parent link="b"/><child link="c"/><axis xyz="1 0 0"/></joint>
)"), "planar.urdf");
    const Model& m = s.model;
    REQUIRE(m.nq() == 4);
    CHECK(m.configNames()[0] == "p.u");
    CHECK(m.configNames()[2] == "p.theta");
    std::mt19937 rng(61);
    const State st = randomState(m, rng);
    checkLinearizationAgainstFd(m, st);
    // The plane's normal is fixed: b's position moves in the plane ⟂ (0, .6, .8) through (0, 0, 1).
    Data d(m);
    computeKinematics(m, d, st.q, st.dq);
    const Eigen::Vector3d n = poseFromXyzRpy({0, 0, 1}, {0.3, 0, 0}).topLeftCorner<3, 3>() * Eigen::Vector3d(0, 0.6, 0.8);
    CHECK(std::abs(n.dot(d.framePose[m.frameIndex("b")].translation() - Eigen::Vector3d(0, 0, 1))) < 1e-14);
    checkEnergyBalance(m, st);
  }
  SECTION("floating: x, y, z, yaw, pitch, roll") {
    const Scene s = parseScene(robot(std::string(kTwoLinks) +
                                     R"(<joint name="f" type="floating"><parent link="a"/><child link="b"/></joint>)"),
                               "floating.urdf");
    const Model& m = s.model;
    REQUIRE(m.nq() == 6);
    CHECK(m.configNames()[3] == "f.yaw");
    CHECK(m.configNames()[5] == "f.roll");
    std::mt19937 rng(62);
    checkLinearizationAgainstFd(m, randomState(m, rng));
    // Child pose = T(x, y, z) · Rz(yaw) Ry(pitch) Rx(roll), the URDF rpy convention.
    Eigen::VectorXd q(6);
    q << 0.1, 0.2, 0.3, 0.4, 0.5, 0.6;
    Data d(m);
    computeKinematics(m, d, q, Eigen::VectorXd::Zero(6));
    const Eigen::Matrix4d expected = poseFromXyzRpy({0.1, 0.2, 0.3}, {0.6, 0.5, 0.4});
    CHECK((d.framePose[m.frameIndex("b")].matrix() - expected).cwiseAbs().maxCoeff() < 1e-15);
  }
}

TEST_CASE("URDF root link named world is the world frame (ROS convention)", "[urdf]") {
  const std::string arm = R"(
  <link name="b"><inertial><origin xyz="0 0 -0.3"/><mass value="0.7"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.012"/></inertial></link>
  <joint name="h" type="revolute"><parent link="base"/><child link="b"/><origin xyz="0 0.1 0.2"/><axis xyz="0 1 0"/></joint>
)";
  const std::string mount = R"(<origin xyz="0.5 -0.2 1" rpy="0.1 0.2 0.3"/>)";
  // The same arm: on a base fixed to a root named 'world', and on a root 'base' placed by hand.
  const Scene onWorld = parseScene(robot(R"(<link name="world"/><link name="base"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/>)" + mount + "</joint>" + arm), "w.urdf");
  const Scene onBase = parseScene(robot(R"(<link name="base"/>)" + arm), "b.urdf");
  const Model& m = onWorld.model;
  REQUIRE(m.nq() == 1);
  CHECK_NOTHROW(m.frameIndex("base"));
  std::mt19937 rng(63);
  const State st = randomState(m, rng);
  checkLinearizationAgainstFd(m, st);
  // Frame b relative to base is the same in both; base sits at the mount pose in the first.
  Data dw(m), db(onBase.model);
  computeKinematics(m, dw, st.q, st.dq);
  computeKinematics(onBase.model, db, st.q, st.dq);
  const Eigen::Matrix4d mountPose = poseFromXyzRpy({0.5, -0.2, 1}, {0.1, 0.2, 0.3});
  CHECK((dw.framePose[m.frameIndex("base")].matrix() - mountPose).cwiseAbs().maxCoeff() < 1e-15);
  const Eigen::Matrix4d rel = mountPose.inverse() * dw.framePose[m.frameIndex("b")].matrix();
  CHECK((rel - db.framePose[onBase.model.frameIndex("b")].matrix()).cwiseAbs().maxCoeff() < 1e-14);
}

TEST_CASE("URDF joint whose parent is an undeclared 'world' hangs from the world (Drake, Pinocchio)", "[urdf]") {
  // Drake's acrobot welds its base so: <joint type="fixed"><parent link="world"/>… with no <link name="world"/>.
  const std::string body = R"(
  <link name="base_link"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="upper"><inertial><origin xyz="0 0 -0.5"/><mass value="1"/><inertia ixx="0.083" ixy="0" ixz="0" iyy="0.083" iyz="0" izz="0.001"/></inertial></link>
  <link name="lower"><inertial><origin xyz="0 0 -1"/><mass value="1"/><inertia ixx="0.33" ixy="0" ixz="0" iyy="0.33" iyz="0" izz="0.001"/></inertial></link>
  <joint name="base_weld" type="fixed"><parent link="world"/><child link="base_link"/><origin xyz="0 0 2"/></joint>
  <joint name="shoulder" type="continuous"><parent link="base_link"/><child link="upper"/><axis xyz="0 1 0"/><dynamics damping="0.1"/></joint>
  <joint name="elbow" type="continuous"><parent link="upper"/><child link="lower"/><origin xyz="0 0 -1"/><axis xyz="0 1 0"/><dynamics damping="0.1"/></joint>
)";
  const Scene implicit = parseScene(robot(body), "acrobot.urdf");
  const Scene declared = parseScene(robot("  <link name=\"world\"/>" + body), "acrobot_world.urdf");
  REQUIRE(implicit.model.nq() == 2);
  CHECK(implicit.model.configNames() == std::vector<std::string>{"shoulder", "elbow"});
  CHECK(importUrdf(robot(body), "acrobot.urdf").rootLink == "world");
  std::mt19937 rng(64);
  for (int k = 0; k < 2; ++k) checkSameLinearization(declared.model, implicit.model, randomState(implicit.model, rng), 0.0);
  Data d(implicit.model);
  computeKinematics(implicit.model, d, Eigen::VectorXd::Zero(2), Eigen::VectorXd::Zero(2));
  CHECK(d.framePose[implicit.model.frameIndex("base_link")].translation() == Eigen::Vector3d(0, 0, 2));
  // Another undeclared parent is still an unknown link.
  CHECK_THROWS_WITH(parseScene(robot(R"(<link name="a"/><joint name="j" type="fixed"><parent link="ground"/><child link="a"/></joint>)"), "bad.urdf"),
                    Catch::Contains("joint 'j': <parent> attribute 'link': unknown link 'ground'"));
}

TEST_CASE("URDF joint limits reach the scene: position limits and effort per coordinate", "[urdf][limits]") {
  const Scene panda = loadScene(robotPath("panda.urdf"));
  const Model& m = panda.model;
  REQUIRE(panda.lowerLimit.size() == m.nq());
  const int j1 = m.configIndex("panda_joint1"), f1 = m.configIndex("panda_finger_joint1");
  CHECK(panda.lowerLimit[j1] == -2.8973);
  CHECK(panda.upperLimit[j1] == 2.8973);
  CHECK(panda.effortLimit[j1] == 87.0);
  CHECK(panda.upperLimit[f1] == 0.04);
  // Continuous joints have no position limits; a scene that includes a URDF keeps them by name,
  // its own coordinates unlimited.
  const Scene pendulum = loadScene(robotPath("double_pendulum_continuous.urdf"));
  CHECK(std::isinf(pendulum.lowerLimit[0]));
  CHECK(std::isinf(pendulum.upperLimit[1]));
  const Scene standing = loadScene(robotPath("solo12_standing.json"));
  REQUIRE(standing.upperLimit.size() == 18);
  CHECK(std::isinf(standing.upperLimit[standing.model.configIndex("floating_base.z")]));
  CHECK(standing.upperLimit[standing.model.configIndex("FL_KFE")] == 10.0);
  // A scene without a URDF has none.
  CHECK(parseScene(R"({"frames": [{"name": "a", "type": "rz", "config": "q"}]})").lowerLimit.size() == 0);
}

TEST_CASE("URDF Coulomb friction: refused, or dropped with a warning on request", "[urdf][friction]") {
  const std::string body = std::string(kTwoLinks) + R"(<joint name="j" type="revolute"><parent link="a"/><child link="b"/>
<dynamics damping="0.1" friction="0.2"/></joint>
)";
  CHECK_THROWS_WITH(importUrdf(robot(body), "f.urdf"),
                    Catch::Contains("f.urdf:6: joint 'j': <dynamics> attribute 'friction': value '0.2': Coulomb friction is "
                                    "not modelled") && Catch::Contains("ignore_friction"));
  UrdfOptions o;
  o.ignoreFriction = true;
  const Scene s = sceneFromUrdf(importUrdf(robot(body), "f.urdf", o));
  REQUIRE(s.warnings.size() == 1);
  CHECK(s.warnings[0] == "f.urdf:6: joint 'j': <dynamics> attribute 'friction': value '0.2': Coulomb friction ignored (ignore_friction)");
  CHECK(s.model.damping()[0] == 0.1);  // the viscous part stays
  // The same through a scene's urdf_options, and <joint_properties friction> (CAD exporters).
  const std::string props = std::string(kTwoLinks) + R"(<joint name="j" type="revolute"><parent link="a"/><child link="b"/>
<joint_properties friction="0.5"/></joint>
)";
  CHECK_THROWS_WITH(importUrdf(robot(props), "p.urdf"), Catch::Contains("<joint_properties> attribute 'friction': value '0.5'"));
  CHECK(sceneFromUrdf(importUrdf(robot(props), "p.urdf", o)).warnings.size() == 1);
  const auto dir = std::filesystem::temp_directory_path() / "trellis_test_urdf_friction";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "f.urdf") << robot(body);
  std::ofstream(dir / "f.json") << R"({"urdf": "f.urdf", "urdf_options": {"ignore_friction": true}})";
  const Scene viaScene = loadScene((dir / "f.json").string());
  REQUIRE(viaScene.warnings.size() == 1);
  CHECK_THAT(viaScene.warnings[0], Catch::Contains("f.urdf:6") && Catch::Contains("Coulomb friction ignored"));
  std::ofstream(dir / "g.json") << R"({"urdf": "f.urdf", "urdf_options": {"ignore_friction": 1}})";
  CHECK_THROWS_WITH(loadScene((dir / "g.json").string()), Catch::Contains("ignore_friction") && Catch::Contains("must be true or false"));
  std::filesystem::remove_all(dir);
}

namespace {

/// The sum of every <mass value> of a URDF text (the robot's total mass).
double totalMass(const std::string& text) {
  double sum = 0.0;
  const std::string key = "<mass value=\"";
  for (std::size_t at = text.find(key); at != std::string::npos; at = text.find(key, at + 1))
    sum += std::stod(text.substr(at + key.size()));
  return sum;
}

std::string readFile(const std::string& path) {
  std::ifstream f(path);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

}  // namespace

TEST_CASE("URDF floating bases: unactuated by default, floating_root, contacts from a scene", "[urdf][floating]") {
  SECTION("floating and planar coordinates get no inputs unless base_inputs") {
    const std::string body = std::string(kTwoLinks) + R"(<link name="c"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
<joint name="f" type="floating"><parent link="a"/><child link="b"/></joint>
<joint name="h" type="revolute"><parent link="b"/><child link="c"/></joint>
)";
    const Model m = sceneFromUrdf(importUrdf(robot(body), "f.urdf")).model;
    CHECK(m.nq() == 7);
    CHECK(m.inputNames() == std::vector<std::string>{"h"});
    UrdfOptions o;
    o.baseInputs = true;
    const Model actuated = sceneFromUrdf(importUrdf(robot(body), "f.urdf", o)).model;
    CHECK(actuated.inputNames() == actuated.configNames());
    const std::string planar = std::string(kTwoLinks) + R"(<joint name="p" type="planar"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>)";
    CHECK(sceneFromUrdf(importUrdf(robot(planar), "p.urdf")).model.nu() == 0);
    CHECK(sceneFromUrdf(importUrdf(robot(planar), "p.urdf", o)).model.nu() == 3);
  }
  SECTION("floating_root: solo12's trunk floats, its mass counts, the legs are the inputs") {
    UrdfOptions o;
    o.floatingRoot = true;
    const std::string text = readFile(robotPath("solo12.urdf"));
    const Model m = sceneFromUrdf(importUrdf(text, "solo12.urdf", o)).model;
    REQUIRE(m.nq() == 18);
    CHECK(m.configNames()[0] == "floating_base.x");
    CHECK(m.configNames()[5] == "floating_base.roll");
    CHECK(m.nu() == 12);
    CHECK(m.inputNames()[0] == "FL_HAA");
    // M's translational entry is the total mass, the trunk's 1.16 kg included.
    Data d(m);
    REQUIRE(computeDynamics(m, d, Eigen::VectorXd::Zero(18), Eigen::VectorXd::Zero(18), Eigen::VectorXd::Zero(12)).ok());
    const double total = totalMass(text);
    CHECK(total > 2.4);
    CHECK(std::abs(d.M(0, 0) - total) <= 1e-14 * total);
    CHECK(std::abs(d.M(2, 2) - total) <= 1e-14 * total);
    // Nothing holds it: it falls with g, whatever the legs do.
    CHECK(std::abs(d.qdd[2] + 9.81) <= 1e-12);
    std::mt19937 rng(65);
    checkLinearizationAgainstFd(m, randomState(m, rng, 0.5, 1.0, 0.1));
  }
  SECTION("floating_root on a root named world makes its fixed joint floating") {
    const std::string body = R"(<link name="world"/>)" + std::string(kTwoLinks) + R"(
<joint name="weld" type="fixed"><parent link="world"/><child link="a"/><origin xyz="0 0 1"/></joint>
<joint name="h" type="revolute"><parent link="a"/><child link="b"/></joint>
)";
    UrdfOptions o;
    o.floatingRoot = true;
    const Model m = sceneFromUrdf(importUrdf(robot(body), "w.urdf", o)).model;
    CHECK(m.configNames()[0] == "weld.x");
    CHECK(m.nq() == 7);
    CHECK(m.inputNames() == std::vector<std::string>{"h"});
    const std::string twoChildren = body + R"(<link name="c"/><joint name="k" type="fixed"><parent link="world"/><child link="c"/></joint>)";
    CHECK_THROWS_WITH(importUrdf(robot(twoChildren), "w.urdf", o),
                      Catch::Contains("floating_root: the root link is 'world' and 2 joints hang from it"));
    const std::string clash = std::string(kTwoLinks) + R"(<joint name="floating_base" type="revolute"><parent link="a"/><child link="b"/></joint>)";
    CHECK_THROWS_WITH(importUrdf(robot(clash), "c.urdf", o),
                      Catch::Contains("floating_root: the file already has a joint or link named 'floating_base'"));
  }
  SECTION("contacts from a scene overlay hold the standing robot; without them nothing does") {
    const Scene standing = loadScene(robotPath("solo12_standing.json"));
    const Model& m = standing.model;
    REQUIRE(m.nq() == 18);
    REQUIRE(m.nc() == 12);
    Data d(m);
    const InverseDynamicsResult held = computeHoldingInputs(m, d, standing.q);
    INFO(held.describe());
    REQUIRE(held.ok());
    // The four normal forces carry the weight (λ of the z rows: h = (p_foot − p_ground)·e_z).
    double normal = 0.0;
    for (int r = 2; r < 12; r += 3) normal += held.lambda[r];
    const double weight = totalMass(readFile(robotPath("solo12.urdf"))) * 9.81;
    CHECK(std::abs(normal - weight) <= 1e-12 * weight);
    // The same pose on the robot without its contacts cannot be held by the legs alone.
    UrdfOptions o;
    o.floatingRoot = true;
    const Model free = sceneFromUrdf(importUrdf(readFile(robotPath("solo12.urdf")), "solo12.urdf", o)).model;
    Data df(free);
    const InverseDynamicsResult r = computeHoldingInputs(free, df, standing.q);
    CHECK(r.status.code == InverseDynamicsCode::kUnreachable);
    CHECK(std::abs(std::abs(r.residual[2]) - weight) <= 1e-12 * weight);  // the weight, on floating_base.z
  }
}

namespace {

/// A link with mass m and a diagonal inertia (its centre of mass at the origin unless com is given).
std::string massLink(const std::string& name, double m, double ixx, double iyy, double izz, const std::string& com = "0 0 0") {
  std::ostringstream s;
  s << "<link name=\"" << name << "\"><inertial><origin xyz=\"" << com << "\"/><mass value=\"" << m
    << "\"/><inertia ixx=\"" << ixx << "\" ixy=\"0\" ixz=\"0\" iyy=\"" << iyy << "\" iyz=\"0\" izz=\"" << izz
    << "\"/></inertial></link>\n";
  return s.str();
}

/// A 3D chain with gravity and two mimics: a prismatic joint following a revolute one two levels
/// up (multiplier 0.5, offset 0.1) and a continuous joint following another with multiplier −1.
std::string mimicChainUrdf() {
  return robot("<link name=\"base\"/>\n" + massLink("l1", 1.2, 0.02, 0.03, 0.025, "0.1 0 -0.2") +
               massLink("l2", 0.8, 0.01, 0.015, 0.012, "0 0.05 -0.15") + massLink("l3", 0.5, 0.004, 0.005, 0.006, "0.02 0 0") +
               massLink("l4", 0.3, 0.002, 0.003, 0.001, "0 0 -0.1") + R"(
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 1 0"/><origin xyz="0 0 1" rpy="0.1 0 0"/></joint>
<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><axis xyz="1 0 0.3"/><origin xyz="0.1 0 -0.4"/></joint>
<joint name="s3" type="prismatic"><parent link="l2"/><child link="l3"/><axis xyz="0 0.6 0.8"/><origin xyz="0 0 -0.3"/>
  <mimic joint="j1" multiplier="0.5" offset="0.1"/></joint>
<joint name="j4" type="continuous"><parent link="l2"/><child link="l4"/><axis xyz="0 0 1"/><origin xyz="0.05 0 -0.3" rpy="0 0.4 0"/>
  <mimic joint="j2" multiplier="-1"/></joint>
)");
}

}  // namespace

TEST_CASE("URDF <mimic> is a coordinate coupling q_j = m q_i + o", "[urdf][mimic]") {
  SECTION("two coaxial rotors coupled by m move as one joint with inertia I_b + m² I_c") {
    // Both spin about the world z axis through their centres of mass: gravity exerts no torque.
    // With q_c = m q_b + o, T = ½ (I_b + m² I_c) q̇_b², so q̈_b = τ / (I_b + m² I_c), q̈_c = m q̈_b, and
    // the coupling's multiplier is the torque on c: I_c q̈_c = λ.
    const double Ib = 0.3, Ic = 0.05, m = -2.0, o = 0.3, tau = 1.5;
    std::ostringstream text;
    text << "<link name=\"a\"/>\n" << massLink("b", 1.0, 0.2, 0.2, Ib) << massLink("c", 2.0, 0.1, 0.1, Ic)
         << R"(<joint name="jb" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>
<joint name="jc" type="revolute"><parent link="a"/><child link="c"/><axis xyz="0 0 1"/>)"
         << "<mimic joint=\"jb\" multiplier=\"" << m << "\" offset=\"" << o << "\"/></joint>\n";
    const Scene scene = sceneFromUrdf(importUrdf(robot(text.str()), "rotors.urdf"));
    const Model& model = scene.model;
    REQUIRE(model.nq() == 2);
    REQUIRE(model.nc() == 1);
    CHECK(model.constraints()[0].type == ConstraintType::kCoordinateCoupling);
    CHECK(model.inputNames() == std::vector<std::string>{"jb"});  // the follower has no input of its own
    Data d(model);
    const Eigen::Vector2d q(0.4, m * 0.4 + o), dq(0.7, m * 0.7);
    REQUIRE(computeDynamics(model, d, q, dq, Eigen::VectorXd::Constant(1, tau)).ok());
    const double qddB = tau / (Ib + m * m * Ic);
    CHECK(std::abs(d.qdd[0] - qddB) <= 1e-14 * std::abs(qddB));
    CHECK(std::abs(d.qdd[1] - m * qddB) <= 1e-14 * std::abs(m * qddB));
    CHECK(std::abs(d.lambda[0] - Ic * m * qddB) <= 1e-13 * std::abs(Ic * m * qddB));
    // h and A: the row is e_c − m e_b, h = q_c − m q_b − o.
    computeConstraints(model, d, q, dq);
    CHECK(std::abs(d.constraintValue[0]) <= 1e-15);
    CHECK(d.constraintJacobian(0, 0) == -m);
    CHECK(std::abs(d.constraintJacobian(0, 1) - 1.0) <= 1e-15);
    std::mt19937 rng(66);
    checkLinearizationAgainstFd(model, randomState(model, rng));
  }
  SECTION("a 3D chain with revolute, prismatic and continuous mimics: central differences, energy") {
    const Model model = sceneFromUrdf(importUrdf(mimicChainUrdf(), "chain.urdf")).model;
    REQUIRE(model.nq() == 4);
    REQUIRE(model.nc() == 2);
    CHECK(model.inputNames() == std::vector<std::string>{"j1", "j2"});
    std::mt19937 rng(67);
    for (int k = 0; k < 3; ++k) {
      // Off the constraint manifold too: h, A and the forces are defined everywhere.
      const State s = randomState(model, rng, 1.2, 1.0, 0.5);
      INFO("random state #" << k);
      checkLinearizationAgainstFd(model, s);
    }
    // On the manifold the coupled chain conserves energy up to the input power (the couplings' forces do no work).
    State s = randomState(model, rng, 1.2, 1.0, 0.5);
    s.q[2] = 0.5 * s.q[0] + 0.1;
    s.q[3] = -s.q[1];
    s.dq[2] = 0.5 * s.dq[0];
    s.dq[3] = -s.dq[1];
    checkEnergyBalance(model, s);
  }
  SECTION("panda with its finger mimic (as upstream): one input fewer, one coupling row") {
    std::string text = readFile(robotPath("panda.urdf"));
    const std::string at = R"(<child link="panda_rightfinger" />)";
    REQUIRE(text.find(at) != std::string::npos);
    text.insert(text.find(at) + at.size(), R"(<mimic joint="panda_finger_joint1" />)");
    const Model model = sceneFromUrdf(importUrdf(text, "panda_mimic.urdf")).model;
    CHECK(model.nq() == 9);
    CHECK(model.nu() == 8);
    REQUIRE(model.nc() == 1);
    std::mt19937 rng(68);
    checkLinearizationAgainstFd(model, randomState(model, rng));
  }
  SECTION("the same coupling written in a scene over the URDF (coordinate_coupling) gives the same model") {
    const auto dir = std::filesystem::temp_directory_path() / "trellis_test_urdf_mimic";
    std::filesystem::create_directories(dir);
    std::string plain = mimicChainUrdf();
    for (const char* tag : {R"(<mimic joint="j1" multiplier="0.5" offset="0.1"/>)", R"(<mimic joint="j2" multiplier="-1"/>)"}) {
      REQUIRE(plain.find(tag) != std::string::npos);
      plain.erase(plain.find(tag), std::string(tag).size());
    }
    std::ofstream(dir / "chain.urdf") << plain;
    std::ofstream(dir / "chain.json") << R"({"urdf": "chain.urdf", "urdf_options": {"joint_inputs": false},
      "forces": [{"type": "config_force", "config": "j1", "input": "j1"}, {"type": "config_force", "config": "j2", "input": "j2"}],
      "constraints": [{"type": "coordinate_coupling", "config": "s3", "leader": "j1", "multiplier": 0.5, "offset": 0.1},
                      {"type": "coordinate_coupling", "config": "j4", "leader": "j2", "multiplier": -1}]})";
    const Model viaScene = loadScene((dir / "chain.json").string()).model;
    const Model viaUrdf = sceneFromUrdf(importUrdf(mimicChainUrdf(), "chain.urdf")).model;
    std::mt19937 rng(69);
    checkSameLinearization(viaUrdf, viaScene, randomState(viaUrdf, rng), 0.0);
    std::ofstream(dir / "bad.json") << R"({"urdf": "chain.urdf", "constraints": [{"type": "coordinate_coupling", "config": "s3", "leader": "j9", "multiplier": 1}]})";
    CHECK_THROWS_WITH(loadScene((dir / "bad.json").string()), Catch::Contains("field 'leader': unknown configuration variable \"j9\""));
    std::filesystem::remove_all(dir);
  }
  SECTION("refusals name the joint and the value") {
    const std::string two = std::string(kTwoLinks) + R"(<link name="c"/><joint name="j" type="revolute"><parent link="a"/><child link="b"/></joint>
)";
    CHECK_THROWS_WITH(importUrdf(robot(two + R"(<joint name="k" type="revolute"><parent link="b"/><child link="c"/><mimic joint="nope"/></joint>)"), "m.urdf"),
                      Catch::Contains("m.urdf:6: joint 'k': <mimic> attribute 'joint': value 'nope' is not a movable joint of the file"));
    CHECK_THROWS_WITH(importUrdf(robot(two + R"(<joint name="k" type="revolute"><parent link="b"/><child link="c"/><mimic joint="j" multiplier="0"/></joint>)"), "m.urdf"),
                      Catch::Contains("joint 'k': <mimic> attribute 'multiplier': value '0' would fix the joint"));
    CHECK_THROWS_WITH(importUrdf(robot(two + R"(<joint name="k" type="revolute"><parent link="b"/><child link="c"/><mimic/></joint>)"), "m.urdf"),
                      Catch::Contains("joint 'k': <mimic> attribute 'joint': missing"));
    CHECK_THROWS_WITH(importUrdf(robot(two + R"(<joint name="k" type="floating"><parent link="b"/><child link="c"/><mimic joint="j"/></joint>)"), "m.urdf"),
                      Catch::Contains("joint 'k': <mimic> on a floating joint"));
  }
}

TEST_CASE("URDF errors name link, joint, attribute, value and line", "[urdf][errors]") {
  const auto fails = [](const std::string& body, const std::string& expected) {
    INFO("expected message containing: " << expected);
    CHECK_THROWS_WITH(parseScene(robot(body), "bad.urdf"), Catch::Contains(expected));
  };
  SECTION("malformed XML gives the parser's line") {
    CHECK_THROWS_WITH(parseScene(std::string(kHeader) + "  <link name=\"a\">\n</robot>", "bad.urdf"),
                      Catch::Contains("bad.urdf:") && Catch::Contains("invalid XML"));
  }
  SECTION("structure") {
    fails(std::string(kTwoLinks), "several root links ('a', 'b')");
    fails(std::string(kTwoLinks) + R"(<joint name="j" type="revolute"><parent link="a"/><child link="x"/></joint>)",
          "bad.urdf:5: joint 'j': <child> attribute 'link': unknown link 'x'");
    fails(std::string(kTwoLinks) + R"(<joint name="j" type="revolute"><parent link="a"/><child link="b"/></joint>
<joint name="k" type="revolute"><parent link="a"/><child link="b"/></joint>)",
          "joint 'k': link 'b' already has a parent joint 'j' (line 5)");
    fails(R"(<link name="a"/><link name="a"/>)", "bad.urdf:3: link 'a': duplicate link name");
    fails(R"(<link name="a"/><link name="world"/><joint name="j" type="fixed"><parent link="a"/><child link="world"/></joint>)",
          "bad.urdf:3: link 'world': the name 'world' is reserved for the fixed world frame; only the root link may have it (the root link is 'a')");
    fails(std::string(kTwoLinks) + R"(<joint name="j" type="screw"><parent link="a"/><child link="b"/></joint>)",
          "joint 'j': attribute 'type': value 'screw' is not one of");
  }
  SECTION("values") {
    fails(std::string(kTwoLinks) + R"(<joint name="j" type="revolute"><parent link="a"/><child link="b"/>
<origin xyz="1 2"/></joint>)",
          "bad.urdf:6: joint 'j': <origin> attribute 'xyz': value '1 2' must be 3 finite numbers");
    fails(std::string(kTwoLinks) + R"(<joint name="j" type="revolute"><parent link="a"/><child link="b"/>
<axis xyz="0 0 0"/></joint>)",
          "bad.urdf:6: joint 'j': <axis> attribute 'xyz': value '0 0 0' is zero");
    fails(R"(<link name="a"/><link name="b"><inertial><mass value="-1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint>)",
          "link 'b' <inertial>: <mass> attribute 'value': value '-1' must be >= 0");
    fails(R"(<link name="a"/><link name="b"><inertial><mass value="1"/><inertia ixx="1" ixy="5" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint>)",
          "bad.urdf:3: link 'b' <inertial>: <inertia> is not positive semidefinite");
    // A bad second number of a cylinder (found by fuzz_urdf: with assertions on, the throw inside
    // an Eigen comma initializer aborted instead of reporting).
    fails(R"(<link name="a"><visual><geometry><cylinder radius="0.02" length="x"/></geometry></visual></link>)",
          "link 'a' <visual>");
    fails(R"(<link name="a"><visual><geometry><cylinder radius="0.02"/></geometry></visual></link>)",
          "'length'");
    fails(R"(<link name="a"/><link name="b"><inertial><mass value="1"/><inertia ixx="nan" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint>)",
          "<inertia> attribute 'ixx': value 'nan' must be 1 finite number");
  }
  SECTION("unsupported features are refused, not approximated") {
    fails(std::string(kTwoLinks) + R"(<joint name="j" type="revolute"><parent link="a"/><child link="b"/>
<dynamics damping="0.1" friction="0.2"/></joint>)",
          "bad.urdf:6: joint 'j': <dynamics> attribute 'friction': value '0.2': Coulomb friction is not modelled");
    fails(std::string(kTwoLinks) + R"(<joint name="j" type="floating"><parent link="a"/><child link="b"/>
<dynamics damping="0.1"/></joint>)",
          "damping': value '0.1' on a floating joint is not supported");
  }
  SECTION("the root must be <robot>") {
    CHECK_THROWS_WITH(parseScene("<?xml version=\"1.0\"?>\n<sdf/>", "x.sdf"),
                      Catch::Contains("x.sdf:2: the root element must be <robot>, not <sdf>"));
  }
}

TEST_CASE("URDF content the importer would drop is refused with file, line and element", "[urdf][errors]") {
  const auto fails = [](const std::string& text, const std::string& expected) {
    INFO("expected message containing: " << expected);
    CHECK_THROWS_WITH(parseScene(text, "bad.urdf"), Catch::Contains(expected));
  };
  const std::string joint = R"(<joint name="j" type="revolute"><parent link="a"/><child link="b"/>)";
  SECTION("xacro: the namespace, a macro element, a ${property}") {
    fails("<robot name=\"r\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\">\n<link name=\"a\"/></robot>",
          "bad.urdf:1: <robot> declares xmlns:xacro: this is a xacro file; trellis reads plain URDF and does not "
          "expand xacro macros, properties or includes. Expand it first: xacro bad.urdf > robot.urdf");
    fails(robot(std::string(kTwoLinks) + "<xacro:include filename=\"arm.xacro\"/>\n"), "bad.urdf:5: <xacro:include>: this is a xacro file");
    fails(robot(std::string(kTwoLinks) + joint + "<origin xyz=\"${l} 0 0\"/></joint>"), "value '${l} 0 0': this is a xacro file");
  }
  SECTION("elements that are not where URDF puts them, and second copies") {
    fails(robot(std::string(kTwoLinks) + "<group>\n<link name=\"c\"/></group>"),
          "bad.urdf:5: robot: unexpected element <group> inside <robot>");
    fails(robot(std::string(kTwoLinks) + joint + "\n<link name=\"c\"/></joint>"),
          "bad.urdf:6: joint 'j': unexpected element <link> inside <joint>");
    fails(robot(std::string(kTwoLinks) + joint + "\n<parent link=\"b\"/></joint>"),
          "bad.urdf:6: joint 'j': a second <parent> (the first is on line 5); <joint> takes one");
    fails(robot(std::string(kTwoLinks) + joint + "<axis xyz=\"1 0 0\"/>\n<axis xyz=\"0 1 0\"/></joint>"),
          "bad.urdf:6: joint 'j': a second <axis>");
    fails(robot(R"(<link name="a"/><link name="b"><inertial><mass value="1"/>
<mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>)"),
          "bad.urdf:4: link 'b' <inertial>: a second <mass>");
    fails(robot(R"(<link name="a"/><link name="b"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
<inertial><mass value="2"/></inertial></link>)"),
          "bad.urdf:4: link 'b': a second <inertial>");
  }
  SECTION("numbers without separators are not split") {
    fails(robot(std::string(kTwoLinks) + joint + "<origin xyz=\"1.5.2 0\"/></joint>"),
          "<origin> attribute 'xyz': value '1.5.2 0' must be 3 finite numbers");
    fails(robot(std::string(kTwoLinks) + joint + "<origin xyz=\"0-1-2\"/></joint>"),
          "value '0-1-2' must be 3 finite numbers");
    fails(robot(std::string(kTwoLinks) + joint + "<axis xyz=\"0 0 1x\"/></joint>"), "value '0 0 1x' must be 3");
  }
  SECTION("inertias no rigid body has, and a massless link with an inertia") {
    const auto link = [](const char* inertia, const char* m = "1") {
      return robot(std::string(R"(<link name="a"/><link name="b"><inertial><mass value=")") + m + "\"/>\n" + inertia +
                   R"(</inertial></link><joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint>)");
    };
    fails(link(R"(<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="3"/>)"),
          "bad.urdf:4: link 'b' <inertial>: <inertia> violates the triangle inequality (principal moments 1, 1, 3");
    fails(link(R"(<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>)", "0"),
          "bad.urdf:4: link 'b' <inertial>: mass 0 with a nonzero <inertia>");
    // Allowed: a thin rod (0, I, I), a point mass (0), a massless link with zero inertia.
    CHECK_NOTHROW(parseScene(link(R"(<inertia ixx="0" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>)"), "ok.urdf"));
    CHECK_NOTHROW(parseScene(link(R"(<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>)"), "ok.urdf"));
    const Scene massless = parseScene(link(R"(<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>)", "0"), "ok.urdf");
    CHECK(massless.model.nq() == 0);
  }
  SECTION("a byte-order mark is skipped, not called invalid JSON") {
    const Scene s = parseScene("\xEF\xBB\xBF" + robot(std::string(kTwoLinks) + joint + "</joint>"), "bom.urdf");
    CHECK(s.model.nq() == 1);
  }
  SECTION("the documented ignored elements still load") {
    const Scene s = parseScene(robot(std::string(kTwoLinks) + joint + R"(<calibration rising="0"/><safety_controller k_velocity="1"/></joint>
<material name="grey"><color rgba="0.5 0.5 0.5 1"/></material><transmission name="t"><type>x</type></transmission><gazebo><anything/></gazebo>)"),
                               "ok.urdf");
    CHECK(s.model.nq() == 1);
  }
}

TEST_CASE("URDF visuals are kept with their shape and pose", "[urdf]") {
  const Scene s = parseScene(robot(R"(<link name="a"><visual><origin xyz="0 0 0.5"/><geometry><box size="1 2 3"/></geometry></visual></link>
<link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
<visual><geometry><mesh filename="package://b.stl" scale="2 2 2"/></geometry></visual>
<visual><geometry><cylinder radius="0.1" length="0.4"/></geometry></visual></link>
<joint name="j" type="continuous"><parent link="a"/><child link="b"/></joint>)"));
  REQUIRE(s.visuals.size() == 3);
  CHECK(s.visuals[0].frame == "a");
  CHECK(s.visuals[0].shape == VisualGeometry::Shape::kBox);
  CHECK(s.visuals[0].size == Eigen::Vector3d(1, 2, 3));
  CHECK(s.visuals[0].pose(2, 3) == 0.5);
  CHECK(s.visuals[1].mesh == "package://b.stl");
  CHECK(s.visuals[2].size == Eigen::Vector3d(0.1, 0.4, 0));
}
