// URDF robots as ModelBuilder calls (urdf.hpp, docs/urdf.md), parsed with tinyxml2.
//
// tinyxml2 rather than urdfdom: urdfdom reports a bad file through console_bridge log lines and a
// null pointer (no line numbers, and some errors only as warnings), and it fills in defaults and
// drops what it does not know before we could refuse it. tinyxml2 gives every element's line, so
// each message here reads "<file>:<line>: joint 'j': attribute 'xyz': value '…' <problem>", and we
// decide ourselves what is supported. It is also one small library with a CMake config.
#include "trellis/core/urdf.hpp"
#include "trellis/core/io.hpp"
#include "trellis/core/names.hpp"

#include <tinyxml2.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>

namespace trellis {
namespace {

using tinyxml2::XMLElement;

std::string fmt(double x) {
  std::ostringstream s;
  s.precision(10);
  s << x;
  return s.str();
}

struct LinkSpec {
  const XMLElement* xml = nullptr;
  std::string name;
};

struct JointSpec {
  const XMLElement* xml = nullptr;
  std::string name, type, parent, child;
};

class UrdfReader {
 public:
  UrdfReader(std::string source, const UrdfOptions& options) : source_(std::move(source)), options_(options) {}

  UrdfImport read(const std::string& text) {
    // Names and values travel on as UTF-8 (JSON output, messages): a file in another encoding is
    // refused here with its line, not by a JSON library later with no file named.
    if (const std::size_t bad = invalidUtf8Offset(text); bad != std::string_view::npos) {
      const std::string_view before = std::string_view(text).substr(0, bad);
      const std::size_t line = 1 + static_cast<std::size_t>(std::count(before.begin(), before.end(), '\n'));
      const std::size_t newline = before.rfind('\n');
      const std::size_t start = newline == std::string_view::npos ? 0 : newline + 1;
      // The line up to the bad byte and a little after (at most 80 bytes), as \xNN where not UTF-8.
      const std::string_view shown = std::string_view(text).substr(start, std::min<std::size_t>(bad - start + 4, 80));
      throw ModelError(source_ + ":" + std::to_string(line) + ": the file is not valid UTF-8 (column " +
                       std::to_string(bad - start + 1) + ": '" + printableName(shown) +
                       "'); URDF names and values must be UTF-8 (convert with iconv -t UTF-8)");
    }
    tinyxml2::XMLDocument doc;
    if (doc.Parse(text.data(), text.size()) != tinyxml2::XML_SUCCESS) {
      throw ModelError(source_ + ":" + std::to_string(doc.ErrorLineNum()) + ": invalid XML: " + doc.ErrorStr());
    }
    const XMLElement* robot = doc.RootElement();
    if (!robot || std::string(robot->Name()) != "robot") {
      throw ModelError(source_ + ":" + std::to_string(robot ? robot->GetLineNum() : 1) +
                       ": the root element must be <robot>, not <" + (robot ? robot->Name() : "") + ">");
    }
    robotXml_ = robot;
    checkStructure(robot);
    const std::string robotLabel = "robot";
    out_.robotName = attribute(robot, "name", robotLabel, false);
    out_.builder = ModelBuilder(out_.robotName);
    readLinks(robot);
    readJoints(robot);
    build();
    return std::move(out_);
  }

 private:
  // ---- messages and attributes ----------------------------------------------------------------

  [[noreturn]] void fail(const XMLElement* at, const std::string& element, const std::string& problem) const {
    throw ModelError(source_ + ":" + std::to_string(at->GetLineNum()) + ": " + element + ": " + problem);
  }

  /// The attribute's text; missing: "" if optional, else an error.
  std::string attribute(const XMLElement* e, const char* name, const std::string& element, bool required) const {
    const char* value = e->Attribute(name);
    if (!value) {
      if (required) fail(e, element, "<" + std::string(e->Name()) + "> attribute '" + name + "': missing");
      return "";
    }
    return value;
  }

  /// `count` finite numbers separated by blanks.
  std::vector<double> numbers(const XMLElement* e, const char* name, const std::string& element,
                              std::size_t count) const {
    const std::string text = attribute(e, name, element, true);
    std::vector<double> values;
    const char* p = text.c_str();
    char* end = nullptr;
    while (true) {
      while (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r') ++p;
      if (!*p) break;
      errno = 0;
      const double x = std::strtod(p, &end);
      // A number ends at a blank or the end: "1.5.2" or "0-1-2" are not split into 1.5, 0.2 or
      // 0, −1, −2 (strtod alone would stop at the second '.' or '-' and go on from there).
      const bool separated = *end == '\0' || *end == ' ' || *end == '\t' || *end == '\n' || *end == '\r';
      if (end == p || !separated || !std::isfinite(x) || errno == ERANGE) {
        values.clear();
        break;
      }
      values.push_back(x);
      p = end;
    }
    if (text.find("${") != std::string::npos || text.find("$(") != std::string::npos)
      failXacro(e, element + ": <" + std::string(e->Name()) + "> attribute '" + name + "': value '" + text + "'");
    if (values.size() != count) {
      fail(e, element, "<" + std::string(e->Name()) + "> attribute '" + name + "': value '" + text +
                           "' must be " + std::to_string(count) + " finite number" + (count > 1 ? "s" : ""));
    }
    return values;
  }
  double number(const XMLElement* e, const char* name, const std::string& element) const {
    return numbers(e, name, element, 1)[0];
  }
  double optionalNumber(const XMLElement* e, const char* name, const std::string& element, double dflt) const {
    return e->Attribute(name) ? number(e, name, element) : dflt;
  }
  Eigen::Vector3d vector3(const XMLElement* e, const char* name, const std::string& element,
                          const Eigen::Vector3d& dflt) const {
    if (!e->Attribute(name)) return dflt;
    const auto v = numbers(e, name, element, 3);
    return {v[0], v[1], v[2]};
  }

  /// The <origin xyz rpy> child of e (identity if absent).
  Eigen::Matrix4d origin(const XMLElement* e, const std::string& element) const {
    const XMLElement* o = e->FirstChildElement("origin");
    if (!o) return Eigen::Matrix4d::Identity();
    return poseFromXyzRpy(vector3(o, "xyz", element, Eigen::Vector3d::Zero()),
                          vector3(o, "rpy", element, Eigen::Vector3d::Zero()));
  }

  /// Runs a builder call; its message gains the file, line and element.
  template <class F>
  void call(const XMLElement* at, const std::string& element, F&& f) const {
    try {
      f();
    } catch (const ModelError& e) {
      fail(at, element, e.what());
    }
  }

  // ---- structure: every element is one we read, or one the docs list as ignored --------------

  /// The xacro refusal: macros, properties and includes are not URDF; importing the rest would
  /// give a smaller robot.
  [[noreturn]] void failXacro(const XMLElement* at, const std::string& what) const {
    throw ModelError(source_ + ":" + std::to_string(at->GetLineNum()) + ": " + what +
                     ": this is a xacro file; trellis reads plain URDF and does not expand xacro macros, "
                     "properties or includes. Expand it first: xacro " +
                     (source_.empty() || source_.front() == '<' ? std::string("robot.urdf.xacro") : source_) +
                     " > robot.urdf");
  }

  /// One level of the URDF schema: the children `e` may have and how many of each (0: any).
  /// An element not listed is refused with its line (it would otherwise be dropped silently:
  /// a <link> inside a <joint>, a second <parent>).
  void checkChildren(const XMLElement* e, const std::string& element,
                     std::initializer_list<std::pair<const char*, int>> allowed) const {
    std::map<std::string, const XMLElement*> seen;
    for (const XMLElement* c = e->FirstChildElement(); c; c = c->NextSiblingElement()) {
      const std::string name = c->Name();
      if (name.rfind("xacro:", 0) == 0) failXacro(c, "<" + name + ">");
      int limit = -1;
      for (const auto& [n, max] : allowed)
        if (name == n) limit = max;
      if (limit < 0) {
        std::string list;
        for (const auto& [n, max] : allowed) list += (list.empty() ? "<" : ", <") + std::string(n) + ">";
        fail(c, element, "unexpected element <" + name + "> inside <" + e->Name() + "> (expected " +
                             (list.empty() ? std::string("no child elements") : list) + ")");
      }
      if (limit == 1) {
        if (auto it = seen.find(name); it != seen.end()) {
          fail(c, element, "a second <" + name + "> (the first is on line " + std::to_string(it->second->GetLineNum()) +
                               "); <" + e->Name() + "> takes one");
        }
        seen[name] = c;
      }
    }
  }

  void checkStructure(const XMLElement* robot) const {
    for (const tinyxml2::XMLAttribute* a = robot->FirstAttribute(); a; a = a->Next()) {
      if (std::string(a->Name()) == "xmlns:xacro") failXacro(robot, "<robot> declares xmlns:xacro");
    }
    // <material>, <transmission>, <gazebo> at the top level are documented as ignored.
    checkChildren(robot, "robot", {{"link", 0}, {"joint", 0}, {"material", 0}, {"transmission", 0}, {"gazebo", 0}});
    for (const XMLElement* l = robot->FirstChildElement("link"); l; l = l->NextSiblingElement("link")) {
      const std::string element = "link '" + attribute(l, "name", "link", false) + "'";
      checkChildren(l, element, {{"inertial", 1}, {"visual", 0}, {"collision", 0}});
      if (const XMLElement* in = l->FirstChildElement("inertial")) {
        checkChildren(in, element + " <inertial>", {{"origin", 1}, {"mass", 1}, {"inertia", 1}});
        for (const XMLElement* c = in->FirstChildElement(); c; c = c->NextSiblingElement())
          checkChildren(c, element + " <inertial>", {});
      }
      for (const XMLElement* v = l->FirstChildElement("visual"); v; v = v->NextSiblingElement("visual")) {
        checkChildren(v, element + " <visual>", {{"origin", 1}, {"geometry", 1}, {"material", 1}});
        if (const XMLElement* g = v->FirstChildElement("geometry")) {
          checkChildren(g, element + " <visual>", {{"box", 1}, {"cylinder", 1}, {"sphere", 1}, {"mesh", 1}, {"capsule", 1}});
          if (g->FirstChildElement() && g->FirstChildElement() != g->LastChildElement())
            fail(g, element + " <visual>", "<geometry> holds more than one shape");
        }
      }
    }
    for (const XMLElement* j = robot->FirstChildElement("joint"); j; j = j->NextSiblingElement("joint")) {
      const std::string element = "joint '" + attribute(j, "name", "joint", false) + "'";
      checkChildren(j, element,
                    {{"origin", 1}, {"parent", 1}, {"child", 1}, {"axis", 1}, {"limit", 1}, {"dynamics", 1},
                     {"mimic", 1}, {"calibration", 1}, {"safety_controller", 1}, {"joint_properties", 1}});
      for (const XMLElement* c = j->FirstChildElement(); c; c = c->NextSiblingElement()) checkChildren(c, element, {});
    }
  }

  // ---- links and joints -----------------------------------------------------------------------

  void readLinks(const XMLElement* robot) {
    for (const XMLElement* l = robot->FirstChildElement("link"); l; l = l->NextSiblingElement("link")) {
      LinkSpec link{l, attribute(l, "name", "link", true)};
      if (link.name.empty()) fail(l, "link", "attribute 'name': empty");
      if (linkIndex_.count(link.name)) fail(l, "link '" + link.name + "'", "duplicate link name");
      linkIndex_[link.name] = static_cast<int>(links_.size());
      links_.push_back(link);
    }
    if (links_.empty()) fail(robot, "robot", "has no <link>");
  }

  void readJoints(const XMLElement* robot) {
    for (const XMLElement* j = robot->FirstChildElement("joint"); j; j = j->NextSiblingElement("joint")) {
      JointSpec joint;
      joint.xml = j;
      joint.name = attribute(j, "name", "joint", true);
      const std::string element = "joint '" + joint.name + "'";
      if (joint.name.empty()) fail(j, "joint", "attribute 'name': empty");
      if (jointNames_.count(joint.name)) fail(j, element, "duplicate joint name");
      jointNames_.insert(joint.name);
      joint.type = attribute(j, "type", element, true);
      const XMLElement* parent = j->FirstChildElement("parent");
      const XMLElement* child = j->FirstChildElement("child");
      if (!parent) fail(j, element, "<parent> missing");
      if (!child) fail(j, element, "<child> missing");
      joint.parent = attribute(parent, "link", element, true);
      joint.child = attribute(child, "link", element, true);
      // <parent link="world"> without a declared link 'world' (Drake's own examples weld their base
      // so): the world itself, as Drake and Pinocchio read it.
      if (joint.parent == "world" && !linkIndex_.count("world")) {
        if (!implicitWorld_) implicitWorld_ = j;
      } else if (!linkIndex_.count(joint.parent)) {
        fail(parent, element, "<parent> attribute 'link': unknown link '" + joint.parent + "'");
      }
      if (!linkIndex_.count(joint.child)) fail(child, element, "<child> attribute 'link': unknown link '" + joint.child + "'");
      if (joint.parent == joint.child) fail(child, element, "link '" + joint.child + "' is its own parent");
      if (auto it = parentJoint_.find(joint.child); it != parentJoint_.end()) {
        fail(child, element, "link '" + joint.child + "' already has a parent joint '" +
                                 joints_[it->second].name + "' (line " +
                                 std::to_string(joints_[it->second].xml->GetLineNum()) +
                                 "): closed chains are added in a scene as constraints");
      }
      parentJoint_[joint.child] = static_cast<int>(joints_.size());
      joints_.push_back(joint);
    }
  }

  /// Adds a mass for link `l` (not the root): on the link frame, or on a constant child frame
  /// "<link>:inertial" when the inertial origin is not the identity.
  void addInertial(const LinkSpec& l) {
    const XMLElement* in = l.xml->FirstChildElement("inertial");
    if (!in) return;
    const std::string element = "link '" + l.name + "' <inertial>";
    const XMLElement* massXml = in->FirstChildElement("mass");
    const XMLElement* inertiaXml = in->FirstChildElement("inertia");
    if (!massXml) fail(in, element, "<mass> missing");
    if (!inertiaXml) fail(in, element, "<inertia> missing");
    Mass mass;
    mass.m = number(massXml, "value", element);
    if (mass.m < 0) fail(massXml, element, "<mass> attribute 'value': value '" + fmt(mass.m) + "' must be >= 0");
    const char* names[6] = {"ixx", "iyy", "izz", "ixy", "ixz", "iyz"};
    double v[6];
    for (int i = 0; i < 6; ++i) v[i] = number(inertiaXml, names[i], element);
    mass.inertia << v[0], v[3], v[4], v[3], v[1], v[5], v[4], v[5], v[2];
    if (mass.m == 0.0) {
      // The docs' rule: mass 0 is a massless frame. An inertia without mass is no body.
      if (!mass.inertia.isZero(0.0)) {
        fail(inertiaXml, element, "mass 0 with a nonzero <inertia>: a link of mass 0 is massless (no inertia); "
                                  "give it a mass or set ixx..iyz to 0");
      }
      return;
    }
    checkInertia(mass.inertia, inertiaXml, element);
    const Eigen::Matrix4d g = origin(in, element);
    if (g.isIdentity(0.0)) {
      pendingMass_[l.name] = mass;
      return;
    }
    inertialFrames_[l.name] = {l.name, g, mass, inertiaXml};
  }

  /// A rigid body's inertia about its centre of mass: symmetric positive semidefinite with principal
  /// moments that satisfy the triangle inequality, I_1 ≤ I_2 + I_3 (I_1 + I_2 − I_3 = 2 ∫ z² dm ≥ 0).
  /// Zero moments are allowed (a point mass, a thin rod). Slack: 1e-9 of the trace (round-off of
  /// values written with ~10 digits).
  void checkInertia(const Eigen::Matrix3d& I, const XMLElement* at, const std::string& element) const {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(I, Eigen::EigenvaluesOnly);
    const Eigen::Vector3d p = eig.eigenvalues();  // ascending
    const double slack = 1e-9 * std::abs(I.trace());
    const std::string values = "principal moments " + fmt(p[0]) + ", " + fmt(p[1]) + ", " + fmt(p[2]);
    if (p[0] < -slack)
      fail(at, element, "<inertia> is not positive semidefinite (" + values + "): no rigid body has it");
    if (p[2] > p[0] + p[1] + slack)
      fail(at, element, "<inertia> violates the triangle inequality (" + values + ": the largest exceeds the sum of "
                        "the other two): no rigid body has it");
  }

  void build() {
    // The root: the one link without a parent joint. It is the world (fixed base). An undeclared
    // 'world' named as a parent is that root (every declared link then has a parent joint).
    std::vector<std::string> roots;
    if (implicitWorld_) roots.push_back("world");
    for (const auto& l : links_)
      if (!parentJoint_.count(l.name)) roots.push_back(l.name);
    if (roots.size() != 1) {
      std::string list;
      for (const auto& r : roots) list += (list.empty() ? "'" : ", '") + r + "'";
      const XMLElement* at = roots.empty() ? links_[0].xml : links_[linkIndex_.at(roots.back())].xml;
      fail(at, "robot", roots.empty() ? "no root link (the joints form a cycle)"
                                      : "several root links (" + list + "); a URDF is one tree");
    }
    out_.rootLink = roots[0];
    // The ROS convention <link name="world"/> as the root (fixed to the ground by a fixed joint)
    // names the world itself; anywhere else in the tree 'world' would be a second world.
    const bool rootIsWorld = out_.rootLink == "world";
    if (!rootIsWorld && linkIndex_.count("world")) {
      fail(links_[linkIndex_.at("world")].xml, "link 'world'",
           "the name 'world' is reserved for the fixed world frame; only the root link may have it "
           "(the root link is '" + out_.rootLink + "')");
    }
    // floatingRoot: a floating joint from the world to the root link (whose mass then counts), or,
    // for a root named 'world', its single fixed child joint made floating.
    if (options_.floatingRoot) {
      if (rootIsWorld) {
        std::vector<int> fromWorld;
        for (int i = 0; i < static_cast<int>(joints_.size()); ++i)
          if (joints_[i].parent == "world") fromWorld.push_back(i);
        if (fromWorld.size() != 1 || joints_[fromWorld[0]].type != "fixed") {
          const XMLElement* at = fromWorld.empty() ? robotXml_ : joints_[fromWorld[0]].xml;
          fail(at, "robot", "floating_root: the root link is 'world' and " +
                                (fromWorld.size() == 1 ? "its child joint '" + joints_[fromWorld[0]].name +
                                                             "' is " + joints_[fromWorld[0]].type + ", not fixed"
                                                       : std::to_string(fromWorld.size()) + " joints hang from it") +
                                "; floating_root needs a single fixed joint from 'world' to the base (it makes that "
                                "joint floating)");
        }
        floatingJoint_ = fromWorld[0];
      } else {
        if (jointNames_.count(kFloatingRootJoint) || linkIndex_.count(kFloatingRootJoint))
          fail(robotXml_, "robot", std::string("floating_root: the file already has a joint or link named '") +
                                       kFloatingRootJoint + "', the name of the floating joint it would add");
      }
    }
    const bool rootHasMass = options_.floatingRoot && !rootIsWorld;
    for (const auto& l : links_)
      if (l.name != out_.rootLink || rootHasMass) addInertial(l);
    for (const auto& [link, f] : inertialFrames_)
      if (linkIndex_.count(f.link + ":inertial"))
        fail(f.at, "link '" + f.link + "' <inertial>", "frame name '" + f.link + ":inertial' clashes with a link");

    std::map<std::string, double> damping;
    std::map<std::string, std::vector<int>> children;  // link -> child joints, in file order
    for (int i = 0; i < static_cast<int>(joints_.size()); ++i) children[joints_[i].parent].push_back(i);

    ModelBuilder& b = out_.builder;
    if (rootHasMass) {
      // The root link floats: a floating joint 'floating_base' from the world (at its origin).
      addJoint(JointSpec{robotXml_, kFloatingRootJoint, "floating", "world", out_.rootLink}, damping);
    } else if (!rootIsWorld) {
      b.addFrame(out_.rootLink, "world", Transform::constSE3(Eigen::Matrix4d::Identity()));
      out_.frames.push_back(out_.rootLink);
    }
    // Depth first from the root, children in file order: the builder sees the tree in pre-order.
    std::vector<int> stack;
    auto push = [&](const std::string& link) {
      const auto& c = children[link];
      for (auto it = c.rbegin(); it != c.rend(); ++it) stack.push_back(*it);
    };
    push(out_.rootLink);
    int visited = 0;
    while (!stack.empty()) {
      const JointSpec& j = joints_[stack.back()];
      stack.pop_back();
      ++visited;
      addJoint(j, damping);
      push(j.child);
    }
    if (visited != static_cast<int>(joints_.size())) {
      for (const auto& j : joints_)
        if (std::find(out_.frames.begin(), out_.frames.end(), j.child) == out_.frames.end())
          fail(j.xml, "joint '" + j.name + "'", "not connected to the root link '" + out_.rootLink + "' (a cycle)");
    }
    for (const auto& l : links_) readVisuals(l);

    if (!damping.empty()) b.addDamping(0.0, damping);
    // <mimic>: q_j = m q_leader + o, a holonomic constraint row (ModelBuilder::addCoordinateCoupling).
    std::set<std::string> followers;
    for (const Mimic& mm : mimics_) {
      const std::string element = "joint '" + mm.joint + "'";
      const auto leader = std::find_if(out_.joints.begin(), out_.joints.end(),
                                       [&](const UrdfJoint& u) { return u.name == mm.leader; });
      if (leader == out_.joints.end())
        fail(mm.at, element, "<mimic> attribute 'joint': value '" + mm.leader + "' is not a movable joint of the file");
      if (leader->configs.size() != 1)
        fail(mm.at, element, "<mimic> attribute 'joint': value '" + mm.leader + "' is a " + leader->type +
                                 " joint; a mimic follows a revolute, continuous or prismatic joint");
      if (mm.multiplier == 0.0)
        fail(mm.at, element, "<mimic> attribute 'multiplier': value '0' would fix the joint, not couple it");
      call(mm.at, element, [&] { b.addCoordinateCoupling(mm.joint, mm.leader, mm.multiplier, mm.offset); });
      followers.insert(mm.joint);
    }
    // Inputs on the joints' coordinates; on a floating or planar joint's only with baseInputs; none
    // on a mimic joint (it is driven through its coupling, as by a linkage or a gear).
    if (options_.jointInputs)
      for (const auto& j : out_.joints)
        if ((options_.baseInputs || (j.type != "floating" && j.type != "planar")) && !followers.count(j.name))
          for (const auto& c : j.configs) b.addConfigForce(c, c);
    if (!options_.gravity.isZero(0.0)) b.addGravity(options_.gravity);
  }

  void addJoint(const JointSpec& spec, std::map<std::string, double>& damping) {
    JointSpec j = spec;
    // floatingRoot with a root named world: its fixed joint to the base becomes floating.
    if (floatingJoint_ >= 0 && &spec == &joints_[floatingJoint_]) j.type = "floating";
    const bool addedRoot = j.name == kFloatingRootJoint && j.parent == "world" && j.xml == robotXml_;
    const std::string element = addedRoot ? std::string("floating_root") : "joint '" + j.name + "'";
    const XMLElement* x = j.xml;
    if (const XMLElement* m = x->FirstChildElement("mimic")) {
      // q_j = multiplier · q_leader + offset: a coordinate coupling, added once every joint exists.
      const std::string leader = attribute(m, "joint", element, true);
      if (j.type != "revolute" && j.type != "continuous" && j.type != "prismatic")
        fail(m, element, "<mimic> on a " + j.type + " joint: only revolute, continuous and prismatic joints can mimic");
      mimics_.push_back({j.name, leader, optionalNumber(m, "multiplier", element, 1.0),
                         optionalNumber(m, "offset", element, 0.0), m});
    }
    const Eigen::Matrix4d g = addedRoot ? Eigen::Matrix4d::Identity() : origin(x, element);
    std::optional<Mass> mass;
    if (auto it = pendingMass_.find(j.child); it != pendingMass_.end()) mass = it->second;
    const bool movable = j.type == "revolute" || j.type == "continuous" || j.type == "prismatic";
    const bool compound = j.type == "floating" || j.type == "planar";
    if (j.type != "fixed" && !movable && !compound) {
      fail(x, element, "attribute 'type': value '" + j.type +
                           "' is not one of revolute, continuous, prismatic, fixed, floating, planar");
    }
    // <dynamics>: damping is modelled, Coulomb friction is not (refused rather than dropped).
    double d = 0.0;
    if (const XMLElement* dyn = x->FirstChildElement("dynamics")) {
      d = optionalNumber(dyn, "damping", element, 0.0);
      if (d < 0) fail(dyn, element, "<dynamics> attribute 'damping': value '" + fmt(d) + "' must be >= 0");
      const double friction = optionalNumber(dyn, "friction", element, 0.0);
      if (friction != 0.0) dropFriction(dyn, element, "<dynamics> attribute 'friction'", friction);
      if (d != 0.0 && !movable) {
        fail(dyn, element, "<dynamics> attribute 'damping': value '" + fmt(d) + "' on a " + j.type +
                               " joint is not supported");
      }
    }
    // <joint_properties> (written by some CAD exporters, not URDF) is read only to refuse what it
    // would add: friction or damping other than 0.
    if (const XMLElement* jp = x->FirstChildElement("joint_properties")) {
      for (const char* field : {"friction", "damping"}) {
        const double value = optionalNumber(jp, field, element, 0.0);
        if (value != 0.0 && std::string(field) == "friction" && options_.ignoreFriction) {
          dropFriction(jp, element, "<joint_properties> attribute 'friction'", value);
        } else if (value != 0.0) {
          fail(jp, element, std::string("<joint_properties> attribute '") + field + "': value '" + fmt(value) +
                                "' is not modelled (only <dynamics damping> is; 0 is accepted)");
        }
      }
    }
    Eigen::Vector3d axis = Eigen::Vector3d::UnitX();  // the URDF default
    if (movable || j.type == "planar") {
      if (const XMLElement* a = x->FirstChildElement("axis")) {
        axis = vector3(a, "xyz", element, axis);
        if (axis.norm() < 1e-12) {
          fail(a, element, "<axis> attribute 'xyz': value '" + attribute(a, "xyz", element, true) +
                               "' is zero (the axis must be a nonzero vector; it is used normalized)");
        }
        axis.normalize();
      }
    }
    UrdfJoint info{j.name, j.type, {}, false, 0, 0, 0, 0};
    if (const XMLElement* lim = x->FirstChildElement("limit")) {
      info.hasLimits = true;
      info.lower = optionalNumber(lim, "lower", element, 0.0);
      info.upper = optionalNumber(lim, "upper", element, 0.0);
      info.effort = optionalNumber(lim, "effort", element, 0.0);
      info.velocity = optionalNumber(lim, "velocity", element, 0.0);
    }

    ModelBuilder& b = out_.builder;
    auto frame = [&](const std::string& name, const std::string& parent, const Transform& t,
                     std::optional<Mass> m = {}) {
      call(x, element, [&] { b.addFrame(name, parent, t, m); });
      out_.frames.push_back(name);
      if (t.isDriven()) {
        out_.configs.push_back(t.config);
        info.configs.push_back(t.config);
      }
    };
    if (j.type == "fixed") {
      frame(j.child, j.parent, Transform::constSE3(g), mass);
    } else if (j.type == "prismatic") {
      frame(j.child, j.parent, Transform::transAxis(axis, j.name, g), mass);
    } else if (movable) {
      frame(j.child, j.parent, Transform::rotAxis(axis, j.name, g), mass);
    } else if (j.type == "floating") {
      // p = origin · T(x, y, z) · Rz(yaw) Ry(pitch) Rx(roll): singular at pitch = ±π/2.
      const std::string n = j.name + ".";
      frame(n + "x", j.parent, Transform::transAxis(Eigen::Vector3d::UnitX(), n + "x", g));
      frame(n + "y", n + "x", Transform::ty(n + "y"));
      frame(n + "z", n + "y", Transform::tz(n + "z"));
      frame(n + "yaw", n + "z", Transform::rz(n + "yaw"));
      frame(n + "pitch", n + "yaw", Transform::ry(n + "pitch"));
      frame(j.child, n + "pitch", Transform::rx(n + "roll"), mass);
    } else {  // planar: translations along two unit vectors u, v ⟂ axis, then the rotation about it.
      int k = 0;
      axis.cwiseAbs().minCoeff(&k);
      const Eigen::Vector3d u = (Eigen::Vector3d::Unit(k) - axis[k] * axis).normalized();
      const Eigen::Vector3d v = axis.cross(u);
      const std::string n = j.name + ".";
      frame(n + "u", j.parent, Transform::transAxis(u, n + "u", g));
      frame(n + "v", n + "u", Transform::transAxis(v, n + "v"));
      frame(j.child, n + "v", Transform::rotAxis(axis, n + "theta"), mass);
    }
    // The child's mass at its inertial origin, right after the child (pre-order of the frames).
    if (auto it = inertialFrames_.find(j.child); it != inertialFrames_.end()) {
      const InertialFrame& f = it->second;
      call(f.at, "link '" + f.link + "' <inertial>",
           [&] { b.addFrame(f.link + ":inertial", f.link, Transform::constSE3(f.origin), f.mass); });
      out_.frames.push_back(f.link + ":inertial");
    }
    if (d != 0.0) damping[j.name] = d;
    if (j.type != "fixed") out_.joints.push_back(std::move(info));
  }

  /// Coulomb friction (a force of size μ opposing the motion, discontinuous at q̇ = 0) has no
  /// exact linearization at rest and trellis does not model it: refused, or with
  /// ignoreFriction dropped with a warning naming the value.
  void dropFriction(const XMLElement* at, const std::string& element, const std::string& field, double value) {
    if (!options_.ignoreFriction) {
      fail(at, element, field + ": value '" + fmt(value) +
                            "': Coulomb friction is not modelled (set it to 0 or remove it, or import with "
                            "ignore_friction: urdf_options {\"ignore_friction\": true} in a scene, "
                            "UrdfOptions::ignoreFriction in C++)");
    }
    out_.warnings.push_back(source_ + ":" + std::to_string(at->GetLineNum()) + ": " + element + ": " + field +
                            ": value '" + fmt(value) + "': Coulomb friction ignored (ignore_friction)");
  }

  void readVisuals(const LinkSpec& l) {
    for (const XMLElement* v = l.xml->FirstChildElement("visual"); v; v = v->NextSiblingElement("visual")) {
      const std::string element = "link '" + l.name + "' <visual>";
      const XMLElement* geometry = v->FirstChildElement("geometry");
      const XMLElement* shape = geometry ? geometry->FirstChildElement() : nullptr;
      if (!shape) continue;  // nothing to draw
      VisualGeometry vg;
      vg.frame = l.name;
      vg.pose = origin(v, element);
      const std::string kind = shape->Name();
      if (kind == "box") {
        vg.shape = VisualGeometry::Shape::kBox;
        vg.size = vector3(shape, "size", element, Eigen::Vector3d::Zero());
      } else if (kind == "cylinder") {
        vg.shape = VisualGeometry::Shape::kCylinder;
        // Both read before the comma initializer: a throw from the second inside it would
        // destroy a half-filled initializer (an Eigen assertion in builds with assertions on).
        const double radius = number(shape, "radius", element);
        const double length = number(shape, "length", element);
        vg.size = Eigen::Vector3d(radius, length, 0.0);
      } else if (kind == "sphere") {
        vg.shape = VisualGeometry::Shape::kSphere;
        vg.size = Eigen::Vector3d(number(shape, "radius", element), 0.0, 0.0);
      } else if (kind == "mesh") {
        vg.shape = VisualGeometry::Shape::kMesh;
        vg.mesh = attribute(shape, "filename", element, true);
        vg.size = vector3(shape, "scale", element, Eigen::Vector3d::Ones());
      } else {
        continue;  // other shapes (e.g. capsule extensions) have no dynamics; not kept
      }
      out_.visuals.push_back(std::move(vg));
    }
  }

  struct Mimic {
    std::string joint, leader;
    double multiplier, offset;
    const XMLElement* at;
  };

  struct InertialFrame {
    std::string link;
    Eigen::Matrix4d origin;
    Mass mass;
    const XMLElement* at;
  };

  static constexpr const char* kFloatingRootJoint = "floating_base";

  std::string source_;
  UrdfOptions options_;
  const XMLElement* robotXml_ = nullptr;    // <robot>, for messages about the whole file
  const XMLElement* implicitWorld_ = nullptr;  // the first joint naming an undeclared 'world' parent
  int floatingJoint_ = -1;
  std::vector<Mimic> mimics_;               // <mimic> elements, added as couplings after the tree                  // floatingRoot with root 'world': the joint made floating
  UrdfImport out_;
  std::vector<LinkSpec> links_;
  std::map<std::string, int> linkIndex_;
  std::vector<JointSpec> joints_;
  std::set<std::string> jointNames_;
  std::map<std::string, int> parentJoint_;  // child link -> joint
  std::map<std::string, Mass> pendingMass_;  // link -> mass at the link origin
  std::map<std::string, InertialFrame> inertialFrames_;  // link -> its offset mass
};

}  // namespace

UrdfImport importUrdf(const std::string& xmlText, const std::string& source, const UrdfOptions& options) {
  if (!options.gravity.allFinite()) throw ModelError(source + ": UrdfOptions.gravity must be finite");
  return UrdfReader(source, options).read(xmlText);
}

void setUrdfLimits(Scene& scene, const std::vector<UrdfJoint>& joints) {
  const int n = scene.model.nq();
  const double inf = std::numeric_limits<double>::infinity();
  scene.lowerLimit = Eigen::VectorXd::Constant(n, -inf);
  scene.upperLimit = Eigen::VectorXd::Constant(n, inf);
  scene.effortLimit = Eigen::VectorXd::Constant(n, inf);
  for (const UrdfJoint& j : joints) {
    // One coordinate: revolute (continuous has no position limits) and prismatic joints.
    if (!j.hasLimits || j.configs.size() != 1 || (j.type != "revolute" && j.type != "prismatic")) continue;
    const int i = scene.model.configIndex(j.configs[0]);
    if (j.lower < j.upper) {
      scene.lowerLimit[i] = j.lower;
      scene.upperLimit[i] = j.upper;
    }
    if (j.effort > 0.0) scene.effortLimit[i] = j.effort;
  }
}

Scene sceneFromUrdf(UrdfImport&& robot) {
  Scene scene{std::move(robot.builder).finalize(), {}, {}, {}, robot.robotName, "URDF robot",
              std::move(robot.visuals), {}, {}, {}, std::move(robot.warnings)};
  setUrdfLimits(scene, robot.joints);
  scene.q = Eigen::VectorXd::Zero(scene.model.nq());
  scene.dq = Eigen::VectorXd::Zero(scene.model.nq());
  scene.u = Eigen::VectorXd::Zero(scene.model.nu());
  return scene;
}

Scene loadUrdf(const std::string& path, const UrdfOptions& options) {
  std::string text;
  try {
    text = readTextFile(path, kMaxSceneFileBytes, "URDF file");  // bounded before it allocates
  } catch (const FileError& e) {
    throw ModelError(e.what());
  }
  return sceneFromUrdf(importUrdf(text, path, options));
}

}  // namespace trellis
