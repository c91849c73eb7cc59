// tests/core/test_axis_transforms.cpp — rotations about and translations along an arbitrary unit
// axis (r_axis / t_axis): the builder, the scene format, and the three legs of the derivative
// tests (central differences; identities; the same joint built from const_se3 sandwiches, an
// independent construction, to 1e-14).
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/linearization_checks.hpp"
#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <string>

using namespace trellis;
using namespace trellis::test;

namespace {

const Eigen::Vector3d kTilted = Eigen::Vector3d(0.3, -0.5, 0.8).normalized();

/// j1 rz(a) (mass) → c1 const_se3 → test: axis transform driven by "t" with origin G (mass) →
/// test_const: the same kind, constant → j2 ry(b) → end tz(.5) (mass); world → anchor. Skewed
/// gravity, a body wrench on `test` (input "w"), a tendon anchor→test→end, a torque on a and,
/// with `constrained`, a distance end–anchor.
/// sandwich: the axis frames are built instead as const_se3(G·Ra) → rz/tz → const_se3(Raᵀ) with
/// Ra from Eigen's FromTwoVectors (not the builder's construction).
TestSystem axisChain(TransformType t, const Eigen::Vector3d& axis, bool sandwich, bool constrained = false) {
  std::mt19937 rng(21);
  const Eigen::Matrix4d G = se3(0.6, {0.2, 1.0, -0.4}, {0.1, 0.25, -0.15});
  const Eigen::Matrix4d G2 = se3(-0.8, {1.0, 0.3, 0.2}, {0.2, -0.1, 0.3});
  const bool rot = t == TransformType::kRotAxis;
  SystemBuilder s;
  s.frame("j1", "world", Transform::rz("a"), Mass{0.8, randomInertia(rng)});
  s.frame("c1", "j1", Transform::constSE3(se3(0.5, {1.0, 0.0, 1.0}, {0.3, 0.1, -0.2})));
  const Mass testMass{0.7, randomInertia(rng)};
  const Transform constant = rot ? Transform::rotAxis(axis, 0.45, G2) : Transform::transAxis(axis, 0.45, G2);
  if (!sandwich) {
    s.frame("test", "c1", rot ? Transform::rotAxis(axis, "t", G) : Transform::transAxis(axis, "t", G), testMass);
    s.frame("test_const", "test", constant);
  } else {
    Eigen::Matrix4d Ra = Eigen::Matrix4d::Identity();
    Ra.topLeftCorner<3, 3>() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), axis).toRotationMatrix();
    s.frame("test_pre", "c1", Transform::constSE3(G * Ra));
    s.frame("test_joint", "test_pre", rot ? Transform::rz("t") : Transform::tz("t"));
    s.frame("test", "test_joint", Transform::constSE3(Ra.transpose()), testMass);
    s.frame("test_const", "test", Transform::constSE3(constant.evaluate(0.0).matrix()));
  }
  s.frame("j2", "test_const", Transform::ry("b"));
  s.frame("end", "j2", Transform::tz(0.5), Mass{0.5, randomInertia(rng)});
  s.frame("anchor", "world", Transform::constSE3(se3(0.3, {0.0, 0.0, 1.0}, {0.9, 0.4, 0.2})));
  s.b.addGravity(Eigen::Vector3d(0.7, -9.6, 1.9));
  s.b.addConfigForce("a", "ua");
  s.b.addBodyWrench("test", {WrenchEntry{std::string("w")}, WrenchEntry{0.2}, WrenchEntry{-0.1},
                             WrenchEntry{0.05}, WrenchEntry{std::string("w")}, WrenchEntry{0.0}});
  s.b.addTendon({"anchor", "test", "end"}, "pull");
  s.b.addLinearSpring("test", "anchor", 2.0, 0.3);
  if (constrained) s.b.addDistanceConstraint("end", "anchor", 0.9);
  return std::move(s).finish();
}

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

}  // namespace

TEST_CASE("Axis transforms: linearization matches central differences", "[axis][linearization][fd]") {
  for (const TransformType t : {TransformType::kRotAxis, TransformType::kTransAxis}) {
    const std::string name = t == TransformType::kRotAxis ? "r_axis" : "t_axis";
    for (const bool constrained : {false, true}) {
      SECTION(name + (constrained ? " with a distance constraint" : " unconstrained")) {
        const Model model = axisChain(t, kTilted, false, constrained).model;
        CHECK(model.nq() == 3);
        std::mt19937 rng(constrained ? 731 : 732);
        for (int k = 0; k < 3; ++k) checkLinearizationAgainstFd(model, randomState(model, rng));
      }
    }
  }
}

TEST_CASE("Axis transforms: identities (M SPD, B = [0; M^-1 dQ/du], energy balance)", "[axis][identities]") {
  for (const TransformType t : {TransformType::kRotAxis, TransformType::kTransAxis}) {
    SECTION(t == TransformType::kRotAxis ? "r_axis" : "t_axis") {
      const Model model = axisChain(t, kTilted, false).model;
      std::mt19937 rng(741);
      const State s = randomState(model, rng);
      Data data(model);
      REQUIRE(computeLinearization(model, data, s.q, s.dq, s.u).ok());
      const Eigen::MatrixXd M = data.M;
      CHECK((M - M.transpose()).cwiseAbs().maxCoeff() <= 1e-14 * M.cwiseAbs().maxCoeff());
      CHECK(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(M).eigenvalues().minCoeff() > 0.0);
      computeInputMatrix(model, data, s.q);
      const int n = model.nq();
      const Eigen::MatrixXd expected = M.llt().solve(data.inputMatrix);
      TRELLIS_CHECK_MATRIX(expected, Eigen::MatrixXd(data.B.bottomRows(n)), 1e-12, Scale::kMatrix);
      CHECK(data.B.topRows(n).isZero(0.0));
      checkEnergyBalance(model, s);
    }
  }
}

TEST_CASE("Axis transforms equal the same joint built from const_se3 sandwiches", "[axis][sandwich]") {
  for (const TransformType t : {TransformType::kRotAxis, TransformType::kTransAxis}) {
    for (const bool constrained : {false, true}) {
      SECTION(std::string(t == TransformType::kRotAxis ? "r_axis" : "t_axis") + (constrained ? ", constrained" : "")) {
        const Model axisModel = axisChain(t, kTilted, false, constrained).model;
        const Model sandwich = axisChain(t, kTilted, true, constrained).model;
        REQUIRE(axisModel.nq() == sandwich.nq());
        REQUIRE(axisModel.nu() == sandwich.nu());
        // The sandwich's extra constant frames fold away: the same number of joints and bodies.
        CHECK(sandwich.nframes() == axisModel.nframes() + 2);
        std::mt19937 rng(751);
        for (int k = 0; k < 3; ++k) {
          const State s = randomState(axisModel, rng);
          Data d1(axisModel), d2(sandwich);
          REQUIRE(computeLinearization(axisModel, d1, s.q, s.dq, s.u).ok());
          REQUIRE(computeLinearization(sandwich, d2, s.q, s.dq, s.u).ok());
          // One computation in two roundings of the same placements: 1e-14 of the matrix scale.
          TRELLIS_CHECK_MATRIX(d2.M, d1.M, 1e-14, Scale::kMatrix);
          TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(d2.qdd), Eigen::MatrixXd(d1.qdd), 1e-14, Scale::kMatrix);
          TRELLIS_CHECK_MATRIX(d2.A, d1.A, 1e-14, Scale::kMatrix);
          TRELLIS_CHECK_MATRIX(d2.B, d1.B, 1e-14, Scale::kMatrix);
          // Frame poses agree, the axis frame included.
          computeKinematics(axisModel, d1, s.q, s.dq);
          computeKinematics(sandwich, d2, s.q, s.dq);
          for (const char* f : {"test", "test_const", "end"}) {
            const Eigen::Matrix4d g1 = d1.framePose[axisModel.frameIndex(f)].matrix();
            const Eigen::Matrix4d g2 = d2.framePose[sandwich.frameIndex(f)].matrix();
            INFO("frame " << f);
            CHECK((g1 - g2).cwiseAbs().maxCoeff() <= 1e-14);
          }
        }
      }
    }
  }
}

TEST_CASE("Axis transforms along a basis vector are exactly rx...tz", "[axis]") {
  const Eigen::Matrix4d G = se3(0.6, {0.2, 1.0, -0.4}, {0.1, 0.25, -0.15});
  for (int i = 0; i < 3; ++i) {
    for (const bool rot : {true, false}) {
      ModelBuilder a, b;
      a.addFrame("g", "world", Transform::constSE3(G));
      a.addFrame("j", "g", rot ? Transform::rotAxis(Eigen::Vector3d::Unit(i), "q") : Transform::transAxis(Eigen::Vector3d::Unit(i), "q"),
                 Mass{1.0, Eigen::Vector3d(0.1, 0.2, 0.3).asDiagonal()});
      const Transform prim[2][3] = {{Transform::tx("q"), Transform::ty("q"), Transform::tz("q")},
                                    {Transform::rx("q"), Transform::ry("q"), Transform::rz("q")}};
      b.addFrame("j", "world", rot ? Transform::rotAxis(Eigen::Vector3d::Unit(i), "q", G) : Transform::transAxis(Eigen::Vector3d::Unit(i), "q", G),
                 Mass{1.0, Eigen::Vector3d(0.1, 0.2, 0.3).asDiagonal()});
      ModelBuilder c;
      c.addFrame("g", "world", Transform::constSE3(G));
      c.addFrame("j", "g", prim[rot][i], Mass{1.0, Eigen::Vector3d(0.1, 0.2, 0.3).asDiagonal()});
      for (ModelBuilder* m : {&a, &b, &c}) {
        m->addGravity(Eigen::Vector3d(0.3, -9.0, 1.0));
        m->addFrame("tip", "j", Transform::tx(0.4), Mass{0.5, Eigen::Matrix3d::Identity() * 0.01});
      }
      const Model ma = a.finalize(), mb = b.finalize(), mc = c.finalize();
      Data da(ma), db(mb), dc(mc);
      const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, 0.7), dq = Eigen::VectorXd::Constant(1, -0.4), u(0);
      REQUIRE(computeLinearization(ma, da, q, dq, u).ok());
      REQUIRE(computeLinearization(mb, db, q, dq, u).ok());
      REQUIRE(computeLinearization(mc, dc, q, dq, u).ok());
      INFO("axis " << i << (rot ? " rotation" : " translation"));
      CHECK(da.A == dc.A);  // bit for bit: the same joint
      CHECK(db.A == dc.A);  // origin folded into the joint placement: the same operations
    }
  }
}

TEST_CASE("Axis transforms: constant values, evaluate(), and validation", "[axis][builder]") {
  SECTION("evaluate is G · exp(x [a])") {
    const Eigen::Matrix4d G = se3(0.6, {0.2, 1.0, -0.4}, {0.1, 0.25, -0.15});
    const Eigen::Isometry3d r = Transform::rotAxis(kTilted, "q", G).evaluate(0.9);
    const Eigen::Matrix3d expected = G.topLeftCorner<3, 3>() * Eigen::AngleAxisd(0.9, kTilted).toRotationMatrix();
    CHECK((r.linear() - expected).cwiseAbs().maxCoeff() < 1e-15);
    const Eigen::Isometry3d p = Transform::transAxis(kTilted, 0.9).evaluate(0.0);
    CHECK((p.translation() - 0.9 * kTilted).cwiseAbs().maxCoeff() < 1e-15);
  }
  SECTION("a constant axis frame places its children as const_se3 does") {
    ModelBuilder a, b;
    a.addFrame("f", "world", Transform::rotAxis(kTilted, 0.8));
    b.addFrame("f", "world", Transform::constSE3(Transform::rotAxis(kTilted, 0.8).evaluate(0.0).matrix()));
    const Model ma = a.finalize(), mb = b.finalize();
    CHECK((ma.frames()[0].R - mb.frames()[0].R).cwiseAbs().maxCoeff() == 0.0);
  }
  SECTION("a non-unit axis is refused with its norm") {
    ModelBuilder b;
    CHECK_THROWS_WITH(b.addFrame("f", "world", Transform::rotAxis(Eigen::Vector3d(1, 1, 0), "q")),
                      Catch::Contains("frame 'f': field 'axis'") && Catch::Contains("unit vector") &&
                          Catch::Contains("1.414"));
    CHECK_THROWS_WITH(b.addFrame("f", "world", Transform::transAxis(Eigen::Vector3d::Zero(), "q")),
                      Catch::Contains("field 'axis'"));
  }
  SECTION("an origin that is not rigid is refused") {
    ModelBuilder b;
    Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
    g(0, 0) = 2.0;
    CHECK_THROWS_WITH(b.addFrame("f", "world", Transform::rotAxis(kTilted, "q", g)),
                      Catch::Contains("frame 'f': field 'origin'"));
  }
}

TEST_CASE("Axis transforms in scene files", "[axis][scene]") {
  SECTION("r_axis and t_axis give the builder's model") {
    const std::string text = R"({"frames": [
      {"name": "a", "type": "r_axis", "axis": [0, 0.6, 0.8], "config": "qa",
       "origin": {"xyz": [0.1, 0.2, 0.3], "rpy": [0.4, -0.5, 0.6]},
       "mass": {"m": 1.0, "inertia": [0.1, 0.2, 0.3, 0.01, 0.02, 0.03]},
       "children": [{"name": "b", "type": "t_axis", "axis": [0.6, 0, -0.8], "config": "qb",
                     "mass": {"m": 0.5}, "children": [{"name": "c", "type": "r_axis", "axis": [1, 0, 0], "value": 0.3}]}]}],
      "potentials": [{"type": "gravity", "g": [0, 0, -9.81]}]})";
    const Scene scene = parseScene(text);
    ModelBuilder b;
    Eigen::Matrix3d I;
    I << 0.1, 0.01, 0.02, 0.01, 0.2, 0.03, 0.02, 0.03, 0.3;
    b.addFrame("a", "world", Transform::rotAxis(Eigen::Vector3d(0, 0.6, 0.8), "qa",
                                                poseFromXyzRpy({0.1, 0.2, 0.3}, {0.4, -0.5, 0.6})),
               Mass{1.0, I});
    b.addFrame("b", "a", Transform::transAxis(Eigen::Vector3d(0.6, 0, -0.8), "qb"), Mass{0.5, Eigen::Matrix3d::Zero()});
    b.addFrame("c", "b", Transform::rotAxis(Eigen::Vector3d(1, 0, 0), 0.3));
    b.addGravity(Eigen::Vector3d(0, 0, -9.81));
    const Model m = b.finalize();
    Data d1(scene.model), d2(m);
    const Eigen::Vector2d q(0.3, -0.2), dq(0.5, 0.1);
    REQUIRE(computeLinearization(scene.model, d1, q, dq, Eigen::VectorXd(0)).ok());
    REQUIRE(computeLinearization(m, d2, q, dq, Eigen::VectorXd(0)).ok());
    CHECK(d1.A == d2.A);
  }
  SECTION("bad axis transforms name frame, field and value") {
    CHECK_THROWS_WITH(parseScene(R"({"frames": [{"name": "a", "type": "r_axis", "axis": [1, 1, 0], "config": "q"}]})"),
                      Catch::Contains("frame 'a': field 'axis': [1,1,0] must be a unit vector"));
    CHECK_THROWS_WITH(parseScene(R"({"frames": [{"name": "a", "type": "t_axis", "config": "q"}]})"),
                      Catch::Contains("frame 'a': field 'axis': missing"));
    CHECK_THROWS_WITH(parseScene(R"({"frames": [{"name": "a", "type": "t_axis", "axis": [1, 0, 0], "config": "q", "origin": {"xyz": [1, 2]}}]})"),
                      Catch::Contains("frame 'a': field 'origin.xyz': [1,2] must be a list of 3 numbers"));
    CHECK_THROWS_WITH(parseScene(R"({"frames": [{"name": "a", "type": "t_axis", "axis": [1, 0, 0], "config": "q", "origin": {"rot": [1, 2, 3]}}]})"),
                      Catch::Contains("field 'origin.rot': unknown field"));
  }
}
