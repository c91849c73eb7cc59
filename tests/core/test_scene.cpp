// tests/core/test_scene.cpp — scene files (SCENE_FORMAT.md): the example scenes load with the
// documented orderings, fields mean what the spec says, and every error of the spec is a ModelError
// naming the element, the field and the offending value. Malformed input never escapes as anything
// but a ModelError.
#include <catch2/catch.hpp>

#include <trellis/core.hpp>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

using Catch::Contains;
using Names = std::vector<std::string>;

std::string scenePath(const std::string& file) {
  return std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/" + file;
}

std::string readText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// The message of the ModelError that parsing `text` throws ("<no error>" if it does not throw).
/// Any other exception type escapes and fails the test.
std::string errorOf(const std::string& text) {
  try {
    trellis::parseScene(text);
  } catch (const trellis::ModelError& e) {
    return e.what();
  }
  return "<no error>";
}

// A two-link arm used as the base of most error cases: world → L (rz, q1) → M (ty -1, mass) →
// N (rz, q2) → P (ty -1, mass); and world → C (tx 2).
constexpr const char* kFrames = R"([
  {"name": "L", "type": "rz", "config": "q1", "children": [
    {"name": "M", "type": "ty", "value": -1, "mass": {"m": 1}, "children": [
      {"name": "N", "type": "rz", "config": "q2", "children": [
        {"name": "P", "type": "ty", "value": -1, "mass": {"m": 1}}]}]}]},
  {"name": "C", "type": "tx", "value": 2}])";

/// A scene with the arm's frames and the given lists (JSON text).
std::string arm(const std::string& potentials = "[]", const std::string& forces = "[]",
                const std::string& constraints = "[]", const std::string& state = "{}") {
  return std::string(R"({"frames": )") + kFrames + R"(, "potentials": )" + potentials +
         R"(, "forces": )" + forces + R"(, "constraints": )" + constraints + R"(, "state": )" + state + "}";
}

/// A scene made of one frame (JSON object text) under the world.
std::string oneFrame(const std::string& frame) { return R"({"frames": [)" + frame + "]}"; }

}  // namespace

TEST_CASE("scene: the example scenes load with the documented orderings", "[scene]") {
  SECTION("paper_pendulum: the state of docs/paper_errata.md") {
    const trellis::Scene s = trellis::loadScene(scenePath("paper_pendulum.json"));
    CHECK(s.name == "paper_pendulum");
    CHECK_THAT(s.description, Contains("docs/paper_errata.md"));
    CHECK(s.model.configNames() == Names{"theta1", "theta2"});
    CHECK(s.model.inputNames() == Names{"u"});
    REQUIRE(s.model.nc() == 1);
    CHECK(s.model.constraints()[0].type == trellis::ConstraintType::kDistance);
    CHECK(s.model.constraints()[0].distance == 1.0);
    CHECK(s.model.gravity() == Eigen::Vector3d(0, -9.8, 0));
    CHECK(s.q == Eigen::Vector2d(0.5246, 1.0472));
    CHECK(s.dq == Eigen::Vector2d(1.0, -2.00116));
    CHECK(s.u == Eigen::VectorXd::Zero(1));
  }
  SECTION("all_elements_3d: pre-order configurations, inputs by first appearance") {
    const trellis::Scene s = trellis::loadScene(scenePath("all_elements_3d.json"));
    const trellis::Model& m = s.model;
    CHECK(m.configNames() == Names{"yaw", "pitch", "roll", "extend", "tilt", "sx", "sy", "sz"});
    CHECK(m.inputNames() == Names{"fx", "fz", "twist", "yaw_torque", "cable", "push"});
    REQUIRE(m.nc() == 4);
    CHECK(m.constraints()[0].type == trellis::ConstraintType::kPoint);
    CHECK(m.constraints()[0].axis == 0);
    CHECK(m.constraints()[1].type == trellis::ConstraintType::kPoint);
    CHECK(m.constraints()[1].axis == 1);
    CHECK(m.constraints()[2].type == trellis::ConstraintType::kPointOnPlane);
    CHECK(m.constraints()[3].type == trellis::ConstraintType::kDistance);
    CHECK(m.nholonomic() == 4);
    // damping: "default" 0.05 except where a coefficient is listed
    CHECK(m.damping()[m.configIndex("extend")] == 1.0);
    CHECK(m.damping()[m.configIndex("sx")] == 0.5);
    CHECK(m.damping()[m.configIndex("yaw")] == 0.05);
    REQUIRE(m.configSprings().size() == 1);
    CHECK(m.configSprings()[0].config == m.configIndex("roll"));
    REQUIRE(m.bodyWrenches().size() == 1);
    CHECK(m.bodyWrenches()[0].input == std::array<int, 6>{0, -1, 1, -1, -1, 2});
    CHECK(m.bodyWrenches()[0].constant[4] == 0.05);
    REQUIRE(m.tendons().size() == 1);
    CHECK(m.tendons()[0].path.size() == 3);
    CHECK(m.tendons()[0].input == m.inputIndex("cable"));
    CHECK(m.linearSprings().size() == 1);
    // every state entry was given
    CHECK(s.q[m.configIndex("tilt")] == 0.2);
    CHECK(s.dq[m.configIndex("tilt")] == 3.1895097207730716);
    CHECK(s.u[m.inputIndex("cable")] == 1.0);
  }
  SECTION("cart_pole, acrobot, pendulum") {
    CHECK(trellis::loadScene(scenePath("cart_pole.json")).model.configNames() == Names{"x", "theta"});
    CHECK(trellis::loadScene(scenePath("acrobot.json")).model.configNames() == Names{"theta1", "theta2"});
    CHECK(trellis::loadScene(scenePath("acrobot.json")).model.inputNames() == Names{"elbow_torque"});
    CHECK(trellis::loadScene(scenePath("pendulum.json")).model.inputNames() == Names{"torque"});
  }
  SECTION("every example scene loads and linearizes at its state") {
    int count = 0;
    for (const auto& entry : std::filesystem::directory_iterator(scenePath(""))) {
      if (entry.path().extension() != ".json") continue;
      INFO(entry.path().string());
      const trellis::Scene s = trellis::loadScene(entry.path().string());
      trellis::Data data(s.model);
      const trellis::DynamicsStatus status = trellis::computeLinearization(s.model, data, s.q, s.dq, s.u);
      CHECK(status.code == trellis::DynamicsStatus::Code::kOk);
      CHECK(data.A.allFinite());
      ++count;
    }
    CHECK(count >= 5);
  }
}

TEST_CASE("scene: ordering rules of the spec", "[scene]") {
  SECTION("configurations in pre-order of the tree, children in the order listed") {
    const std::string text = R"({"frames": [
      {"name": "a", "type": "rz", "config": "qa", "mass": {"m": 1}, "children": [
        {"name": "b", "type": "tx", "config": "qb", "mass": {"m": 1}, "children": [
          {"name": "c", "type": "ty", "config": "qc", "mass": {"m": 1}}]},
        {"name": "d", "type": "tz", "config": "qd", "mass": {"m": 1}}]},
      {"name": "e", "type": "tx", "config": "qe", "mass": {"m": 1}}]})";
    CHECK(trellis::parseScene(text).model.configNames() == Names{"qa", "qb", "qc", "qd", "qe"});
  }
  SECTION("inputs by first appearance in forces, wrench entries in order, names reused") {
    const std::string forces = R"([
      {"type": "tendon", "path": ["C", "P", "M"], "input": "t"},
      {"type": "body_wrench", "frame": "P", "wrench": ["w1", 0, "t", "w2", 0, "w1"]},
      {"type": "config_force", "config": "q2", "input": "w2"},
      {"type": "config_force", "config": "q1", "input": "c"}])";
    const trellis::Model m = trellis::parseScene(arm("[]", forces)).model;
    CHECK(m.inputNames() == Names{"t", "w1", "w2", "c"});
    CHECK(m.bodyWrenches()[0].input == std::array<int, 6>{1, -1, 0, 2, -1, 1});
  }
  SECTION("constraints in the order listed") {
    const std::string constraints = R"([
      {"type": "point", "frame1": "P", "frame2": "C", "axis": "z"},
      {"type": "distance", "frame1": "P", "frame2": "C", "distance": 1},
      {"type": "point_on_plane", "plane_frame": "C", "normal": [1, 0, 0], "point_frame": "P"}])";
    const trellis::Model m = trellis::parseScene(arm("[]", "[]", constraints)).model;
    REQUIRE(m.nc() == 3);
    CHECK(m.constraints()[0].type == trellis::ConstraintType::kPoint);
    CHECK(m.constraints()[0].axis == 2);
    CHECK(m.constraints()[1].type == trellis::ConstraintType::kDistance);
    CHECK(m.constraints()[2].type == trellis::ConstraintType::kPointOnPlane);
  }
}

TEST_CASE("scene: fields are read as the spec defines them", "[scene]") {
  SECTION("inertia [Ixx, Iyy, Izz, Ixy, Ixz, Iyz] is the tensor about the frame origin") {
    const trellis::Model m = trellis::parseScene(oneFrame(
        R"({"name": "b", "type": "rz", "config": "q", "mass": {"m": 2, "inertia": [1, 2, 3, 0.1, 0.2, 0.3]}})")).model;
    Eigen::Matrix3d expected;
    expected << 1, 0.1, 0.2, 0.1, 2, 0.3, 0.2, 0.3, 3;
    CHECK(m.joints()[0].mass == 2.0);
    CHECK(m.joints()[0].inertiaAtOrigin.isApprox(expected, 1e-15));
  }
  SECTION("const_se3 is the transform from the frame to its parent; primitives too") {
    const trellis::Model m = trellis::parseScene(oneFrame(R"({"name": "f", "type": "const_se3",
        "matrix": [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], "children": [
          {"name": "g", "type": "tx", "value": 0.5}]})")).model;
    const trellis::FramePlacement& g = m.frames()[m.frameIndex("g")];
    CHECK(g.joint == trellis::kWorld);
    CHECK(g.p.isApprox(Eigen::Vector3d(1, 2.5, 3), 1e-15));  // f's x axis is the world's y axis
  }
  SECTION("missing state names are 0; name and description are kept") {
    // (keys the spec does not list, such as "reference", are ignored)
    const trellis::Scene s = trellis::parseScene(R"({"name": "n", "description": "d", "reference": {"any": "data"}, )" +
                                                 arm("[]", "[]", "[]", R"({"q": {"q2": 0.25}, "dq": {"q1": -1}})").substr(1));
    CHECK(s.name == "n");
    CHECK(s.description == "d");
    CHECK(s.q == Eigen::Vector2d(0, 0.25));
    CHECK(s.dq == Eigen::Vector2d(-1, 0));
    CHECK(s.u.size() == 0);
  }
  SECTION("knife_edge, an extension beyond version 1: a nonholonomic row") {
    const trellis::Model m = trellis::parseScene(arm("[]", "[]", R"([
        {"type": "distance", "frame1": "P", "frame2": "C", "distance": 1},
        {"type": "knife_edge", "frame": "P", "axis": [0, 1, 0]}])")).model;
    REQUIRE(m.nc() == 2);
    CHECK(m.constraints()[1].type == trellis::ConstraintType::kKnifeEdge);
    CHECK(m.nholonomic() == 1);
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "knife_edge", "frame": "P", "axis": [0, 0, 0]}])")),
               Contains("constraints[0] (knife_edge)") && Contains("'axis'") && Contains("[0,0,0]"));
  }
  SECTION("optional lists and state may be absent; several gravity entries add up") {
    const trellis::Scene s = trellis::parseScene(std::string(R"({"frames": )") + kFrames + R"(,
        "potentials": [{"type": "gravity", "g": [0, -9, 0]}, {"type": "gravity", "g": [0, -1, 0]}]})");
    CHECK(s.model.gravity() == Eigen::Vector3d(0, -10, 0));
    CHECK(s.q.size() == 2);
    CHECK(s.model.nc() == 0);
  }
}

TEST_CASE("scene: every error of the spec names the element, the field and the value", "[scene]") {
  SECTION("unknown type") {
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "type": "rw", "config": "q"})")),
               Contains("frame 'L'") && Contains("'type'") && Contains("\"rw\""));
    CHECK_THAT(errorOf(arm(R"([{"type": "gravity", "g": [0, 0, 0]}, {"type": "magnet"}])")),
               Contains("potentials[1]") && Contains("'type'") && Contains("\"magnet\""));
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "thrust"}])")),
               Contains("forces[0]") && Contains("'type'") && Contains("\"thrust\""));
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "rolling"}])")),
               Contains("constraints[0]") && Contains("'type'") && Contains("\"rolling\""));
  }
  SECTION("missing field") {
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "config": "q"})")),
               Contains("frame 'L'") && Contains("'type'") && Contains("missing"));
    CHECK_THAT(errorOf(oneFrame(R"({"type": "rz", "config": "q"})")),
               Contains("frames[0]") && Contains("'name'") && Contains("missing"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "type": "rz"})")),
               Contains("frame 'L'") && Contains("'config'") && Contains("missing"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "type": "const_se3"})")),
               Contains("frame 'L'") && Contains("'matrix'") && Contains("missing"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "type": "rz", "config": "q", "mass": {"inertia": [1, 1, 1, 0, 0, 0]}})")),
               Contains("frame 'L'") && Contains("'mass.m'") && Contains("missing"));
    CHECK_THAT(errorOf(arm(R"([{"type": "linear_spring", "frame1": "P", "frame2": "C", "x0": 1}])")),
               Contains("potentials[0] (linear_spring)") && Contains("'k'") && Contains("missing"));
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "distance", "frame1": "P", "frame2": "C"}])")),
               Contains("constraints[0] (distance)") && Contains("'distance'") && Contains("missing"));
    CHECK_THAT(errorOf(R"({"potentials": []})"), Contains("'frames'") && Contains("missing"));
  }
  SECTION("non-numeric field") {
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "type": "tx", "value": "1.0"})")),
               Contains("frame 'L'") && Contains("'value'") && Contains("\"1.0\"") && Contains("number"));
    CHECK_THAT(errorOf(arm(R"([{"type": "config_spring", "config": "q1", "k": "stiff", "q0": 0}])")),
               Contains("potentials[0] (config_spring)") && Contains("'k'") && Contains("\"stiff\""));
    CHECK_THAT(errorOf(arm(R"([{"type": "gravity", "g": [0, null, 0]}])")),
               Contains("potentials[0] (gravity)") && Contains("'g[1]'") && Contains("null"));
    CHECK_THAT(errorOf(arm(R"([{"type": "gravity", "g": [0, -9.8]}])")),
               Contains("potentials[0] (gravity)") && Contains("'g'") && Contains("[0,-9.8]"));
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "damping", "default": true}])")),
               Contains("forces[0] (damping)") && Contains("'default'") && Contains("true"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "type": "rz", "config": "q", "mass": {"m": [1]}})")),
               Contains("frame 'L'") && Contains("'mass.m'") && Contains("[1]"));
  }
  SECTION("unknown or duplicate frame name, reserved name") {
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "distance", "frame1": "P", "frame2": "Nope", "distance": 1}])")),
               Contains("constraints[0] (distance)") && Contains("'frame2'") && Contains("\"Nope\""));
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "point_on_plane", "plane_frame": "X", "normal": [0, 0, 1], "point_frame": "P"}])")),
               Contains("constraints[0] (point_on_plane)") && Contains("'plane_frame'") && Contains("\"X\""));
    CHECK_THAT(errorOf(arm(R"([{"type": "linear_spring", "frame1": "ghost", "frame2": "C", "k": 1, "x0": 0}])")),
               Contains("potentials[0] (linear_spring)") && Contains("'frame1'") && Contains("\"ghost\""));
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "body_wrench", "frame": "ghost", "wrench": [0, 0, 0, 0, 0, 0]}])")),
               Contains("forces[0] (body_wrench)") && Contains("'frame'") && Contains("\"ghost\""));
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "tendon", "path": ["C", "ghost"], "input": "t"}])")),
               Contains("forces[0] (tendon)") && Contains("'path[1]'") && Contains("\"ghost\""));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "A", "type": "tx", "value": 1, "children": [{"name": "A", "type": "ty", "value": 1}]})")),
               Contains("frames[0].children[0]") && Contains("'name'") && Contains("\"A\"") && Contains("already used"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "world", "type": "tx", "value": 1})")),
               Contains("frames[0]") && Contains("'name'") && Contains("\"world\"") && Contains("reserved"));
  }
  SECTION("a configuration name used twice") {
    CHECK_THAT(errorOf(oneFrame(R"({"name": "A", "type": "rz", "config": "q", "mass": {"m": 1},
                                    "children": [{"name": "B", "type": "tx", "config": "q"}]})")),
               Contains("frame 'B'") && Contains("'config'") && Contains("\"q\"") && Contains("frame 'A'"));
  }
  SECTION("negative mass") {
    CHECK_THAT(errorOf(oneFrame(R"({"name": "Link1", "type": "rz", "config": "q", "mass": {"m": -1}})")),
               Contains("frame 'Link1': field 'mass.m': -1 must be >= 0"));
  }
  SECTION("inertia tensor not symmetric positive semidefinite") {
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "type": "rz", "config": "q", "mass": {"m": 1, "inertia": [1, 1, 1, 5, 0, 0]}})")),
               Contains("frame 'L'") && Contains("'mass.inertia'") && Contains("[1,1,1,5,0,0]") &&
                   Contains("positive semidefinite"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "L", "type": "rz", "config": "q", "mass": {"m": 1, "inertia": [1, 1]}})")),
               Contains("frame 'L'") && Contains("'mass.inertia'") && Contains("[1,1]"));
  }
  SECTION("const_se3 rotation not orthonormal") {
    CHECK_THAT(errorOf(oneFrame(R"({"name": "F", "type": "const_se3", "matrix": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]})")),
               Contains("frame 'F'") && Contains("'matrix'") && Contains("[[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]") &&
                   Contains("orthonormal"));
    // a reflection is orthonormal but not a rotation
    CHECK_THAT(errorOf(oneFrame(R"({"name": "F", "type": "const_se3", "matrix": [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]})")),
               Contains("frame 'F'") && Contains("'matrix'") && Contains("det"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "F", "type": "const_se3", "matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]})")),
               Contains("frame 'F'") && Contains("'matrix[3]'") && Contains("[0,0,1,1]"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "F", "type": "const_se3", "matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]})")),
               Contains("frame 'F'") && Contains("'matrix'") && Contains("4x4"));
  }
  SECTION("a force or constraint naming a missing configuration") {
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "config_force", "config": "phi", "input": "u"}])")),
               Contains("forces[0] (config_force)") && Contains("'config'") && Contains("\"phi\""));
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "damping", "default": 0.1, "coefficients": {"q1": 1, "phi": 2}}])")),
               Contains("forces[0] (damping)") && Contains("'coefficients.phi'") && Contains("\"phi\""));
    CHECK_THAT(errorOf(arm(R"([{"type": "config_spring", "config": "phi", "k": 1, "q0": 0}])")),
               Contains("potentials[0] (config_spring)") && Contains("'config'") && Contains("\"phi\""));
  }
  SECTION("a state naming an unknown variable") {
    CHECK_THAT(errorOf(arm("[]", "[]", "[]", R"({"q": {"q1": 0, "theta9": 1}})")),
               Contains("state") && Contains("'q.theta9'") && Contains("\"theta9\""));
    CHECK_THAT(errorOf(arm("[]", "[]", "[]", R"({"dq": {"q3": 1}})")),
               Contains("state") && Contains("'dq.q3'") && Contains("\"q3\""));
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "config_force", "config": "q1", "input": "u"}])", "[]", R"({"u": {"v": 1}})")),
               Contains("state") && Contains("'u.v'") && Contains("\"v\""));
    CHECK_THAT(errorOf(arm("[]", "[]", "[]", R"({"q": {"q1": "zero"}})")),
               Contains("state") && Contains("'q.q1'") && Contains("\"zero\""));
    CHECK_THAT(errorOf(arm("[]", "[]", "[]", R"({"q": [0, 1]})")),
               Contains("state") && Contains("'q'") && Contains("[0,1]"));
  }
}

TEST_CASE("scene: malformed files beyond the spec's list", "[scene]") {
  SECTION("invalid JSON reports line and column") {
    CHECK_THAT(errorOf("{\"frames\": [\n  {\"name\": \"a\",, }]}"),
               Contains("invalid JSON") && Contains("line 2") && Contains("column"));
    CHECK_THAT(errorOf(""), Contains("invalid JSON"));
    CHECK_THAT(errorOf("{\"frames\": []} trailing"), Contains("invalid JSON"));
  }
  SECTION("wrong JSON types") {
    CHECK_THAT(errorOf("[1, 2]"), Contains("object") && Contains("[1,2]"));
    CHECK_THAT(errorOf(R"({"frames": {"name": "a"}})"), Contains("'frames'") && Contains("list"));
    CHECK_THAT(errorOf(R"({"frames": [3]})"), Contains("frames[0]") && Contains("3"));
    CHECK_THAT(errorOf(R"({"frames": [], "forces": {}})"), Contains("'forces'") && Contains("list"));
    CHECK_THAT(errorOf(R"({"frames": [], "constraints": ["distance"]})"),
               Contains("constraints[0]") && Contains("\"distance\""));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "a", "type": "tx", "value": 1, "children": {"name": "b"}})")),
               Contains("frame 'a'") && Contains("'children'") && Contains("list"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "a", "type": "tx", "value": 1, "mass": 1})")),
               Contains("frame 'a'") && Contains("'mass'") && Contains("1"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": 7, "type": "tx", "value": 1})")),
               Contains("frames[0]") && Contains("'name'") && Contains("7"));
    CHECK_THAT(errorOf(R"({"frames": [], "name": 3})"), Contains("'name'") && Contains("3"));
    CHECK_THAT(errorOf(R"({"frames": [], "state": []})"), Contains("'state'") && Contains("[]"));
  }
  SECTION("non-finite numbers") {
    CHECK_THAT(errorOf(oneFrame(R"({"name": "a", "type": "tx", "value": 1e999})")),
               Contains("1e999") && Contains("line 1"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "a", "type": "tx", "value": NaN})")), Contains("invalid JSON"));
  }
  SECTION("body_wrench entry neither number nor string; wrong length") {
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "body_wrench", "frame": "P", "wrench": [0, 0, true, 0, 0, 0]}])")),
               Contains("forces[0] (body_wrench)") && Contains("'wrench[2]'") && Contains("true"));
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "body_wrench", "frame": "P", "wrench": [0, 0, 0]}])")),
               Contains("forces[0] (body_wrench)") && Contains("'wrench'") && Contains("[0,0,0]"));
  }
  SECTION("tendon path with fewer than 2 frames") {
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "tendon", "path": ["P"], "input": "t"}])")),
               Contains("forces[0] (tendon)") && Contains("'path'") && Contains("[\"P\"]") && Contains("at least 2"));
  }
  SECTION("axis not x, y or z") {
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "point", "frame1": "P", "frame2": "C", "axis": "w"}])")),
               Contains("constraints[0] (point)") && Contains("'axis'") && Contains("\"w\""));
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "point", "frame1": "P", "frame2": "C", "axis": 0}])")),
               Contains("constraints[0] (point)") && Contains("'axis'") && Contains("0"));
  }
  SECTION("values the builder would reject are named by their field") {
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "distance", "frame1": "P", "frame2": "C", "distance": -1}])")),
               Contains("constraints[0] (distance)") && Contains("'distance'") && Contains("-1"));
    CHECK_THAT(errorOf(arm(R"([{"type": "linear_spring", "frame1": "P", "frame2": "C", "k": 1, "x0": -0.5}])")),
               Contains("potentials[0] (linear_spring)") && Contains("'x0'") && Contains("-0.5"));
    CHECK_THAT(errorOf(arm("[]", "[]", R"([{"type": "point_on_plane", "plane_frame": "C", "normal": [0, 0, 0], "point_frame": "P"}])")),
               Contains("constraints[0] (point_on_plane)") && Contains("'normal'") && Contains("[0,0,0]"));
    CHECK_THAT(errorOf(oneFrame(R"({"name": "a", "type": "tx", "value": 1, "config": "q"})")),
               Contains("frame 'a'") && Contains("both"));
    CHECK_THAT(errorOf(arm("[]", R"([{"type": "config_force", "config": "q1", "input": ""}])")),
               Contains("forces[0] (config_force)") && Contains("'input'") && Contains("empty"));
  }
  SECTION("deep nesting and unreadable files are rejected, not crashed on") {
    CHECK_THAT(errorOf(std::string(100000, '[') + std::string(100000, ']')), Contains("nested deeper"));
    CHECK_THROWS_AS(trellis::loadScene(scenePath("no_such_scene.json")), trellis::ModelError);
    CHECK_THROWS_WITH(trellis::loadScene(scenePath("no_such_scene.json")), Contains("no_such_scene.json"));
    CHECK_THROWS_WITH(trellis::loadScene(scenePath("")), Contains("directory"));
  }
  SECTION("the file name is in the message") {
    CHECK_THROWS_WITH(trellis::parseScene("{", "my_scene.json"), Contains("my_scene.json:"));
  }
}

TEST_CASE("scene: any corruption of a valid scene is a ModelError or a valid scene", "[scene]") {
  // Deterministic corruptions of the paper's scene: every prefix of its text, and every value in
  // it replaced by values of every JSON type. parseScene must either accept the result or throw
  // ModelError — never another exception, never a crash.
  const std::string text = readText(scenePath("paper_pendulum.json"));
  REQUIRE(!text.empty());
  int rejected = 0;
  for (std::size_t n = 0; n < text.size(); ++n) {
    CHECK_NOTHROW(rejected += errorOf(text.substr(0, n)) != "<no error>");
  }
  CHECK(rejected > 0);

  const nlohmann::json root = nlohmann::json::parse(text);
  const nlohmann::json flat = root.flatten();
  const std::vector<nlohmann::json> replacements{nullptr, true, "x", "", -1, 0, 1e308, nlohmann::json::array(),
                                                  nlohmann::json::object(), {{"m", 1}}};
  std::vector<nlohmann::json::json_pointer> pointers;
  for (const auto& [key, value] : flat.items()) {
    nlohmann::json::json_pointer p(key);
    // the leaf and every container above it
    while (!p.empty()) {
      pointers.push_back(p);
      p = p.parent_pointer();
    }
  }
  int accepted = 0;
  for (const auto& p : pointers) {
    for (const auto& r : replacements) {
      nlohmann::json corrupt = root;
      corrupt[p] = r;
      INFO(p.to_string() << " = " << r.dump());
      const std::string message = errorOf(corrupt.dump());
      accepted += message == "<no error>";
    }
  }
  CHECK(accepted > 0);  // e.g. a different description or a different number are fine
}
