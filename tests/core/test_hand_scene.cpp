// tests/core/test_hand_scene.cpp — the human hand of issue 5 (examples/scenes/hand.json, written by
// examples/hand/make_hand_scene.py): it loads with the documented sizes, its stored state lies on
// the constraint manifold, the grasp leaves a 5-dimensional configuration manifold (tangent space
// of dimension 10), its linearization agrees with central differences of computeDynamics, and its
// tendon input matrix agrees with an independent reference (differences of the cable length
// measured from the frame positions) and has moment arms of anatomical size.
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/linearization_checks.hpp"
#include "support/matrix_compare.hpp"

#include <trellis/core.hpp>

#include <Eigen/SVD>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <random>
#include <string>
#include <vector>

using namespace trellis;

namespace {

Scene loadHand() { return loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand.json"); }

/// Cable length Σ‖p_{i+1} − p_i‖ of tendon `t`, measured from the world poses of its via frames —
/// an independent path to ∂l/∂q (the core differentiates the body points analytically).
double tendonLength(const Model& model, Data& data, const std::vector<std::string>& path,
                    const Eigen::VectorXd& q) {
  computeKinematics(model, data, q, Eigen::VectorXd::Zero(model.nq()));
  double l = 0.0;
  for (std::size_t i = 0; i + 1 < path.size(); ++i) {
    l += (data.framePose[model.frameIndex(path[i + 1])].translation() -
          data.framePose[model.frameIndex(path[i])].translation())
             .norm();
  }
  return l;
}

}  // namespace

TEST_CASE("The hand scene loads with 20 coordinates, 23 tendons and 15 constraint rows",
          "[hand][scene]") {
  const Scene s = loadHand();
  const Model& m = s.model;
  CHECK(m.nq() == 20);
  CHECK(m.nu() == 23);
  CHECK(m.nc() == 15);
  CHECK(m.nholonomic() == 15);
  CHECK(m.tendons().size() == 23);
  for (const char* digit : {"index", "middle", "ring", "little"}) {
    for (const char* joint : {"_mcp_abd", "_mcp_flex", "_pip", "_dip"}) {
      CHECK_NOTHROW(m.configIndex(std::string(digit) + joint));
    }
    for (const char* muscle : {"FDP_", "FDS_", "EDC_"}) CHECK_NOTHROW(m.inputIndex(muscle + std::string(digit)));
  }
  for (const char* name : {"thumb_cmc_abd", "thumb_cmc_flex", "thumb_mcp", "thumb_ip"})
    CHECK_NOTHROW(m.configIndex(name));
  for (const char* name : {"FPL", "EPL", "APL", "ADP", "DI1_index", "PI1_index", "DI2_middle",
                           "DI3_middle", "PI2_ring", "DI4_ring", "PI3_little"})
    CHECK_NOTHROW(m.inputIndex(name));
  // Every tendon crosses at least one joint, most several: count the distinct joint bodies on
  // each path (a path on one body would have constant length and a zero column of B).
  int multiJoint = 0;
  for (const Tendon& t : m.tendons()) {
    std::vector<int> bodies;
    for (const BodyPoint& p : t.path)
      if (std::find(bodies.begin(), bodies.end(), p.joint) == bodies.end()) bodies.push_back(p.joint);
    CHECK(bodies.size() >= 2);
    if (bodies.size() >= 3) ++multiJoint;
  }
  // Every tendon but APL spans ≥ 3 bodies (palm and ≥ 2 moving segments); APL runs from the
  // forearm to the thumb metacarpal (2 bodies), crossing both axes of the CMC.
  CHECK(multiJoint == 22);
  CHECK(s.dq.isZero());
}

TEST_CASE("The hand's stored state satisfies the grasp constraints", "[hand][scene]") {
  const Scene s = loadHand();
  Data data(s.model);
  computeConstraints(s.model, data, s.q, s.dq);
  // The generator solves each digit to ~1e-17 m and writes q with 17 significant digits; what is
  // left is the rounding of positions of size 0.2 m (eps · 0.2 ≈ 4e-17 m, times the number of
  // frames composed). 1e-13 m leaves three orders of margin; a wrong contact point is ≥ 1e-4 m.
  CHECK(data.constraintValue.cwiseAbs().maxCoeff() < 1e-13);
  // Independent of A: the pad frames coincide with their contact frames on the ball.
  computeKinematics(s.model, data, s.q, s.dq);
  for (const char* digit : {"thumb", "index", "middle", "ring", "little"}) {
    const Eigen::Vector3d pad = data.framePose[s.model.frameIndex(std::string(digit) + "_tip")].translation();
    const Eigen::Vector3d contact =
        data.framePose[s.model.frameIndex(std::string("ball_contact_") + digit)].translation();
    INFO(digit);
    CHECK((pad - contact).norm() < 1e-13);
    // On the ball's surface (radius 35 mm).
    const Eigen::Vector3d centre = data.framePose[s.model.frameIndex("ball")].translation();
    CHECK((contact - centre).norm() == Approx(0.035).epsilon(1e-12));
  }
}

TEST_CASE("The hand's grasp leaves a 5-dimensional configuration manifold", "[hand][scene]") {
  const Scene s = loadHand();
  Data data(s.model);
  REQUIRE(computeLinearization(s.model, data, s.q, s.dq, s.u).ok());
  CHECK(data.status.code == DynamicsStatus::Code::kOk);
  CHECK(data.status.constraintRank == 15);
  // Full row rank with margin: σ_min(A) / σ_max(A) well above rounding (a pad at a singular
  // posture, e.g. a straight finger, would drive it to ~0).
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(data.constraintJacobian);
  const Eigen::VectorXd sv = svd.singularValues();
  CHECK(sv(sv.size() - 1) / sv(0) > 1e-2);
  // Tangent space of {h = 0, A q̇ = 0}: 2 · (20 − 15) = 10.
  CHECK(computeConstraintTangentBasis(s.model, data) == 10);
  CHECK(data.tangentBasis.cols() == 10);
  // T spans directions along which the constraints stay satisfied to first order.
  Eigen::MatrixXd stateJacobian(30, 40);
  stateJacobian << data.constraintJacobian, Eigen::MatrixXd::Zero(15, 20),
      data.constraintVelocityJacobian, data.constraintJacobian;
  CHECK((stateJacobian * data.tangentBasis).cwiseAbs().maxCoeff() < 1e-12 * stateJacobian.norm());
}

TEST_CASE("The hand's linearization agrees with central differences of computeDynamics",
          "[hand][linearization][fd]") {
  const Scene s = loadHand();
  // At the stored grasp with a velocity and tensions that exercise every term (Coriolis, damping,
  // the tendons' configuration dependence). The linearization is defined off the manifold too.
  std::mt19937 rng(505);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  test::State st{s.q, Eigen::VectorXd(20), Eigen::VectorXd(23)};
  for (int i = 0; i < 20; ++i) st.dq(i) = 0.5 * unit(rng);
  for (int i = 0; i < 23; ++i) st.u(i) = 1.0 + 0.5 * unit(rng);
  // The hand's inertias are small (M ~ 1e-6 … 1e-5 kg m²) against stiffness, tendon and gravity
  // terms of ~1e-2, so q̈ reaches ~1e4 rad/s² here and its derivatives ~4e4: central differences
  // carry a rounding error ~ (κ eps)^(2/3) relative, measured 1.9e-6 (column-relative) with the
  // second-order stencil — too close to 1e-6 — and 5e-8 with the fourth-order one, whose error is
  // ~(κ eps)^(4/5) (finite_difference.hpp). kFdTolerance = 1e-6 then leaves a margin of ~20 and
  // still catches any wrong term (those are ≥ 1e-3 relative).
  test::checkLinearizationAgainstFd(s.model, st, test::kFdTolerance, 1.0, test::Stencil::kFourthOrder);
}

TEST_CASE("The hand's tendon input matrix is -dl/dq with moment arms of anatomical size",
          "[hand][tendons]") {
  const Scene s = loadHand();
  const Model& m = s.model;
  Data data(m);
  computeInputMatrix(m, data, s.q);
  const Eigen::MatrixXd B = data.inputMatrix;
  // Independent reference: central differences of the cable length measured from frame positions
  // (error ~eps^(2/3)·l ≈ 1e-11 m per rad; moment arms are ~1e-2 m, so 1e-8 absolute is a
  // margin of ~1000 and any wrong via point shows at ≥ 1e-4).
  const std::vector<std::vector<std::string>> paths = [&] {
    // Recover each tendon's frame names from its body points.
    std::vector<std::vector<std::string>> out;
    for (const Tendon& t : m.tendons()) {
      std::vector<std::string> names;
      for (const BodyPoint& p : t.path) {
        for (const FramePlacement& f : m.frames()) {
          if (f.joint == p.joint && (f.p - p.local).norm() < 1e-15 && f.name.find("_com") == std::string::npos) {
            names.push_back(f.name);
            break;
          }
        }
      }
      out.push_back(names);
    }
    return out;
  }();
  for (int j = 0; j < m.nu(); ++j) {
    INFO("tendon " << m.inputNames()[j]);
    REQUIRE(paths[j].size() == m.tendons()[j].path.size());
    const test::VectorFunction length = [&](const Eigen::VectorXd& q) {
      return Eigen::VectorXd::Constant(1, tendonLength(m, data, paths[j], q));
    };
    const Eigen::VectorXd dl = test::centralDifferenceJacobian(length, s.q).row(0).transpose();
    CHECK((B.col(m.tendons()[j].input) + dl).cwiseAbs().maxCoeff() < 1e-8);
  }
  // Moment arms (N m per N of tension = m): flexors flex (positive), extensors extend, with sizes
  // within a factor ~1.5 of the cited values (Ketchum et al. 1978: FDP at MCP 8.9–11.6 mm; An et
  // al. 1983: EDC at MCP ~8.5 mm) — the via points give the cited arm in extension, growing for
  // flexors and shrinking for extensors as the joint flexes.
  for (const char* f : {"index", "middle", "ring", "little"}) {
    INFO(f);
    const int mcp = m.configIndex(std::string(f) + "_mcp_flex"), pip = m.configIndex(std::string(f) + "_pip"),
              dip = m.configIndex(std::string(f) + "_dip");
    const int fdp = m.inputIndex(std::string("FDP_") + f), fds = m.inputIndex(std::string("FDS_") + f),
              edc = m.inputIndex(std::string("EDC_") + f);
    CHECK(B(mcp, fdp) > 0.006);
    CHECK(B(mcp, fdp) < 0.018);
    CHECK(B(pip, fdp) > 0.005);
    CHECK(B(dip, fdp) > 0.003);
    CHECK(B(mcp, fds) > 0.006);
    CHECK(B(dip, fds) == 0.0);  // FDS inserts on the middle phalanx: it cannot act on the DIP
    CHECK(B(mcp, edc) < -0.004);
    CHECK(B(mcp, edc) > -0.012);
    CHECK(B(pip, edc) < 0.0);
  }
  // Non-collocation: no column of B is a multiple of a unit vector (each tendon moves ≥ 2 joints),
  // except APL (CMC only, both of its axes).
  int collocated = 0;
  for (int j = 0; j < m.nu(); ++j) {
    int nonzero = 0;
    for (int i = 0; i < m.nq(); ++i) nonzero += std::abs(B(i, j)) > 1e-9;
    collocated += nonzero <= 1;
  }
  CHECK(collocated == 0);
}

// A via pair straddling a joint on the side it closes towards meets when the joint turns far
// enough; past that angle the segment between them points the other way and the tendon's moment
// arm jumps from +r to −r (a flexor turned extensor): the generator first put that angle at 53°,
// inside every flexion range (the free-ball turn's optimizer stalled on the jump at the thumb MCP).
// Every entry of B(q) must be Lipschitz in each joint over its whole range (plus 0.05 rad), at the
// stored grasp and at random postures inside the ranges: |ΔB| ≤ 0.1 m/rad · Δq. The cable's arm
// changes by ≲ 0.01 m per rad; the jump was 0.02 m within one 0.005 rad step (4 m/rad).
TEST_CASE("The hand's tendon moment arms are continuous over every joint's range", "[hand][tendons]") {
  std::ifstream in(std::string(TRELLIS_SOURCE_DIR) + "/examples/hand/hand_ball_limits.json");
  REQUIRE(in.good());
  const nlohmann::json ranges = nlohmann::json::parse(in).at("joint_range");
  for (const char* file : {"hand.json", "hand_ball.json", "hand_ball_pinch.json"}) {
    INFO(file);
    const Scene s = loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/" + file);
    const Model& m = s.model;
    const auto& names = m.configNames();
    const auto has = [&](const std::string& n) { return std::find(names.begin(), names.end(), n) != names.end(); };
    Data data(m);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    int joints = 0;
    for (int posture = 0; posture < 4; ++posture) {
      Eigen::VectorXd q0 = s.q;
      if (posture > 0)
        for (auto it = ranges.begin(); it != ranges.end(); ++it)
          if (has(it.key())) {
            const double lo = it.value()[0], hi = it.value()[1];
            q0(m.configIndex(it.key())) = lo + (hi - lo) * unit(rng);
          }
      for (auto it = ranges.begin(); it != ranges.end(); ++it) {
        if (!has(it.key())) continue;
        ++joints;
        const int j = m.configIndex(it.key());
        const double lo = double(it.value()[0]) - 0.05, hi = double(it.value()[1]) + 0.05, step = 0.005;
        Eigen::VectorXd q = q0;
        q(j) = lo;
        computeInputMatrix(m, data, q);
        Eigen::MatrixXd previous = data.inputMatrix;
        double worst = 0.0;
        for (double t = lo + step; t <= hi + 1e-12; t += step) {
          q(j) = t;
          computeInputMatrix(m, data, q);
          worst = std::max(worst, (data.inputMatrix - previous).cwiseAbs().maxCoeff() / step);
          previous = data.inputMatrix;
        }
        INFO("posture " << posture << ", joint " << it.key());
        CHECK(worst < 0.1);
      }
    }
    CHECK(joints >= 4 * 8);  // the pinch scene has thumb and index only
  }
}
