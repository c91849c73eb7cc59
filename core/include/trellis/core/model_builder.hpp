// trellis/core/model_builder.hpp — builds and validates a Model.
//
// Every add* call checks its own arguments at once and throws trellis::ModelError naming the
// element, the field and the offending value; finalize() checks cross references (frame and
// configuration names), folds constant transforms and lumps masses into joint bodies.
#pragma once

#include "trellis/core/model.hpp"

#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

namespace trellis {

/// Thrown for an invalid model description (builder or scene file). The message names the
/// element (frame name or list position), the field and the value.
class ModelError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A body-wrench entry: a constant number or the name of an input.
using WrenchEntry = std::variant<double, std::string>;

/// The homogeneous transform of a URDF-style origin: translation xyz, rotation from fixed-axis
/// roll-pitch-yaw, R = Rz(yaw) · Ry(pitch) · Rx(roll).
Eigen::Matrix4d poseFromXyzRpy(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy);

/// Builds a Model from frames, masses, forces and constraints, checking each call (ModelError
/// naming the element, the field and the value), then finalize() folds the frame tree into joints
/// and validates the whole (paper Sec. II; docs/scene_format.md for the elements).
class ModelBuilder {
 public:
  ModelBuilder() = default;
  /// A builder for a model named `name` (Model::name(); may be empty).
  explicit ModelBuilder(std::string name) : name_(std::move(name)) {}

  /// Adds frame `name` under `parent` ("world" or an earlier frame). Returns the frame's name.
  /// Throws on a duplicate or reserved name, an unknown parent, a configuration name used twice,
  /// a non-finite value, a const_se3 matrix (or axis-transform origin) that is not a rigid
  /// transform, an axis that is not a unit vector (|‖a‖ − 1| > 1e-9; it is then normalized
  /// exactly), a negative mass or an inertia tensor that is not symmetric positive semidefinite.
  const std::string& addFrame(const std::string& name, const std::string& parent,
                              const Transform& transform, std::optional<Mass> mass = {});

  /// Adds g (world axes, m/s²) to the gravity: V = −Σ m_b gᵀ p_b. Throws on a non-finite entry.
  void addGravity(const Eigen::Vector3d& g);
  /// V = ½ k (‖p1 − p2‖ − x0)² between the origins of two frames ("world" allowed). Throws on an
  /// unknown frame, a non-finite k or x0, or x0 < 0.
  void addLinearSpring(const std::string& frame1, const std::string& frame2, double k, double x0);
  /// V = ½ k (q_config − q0)². Throws on a non-finite k or q0; an unknown configuration throws at
  /// finalize.
  void addConfigSpring(const std::string& config, double k, double q0);
  /// Q[config] += u[input]: input `input` (created on first use) is a generalized force on one
  /// coordinate. Throws on an empty input name; an unknown configuration throws at finalize.
  void addConfigForce(const std::string& config, const std::string& input);
  /// Q_i −= c_i q̇_i with c_i = coefficients[config] if listed, else `defaultCoefficient`.
  void addDamping(double defaultCoefficient, const std::map<std::string, double>& coefficients = {});
  /// w = [fx, fy, fz, τx, τy, τz] in `frame`'s axes at its origin; each entry a constant or input.
  void addBodyWrench(const std::string& frame, const std::array<WrenchEntry, 6>& wrench);
  /// A cable through the origins of `path` (≥ 2 frames) with tension u[input] ≥ 0.
  void addTendon(const std::vector<std::string>& path, const std::string& input);
  /// h = ‖p1 − p2‖² − d² = 0 between two frames' origins (one holonomic row). Throws on an
  /// unknown frame or d not > 0 (at d = 0 the gradient vanishes where the constraint holds).
  void addDistanceConstraint(const std::string& frame1, const std::string& frame2, double distance);
  /// axis: 0 = x, 1 = y, 2 = z (world axes).
  void addPointConstraint(const std::string& frame1, const std::string& frame2, int axis);
  /// h = n_wᵀ (p_point − p_plane) = 0 with n_w = R_plane n: `pointFrame`'s origin stays on the plane
  /// through `planeFrame`'s origin with normal `normal` (plane frame axes; one holonomic row).
  /// Throws on an unknown frame or a zero or non-finite normal.
  void addPointOnPlaneConstraint(const std::string& planeFrame, const Eigen::Vector3d& normal,
                                 const std::string& pointFrame);
  /// Nonholonomic knife edge: the velocity of `frame`'s origin along its own axis `axis` (in the
  /// frame's axes) is zero, e_wᵀ ṗ = 0 — an A(q) q̇ = 0 row that is not the derivative of any h(q).
  void addKnifeEdgeConstraint(const std::string& frame, const Eigen::Vector3d& axis);
  /// h = q_follower − multiplier · q_leader − offset = 0 (one holonomic row with the constant
  /// Jacobian row e_follower − multiplier · e_leader): a URDF `<mimic>`. Its force Aᵀλ is a
  /// generalized force λ on the follower and −multiplier·λ on the leader. Throws on an unknown
  /// configuration (at finalize), one coupled to itself, or a non-finite or zero multiplier.
  void addCoordinateCoupling(const std::string& follower, const std::string& leader, double multiplier,
                             double offset);

  /// Size limits of a model, the same as a scene file's: the workspace of the linearization (Data)
  /// holds about 25 dense n×n matrices, ≈ 200·n² bytes — 200 MB at 1000 configuration variables.
  static constexpr int kMaxConfigs = 1000;  ///< configuration variables
  static constexpr int kMaxFrames = 20000;  ///< frames

  /// Validates cross references and the size limits above (before any Data can allocate) and
  /// returns the immutable model. Throws ModelError naming the count and the limit.
  Model finalize() &&;
  /// finalize() on a copy: the builder stays usable (e.g. to add a constraint and build again).
  Model finalize() const&;

 private:
  struct FrameSpec {
    std::string name;
    int parent;  // index into frames_, or kWorld
    Transform transform;
    std::optional<Mass> mass;
  };
  struct ElementSpec;  // defined in the .cpp
  int frameId(const std::string& name, const std::string& element, const std::string& field) const;
  int inputId(const std::string& input);

  std::string name_;
  std::vector<FrameSpec> frames_;
  std::map<std::string, int> frameIds_;
  std::map<std::string, int> configFrames_;
  std::vector<std::string> inputNames_;
  Eigen::Vector3d gravity_ = Eigen::Vector3d::Zero();
  struct SpringSpec { int f1, f2; double k, x0; };
  struct ConfigSpringSpec { std::string config; double k, q0; std::string element; };
  struct ConfigForceSpec { std::string config; int input; std::string element; };
  struct DampingSpec { double dflt; std::map<std::string, double> coeffs; std::string element; };
  struct WrenchSpec { int frame; std::array<double, 6> constant; std::array<int, 6> input; };
  struct TendonSpec { std::vector<int> path; int input; };
  struct ConstraintSpec { ConstraintType type; int f1, f2; double distance; int axis;
                          Eigen::Vector3d direction; std::string name;
                          std::string follower = {}, leader = {}; double multiplier = 1.0, offset = 0.0; };
  std::vector<SpringSpec> springs_;
  std::vector<ConfigSpringSpec> configSprings_;
  std::vector<ConfigForceSpec> configForces_;
  std::vector<DampingSpec> dampings_;
  std::vector<WrenchSpec> wrenches_;
  std::vector<TendonSpec> tendons_;
  std::vector<ConstraintSpec> constraints_;
};

}  // namespace trellis
