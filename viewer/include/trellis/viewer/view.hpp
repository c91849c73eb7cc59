// trellis/viewer/view.hpp — a self-contained HTML page that shows a model, a state and
// trajectories in 3D in the browser (three.js, WebGL), written by `trellis view`, the main job and
// Python's trellis_mech.view (docs/viewer.md).
//
// What the page draws: every joint body (one sphere at its centre of mass, volume ∝ mass), the
// links between each frame and its parent frame as capsules, URDF visual geometry (box, cylinder,
// sphere, STL meshes), constraints as lines between their two points, tendons as polylines through
// their path points, world axes and a ground grid perpendicular to gravity.
//
// Where the poses come from: the library's kinematics (computeKinematics), never the page. For
// every sample time and every joint body the page holds the world pose of the body's joint frame
// (the frame that carries the configuration variable), exactly the numbers `trellis kinematics`
// prints for that frame (float64: position, then the unit quaternion w, x, y, z; ghost
// trajectories in float32 unless ViewOptions::exactGhosts). Every other
// frame sits on a body at the model's constant placement relative to the joint frame; the page's
// scene graph applies it (one rigid-transform product). Between samples the page interpolates:
// positions linearly, orientations by spherical linear interpolation. The sample times of a
// trajectory are its knots together with the grid t_0 + k / displayRate; q(t) between knots is
// the cubic Hermite spline through (q_k, q̇_k) — the configuration part of Trajectory::evaluate.
//
// The three.js library is read from the Debian package libjs-three (three.min.js and
// examples/js/controls/OrbitControls.js) and included in the page with the package's copyright
// notice, so the file opens offline from disk (file://).
#pragma once

#include "trellis/core/scene.hpp"
#include "trellis/core/trajectory.hpp"

#include <stdexcept>
#include <string>
#include <vector>

namespace trellis {

/// Bad input to the viewer: a trajectory that does not match the model, a visual with a bad size,
/// a mesh that cannot be read, a missing three.js. The message names the element and the value.
class ViewError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// One trajectory to show. The first non-ghost trajectory is the one the page's time slider and
/// probes refer to first; ghosts are drawn translucent (closed loops beside their reference).
struct ViewTrajectory {
  std::string name;         ///< shown in the page's legend (e.g. "reference", "closed loop 3")
  Trajectory trajectory;    ///< names must equal the model's (checkCompatible)
  bool ghost = false;       ///< drawn translucent, bodies and capsules only (no lines, no arrows)
};

/// How renderView samples, stores and draws (defaults: 60 samples per second, ghosts in float32,
/// force arrows on).
struct ViewOptions {
  std::string title;               ///< page title; default: the scene's name
  double displayRate = 60.0;       ///< samples per second besides the knots; > 0, finite
  /// Directory relative mesh file names are resolved against (the URDF's directory); empty: the
  /// working directory.
  std::string meshBaseDirectory;
  /// Directories searched for package://PKG/PATH meshes: DIR/PKG/PATH for each DIR in order (then
  /// the entries of ROS_PACKAGE_PATH, then each ancestor directory of meshBaseDirectory named PKG).
  std::vector<std::string> packagePath;
  /// three.js directory (holding three.min.js); empty: $TRELLIS_THREE_DIR, else the directory
  /// found when trellis was configured (Debian: /usr/share/javascript/three), else the copy
  /// installed with trellis (PREFIX/share/trellis/three, with its LICENSE).
  std::string threeDirectory;
  /// Ghost trajectories are stored in float32 (half the size) unless this is set; solid
  /// trajectories and the state are always float64. A ghost sampled at the same times as the first
  /// solid trajectory is stored as its float32 difference from that one (rounding ~6e-8 of the
  /// deviation, ~1e-10 m for a closed loop beside its reference; its quaternions signed like the
  /// base's, q or −q, the same rotation), any other ghost as float32 coordinates (rounding ~6e-8
  /// relative). ViewReport::ghostRounding gives the largest rounding (the page: each ghost's).
  bool exactGhosts = false;
  /// Draw the constraint forces of the solid trajectories as arrows (a model with constraints):
  /// λ(q, q̇, u) from computeDynamics at every sample, split into forces at the constraint points
  /// by computeConstraintPointForces: the force each row exerts on its first body (on its second
  /// when the first is the world), one arrow per body point (the x, y, z rows of a point
  /// constraint add up to one arrow); the opposite force on the other body is not drawn.
  bool constraintForces = true;
  /// Upper limit of samples × bodies over all trajectories (memory and file size guard).
  long maxPoseSamples = 20'000'000;
};

/// What writeView / renderView produced, besides the page.
struct ViewReport {
  std::vector<std::string> warnings;  ///< e.g. an unsupported mesh format drawn as a stand-in box
  long samples = 0;                   ///< pose samples over all trajectories (or 1 for a state)
  std::size_t bytes = 0;              ///< size of the page
  /// Largest change of a stored ghost number by the float32 encoding (positions in m, quaternion
  /// entries unitless); 0 without ghosts or with ViewOptions::exactGhosts.
  double ghostRounding = 0.0;
};

/// The HTML page for `scene` at the configuration `q` (n; the state shown when there is no
/// trajectory, and before a trajectory starts) and the given trajectories (any number, possibly
/// none). Throws ViewError for bad input (see the class), std::invalid_argument for a q of the
/// wrong size. Deterministic: the same input gives the same bytes.
std::string renderView(const Scene& scene, const Eigen::VectorXd& q,
                       const std::vector<ViewTrajectory>& trajectories, const ViewOptions& options,
                       ViewReport* report = nullptr);

/// renderView, then writeFileAtomically(path, page): the file is complete or absent (a failure
/// before or during the write leaves no partial page under `path`). Throws ViewError, FileError.
ViewReport writeView(const std::string& path, const Scene& scene, const Eigen::VectorXd& q,
                     const std::vector<ViewTrajectory>& trajectories, const ViewOptions& options = {});

/// The three.js directory renderView uses for `options` (see ViewOptions::threeDirectory).
std::string threeDirectory(const ViewOptions& options);

/// Standard base64 (RFC 4648, with padding) of `size` bytes — the page's encoding of its arrays.
std::string encodeBase64(const unsigned char* bytes, std::size_t size);

}  // namespace trellis
