// Tests of trellis/viewer/view.hpp: the page's data against the library's kinematics (exact), the
// sample times, visual and mesh handling, bad input (clear errors, no partial file). The page in a
// real browser: tests/viewer/browser_check.py.
#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/io.hpp"
#include "trellis/core/kinematics.hpp"
#include "trellis/core/scene.hpp"
#include "trellis/core/urdf.hpp"
#include "trellis/viewer/view.hpp"

#include <catch2/catch.hpp>

#include <unistd.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using trellis::ViewError;

namespace {

const std::string kSource = TRELLIS_SOURCE_DIR;

/// A fresh directory under the system's temporary directory, removed at the end of the test.
struct TempDir {
  fs::path path;
  explicit TempDir(const std::string& name) : path(fs::temp_directory_path() / ("trellis_viewer_" + std::to_string(::getpid()) + "_" + name)) {
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
};

std::vector<unsigned char> decodeBase64(const std::string& text) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::vector<unsigned char> out;
  unsigned buffer = 0;
  int bits = 0;
  for (char c : text) {
    const int v = value(c);
    if (v < 0) break;  // padding
    buffer = (buffer << 6) | static_cast<unsigned>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<unsigned char>((buffer >> bits) & 0xFF));
    }
  }
  return out;
}

template <class T>
std::vector<T> decodeArray(const std::string& text) {
  const std::vector<unsigned char> bytes = decodeBase64(text);
  REQUIRE(bytes.size() % sizeof(T) == 0);
  std::vector<T> values(bytes.size() / sizeof(T));
  std::memcpy(values.data(), bytes.data(), bytes.size());
  return values;
}

/// The JSON block of a page.
nlohmann::json pageData(const std::string& page) {
  const std::string open = "<script type=\"application/json\" id=\"trellis-data\">";
  const std::size_t begin = page.find(open);
  REQUIRE(begin != std::string::npos);
  const std::size_t end = page.find("</script>", begin);
  return nlohmann::json::parse(page.substr(begin + open.size(), end - begin - open.size()));
}

trellis::ViewTrajectory pendulumSwing() {
  return {"swing", trellis::Trajectory::readCsvFile(kSource + "/examples/trajectories/pendulum_swing.csv"), false};
}

std::string urdfWithVisual(const std::string& geometry) {
  return R"(<robot name="arm">
  <link name="base"/>
  <link name="upper"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 0.25"/><geometry>)" + geometry + R"(</geometry></visual></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
</robot>)";
}

trellis::Scene urdfScene(const std::string& geometry) {
  return trellis::sceneFromUrdf(trellis::importUrdf(urdfWithVisual(geometry), "arm.urdf"));
}

void writeBinaryStl(const fs::path& path, int triangles) {
  std::string bytes(80, '\0');
  const std::uint32_t count = static_cast<std::uint32_t>(triangles);
  bytes.append(reinterpret_cast<const char*>(&count), 4);
  for (int t = 0; t < triangles; ++t) {
    float v[12] = {0, 0, 1, 0, 0, 0, 0.1f * (t + 1), 0, 0, 0, 0.2f, 0.3f};
    bytes.append(reinterpret_cast<const char*>(v), sizeof v);
    bytes.append(2, '\0');
  }
  trellis::writeFileAtomically(path.string(), bytes);
}

}  // namespace

TEST_CASE("encodeBase64 follows RFC 4648", "[viewer]") {
  auto encode = [](const std::string& s) {
    return trellis::encodeBase64(reinterpret_cast<const unsigned char*>(s.data()), s.size());
  };
  CHECK(encode("") == "");
  CHECK(encode("f") == "Zg==");
  CHECK(encode("fo") == "Zm8=");
  CHECK(encode("foo") == "Zm9v");
  CHECK(encode("foobar") == "Zm9vYmFy");
  CHECK(encode(std::string("\xff\xfe\x00", 3)) == "//4A");
}

TEST_CASE("the page holds the library's kinematics at every knot, exactly", "[viewer]") {
  const trellis::Scene scene = trellis::loadScene(kSource + "/examples/scenes/pendulum.json");
  const trellis::Model& model = scene.model;
  const trellis::ViewTrajectory swing = pendulumSwing();
  trellis::ViewReport report;
  const std::string page = trellis::renderView(scene, scene.q, {swing}, {}, &report);
  const nlohmann::json data = pageData(page);
  REQUIRE(data["trajectories"].size() == 1);
  const std::vector<double> times = decodeArray<double>(data["trajectories"][0]["t"]);
  const std::vector<double> poses = decodeArray<double>(data["trajectories"][0]["poses"]);
  const int nb = model.nq();
  REQUIRE(poses.size() == times.size() * 7 * nb);
  CHECK(report.samples == static_cast<long>(times.size()));
  CHECK(report.bytes == page.size());

  SECTION("every knot is a sample, and its pose is computeKinematics' exactly") {
    trellis::Data data_(model);
    const Eigen::VectorXd& knots = swing.trajectory.times();
    for (Eigen::Index k = 0; k < knots.size(); ++k) {
      const auto at = std::find(times.begin(), times.end(), knots(k));
      REQUIRE(at != times.end());
      const std::size_t s = static_cast<std::size_t>(at - times.begin());
      trellis::computeKinematics(model, data_, swing.trajectory.states().col(k).head(model.nq()),
                                 Eigen::VectorXd::Zero(model.nq()));
      for (int j = 0; j < nb; ++j) {
        const int f = model.frameIndex(model.joints()[j].frame);
        const Eigen::Vector3d p = data_.framePose[f].translation();
        for (int i = 0; i < 3; ++i) CHECK(poses[7 * (s * nb + j) + i] == p(i));
        const Eigen::Quaterniond q(data_.framePose[f].linear());
        // Same rotation (the sign of a quaternion is free; the page stores w >= 0).
        const Eigen::Quaterniond stored(poses[7 * (s * nb + j) + 3], poses[7 * (s * nb + j) + 4],
                                        poses[7 * (s * nb + j) + 5], poses[7 * (s * nb + j) + 6]);
        CHECK(std::abs(std::abs(stored.dot(q.normalized())) - 1.0) < 1e-15);
        CHECK(stored.w() >= 0.0);
      }
    }
  }

  SECTION("between knots: the display grid t0 + k/60 where the knots are sparser; q(t) is the trajectory's Hermite q") {
    const double t0 = swing.trajectory.startTime(), t1 = swing.trajectory.endTime();
    CHECK(std::is_sorted(times.begin(), times.end()));
    CHECK(std::adjacent_find(times.begin(), times.end()) == times.end());
    CHECK(times.front() == t0);
    CHECK(times.back() == t1);
    // Knots 0.05 s apart: the grid times 1/60 and 2/60 s past each knot are added, 3/60 is a knot.
    CHECK(times.size() == static_cast<std::size_t>(swing.trajectory.size()) + 2 * (swing.trajectory.size() - 1));
    for (std::size_t i = 1; i < times.size(); ++i) CHECK(times[i] - times[i - 1] <= 1 / 60.0 + 1e-12);
    // A grid sample's pose: the configuration part of Trajectory::evaluate (dynamics-based knot
    // derivatives give the same q: the cubic Hermite q uses q and q̇ at the knots only).
    trellis::Trajectory reference = swing.trajectory;
    trellis::Data data_(model);
    reference.computeStateDerivatives(model, data_);
    const std::size_t s = 1;  // 1/60 s lies between the first two knots (0.05 s apart)
    REQUIRE(times[s] == t0 + 1 / 60.0);
    trellis::computeKinematics(model, data_, reference.state(times[s]).head(model.nq()),
                               Eigen::VectorXd::Zero(model.nq()));
    // The pivot stays at the origin: its rotation carries the motion. The bob (1 m down the body)
    // placed with the stored pose lands where the kinematics put it.
    const double* stored = &poses[7 * s * nb];
    const Eigen::Quaterniond rotation(stored[3], stored[4], stored[5], stored[6]);
    const Eigen::Vector3d bob = Eigen::Vector3d(stored[0], stored[1], stored[2]) + rotation * Eigen::Vector3d(0, -1, 0);
    CHECK((bob - data_.framePose[model.frameIndex("bob")].translation()).norm() <= 1e-15);
    CHECK(bob.x() > 0.5);  // the swing starts at theta = 1: far from the hanging position
  }

  SECTION("frames: the joint frame has no offset; the bob sits at its placement on the body") {
    const nlohmann::json& frames = data["frames"];
    REQUIRE(frames.size() == 2);
    CHECK(frames[0]["name"] == "pivot");
    CHECK_FALSE(frames[0].contains("p"));
    CHECK(frames[1]["name"] == "bob");
    CHECK(frames[1]["p"] == nlohmann::json::array({0.0, -1.0, 0.0}));
    CHECK(data["bodies"][0]["mass"] == 1.0);
    CHECK(data["view"]["up"] == nlohmann::json::array({0.0, 1.0, 0.0}));
  }
}

TEST_CASE("tendons and constraints refer to frames of the bodies they are fixed to", "[viewer]") {
  const trellis::Scene scene = trellis::loadScene(kSource + "/examples/scenes/all_elements_3d.json");
  const nlohmann::json data = pageData(trellis::renderView(scene, scene.q, {}, {}));
  CHECK(data["constraints"].size() == scene.model.constraints().size());
  CHECK(data["tendons"].size() == scene.model.tendons().size());
  trellis::Data work(scene.model);
  trellis::computeKinematics(scene.model, work, scene.q, Eigen::VectorXd::Zero(scene.model.nq()));
  // Each constraint point placed through its frame lands where the model's body point is.
  for (std::size_t c = 0; c < scene.model.constraints().size(); ++c) {
    const trellis::Constraint& constraint = scene.model.constraints()[c];
    for (const auto& [point, name] : {std::pair{constraint.a, "a"}, std::pair{constraint.b, "b"}}) {
      const nlohmann::json& p = data["constraints"][c][name];
      const Eigen::Vector3d local(p["p"][0], p["p"][1], p["p"][2]);
      const int f = p["f"];
      const Eigen::Vector3d world = f < 0 ? local : Eigen::Vector3d(work.framePose[f] * local);
      Eigen::Vector3d expected = point.local;
      if (point.joint != trellis::kWorld) {
        const trellis::FramePlacement& rep = scene.model.frames()[f];
        expected = work.framePose[f] * (rep.R.transpose() * (point.local - rep.p));
      }
      CHECK((world - expected).norm() <= 1e-14);
      if (point.joint != trellis::kWorld) CHECK(scene.model.frames()[f].joint == point.joint);
    }
  }
}

TEST_CASE("bad input: clear errors, and no file left behind", "[viewer]") {
  TempDir dir("bad_input");
  const std::string out = (dir.path / "view.html").string();
  const trellis::Scene pendulum = trellis::loadScene(kSource + "/examples/scenes/pendulum.json");

  SECTION("a trajectory whose columns do not match the model") {
    const trellis::Scene cartPole = trellis::loadScene(kSource + "/examples/scenes/cart_pole.json");
    const trellis::ViewTrajectory swing = pendulumSwing();
    try {
      trellis::writeView(out, cartPole, cartPole.q, {swing});
      FAIL("no error");
    } catch (const ViewError& e) {
      const std::string message = e.what();
      CHECK(message.find("trajectory 1 ('swing')") != std::string::npos);
      CHECK(message.find("theta") != std::string::npos);
    }
    CHECK_FALSE(fs::exists(out));
  }
  SECTION("an existing page is kept whole when the new one fails") {
    trellis::writeView(out, pendulum, pendulum.q, {pendulumSwing()});
    const std::string before = trellis::readTextFile(out, std::size_t{1} << 30, "page");
    trellis::ViewOptions options;
    options.displayRate = -1.0;
    CHECK_THROWS_WITH(trellis::writeView(out, pendulum, pendulum.q, {pendulumSwing()}, options),
                      Catch::Contains("displayRate"));
    CHECK(trellis::readTextFile(out, std::size_t{1} << 30, "page") == before);
    CHECK(fs::directory_iterator(dir.path) != fs::directory_iterator());
    int files = 0;
    for ([[maybe_unused]] const auto& entry : fs::directory_iterator(dir.path)) ++files;
    CHECK(files == 1);  // no temporary left beside it
  }
  SECTION("a URDF visual with a bad size names the link and the field") {
    for (const auto& [geometry, field] : {std::pair{"<box size=\"0.1 -0.2 0.3\"/>", "<box size>"},
                                          std::pair{"<cylinder radius=\"0\" length=\"1\"/>", "<cylinder radius>"},
                                          std::pair{"<cylinder radius=\"0.1\" length=\"-1\"/>", "<cylinder length>"},
                                          std::pair{"<sphere radius=\"-0.1\"/>", "<sphere radius>"},
                                          std::pair{"<mesh filename=\"x.stl\" scale=\"1 0 1\"/>", "<mesh scale>"}}) {
      const trellis::Scene robot = urdfScene(geometry);
      CHECK_THROWS_WITH(trellis::writeView(out, robot, robot.q, {}),
                        Catch::Contains("link 'upper' <visual> #1") && Catch::Contains(field));
      CHECK_FALSE(fs::exists(out));
    }
  }
  SECTION("a mesh that cannot be found or read is an error naming the link and the file") {
    const trellis::Scene robot = urdfScene("<mesh filename=\"meshes/upper.stl\"/>");
    trellis::ViewOptions options;
    options.meshBaseDirectory = dir.path.string();
    CHECK_THROWS_WITH(trellis::writeView(out, robot, robot.q, {}, options),
                      Catch::Contains("link 'upper'") && Catch::Contains("meshes/upper.stl") &&
                          Catch::Contains("not found"));
    fs::create_directories(dir.path / "meshes");
    trellis::writeFileAtomically((dir.path / "meshes/upper.stl").string(), "this is not an STL file");
    CHECK_THROWS_WITH(trellis::writeView(out, robot, robot.q, {}, options),
                      Catch::Contains("link 'upper'") && Catch::Contains("neither binary STL"));
    CHECK_FALSE(fs::exists(out));
  }
  SECTION("three.js missing: an error that says how to install it") {
    trellis::ViewOptions options;
    options.threeDirectory = (dir.path / "no_three").string();
    CHECK_THROWS_WITH(trellis::writeView(out, pendulum, pendulum.q, {}, options),
                      Catch::Contains("libjs-three") && Catch::Contains("three.min.js"));
    CHECK_FALSE(fs::exists(out));
  }
}

TEST_CASE("meshes: STL drawn, package:// resolved, other formats as a stand-in with a warning", "[viewer]") {
  TempDir dir("meshes");
  fs::create_directories(dir.path / "share/arm_description/meshes");
  writeBinaryStl(dir.path / "share/arm_description/meshes/upper.stl", 3);
  trellis::ViewOptions options;
  options.meshBaseDirectory = (dir.path / "urdf").string();
  options.packagePath = {(dir.path / "share").string()};

  SECTION("binary STL through package://") {
    const trellis::Scene robot = urdfScene("<mesh filename=\"package://arm_description/meshes/upper.stl\" scale=\"2 2 2\"/>");
    trellis::ViewReport report;
    const nlohmann::json data = pageData(trellis::renderView(robot, robot.q, {}, options, &report));
    CHECK(report.warnings.empty());
    REQUIRE(data["meshes"].size() == 1);
    const std::vector<float> triangles = decodeArray<float>(data["meshes"][0]);
    REQUIRE(triangles.size() == 27);
    // Triangle t: (0, 0, 0), (0.1 (t + 1), 0, 0), (0, 0.2, 0.3); the normals are not kept.
    CHECK(triangles[0] == 0.0f);
    CHECK(triangles[3] == 0.1f);
    CHECK(triangles[8] == 0.3f);
    CHECK(triangles[18 + 3] == 0.3f);
    CHECK(data["visuals"][0]["shape"] == "mesh");
    CHECK(data["visuals"][0]["size"] == nlohmann::json::array({2.0, 2.0, 2.0}));
  }
  SECTION("ASCII STL relative to the URDF") {
    fs::create_directories(dir.path / "urdf");
    trellis::writeFileAtomically((dir.path / "urdf/part.STL").string(),
                                 "solid part\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                                 "vertex 0 1 0\nendloop\nendfacet\nendsolid part\n");
    const trellis::Scene robot = urdfScene("<mesh filename=\"part.STL\"/>");
    const nlohmann::json data = pageData(trellis::renderView(robot, robot.q, {}, options));
    CHECK(decodeArray<float>(data["meshes"][0]).size() == 9);
  }
  SECTION("OBJ: its bounding box, with a warning") {
    fs::create_directories(dir.path / "urdf");
    trellis::writeFileAtomically((dir.path / "urdf/part.obj").string(), "v 0 0 0\nv 1 2 3\nv -1 0 1\nf 1 2 3\n");
    const trellis::Scene robot = urdfScene("<mesh filename=\"part.obj\"/>");
    trellis::ViewReport report;
    const nlohmann::json data = pageData(trellis::renderView(robot, robot.q, {}, options, &report));
    REQUIRE(report.warnings.size() == 1);
    CHECK(report.warnings[0].find("link 'upper'") != std::string::npos);
    CHECK(report.warnings[0].find("bounding box") != std::string::npos);
    CHECK(data["visuals"][0]["shape"] == "standin");
    CHECK(data["visuals"][0]["size"] == nlohmann::json::array({2.0, 2.0, 3.0}));
    CHECK(data["warnings"].size() == 1);
  }
  SECTION("an unsupported format: a stand-in cube, with a warning") {
    fs::create_directories(dir.path / "urdf");
    trellis::writeFileAtomically((dir.path / "urdf/part.dae").string(), "<COLLADA/>");
    const trellis::Scene robot = urdfScene("<mesh filename=\"part.dae\"/>");
    trellis::ViewReport report;
    const nlohmann::json data = pageData(trellis::renderView(robot, robot.q, {}, options, &report));
    REQUIRE(report.warnings.size() == 1);
    CHECK(report.warnings[0].find("'.dae' is not supported") != std::string::npos);
    CHECK(data["visuals"][0]["shape"] == "standin");
  }
}

TEST_CASE("the page includes three.js with its licence notice and cannot be cut short by data", "[viewer]") {
  trellis::Scene scene = trellis::loadScene(kSource + "/examples/scenes/pendulum.json");
  trellis::ViewOptions options;
  options.title = "a </script> title";
  const std::string page = trellis::renderView(scene, scene.q, {}, options);
  CHECK(page.find("three.js (https://threejs.org), MIT (Expat) licence") != std::string::npos);
  CHECK(page.find("OrbitControls") != std::string::npos);
  CHECK(pageData(page)["title"] == "a </script> title");
  CHECK(page.find("<title>a &lt;/script&gt; title</title>") != std::string::npos);
  // Same input, same bytes.
  CHECK(trellis::renderView(scene, scene.q, {}, options) == page);
}

TEST_CASE("ghost trajectories: float32 differences from the first trajectory, float32, or float64", "[viewer]") {
  const trellis::Scene scene = trellis::loadScene(kSource + "/examples/scenes/pendulum.json");
  trellis::ViewTrajectory reference = pendulumSwing(), ghost = pendulumSwing(), other = pendulumSwing();
  ghost.name = "ghost";
  ghost.ghost = true;
  // The same knot times, another motion: θ scaled by 1.01 (a closed loop beside its reference).
  {
    const trellis::Trajectory& r = reference.trajectory;
    ghost.trajectory = trellis::Trajectory(r.configNames(), r.inputNames(), r.times(), 1.01 * r.states(), r.inputs());
  }
  // Other times (shifted by 1 ms): stored as float32 coordinates.
  other.name = "other";
  other.ghost = true;
  {
    const trellis::Trajectory& r = reference.trajectory;
    other.trajectory = trellis::Trajectory(r.configNames(), r.inputNames(), r.times().array() + 1e-3, r.states(), r.inputs());
  }
  trellis::ViewOptions options;
  trellis::ViewReport report;
  const nlohmann::json rounded = pageData(trellis::renderView(scene, scene.q, {reference, ghost, other}, options, &report));
  options.exactGhosts = true;
  trellis::ViewReport exactReport;
  const nlohmann::json exact = pageData(trellis::renderView(scene, scene.q, {reference, ghost, other}, options, &exactReport));
  CHECK(rounded["trajectories"][0]["encoding"] == "float64");
  CHECK(rounded["trajectories"][1]["encoding"] == "delta32");
  CHECK(rounded["trajectories"][1]["base"] == 0);
  CHECK(rounded["trajectories"][1]["timesOf"] == 0);  // the times are not stored twice
  CHECK_FALSE(rounded["trajectories"][1].contains("t"));
  CHECK(rounded["trajectories"][2]["encoding"] == "float32");
  CHECK(rounded["trajectories"][2].contains("t"));
  CHECK(exact["trajectories"][1]["encoding"] == "float64");
  CHECK(exact["trajectories"][2]["encoding"] == "float64");
  CHECK(exactReport.ghostRounding == 0.0);

  const std::vector<double> base = decodeArray<double>(rounded["trajectories"][0]["poses"]);
  const std::vector<double> full = decodeArray<double>(exact["trajectories"][1]["poses"]);
  const std::vector<float> delta = decodeArray<float>(rounded["trajectories"][1]["poses"]);
  REQUIRE(full.size() == delta.size());
  REQUIRE(base.size() == delta.size());
  // The page's reading, base + delta in float64, against the exact poses: the rounding of the
  // difference (here ≤ 6e-8 of a deviation ≤ 0.03 m and ≤ 0.02 in quaternion entries), far below
  // the rounding of float32 coordinates (6e-8 of 1 m).
  double worst = 0.0;
  for (std::size_t i = 0; i < full.size(); ++i) {
    CHECK(delta[i] == static_cast<float>(full[i] - base[i]));
    worst = std::max(worst, std::abs(base[i] + static_cast<double>(delta[i]) - full[i]));
  }
  CHECK(worst <= 1e-9);
  const std::vector<double> otherFull = decodeArray<double>(exact["trajectories"][2]["poses"]);
  const std::vector<float> otherSingle = decodeArray<float>(rounded["trajectories"][2]["poses"]);
  REQUIRE(otherFull.size() == otherSingle.size());
  double worstOther = 0.0;
  for (std::size_t i = 0; i < otherFull.size(); ++i) {
    CHECK(otherSingle[i] == static_cast<float>(otherFull[i]));
    worstOther = std::max(worstOther, std::abs(static_cast<double>(otherSingle[i]) - otherFull[i]));
  }
  CHECK(report.ghostRounding == std::max(worst, worstOther));
  CHECK(worstOther > worst);
}

TEST_CASE("force arrows: the constraint forces of the library at every sample", "[viewer]") {
  // The paper's pendulum: one distance constraint between the frames B and C.
  const trellis::Scene scene = trellis::loadScene(kSource + "/examples/scenes/paper_pendulum.json");
  const trellis::Model& model = scene.model;
  REQUIRE(model.nc() == 1);
  trellis::ViewTrajectory swing{
      "swing", trellis::Trajectory::readCsvFile(kSource + "/examples/trajectories/paper_pendulum_swing.csv"), false};
  trellis::ViewTrajectory ghost = swing;
  ghost.ghost = true;
  const nlohmann::json data = pageData(trellis::renderView(scene, scene.q, {swing, ghost}, {}));
  REQUIRE(data["arrows"].size() == 1);
  CHECK(data["arrows"][0]["names"][0] == model.constraints()[0].name);
  CHECK(data["arrows"][0]["rows"] == nlohmann::json::array({0}));
  CHECK_FALSE(data["trajectories"][1].contains("forces"));  // ghosts draw no arrows
  const std::vector<double> times = decodeArray<double>(data["trajectories"][0]["t"]);
  const std::vector<double> forces = decodeArray<double>(data["trajectories"][0]["forces"]);
  REQUIRE(forces.size() == 6 * times.size());

  // At every sample: λ from computeDynamics at the trajectory's interpolated state and input, the
  // force λ · 2(p_B − p_C) on B's body at p_B (h = ‖p_B − p_C‖² − ℓ²), computed here from the frames.
  trellis::Trajectory reference = swing.trajectory;
  trellis::Data work(model);
  reference.computeStateDerivatives(model, work);
  Eigen::VectorXd x, u;
  double largest = 0.0;
  const int n = model.nq();
  for (std::size_t s = 0; s < times.size(); ++s) {
    reference.evaluate(times[s], x, u);
    REQUIRE(trellis::computeDynamics(model, work, x.head(n), x.tail(n), u).ok());
    const double lambda = work.lambda(0);
    trellis::computeKinematics(model, work, x.head(n), x.tail(n));  // the frames' poses
    const Eigen::Vector3d pB = work.framePose[model.frameIndex("B")].translation();
    const Eigen::Vector3d pC = work.framePose[model.frameIndex("C")].translation();
    const Eigen::Vector3d force = lambda * 2.0 * (pB - pC);
    largest = std::max(largest, force.norm());
    for (int k = 0; k < 3; ++k) {
      CHECK(forces[6 * s + k] == pB(k));
      CHECK(std::abs(forces[6 * s + 3 + k] - force(k)) <= 1e-14 * force.norm());
    }
  }
  CHECK(data["largestForce"].get<double>() == Approx(largest).epsilon(1e-14));

  SECTION("ViewOptions::constraintForces = false: no arrows") {
    trellis::ViewOptions options;
    options.constraintForces = false;
    const nlohmann::json none = pageData(trellis::renderView(scene, scene.q, {swing}, options));
    CHECK_FALSE(none.contains("arrows"));
    CHECK_FALSE(none["trajectories"][0].contains("forces"));
  }
}
