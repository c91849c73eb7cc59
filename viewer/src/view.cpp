// view.cpp — see trellis/viewer/view.hpp. Assembles the page: the model's drawable elements and
// the sampled body poses as JSON (arrays as base64 float64), three.js and the page's own script.
#include "trellis/viewer/view.hpp"

#include "mesh_files.hpp"
#include "page_template.hpp"

#include "trellis/core/constraint_forces.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/io.hpp"
#include "trellis/core/kinematics.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <sstream>

#ifndef TRELLIS_THREE_JS_DIR
#define TRELLIS_THREE_JS_DIR "/usr/share/javascript/three"
#endif
#ifndef TRELLIS_THREE_INSTALLED_DIR
#define TRELLIS_THREE_INSTALLED_DIR ""
#endif

namespace trellis {
namespace {

using Json = nlohmann::json;
static_assert(std::endian::native == std::endian::little,
              "the page decodes arrays as little-endian Float64Array / Float32Array");

std::string formatVector(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s.precision(17);
  s << '(' << v(0) << ", " << v(1) << ", " << v(2) << ')';
  return s.str();
}

std::string formatNumber(double x) {
  std::ostringstream s;
  s.precision(17);
  s << x;
  return s.str();
}

Json vec(const Eigen::Vector3d& v) { return Json::array({v(0), v(1), v(2)}); }

/// Unit quaternion (w, x, y, z) of R with w >= 0, as `trellis kinematics` prints it.
Eigen::Quaterniond canonicalQuaternion(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  return q;
}

Json quat(const Eigen::Matrix3d& R) {
  const Eigen::Quaterniond q = canonicalQuaternion(R);
  return Json::array({q.w(), q.x(), q.y(), q.z()});
}

template <class T>
std::string encodeArray(const std::vector<T>& values) {
  return encodeBase64(reinterpret_cast<const unsigned char*>(values.data()), values.size() * sizeof(T));
}

std::string readWholeFile(const std::string& path, const std::string& what) {
  return readTextFile(path, std::size_t{64} << 20, what);
}

/// The body structure of the page: body j is shown by its joint frame rep[j]; every frame f sits on
/// body frames[f].joint at the constant transform rep⁻¹ · placement(f) (world frames: their placement).
struct BodyLayout {
  std::vector<int> rep;  ///< per joint: index of the frame that carries its configuration variable
  /// A point fixed on body `joint` (body coordinates) in the coordinates of that body's joint frame
  /// (kWorld: world coordinates unchanged).
  Eigen::Vector3d inRepFrame(const Model& model, int joint, const Eigen::Vector3d& local) const {
    if (joint == kWorld) return local;
    const FramePlacement& r = model.frames()[rep[joint]];
    return r.R.transpose() * (local - r.p);
  }
  int frameOf(int joint) const { return joint == kWorld ? -1 : rep[joint]; }
};

BodyLayout layoutBodies(const Model& model) {
  BodyLayout layout;
  for (int j = 0; j < model.nq(); ++j) {
    const int f = model.frameIndex(model.joints()[j].frame);
    if (model.frames()[f].joint != j) {
      throw std::logic_error("viewer: frame '" + model.frames()[f].name + "' carries configuration '" +
                             model.joints()[j].config + "' but is not on its body");
    }
    layout.rep.push_back(f);
  }
  return layout;
}

Json pointJson(const Model& model, const BodyLayout& layout, const BodyPoint& point) {
  return Json{{"f", layout.frameOf(point.joint)}, {"p", vec(layout.inRepFrame(model, point.joint, point.local))}};
}

/// Running bounds of every frame origin shown (for the camera and the ground grid).
struct Bounds {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  void add(const Eigen::Vector3d& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
};

/// Appends the world pose of every body's joint frame (7 numbers: x, y, z, qw, qx, qy, qz) at q.
void appendBodyPoses(const Model& model, Data& data, const BodyLayout& layout, const Eigen::VectorXd& q,
                     const Eigen::VectorXd& zero, std::vector<double>& out, Bounds& bounds) {
  computeKinematics(model, data, q, zero);
  for (int f = 0; f < model.nframes(); ++f) bounds.add(data.framePose[f].translation());
  for (int f : layout.rep) {
    const Eigen::Isometry3d& g = data.framePose[f];
    const Eigen::Quaterniond r = canonicalQuaternion(g.linear());
    const Eigen::Vector3d p = g.translation();
    out.insert(out.end(), {p(0), p(1), p(2), r.w(), r.x(), r.y(), r.z()});
  }
}

/// Every knot, and the display grid t_0 + k / rate where the knots are sparser: a grid time is
/// added when no knot lies within half a display interval of it. So consecutive samples are at most
/// about 1 / rate apart, and a trajectory whose knots are denser than the display rate (a
/// simulation's output) is shown at its knots alone.
std::vector<double> sampleTimes(const Trajectory& trajectory, double rate) {
  const Eigen::VectorXd& knots = trajectory.times();
  std::vector<double> times(knots.data(), knots.data() + knots.size());
  const double t0 = trajectory.startTime(), t1 = trajectory.endTime();
  const double halfInterval = 0.5 / rate;
  std::size_t k = 0;
  for (long i = 1;; ++i) {
    const double t = t0 + static_cast<double>(i) / rate;
    if (!(t < t1)) break;
    while (k + 1 < knots.size() && knots(static_cast<Eigen::Index>(k) + 1) <= t) ++k;
    const double before = t - knots(static_cast<Eigen::Index>(k));
    const double after = k + 1 < static_cast<std::size_t>(knots.size()) ? knots(static_cast<Eigen::Index>(k) + 1) - t : INFINITY;
    if (std::min(before, after) > halfInterval) times.push_back(t);
  }
  std::sort(times.begin(), times.end());
  return times;
}

void checkVisual(const VisualGeometry& v, int index) {
  const std::string element = "link '" + v.frame + "' <visual> #" + std::to_string(index + 1);
  auto fail = [&](const std::string& field, const std::string& rule) {
    throw ViewError(element + ": " + field + " " + rule);
  };
  if (!v.size.allFinite()) fail("size", formatVector(v.size) + " must be finite");
  if (!v.pose.allFinite()) fail("origin", "must be finite");
  switch (v.shape) {
    case VisualGeometry::Shape::kBox:
      if (!(v.size.minCoeff() > 0.0)) fail("<box size>", formatVector(v.size) + ": every edge must be > 0");
      break;
    case VisualGeometry::Shape::kCylinder:
      if (!(v.size(0) > 0.0)) fail("<cylinder radius>", formatNumber(v.size(0)) + " must be > 0");
      if (!(v.size(1) > 0.0)) fail("<cylinder length>", formatNumber(v.size(1)) + " must be > 0");
      break;
    case VisualGeometry::Shape::kSphere:
      if (!(v.size(0) > 0.0)) fail("<sphere radius>", formatNumber(v.size(0)) + " must be > 0");
      break;
    case VisualGeometry::Shape::kMesh:
      if ((v.size.array() == 0.0).any()) fail("<mesh scale>", formatVector(v.size) + " must have no zero entry");
      break;
  }
}

std::string jsonForScript(const Json& data) {
  // ASCII only, and "</" written as "<\/" (the same JSON string) so that no "</script>" ends the block.
  std::string text = data.dump(-1, ' ', true);
  std::string out;
  out.reserve(text.size() + 16);
  for (std::size_t i = 0; i < text.size(); ++i) {
    out += text[i];
    if (text[i] == '<' && i + 1 < text.size() && text[i + 1] == '/') out += '\\';
  }
  return out;
}

/// Text safe inside a JavaScript block comment.
std::string asComment(std::string text) {
  for (std::size_t at = text.find("*/"); at != std::string::npos; at = text.find("*/", at)) text.replace(at, 2, "* /");
  for (std::size_t at = text.find("</"); at != std::string::npos; at = text.find("</", at)) text.replace(at, 2, "< /");
  return text;
}

std::string escapeHtml(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

/// A library file as a script block; refuses text that would end the block early.
std::string scriptBlock(const std::string& code, const std::string& path) {
  if (code.find("</script") != std::string::npos || code.find("</SCRIPT") != std::string::npos) {
    throw ViewError(path + ": contains '</script' and cannot be included in the page");
  }
  return "<script>\n" + code + "\n</script>\n";
}

}  // namespace

std::string encodeBase64(const unsigned char* bytes, std::size_t size) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((size + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= size; i += 3) {
    const unsigned v = (unsigned{bytes[i]} << 16) | (unsigned{bytes[i + 1]} << 8) | bytes[i + 2];
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (size - i == 1) {
    const unsigned v = unsigned{bytes[i]} << 16;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += "==";
  } else if (size - i == 2) {
    const unsigned v = (unsigned{bytes[i]} << 16) | (unsigned{bytes[i + 1]} << 8);
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

std::string threeDirectory(const ViewOptions& options) {
  if (!options.threeDirectory.empty()) return options.threeDirectory;
  if (const char* env = std::getenv("TRELLIS_THREE_DIR"); env && *env) return env;
  // The directory found when trellis was configured, else the copy installed with trellis.
  const std::string installed = TRELLIS_THREE_INSTALLED_DIR;
  if (!std::filesystem::is_regular_file(std::string(TRELLIS_THREE_JS_DIR) + "/three.min.js") && !installed.empty() &&
      std::filesystem::is_regular_file(installed + "/three.min.js")) {
    return installed;
  }
  return TRELLIS_THREE_JS_DIR;
}

std::string renderView(const Scene& scene, const Eigen::VectorXd& q, const std::vector<ViewTrajectory>& trajectories,
                       const ViewOptions& options, ViewReport* report) {
  const Model& model = scene.model;
  if (q.size() != model.nq()) {
    throw std::invalid_argument("renderView: q has " + std::to_string(q.size()) + " entries, the model has " +
                                std::to_string(model.nq()) + " configuration variables");
  }
  if (!q.allFinite()) throw ViewError("the state to show is not finite");
  if (!(options.displayRate > 0.0) || !std::isfinite(options.displayRate)) {
    throw ViewError("ViewOptions.displayRate: " + formatNumber(options.displayRate) + " must be > 0 and finite");
  }
  ViewReport local;
  ViewReport& out = report ? *report : local;
  out = ViewReport{};

  // The library first: a missing three.js is reported before any work.
  const std::string three = threeDirectory(options);
  const std::string threePath = three + "/three.min.js";
  const std::string orbitPath = three + "/examples/js/controls/OrbitControls.js";
  std::string threeCode, orbitCode;
  try {
    threeCode = readWholeFile(threePath, "three.js");
    orbitCode = readWholeFile(orbitPath, "three.js OrbitControls");
  } catch (const FileError& e) {
    throw ViewError(std::string(e.what()) +
                    " (the viewer needs three.js: install Debian's libjs-three (scripts/setup.sh), or set "
                    "TRELLIS_THREE_DIR to a directory holding three.min.js and examples/js/controls/OrbitControls.js)");
  }
  std::string licence = "three.js (https://threejs.org), MIT (Expat) licence, copyright three.js authors.\n";
  const std::string copyrightPath = three.rfind("/usr/share/javascript/three", 0) == 0
                                        ? std::string("/usr/share/doc/libjs-three/copyright")
                                        : three + "/LICENSE";
  if (std::filesystem::is_regular_file(copyrightPath)) {
    licence += "The package's notice, " + copyrightPath + ":\n\n" + readWholeFile(copyrightPath, "three.js licence");
  }

  for (std::size_t i = 0; i < trajectories.size(); ++i) {
    const Trajectory& t = trajectories[i].trajectory;
    try {
      t.checkCompatible(model);
    } catch (const TrajectoryError& e) {
      throw ViewError("trajectory " + std::to_string(i + 1) + " ('" + trajectories[i].name + "'): " + e.what());
    }
    if (t.size() < 1) throw ViewError("trajectory " + std::to_string(i + 1) + " ('" + trajectories[i].name + "') has no knots");
  }

  const BodyLayout layout = layoutBodies(model);
  Json data;
  data["title"] = options.title.empty() ? (scene.name.empty() ? std::string("trellis view") : scene.name) : options.title;
  data["model"] = model.name();

  // Markers: leaf frames (not joint frames) at a tendon path point or a constraint point. The
  // page draws no capsule to them (the tendon or constraint line shows them), which keeps a model
  // with many via points (the hand) legible.
  std::vector<bool> hasChildren(model.nframes(), false), marker(model.nframes(), false);
  for (const FramePlacement& p : model.frames()) {
    if (p.parentFrame >= 0) hasChildren[p.parentFrame] = true;
  }
  auto markPoint = [&](const BodyPoint& point) {
    for (int f = 0; f < model.nframes(); ++f) {
      const FramePlacement& p = model.frames()[f];
      const bool jointFrame = p.joint != kWorld && layout.rep[p.joint] == f;
      if (!hasChildren[f] && !jointFrame && p.joint == point.joint && (p.p - point.local).norm() <= 1e-12) marker[f] = true;
    }
  };
  for (const Tendon& t : model.tendons()) {
    for (const BodyPoint& p : t.path) markPoint(p);
  }
  for (const Constraint& c : model.constraints()) {
    markPoint(c.a);
    markPoint(c.b);
  }

  Json frames = Json::array();
  for (int f = 0; f < model.nframes(); ++f) {
    const FramePlacement& p = model.frames()[f];
    Eigen::Matrix3d R = p.R;
    Eigen::Vector3d t = p.p;
    if (p.joint != kWorld) {
      const FramePlacement& r = model.frames()[layout.rep[p.joint]];
      R = r.R.transpose() * p.R;
      t = r.R.transpose() * (p.p - r.p);
    }
    Json frame{{"name", p.name}, {"body", p.joint}, {"parent", p.parentFrame}};
    if (marker[f]) frame["marker"] = true;
    // The joint frames themselves are shown at their stored pose: identity, so the page's world
    // position of such a frame is the stored number exactly.
    if (p.joint == kWorld || f != layout.rep[p.joint]) {
      frame["p"] = vec(t);
      frame["q"] = quat(R);
    }
    frames.push_back(std::move(frame));
  }
  data["frames"] = std::move(frames);

  Json bodies = Json::array();
  for (int j = 0; j < model.nq(); ++j) {
    const Joint& joint = model.joints()[j];
    Json body{{"frame", layout.rep[j]}, {"config", joint.config}, {"mass", joint.mass}};
    if (joint.mass > 0.0) body["com"] = vec(layout.inRepFrame(model, j, joint.firstMoment / joint.mass));
    bodies.push_back(std::move(body));
  }
  data["bodies"] = std::move(bodies);

  Json constraints = Json::array();
  for (const Constraint& c : model.constraints()) {
    constraints.push_back({{"name", c.name}, {"a", pointJson(model, layout, c.a)}, {"b", pointJson(model, layout, c.b)}});
  }
  data["constraints"] = std::move(constraints);
  Json tendons = Json::array();
  for (const Tendon& t : model.tendons()) {
    Json points = Json::array();
    for (const BodyPoint& p : t.path) points.push_back(pointJson(model, layout, p));
    tendons.push_back({{"name", model.inputNames()[t.input]}, {"input", t.input}, {"points", std::move(points)}});
  }
  data["tendons"] = std::move(tendons);

  // Visual geometry, checked; meshes read once per resolved file.
  Json visuals = Json::array(), meshes = Json::array();
  std::vector<std::string> meshPaths;
  std::map<std::string, int> visualCount;
  MeshSearch search{options.meshBaseDirectory, options.packagePath};
  for (const VisualGeometry& v : scene.visuals) {
    const int index = visualCount[v.frame]++;
    checkVisual(v, index);
    int frame = -1;
    try {
      frame = model.frameIndex(v.frame);
    } catch (const std::out_of_range&) {
      throw ViewError("link '" + v.frame + "' <visual>: the model has no frame of that name");
    }
    const Eigen::Matrix3d R = v.pose.topLeftCorner<3, 3>();
    Json visual{{"f", frame}, {"p", vec(v.pose.topRightCorner<3, 1>())}, {"q", quat(R)}, {"size", vec(v.size)}};
    switch (v.shape) {
      case VisualGeometry::Shape::kBox: visual["shape"] = "box"; break;
      case VisualGeometry::Shape::kCylinder: visual["shape"] = "cylinder"; break;
      case VisualGeometry::Shape::kSphere: visual["shape"] = "sphere"; break;
      case VisualGeometry::Shape::kMesh: {
        const std::string element = "link '" + v.frame + "' <visual> #" + std::to_string(index + 1) + " mesh '" + v.mesh + "'";
        const MeshShape mesh = loadMeshShape(v.mesh, search, element);
        if (!mesh.warning.empty()) out.warnings.push_back(mesh.warning);
        if (mesh.triangles.empty()) {
          // Unsupported format: its bounding box (scaled like the mesh), or a stand-in cube.
          visual["shape"] = "standin";
          const Eigen::Vector3d centre = 0.5 * (mesh.lo + mesh.hi), extent = mesh.hi - mesh.lo;
          visual["size"] = vec(extent.cwiseProduct(v.size).cwiseAbs());
          visual["p"] = vec(v.pose.topRightCorner<3, 1>() + R * centre.cwiseProduct(v.size));
        } else {
          auto found = std::find(meshPaths.begin(), meshPaths.end(), mesh.path);
          if (found == meshPaths.end()) {
            meshPaths.push_back(mesh.path);
            meshes.push_back(encodeArray(mesh.triangles));
            found = meshPaths.end() - 1;
          }
          visual["shape"] = "mesh";
          visual["mesh"] = static_cast<int>(found - meshPaths.begin());
        }
        break;
      }
    }
    visuals.push_back(std::move(visual));
  }
  data["visuals"] = std::move(visuals);
  data["meshes"] = std::move(meshes);

  // Force arrows: the force each constraint row exerts on its first body (computeConstraintPointForces;
  // on its second body when the first is the world), one arrow per body point they act at (the
  // rows of a point constraint, x, y and z, add up to one arrow). The equal and opposite force on
  // the other body is not drawn: it would lie on the same line.
  struct ArrowGroup {
    int joint;
    BodyPoint at;
    std::vector<int> rows;
  };
  std::vector<ArrowGroup> arrowGroups;
  std::vector<int> arrowOf;  // per entry of computeConstraintPointForces' list: its group, or −1
  Data work(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq());
  const bool forces = options.constraintForces && model.nc() > 0 &&
                      std::any_of(trajectories.begin(), trajectories.end(), [](const ViewTrajectory& t) { return !t.ghost; });
  if (forces) {
    computeKinematics(model, work, q, zero);
    for (const ConstraintPointForce& f : computeConstraintPointForces(model, work, Eigen::VectorXd::Zero(model.nc()))) {
      const Constraint& c = model.constraints()[f.row];
      const BodyPoint& at = f.side == 0 ? c.a : c.b;
      int group = -1;
      const bool drawn = f.joint != kWorld && std::none_of(arrowGroups.begin(), arrowGroups.end(), [&](const ArrowGroup& g) {
        return std::find(g.rows.begin(), g.rows.end(), f.row) != g.rows.end();
      });
      if (drawn) {
        for (std::size_t g = 0; g < arrowGroups.size(); ++g) {
          if (arrowGroups[g].joint == f.joint && arrowGroups[g].at.joint == at.joint && arrowGroups[g].at.local == at.local) {
            group = static_cast<int>(g);
          }
        }
        if (group < 0) {
          group = static_cast<int>(arrowGroups.size());
          arrowGroups.push_back({f.joint, at, {}});
        }
        arrowGroups[group].rows.push_back(f.row);
      }
      arrowOf.push_back(group);
    }
    Json arrows = Json::array();
    for (const ArrowGroup& g : arrowGroups) {
      Json names = Json::array();
      for (int r : g.rows) names.push_back(model.constraints()[r].name);
      arrows.push_back({{"body", g.joint}, {"rows", g.rows}, {"names", std::move(names)}});
    }
    data["arrows"] = std::move(arrows);
  }

  // Poses: the state, then each trajectory at its sample times.
  Bounds bounds;
  std::vector<double> poses;
  appendBodyPoses(model, work, layout, q, zero, poses, bounds);
  data["state"] = encodeArray(poses);
  out.samples = trajectories.empty() ? 1 : 0;
  Json shown = Json::array();
  const long bodiesPerSample = std::max(1, model.nq());
  Eigen::VectorXd x, u;
  // The first solid trajectory, float64: ghosts sampled at the same times are stored as float32
  // differences from it (see below).
  int base = -1;
  std::vector<double> baseTimes, basePoses;
  double largestForce = 0.0;
  for (std::size_t i = 0; i < trajectories.size(); ++i) {
    // q(t) is the configuration part of Trajectory::evaluate: the cubic Hermite spline through
    // (q_k, q̇_k). Its value does not depend on the q̈ part of the knot derivatives, so [q̇_k; 0]
    // serves (no dynamics needed: a trajectory whose dynamics fail somewhere still shows).
    const ViewTrajectory& shownTrajectory = trajectories[i];
    Trajectory t = shownTrajectory.trajectory;
    const int n = t.nq();
    Eigen::MatrixXd derivatives = Eigen::MatrixXd::Zero(2 * n, t.size());
    derivatives.topRows(n) = t.states().bottomRows(n);
    t.setStateDerivatives(std::move(derivatives));
    const std::vector<double> times = sampleTimes(t, options.displayRate);
    out.samples += static_cast<long>(times.size());
    if (out.samples * bodiesPerSample > options.maxPoseSamples) {
      throw ViewError("trajectory " + std::to_string(i + 1) + " ('" + shownTrajectory.name + "'): " +
                      std::to_string(out.samples) + " samples of " + std::to_string(bodiesPerSample) +
                      " bodies exceed ViewOptions.maxPoseSamples = " + std::to_string(options.maxPoseSamples) +
                      " (lower the display rate)");
    }
    poses.clear();
    poses.reserve(times.size() * model.nq() * 7);
    // Tendon tensions, the forces a trajectory carries (its inputs, by its input rule), for the
    // solid trajectories (ghosts draw no tendons).
    const bool tensions = !shownTrajectory.ghost && !model.tendons().empty();
    std::vector<double> tension;
    double maxTension = 0.0;
    for (double time : times) {
      t.evaluate(time, x, u);
      appendBodyPoses(model, work, layout, x.head(n), zero, poses, bounds);
      if (tensions) {
        for (const Tendon& tendon : model.tendons()) {
          tension.push_back(u(tendon.input));
          maxTension = std::max(maxTension, u(tendon.input));
        }
      }
    }
    const std::string which = "trajectory " + std::to_string(i + 1) + " ('" + shownTrajectory.name + "')";
    // Constraint forces of the solid trajectories: λ(q, q̇, u) from the forward dynamics at every
    // sample, the state and input by the trajectory's own interpolation (its knot derivatives from
    // the dynamics). Per sample and arrow: the point it acts at and the summed force, world
    // coordinates; NaN where the dynamics fail (the page hides the arrow there; a warning says so).
    std::vector<double> arrowData;
    if (forces && !shownTrajectory.ghost) {
      Trajectory dynamic = shownTrajectory.trajectory;
      std::string failure;
      try {
        if (!dynamic.hasStateDerivatives()) dynamic.computeStateDerivatives(model, work);
      } catch (const TrajectoryError& e) {
        failure = e.what();
      }
      if (!failure.empty()) {
        out.warnings.push_back(which + ": no constraint force arrows: " + failure);
      } else {
        const std::size_t na = arrowGroups.size();
        arrowData.reserve(times.size() * na * 6);
        long failed = 0;
        std::string firstFailure;
        for (double time : times) {
          dynamic.evaluate(time, x, u);
          const DynamicsStatus status = computeDynamics(model, work, x.head(n), x.tail(n), u);
          std::vector<double> sample(na * 6, 0.0);
          if (!status.ok() || !work.lambda.allFinite()) {
            if (failed++ == 0) firstFailure = "t = " + formatNumber(time) + ": " + status.describe();
            std::fill(sample.begin(), sample.end(), std::numeric_limits<double>::quiet_NaN());
          } else {
            const std::vector<ConstraintPointForce> list = computeConstraintPointForces(model, work, work.lambda);
            std::vector<bool> placed(na, false);
            for (std::size_t e = 0; e < list.size(); ++e) {
              if (arrowOf[e] < 0) continue;
              double* a = &sample[6 * static_cast<std::size_t>(arrowOf[e])];
              if (!placed[arrowOf[e]]) {
                for (int k = 0; k < 3; ++k) a[k] = list[e].point(k);
                placed[arrowOf[e]] = true;
              }
              for (int k = 0; k < 3; ++k) a[3 + k] += list[e].force(k);
            }
            for (std::size_t g = 0; g < na; ++g) {
              largestForce = std::max(largestForce, Eigen::Vector3d(sample[6 * g + 3], sample[6 * g + 4], sample[6 * g + 5]).norm());
            }
          }
          arrowData.insert(arrowData.end(), sample.begin(), sample.end());
        }
        if (failed > 0) {
          out.warnings.push_back(which + ": the dynamics fail at " + std::to_string(failed) + " of " +
                                 std::to_string(times.size()) + " samples (first " + firstFailure +
                                 "); no force arrows there");
        }
      }
    }
    Json entry{{"name", shownTrajectory.name}, {"ghost", shownTrajectory.ghost}, {"knots", t.size()}};
    const bool sameTimes = base >= 0 && times == baseTimes;
    if (sameTimes) {
      entry["timesOf"] = base;  // the same sample times as the base trajectory: not stored twice
    } else {
      entry["t"] = encodeArray(times);
    }
    // Ghosts in float32 unless asked otherwise (half the bytes: the twenty closed loops dominate
    // the hand's page). Sampled at the base trajectory's times (a closed loop beside its
    // reference), a ghost is stored as the float32 difference from the base's float64 poses: the
    // page adds them back in float64, and the rounding is that of the difference (~6e-8 of a
    // deviation of millimetres: ~1e-10 m) instead of that of the coordinates (~6e-8 of the pose).
    // Solid trajectories stay float64: exact.
    if (shownTrajectory.ghost && !options.exactGhosts) {
      std::vector<float> single(poses.size());
      const bool delta = sameTimes && basePoses.size() == poses.size();
      if (delta) {
        // q and −q are the same rotation: the ghost's quaternion on the base's side (a rotation near
        // a half turn, w ≈ 0, would otherwise differ by ~2 and lose the difference's precision).
        for (std::size_t o = 0; o < poses.size(); o += 7) {
          double dot = 0.0;
          for (int k = 3; k < 7; ++k) dot += poses[o + k] * basePoses[o + k];
          if (dot < 0.0) {
            for (int k = 3; k < 7; ++k) poses[o + k] = -poses[o + k];
          }
        }
      }
      double rounding = 0.0;
      for (std::size_t k = 0; k < poses.size(); ++k) {
        const double reference = delta ? basePoses[k] : 0.0;
        single[k] = static_cast<float>(poses[k] - reference);
        // What the page reads back (float64 sum, as here): its difference from the exact number.
        rounding = std::max(rounding, std::abs(reference + static_cast<double>(single[k]) - poses[k]));
      }
      out.ghostRounding = std::max(out.ghostRounding, rounding);
      entry["encoding"] = delta ? "delta32" : "float32";
      entry["rounding"] = rounding;  // the largest change of a stored number (m, or unitless)
      if (delta) entry["base"] = base;
      entry["poses"] = encodeArray(single);
    } else {
      entry["encoding"] = "float64";
      entry["poses"] = encodeArray(poses);
    }
    if (tensions) {
      entry["tensions"] = encodeArray(tension);
      entry["maxTension"] = maxTension;
    }
    if (!arrowData.empty()) entry["forces"] = encodeArray(arrowData);
    if (base < 0 && !shownTrajectory.ghost) {
      base = static_cast<int>(i);
      baseTimes = times;
      basePoses = poses;
    }
    shown.push_back(std::move(entry));
  }
  if (forces) data["largestForce"] = largestForce;
  data["trajectories"] = std::move(shown);

  // Up = −gravity (z without gravity); the ground grid just below everything shown.
  Eigen::Vector3d up = -model.gravity();
  up = up.norm() > 0.0 ? Eigen::Vector3d(up.normalized()) : Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d centre = 0.5 * (bounds.lo + bounds.hi);
  const double radius = std::max(0.5 * (bounds.hi - bounds.lo).norm(), 0.05);
  double lowest = INFINITY;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d corner((c & 1) ? bounds.hi(0) : bounds.lo(0), (c & 2) ? bounds.hi(1) : bounds.lo(1),
                                 (c & 4) ? bounds.hi(2) : bounds.lo(2));
    lowest = std::min(lowest, corner.dot(up));
  }
  data["view"] = {{"up", vec(up)}, {"centre", vec(centre)}, {"radius", radius}, {"floor", lowest - 0.05 * radius}};
  data["warnings"] = out.warnings;

  std::string page;
  page.reserve(threeCode.size() + orbitCode.size() + (std::size_t{1} << 20));
  page += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>";
  page += escapeHtml(data["title"].get<std::string>());
  page += "</title>\n";
  page += kViewerStyle;
  page += "</head>\n<body>\n";
  page += kViewerBody;
  page += "<script type=\"application/json\" id=\"trellis-data\">";
  page += jsonForScript(data);
  page += "</script>\n";
  page += "<script>/*\n" + asComment(licence) + "\n*/</script>\n";
  page += scriptBlock(threeCode, threePath);
  page += scriptBlock(orbitCode, orbitPath);
  page += "<script>\n";
  page += kViewerScript;
  page += "</script>\n</body>\n</html>\n";
  out.bytes = page.size();
  return page;
}

ViewReport writeView(const std::string& path, const Scene& scene, const Eigen::VectorXd& q,
                     const std::vector<ViewTrajectory>& trajectories, const ViewOptions& options) {
  ViewReport report;
  const std::string page = renderView(scene, q, trajectories, options, &report);
  writeFileAtomically(path, page);
  return report;
}

}  // namespace trellis
