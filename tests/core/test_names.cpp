// tests/core/test_names.cpp — names that files must carry back (trellis/core/names.hpp): every
// class of name the CSV writers cannot read back is refused when the model is built (scene, URDF,
// builder), with a message naming the element and the name; every accepted name round-trips
// through a trajectory CSV.
#include <catch2/catch.hpp>

#include <trellis/core.hpp>
#include <trellis/core/names.hpp>

#include <nlohmann/json.hpp>

#include <sstream>
#include <string>
#include <vector>

namespace {

using Catch::Contains;

/// A scene with two prismatic frames driven by `a` and `b` and a force input `input` on `a`.
std::string scene(const std::string& a, const std::string& b = "y", const std::string& input = "u") {
  nlohmann::json j;
  j["frames"] = {{{"name", "f1"}, {"type", "tx"}, {"config", a}, {"mass", {{"m", 1.0}}}},
                 {{"name", "f2"}, {"type", "ty"}, {"config", b}, {"mass", {{"m", 1.0}}}}};
  j["forces"] = {{{"type", "config_force"}, {"config", a}, {"input", input}}};
  return j.dump();
}

std::string errorOf(const std::string& text) {
  try {
    trellis::parseScene(text, "names.json");
  } catch (const trellis::ModelError& e) {
    return e.what();
  }
  return "<no error>";
}

}  // namespace

TEST_CASE("names that cannot round-trip through the CSV files are refused at load time", "[names]") {
  // The classes of the reliability run (issue 24), each with the element and the name in the message.
  CHECK_THAT(errorOf(scene("a,b")), Contains("names.json") && Contains("frame 'f1'") && Contains("name 'a,b' holds ','"));
  CHECK_THAT(errorOf(scene("a\nb")), Contains("frame 'f1'") && Contains("name 'a\\x0Ab' holds a control character"));
  CHECK_THAT(errorOf(scene("   ")), Contains("name '   ' begins or ends with a blank"));
  CHECK_THAT(errorOf(scene(" x")), Contains("name ' x' begins or ends with a blank"));
  CHECK_THAT(errorOf(scene("q\"1")), Contains("holds '\"'"));
  CHECK_THAT(errorOf(scene("x", "y", "rate_x")), Contains("input 'rate_x': names beginning with 'rate_' are reserved"));
  CHECK_THAT(errorOf(scene("x", "dx")),
             Contains("configuration 'dx'") && Contains("velocity column 'dx' of configuration 'x'") &&
                 Contains("share the CSV column name 'dx'"));
  CHECK_THAT(errorOf(scene("dy", "y")), Contains("velocity column 'dy' of configuration 'y' and configuration 'dy'"));
  // The builder applies the same rule to code that builds a model directly, frames included.
  trellis::ModelBuilder b;
  CHECK_THROWS_WITH(b.addFrame(std::string("f\xff"), "world", trellis::Transform::tx(0.1)),
                    Contains("frame 'f\\xFF': field 'name': name 'f\\xFF' is not valid UTF-8 (byte 2)"));
  b.addFrame("g", "world", trellis::Transform::tx("x"));
  CHECK_THROWS_WITH(b.addConfigForce("x", "u,1"), Contains("'u,1' holds ','"));
  // And the URDF importer, whose joint names become configuration names.
  const std::string urdf = "<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/>\n"
                           "<joint name=\"j,1\" type=\"revolute\"><parent link=\"a\"/><child link=\"b\"/></joint></robot>";
  CHECK_THAT(errorOf(urdf), Contains("names.json:2: joint 'j,1'") && Contains("holds ','"));
  const std::string latin1 = "<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/>\n"
                             "<joint name=\"\xe9\" type=\"revolute\"><parent link=\"a\"/><child link=\"b\"/></joint></robot>";
  CHECK_THAT(errorOf(latin1), Contains("names.json:2: the file is not valid UTF-8 (column 14: '<joint name=\"\\xE9\""));
}

TEST_CASE("accepted names round-trip through a trajectory CSV", "[names]") {
  for (const auto& [a, b] : std::vector<std::pair<std::string, std::string>>{
           {"x", "y"}, {"θ", "φ₁"}, {"left arm", "d"}, {"rate", "dd"}, {"x.y", "a:b"}, {"t", "dd"}}) {
    // An input may repeat a column name (read by position): here the first configuration's.
    const trellis::Scene s = trellis::parseScene(scene(a, b, a), "names.json");
    const trellis::Trajectory t(s.model.configNames(), s.model.inputNames(), Eigen::Vector2d(0.0, 1.0),
                                Eigen::MatrixXd::Ones(4, 2), Eigen::MatrixXd::Zero(1, 2));
    std::stringstream csv;
    t.writeCsv(csv);
    const trellis::Trajectory back = trellis::Trajectory::readCsv(csv, "names.csv");
    CHECK(back.configNames() == s.model.configNames());
    CHECK(back.inputNames() == s.model.inputNames());
  }
  CHECK(trellis::nameProblem("ok name").empty());
  CHECK(trellis::printableName("a\tb\xc3") == "a\\x09b\\xC3");
}
