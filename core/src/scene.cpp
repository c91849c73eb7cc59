// Scene files (SCENE_FORMAT.md, version 1): JSON text -> ModelBuilder calls -> Model + state.
//
// This file checks the *structure* of the file (types, required fields, names that refer to other
// elements) and phrases every problem as "<source>: <element>: field '<field>': <value> <problem>";
// the ModelBuilder checks the values again (and is the authority on them). Everything is read
// iteratively, so a deep frame tree cannot overflow the stack.
#include "trellis/core/scene.hpp"
#include "trellis/core/io.hpp"

#include "trellis/core/urdf.hpp"
#include "state_json.hpp"

#include <nlohmann/json.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string_view>
#include <utility>
#include <vector>

namespace trellis {
namespace {

using Json = nlohmann::json;

// Limits that keep hostile input cheap: nesting depth (a frame level costs two: the frame object
// and its "children" list, so chains of ~5000 frames fit) and text size.
constexpr int kMaxNestingDepth = 10000;
constexpr std::size_t kMaxSceneBytes = kMaxSceneFileBytes;
// Limits on the size of the model, checked while reading (before any n×n matrix exists): the
// workspace of the linearization (Data) holds about 25 dense n×n matrices (M, its inverse, A and
// the tangent-space blocks of 2n×2n, the right-hand sides of 2n + m columns), ≈ 200·n² bytes:
// 200 MB at the limit of 1000 configuration variables, 5 GB at 5000.
constexpr std::size_t kMaxSceneConfigs = 1000;
constexpr std::size_t kMaxSceneFrames = 20000;

// Pre-checks mirror the builder's so that the message can name the JSON field; the builder stays
// the authority (these tolerances are not tighter than its own).
constexpr double kRotationTolerance = 1e-9;   // max |RᵀR − I| entry of a const_se3 rotation
constexpr double kInertiaTolerance = 1e-12;   // relative, smallest eigenvalue of an inertia tensor

/// The value as it appears in the file, shortened for messages (one helper with state files).
std::string show(const Json& value) { return detail::showJson(value); }

std::string quote(std::string_view name) { return show(Json(std::string(name))); }

/// The JSON type of a value with its article, for "must be a number, not a string".
std::string kind(const Json& value) {
  switch (value.type()) {
    case Json::value_t::null: return "null";
    case Json::value_t::object: return "an object";
    case Json::value_t::array: return "an array";
    case Json::value_t::string: return "a string";
    case Json::value_t::boolean: return "a boolean";
    default: return "a number";
  }
}

using detail::listNames;  // "a, b, c" for "expected one of" hints (state_json.hpp)

/// One element of the scene (a frame, "potentials[2] (linear_spring)", "state") and the JSON
/// object that describes it. All field accessors throw ModelError naming element, field and value.
class Element {
 public:
  Element(const Json& object, std::string label) : object_(object), label_(std::move(label)) {}

  const std::string& label() const { return label_; }
  void relabel(std::string label) { label_ = std::move(label); }

  [[noreturn]] void fail(std::string_view field, const std::string& problem) const {
    throw ModelError(label_ + ": field '" + std::string(field) + "': " + problem);
  }
  [[noreturn]] void failValue(std::string_view field, const Json& value,
                              const std::string& problem) const {
    fail(field, show(value) + " " + problem);
  }

  const Json* find(std::string_view key) const {
    const auto it = object_.find(key);
    return it == object_.end() ? nullptr : &*it;
  }
  const Json& require(std::string_view key) const {
    if (const Json* value = find(key)) return *value;
    fail(key, "missing");
  }

  double number(std::string_view key) const { return toNumber(require(key), key); }
  std::optional<double> optionalNumber(std::string_view key) const {
    const Json* value = find(key);
    return value ? std::optional<double>(toNumber(*value, key)) : std::nullopt;
  }
  /// A non-empty string (a name).
  std::string name(std::string_view key) const { return toName(require(key), key); }
  Eigen::Vector3d vector3(std::string_view key) const {
    const Json& value = require(key);
    if (!value.is_array() || value.size() != 3) failValue(key, value, "must be a list of 3 numbers");
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v[i] = toNumber(value[i], std::string(key) + "[" + std::to_string(i) + "]");
    return v;
  }
  const Json& list(std::string_view key) const {
    const Json& value = require(key);
    if (!value.is_array()) failValue(key, value, "must be a list");
    return value;
  }
  const Json* optionalObject(std::string_view key) const {
    const Json* value = find(key);
    if (value && !value->is_object()) failValue(key, *value, "must be an object");
    return value;
  }

  double toNumber(const Json& value, std::string_view field) const {
    if (!value.is_number()) failValue(field, value, "must be a number, not " + kind(value));
    const double x = value.get<double>();
    if (!std::isfinite(x)) failValue(field, value, "must be finite");
    return x;
  }
  std::string toName(const Json& value, std::string_view field) const {
    if (!value.is_string()) failValue(field, value, "must be a string, not " + kind(value));
    std::string text = value.get<std::string>();
    if (text.empty()) failValue(field, value, "must not be empty");
    return text;
  }

 private:
  const Json& object_;
  std::string label_;
};

/// Reads one scene; owns the builder and the names seen so far.
class SceneReader {
 public:
  /// `baseDir`: the directory a "urdf" include is relative to.
  explicit SceneReader(std::filesystem::path baseDir) : baseDir_(std::move(baseDir)) {}

  Scene read(const Json& root) {
    if (!root.is_object()) {
      throw ModelError("the scene must be a JSON object, not " + kind(root) + " " + show(root));
    }
    Element top(root, "scene");
    Scene scene{Model{}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}};
    if (auto name = optionalText(top, "name")) scene.name = *name;
    if (auto description = optionalText(top, "description")) scene.description = *description;
    builder_ = ModelBuilder(scene.name);

    if (top.find("urdf")) {
      readUrdfInclude(top, scene);
      if (top.find("frames")) readFrames(top.list("frames"));
    } else {
      if (top.find("urdf_options")) top.fail("urdf_options", "given without \"urdf\"");
      readFrames(top.list("frames"));
    }
    readList(top, "potentials", [this](Element& e, const std::string& type) { readPotential(e, type); });
    readList(top, "forces", [this](Element& e, const std::string& type) { readForce(e, type); });
    readList(top, "constraints", [this](Element& e, const std::string& type) { readConstraint(e, type); });

    call("scene", [&] { scene.model = std::move(builder_).finalize(); });
    if (urdfJoints_) setUrdfLimits(scene, *urdfJoints_);
    readState(top, scene);
    return scene;
  }

 private:
  // ---- helpers --------------------------------------------------------------------------------

  static std::optional<std::string> optionalText(const Element& e, std::string_view key) {
    const Json* value = e.find(key);
    if (!value) return std::nullopt;
    if (!value->is_string()) e.failValue(key, *value, "must be a string, not " + kind(*value));
    return value->get<std::string>();
  }

  /// Runs a builder call; its messages gain the element's label unless they already name it
  /// (by frame name or list position).
  template <class F>
  static void call(const std::string& label, F&& f) {
    try {
      f();
    } catch (const ModelError& e) {
      const std::string what = e.what();
      const std::string position = label.substr(0, label.find(" ("));
      throw ModelError(what.rfind(position, 0) == 0 ? what : label + ": " + what);
    } catch (const std::exception& e) {
      throw ModelError(label + ": " + e.what());
    }
  }

  std::string frameRef(const Element& e, std::string_view key) const {
    std::string name = e.name(key);
    if (name != "world" && !frames_.count(name)) {
      e.fail(key, "unknown frame " + quote(name));
    }
    return name;
  }
  std::string configRef(const Element& e, std::string_view key) const {
    std::string name = e.name(key);
    if (!configs_.count(name)) {
      e.fail(key, "unknown configuration variable " + quote(name) + " (known: " +
                      listNames(configOrder_) + ")");
    }
    return name;
  }

  template <class F>
  void readList(const Element& top, const char* key, F&& readOne) {
    const Json* list = top.find(key);
    if (!list) return;
    if (!list->is_array()) top.failValue(key, *list, "must be a list");
    for (std::size_t i = 0; i < list->size(); ++i) {
      const std::string position = std::string(key) + "[" + std::to_string(i) + "]";
      const Json& item = (*list)[i];
      if (!item.is_object()) {
        throw ModelError(position + ": must be an object, not " + kind(item) + " " + show(item));
      }
      Element e(item, position);
      const std::string type = e.name("type");
      e.relabel(position + " (" + type + ")");
      readOne(e, type);
    }
  }

  // ---- frames ---------------------------------------------------------------------------------

  void readFrames(const Json& roots) {
    struct Pending {
      const Json* node;
      std::string parent;
      std::string position;
    };
    std::vector<Pending> stack;
    auto pushChildren = [&stack](const Json& list, const std::string& parent, const std::string& at) {
      for (std::size_t i = list.size(); i-- > 0;) {
        stack.push_back({&list[i], parent, at + "[" + std::to_string(i) + "]"});
      }
    };
    pushChildren(roots, "", "frames");  // "": the frame's own "parent", else the world
    // Depth-first, children in the order listed: the builder sees the frames in pre-order.
    while (!stack.empty()) {
      Pending next = std::move(stack.back());
      stack.pop_back();
      const std::string name = readFrame(*next.node, next.parent, next.position);
      Element e(*next.node, "frame '" + name + "'");
      if (const Json* children = e.find("children")) {
        if (!children->is_array()) e.failValue("children", *children, "must be a list");
        pushChildren(*children, name, next.position + ".children");
      }
    }
  }

  /// Reads and adds one frame; returns its name.
  std::string readFrame(const Json& node, std::string parent, const std::string& position) {
    if (!node.is_object()) {
      throw ModelError(position + ": a frame must be an object, not " + kind(node) + " " + show(node));
    }
    Element e(node, position);
    const std::string name = e.name("name");
    if (name == "world") e.fail("name", "\"world\" is reserved for the fixed world frame");
    if (auto it = frames_.find(name); it != frames_.end()) {
      e.fail("name", quote(name) + " is already used by " + it->second);
    }
    e.relabel("frame '" + name + "'");
    if (parent.empty()) {
      parent = e.find("parent") ? frameRef(e, "parent") : "world";
    } else if (e.find("parent")) {
      e.fail("parent", "only a top-level frame names its parent (a child's parent is the frame that lists it)");
    }

    const std::string type = e.name("type");
    const Transform transform = readTransform(e, type);
    if (transform.isDriven()) {
      if (auto it = configs_.find(transform.config); it != configs_.end()) {
        e.fail("config", quote(transform.config) + " is already used by " + it->second);
      }
    }
    std::optional<Mass> mass;
    if (const Json* massNode = e.optionalObject("mass")) mass = readMass(e, *massNode);

    if (frames_.size() >= kMaxSceneFrames) {
      e.fail("name", "the scene has more than " + std::to_string(kMaxSceneFrames) + " frames (the limit)");
    }
    if (transform.isDriven() && configOrder_.size() >= kMaxSceneConfigs) {
      e.fail("config", "the scene has more than " + std::to_string(kMaxSceneConfigs) +
                           " configuration variables (the limit: the dense matrices of the linearization "
                           "take about 200 n^2 bytes, 200 MB at n = " + std::to_string(kMaxSceneConfigs) + ")");
    }
    call(e.label(), [&] { builder_.addFrame(name, parent, transform, mass); });
    frames_.emplace(name, "frame '" + name + "' (" + position + ")");
    if (transform.isDriven()) {
      configs_.emplace(transform.config, "frame '" + name + "'");
      configOrder_.push_back(transform.config);
    }
    return name;
  }

  static Transform readTransform(const Element& e, const std::string& type) {
    if (type == "r_axis" || type == "t_axis") return readAxisTransform(e, type);
    if (type == "const_se3") {
      if (e.find("config")) e.fail("config", "a const_se3 frame has no configuration variable");
      return Transform::constSE3(readMatrix4(e));
    }
    using ByValue = Transform (*)(double);
    using ByConfig = Transform (*)(std::string);
    struct Primitive {
      const char* type;
      ByValue byValue;
      ByConfig byConfig;
    };
    static const std::array<Primitive, 6> kPrimitives{{
        {"tx", &Transform::tx, &Transform::tx},
        {"ty", &Transform::ty, &Transform::ty},
        {"tz", &Transform::tz, &Transform::tz},
        {"rx", &Transform::rx, &Transform::rx},
        {"ry", &Transform::ry, &Transform::ry},
        {"rz", &Transform::rz, &Transform::rz},
    }};
    for (const Primitive& p : kPrimitives) {
      if (type != p.type) continue;
      const bool hasConfig = e.find("config") != nullptr;
      const bool hasValue = e.find("value") != nullptr;
      if (hasConfig && hasValue) {
        e.fail("config", "give either 'config' (a coordinate) or 'value' (a constant), not both");
      }
      if (hasConfig) return p.byConfig(e.name("config"));
      if (hasValue) return p.byValue(e.number("value"));
      e.fail("config", "missing: a " + type + " frame needs 'config' (a coordinate) or 'value' (a constant)");
    }
    e.failValue("type", Json(type), "is not one of tx, ty, tz, rx, ry, rz, r_axis, t_axis, const_se3");
  }

  /// r_axis / t_axis: "axis" (unit 3-vector), "config" or "value", optional "origin" {"xyz", "rpy"}
  /// (URDF convention, R = Rz(yaw) Ry(pitch) Rx(roll)) placed before the motion.
  static Transform readAxisTransform(const Element& e, const std::string& type) {
    const Eigen::Vector3d axis = e.vector3("axis");
    const double norm = axis.norm();
    if (std::abs(norm - 1.0) > 1e-9) {
      std::ostringstream problem;
      problem << "must be a unit vector (norm " << norm << ")";
      e.failValue("axis", e.require("axis"), problem.str());
    }
    Eigen::Matrix4d origin = Eigen::Matrix4d::Identity();
    if (const Json* node = e.optionalObject("origin")) {
      Element o(*node, e.label());
      for (const auto& [key, value] : node->items()) {
        if (key != "xyz" && key != "rpy") o.fail("origin." + key, "unknown field (known: xyz, rpy)");
      }
      const auto read3 = [&](const char* key) -> Eigen::Vector3d {
        const Json* v = o.find(key);
        if (!v) return Eigen::Vector3d::Zero();
        const std::string field = std::string("origin.") + key;
        if (!v->is_array() || v->size() != 3) o.failValue(field, *v, "must be a list of 3 numbers");
        return {o.toNumber((*v)[0], field + "[0]"), o.toNumber((*v)[1], field + "[1]"), o.toNumber((*v)[2], field + "[2]")};
      };
      origin = poseFromXyzRpy(read3("xyz"), read3("rpy"));
    }
    const bool hasConfig = e.find("config") != nullptr, hasValue = e.find("value") != nullptr;
    if (hasConfig && hasValue) e.fail("config", "give either 'config' (a coordinate) or 'value' (a constant), not both");
    if (!hasConfig && !hasValue) {
      e.fail("config", "missing: a " + type + " frame needs 'config' (a coordinate) or 'value' (a constant)");
    }
    if (type == "r_axis") {
      return hasConfig ? Transform::rotAxis(axis, e.name("config"), origin)
                       : Transform::rotAxis(axis, e.number("value"), origin);
    }
    return hasConfig ? Transform::transAxis(axis, e.name("config"), origin)
                     : Transform::transAxis(axis, e.number("value"), origin);
  }

  static Eigen::Matrix4d readMatrix4(const Element& e) {
    const Json& rows = e.require("matrix");
    const auto badShape = [&] { e.failValue("matrix", rows, "must be a 4x4 matrix (a list of 4 rows of 4 numbers)"); };
    if (!rows.is_array() || rows.size() != 4) badShape();
    Eigen::Matrix4d m;
    for (int i = 0; i < 4; ++i) {
      if (!rows[i].is_array() || rows[i].size() != 4) badShape();
      for (int j = 0; j < 4; ++j) {
        m(i, j) = e.toNumber(rows[i][j], "matrix[" + std::to_string(i) + "][" + std::to_string(j) + "]");
      }
    }
    if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > kRotationTolerance) {
      e.failValue("matrix[3]", rows[3], "must be [0, 0, 0, 1]");
    }
    const Eigen::Matrix3d r = m.topLeftCorner<3, 3>();
    const double orthoError = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (orthoError > kRotationTolerance || r.determinant() <= 0.0) {
      std::ostringstream problem;
      problem << "has a rotation part that is not orthonormal with determinant +1 (max |RᵀR − I| = "
              << orthoError << ", det R = " << r.determinant() << ")";
      e.failValue("matrix", rows, problem.str());
    }
    return m;
  }

  static Mass readMass(const Element& frame, const Json& node) {
    Element e(node, frame.label());
    Mass mass;
    const Json* mNode = e.find("m");
    if (!mNode) e.fail("mass.m", "missing");
    const Json& m = *mNode;
    mass.m = e.toNumber(m, "mass.m");
    if (mass.m < 0.0) e.failValue("mass.m", m, "must be >= 0");
    if (const Json* inertia = e.find("inertia")) {
      if (!inertia->is_array() || inertia->size() != 6) {
        e.failValue("mass.inertia", *inertia, "must be a list of 6 numbers [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]");
      }
      std::array<double, 6> v{};
      for (int i = 0; i < 6; ++i) v[i] = e.toNumber((*inertia)[i], "mass.inertia[" + std::to_string(i) + "]");
      Eigen::Matrix3d& I = mass.inertia;
      I << v[0], v[3], v[4],  //
          v[3], v[1], v[5],   //
          v[4], v[5], v[2];
      const double scale = std::max(1.0, I.cwiseAbs().maxCoeff());
      const double smallest = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(I, Eigen::EigenvaluesOnly)
                                  .eigenvalues()
                                  .minCoeff();
      if (smallest < -kInertiaTolerance * scale) {
        std::ostringstream problem;
        problem << "is not positive semidefinite (smallest eigenvalue " << smallest << ")";
        e.failValue("mass.inertia", *inertia, problem.str());
      }
    }
    return mass;
  }

  // ---- potentials, forces, constraints --------------------------------------------------------

  void readPotential(const Element& e, const std::string& type) {
    if (type == "gravity") {
      // Several gravity entries add up (V = −Σ m g·p for each), as the builder does.
      const Eigen::Vector3d g = e.vector3("g");
      call(e.label(), [&] { builder_.addGravity(g); });
    } else if (type == "linear_spring") {
      const std::string f1 = frameRef(e, "frame1"), f2 = frameRef(e, "frame2");
      const double k = e.number("k"), x0 = e.number("x0");
      if (x0 < 0.0) e.failValue("x0", e.require("x0"), "must be >= 0");
      call(e.label(), [&] { builder_.addLinearSpring(f1, f2, k, x0); });
    } else if (type == "config_spring") {
      const std::string config = configRef(e, "config");
      const double k = e.number("k"), q0 = e.number("q0");
      call(e.label(), [&] { builder_.addConfigSpring(config, k, q0); });
    } else {
      e.failValue("type", Json(type), "is not one of gravity, linear_spring, config_spring");
    }
  }

  void readForce(const Element& e, const std::string& type) {
    if (type == "config_force") {
      const std::string config = configRef(e, "config");
      const std::string input = e.name("input");
      call(e.label(), [&] { builder_.addConfigForce(config, input); });
    } else if (type == "damping") {
      const double dflt = e.optionalNumber("default").value_or(0.0);
      std::map<std::string, double> coefficients;
      if (const Json* node = e.optionalObject("coefficients")) {
        for (const auto& [config, c] : node->items()) {
          const std::string field = "coefficients." + config;
          if (!configs_.count(config)) {
            e.fail(field, "unknown configuration variable " + quote(config) + " (known: " +
                              listNames(configOrder_) + ")");
          }
          coefficients[config] = e.toNumber(c, field);
        }
      }
      call(e.label(), [&] { builder_.addDamping(dflt, coefficients); });
    } else if (type == "body_wrench") {
      const std::string frame = frameRef(e, "frame");
      const Json& w = e.require("wrench");
      if (!w.is_array() || w.size() != 6) {
        e.failValue("wrench", w, "must be a list of 6 entries [fx, fy, fz, tx, ty, tz]");
      }
      std::array<WrenchEntry, 6> wrench;
      for (int i = 0; i < 6; ++i) {
        const std::string field = "wrench[" + std::to_string(i) + "]";
        if (w[i].is_string()) {
          wrench[i] = e.toName(w[i], field);
        } else if (w[i].is_number()) {
          wrench[i] = e.toNumber(w[i], field);
        } else {
          e.failValue(field, w[i], "must be a number or an input name, not " + kind(w[i]));
        }
      }
      call(e.label(), [&] { builder_.addBodyWrench(frame, wrench); });
    } else if (type == "tendon") {
      const Json& path = e.list("path");
      if (path.size() < 2) e.failValue("path", path, "must list at least 2 frames");
      std::vector<std::string> frames;
      for (std::size_t i = 0; i < path.size(); ++i) {
        const std::string field = "path[" + std::to_string(i) + "]";
        const std::string name = e.toName(path[i], field);
        if (name != "world" && !frames_.count(name)) e.fail(field, "unknown frame " + quote(name));
        frames.push_back(name);
      }
      const std::string input = e.name("input");
      call(e.label(), [&] { builder_.addTendon(frames, input); });
    } else {
      e.failValue("type", Json(type), "is not one of config_force, damping, body_wrench, tendon");
    }
  }

  void readConstraint(const Element& e, const std::string& type) {
    if (type == "distance") {
      const std::string f1 = frameRef(e, "frame1"), f2 = frameRef(e, "frame2");
      const double d = e.number("distance");
      // d = 0: h = |p1 - p2|^2 has a vanishing gradient wherever it holds, a degenerate row whose
      // constraint force is undetermined (use three "point" constraints to join two points).
      if (!(d > 0.0)) e.failValue("distance", e.require("distance"), "must be > 0 (a distance of 0 makes the constraint's gradient vanish wherever it holds; join two points with \"point\" constraints)");
      call(e.label(), [&] { builder_.addDistanceConstraint(f1, f2, d); });
    } else if (type == "point") {
      const std::string f1 = frameRef(e, "frame1"), f2 = frameRef(e, "frame2");
      const Json& axisNode = e.require("axis");
      const std::string axis = e.toName(axisNode, "axis");
      if (axis != "x" && axis != "y" && axis != "z") e.failValue("axis", axisNode, "must be \"x\", \"y\" or \"z\"");
      const int index = axis[0] - 'x';
      call(e.label(), [&] { builder_.addPointConstraint(f1, f2, index); });
    } else if (type == "point_on_plane") {
      const std::string plane = frameRef(e, "plane_frame");
      const Eigen::Vector3d normal = e.vector3("normal");
      if (normal.isZero(0.0)) e.failValue("normal", e.require("normal"), "must not be zero");
      const std::string point = frameRef(e, "point_frame");
      call(e.label(), [&] { builder_.addPointOnPlaneConstraint(plane, normal, point); });
    } else if (type == "knife_edge") {
      // Extension beyond version 1 of the spec: the nonholonomic constraint the builder offers.
      const std::string frame = frameRef(e, "frame");
      const Eigen::Vector3d axis = e.vector3("axis");
      if (axis.isZero(0.0)) e.failValue("axis", e.require("axis"), "must not be zero");
      call(e.label(), [&] { builder_.addKnifeEdgeConstraint(frame, axis); });
    } else if (type == "coordinate_coupling") {
      // q_config = multiplier · q_leader + offset (a URDF <mimic>).
      const std::string follower = configRef(e, "config"), leader = configRef(e, "leader");
      const double multiplier = e.number("multiplier");
      if (multiplier == 0.0) e.failValue("multiplier", e.require("multiplier"), "must not be 0 (that fixes the coordinate)");
      const double offset = e.optionalNumber("offset").value_or(0.0);
      call(e.label(), [&] { builder_.addCoordinateCoupling(follower, leader, multiplier, offset); });
    } else {
      e.failValue("type", Json(type), "is not one of distance, point, point_on_plane, knife_edge, coordinate_coupling");
    }
  }

  // ---- URDF include ---------------------------------------------------------------------------

  /// {"urdf": "arm.urdf", "urdf_options": {"gravity": [gx, gy, gz], "joint_inputs": true}}: the
  /// robot's frames and configuration variables come first; the path is relative to the scene.
  void readUrdfInclude(const Element& top, Scene& scene) {
    const std::string file = top.name("urdf");
    UrdfOptions options;
    if (const Json* node = top.optionalObject("urdf_options")) {
      Element o(*node, "urdf_options");
      static const char* const kKnown = "gravity, joint_inputs, base_inputs, floating_root, ignore_friction";
      for (const auto& [key, value] : node->items()) {
        if (key != "gravity" && key != "joint_inputs" && key != "base_inputs" && key != "floating_root" &&
            key != "ignore_friction")
          o.fail(key, std::string("unknown option (known: ") + kKnown + ")");
      }
      if (o.find("gravity")) options.gravity = o.vector3("gravity");
      const auto flag = [&](const char* key, bool& target) {
        if (const Json* v = o.find(key)) {
          if (!v->is_boolean()) o.failValue(key, *v, "must be true or false, not " + kind(*v));
          target = v->get<bool>();
        }
      };
      flag("joint_inputs", options.jointInputs);
      flag("base_inputs", options.baseInputs);
      flag("floating_root", options.floatingRoot);
      flag("ignore_friction", options.ignoreFriction);
    }
    std::filesystem::path path(file);
    if (path.is_relative()) path = baseDir_ / path;
    std::string text;
    try {
      text = readTextFile(path.string(), kMaxSceneBytes, "URDF file");  // "/dev/zero" is refused
    } catch (const FileError& e) {
      top.failValue("urdf", Json(file), "cannot be read (looked for " + path.string() + "): " + e.what());
    }
    UrdfImport robot = importUrdf(text, path.string(), options);
    builder_ = std::move(robot.builder);
    urdfJoints_ = std::move(robot.joints);
    for (const auto& f : robot.frames) frames_.emplace(f, "frame '" + f + "' of " + file);
    for (const auto& c : robot.configs) {
      configs_.emplace(c, "a joint of " + file);
      configOrder_.push_back(c);
    }
    scene.visuals = std::move(robot.visuals);
    for (auto& w : robot.warnings) scene.warnings.push_back(std::move(w));
    if (scene.name.empty()) scene.name = robot.robotName;
  }

  // ---- state ----------------------------------------------------------------------------------

  static void readState(const Element& top, Scene& scene) {
    ModelState state = zeroState(scene.model);
    if (const Json* node = top.optionalObject("state")) {
      detail::readStateObject(scene.model, *node, "state", false, false, state);  // state_json.hpp
    }
    scene.q = std::move(state.q);
    scene.dq = std::move(state.dq);
    scene.u = std::move(state.u);
  }

  std::filesystem::path baseDir_;
  ModelBuilder builder_;
  std::map<std::string, std::string> frames_;   // name -> where it was defined, for messages
  std::map<std::string, std::string> configs_;  // config -> frame that carries it
  std::vector<std::string> configOrder_;
  std::optional<std::vector<UrdfJoint>> urdfJoints_;  // a "urdf" include's joints (for the limits)
};

/// Rejects text nested deeper than kMaxNestingDepth before nlohmann builds a tree of it.
void checkNesting(const std::string& text) {
  int depth = 0;
  bool inString = false, escaped = false;
  int line = 1;
  std::size_t lineStart = 0;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '\n') {
      ++line;
      lineStart = i + 1;
    }
    if (inString) {
      if (escaped) {
        escaped = false;
      } else if (c == '\\') {
        escaped = true;
      } else if (c == '"') {
        inString = false;
      }
    } else if (c == '"') {
      inString = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxNestingDepth) {
        throw ModelError("invalid JSON at line " + std::to_string(line) + ", column " +
                         std::to_string(i - lineStart + 1) + ": nested deeper than " +
                         std::to_string(kMaxNestingDepth) + " levels");
      }
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
}

/// " at line L, column C" of the first occurrence of the token quoted in `what` ('...'), if any.
std::string locateToken(const std::string& text, const std::string& what) {
  const auto open = what.find('\'');
  const auto close = open == std::string::npos ? open : what.find('\'', open + 1);
  if (close == std::string::npos || close == open + 1) return "";
  const auto at = text.find(what.substr(open + 1, close - open - 1));
  if (at == std::string::npos) return "";
  const auto lineStart = text.rfind('\n', at);
  const auto line = 1 + std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(at), '\n');
  const auto column = at - (lineStart == std::string::npos ? 0 : lineStart + 1) + 1;
  return " at line " + std::to_string(line) + ", column " + std::to_string(column);
}

/// nlohmann's message without its "[json.exception.parse_error.101] " prefix.
std::string jsonMessage(const nlohmann::json::exception& e) {
  std::string what = e.what();
  if (const auto end = what.find("] "); what.rfind("[json.exception.", 0) == 0 && end != std::string::npos) {
    what.erase(0, end + 2);
  }
  return what;
}

}  // namespace

Scene parseScene(const std::string& jsonText, const std::string& source) {
  // A URDF robot (XML) loads wherever a scene does. A UTF-8 byte-order mark (editors on Windows
  // write one) comes before either kind; it is skipped, not called invalid JSON.
  const std::size_t start = jsonText.rfind("\xEF\xBB\xBF", 0) == 0 ? 3 : 0;
  if (const auto first = jsonText.find_first_not_of(" \t\r\n", start); first != std::string::npos && jsonText[first] == '<') {
    return sceneFromUrdf(importUrdf(start ? jsonText.substr(start) : jsonText, source));
  }
  try {
    if (jsonText.size() > kMaxSceneBytes) {
      throw ModelError("the scene is larger than " + std::to_string(kMaxSceneBytes >> 20) + " MiB");
    }
    checkNesting(jsonText);
    Json root;
    try {
      root = Json::parse(jsonText);
    } catch (const nlohmann::json::parse_error& e) {
      throw ModelError("invalid JSON: " + jsonMessage(e));
    } catch (const nlohmann::json::exception& e) {
      // e.g. "number overflow parsing '1e999'" (a non-finite number), which carries no position.
      throw ModelError("invalid JSON" + locateToken(jsonText, e.what()) + ": " + jsonMessage(e));
    }
    // A "urdf" include is relative to the scene file (to the working directory for "<stdin>").
    const bool isPath = !source.empty() && source.front() != '<';
    return SceneReader(isPath ? std::filesystem::path(source).parent_path() : std::filesystem::path())
        .read(root);
  } catch (const ModelError& e) {
    throw ModelError(source + ": " + e.what());
  } catch (const nlohmann::json::exception& e) {
    // A structural check missed a type: still report it as a bad scene, never as a crash.
    throw ModelError(source + ": " + jsonMessage(e));
  }
}

Scene loadScene(const std::string& path) {
  std::string text;
  try {
    text = readTextFile(path, kMaxSceneBytes, "scene file");  // bounded before it allocates
  } catch (const FileError& e) {
    throw ModelError(e.what());
  }
  return parseScene(text, path);
}

}  // namespace trellis
