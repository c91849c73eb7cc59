// trellis/core/model.hpp — the immutable description of a mechanical system.
//
// A Model is a tree of coordinate frames (paper Sec. II-A) reduced, when it is finalized by a
// ModelBuilder, to what the algorithms need: one *joint* per configuration variable (a frame whose
// local transform is driven by that variable) and constant placements for everything else.
// Chains of constant transforms are folded together, so every cost follows the joints, not the
// frames. Masses are lumped into one rigid-body inertia per joint; forces, potentials and
// constraints refer to points fixed on joint bodies.
//
// Conventions used by every algorithm:
//  - configuration order = pre-order of the frame tree (parent before children, children in the
//    order they were added) of the frames that carry a configuration variable; a joint's subtree
//    is therefore the contiguous index range [j, joint(j).subtreeEnd);
//  - spatial vectors are 6-vectors expressed in world axes at the world origin, ordered
//    (linear, angular): a twist [v_o; ω], a wrench [f; n].
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "trellis/core/enum_names.hpp"

#include <array>
#include <string>
#include <string_view>
#include <vector>

namespace trellis {

using Vector6d = Eigen::Matrix<double, 6, 1>;

/// Index of the fixed world frame / of "no joint" (a point fixed in the world).
inline constexpr int kWorld = -1;

/// The six primitive transforms of the paper, a constant homogeneous transform, and a rotation
/// about / translation along an arbitrary unit axis (after an optional constant placement).
enum class TransformType { kTx, kTy, kTz, kRx, kRy, kRz, kConstSE3, kRotAxis, kTransAxis };

/// Names as in scene files: tx, ty, tz, rx, ry, rz, const_se3, r_axis, t_axis.
inline EnumNameTable<TransformType> enumNames(TransformType) {
  static constexpr EnumName<TransformType> table[] = {
      {TransformType::kTx, "tx"},         {TransformType::kTy, "ty"},
      {TransformType::kTz, "tz"},         {TransformType::kRx, "rx"},
      {TransformType::kRy, "ry"},         {TransformType::kRz, "rz"},
      {TransformType::kConstSE3, "const_se3"}, {TransformType::kRotAxis, "r_axis"},
      {TransformType::kTransAxis, "t_axis"}};
  return table;
}

/// A frame's local transform g_local from the frame to its parent:
/// g_world,k = g_world,parent · g_local. Either driven by a configuration variable or constant.
///
/// kRotAxis / kTransAxis: g_local = G · exp(x [a]) with G = `matrix` (constant, identity by
/// default), a = `axis` (unit, in the axes of G) and x the coordinate or `value`: a rotation by x
/// about a through G's origin, or a translation by x along a. The builder turns one such frame
/// into one joint (a rotation about or translation along the joint body's z axis, body chosen so
/// that z = a), so it costs what rz/tz cost, with the same exact derivatives.
struct Transform {
  TransformType type = TransformType::kConstSE3;      ///< which motion (a primitive, constant, or about/along an axis)
  std::string config;                                  ///< empty: constant transform
  double value = 0.0;                                  ///< constant value (all but kConstSE3)
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();  ///< kConstSE3: the transform; axis types: G
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();     ///< kRotAxis / kTransAxis only

  ///@{
  /// Constant primitives: a translation by `value` [m] along, or a rotation by `angle` [rad] about,
  /// the parent's x, y or z axis.
  static Transform tx(double value);
  static Transform ty(double value);
  static Transform tz(double value);
  static Transform rx(double angle);
  static Transform ry(double angle);
  static Transform rz(double angle);
  ///@}
  ///@{
  /// Driven primitives: the same motions by the configuration variable `config` (metres or
  /// radians); `config` must be non-empty (ModelBuilder::addFrame checks the names).
  static Transform tx(std::string config);
  static Transform ty(std::string config);
  static Transform tz(std::string config);
  static Transform rx(std::string config);
  static Transform ry(std::string config);
  static Transform rz(std::string config);
  ///@}
  /// A constant homogeneous transform (4×4, rigid: checked by ModelBuilder::addFrame).
  static Transform constSE3(const Eigen::Matrix4d& matrix);
  ///@{
  /// Rotation about / translation along the unit vector `axis` (given in the axes of `origin`),
  /// after the constant placement `origin` (4×4 rigid): g_local = origin · exp(x [axis]) with x
  /// the configuration variable `config` or the constant `angle` [rad] / `distance` [m]. The axis
  /// must be nonzero (normalized by the builder, which throws ModelError naming the frame otherwise).
  static Transform rotAxis(const Eigen::Vector3d& axis, std::string config,
                           const Eigen::Matrix4d& origin = Eigen::Matrix4d::Identity());
  static Transform rotAxis(const Eigen::Vector3d& axis, double angle,
                           const Eigen::Matrix4d& origin = Eigen::Matrix4d::Identity());
  static Transform transAxis(const Eigen::Vector3d& axis, std::string config,
                             const Eigen::Matrix4d& origin = Eigen::Matrix4d::Identity());
  static Transform transAxis(const Eigen::Vector3d& axis, double distance,
                             const Eigen::Matrix4d& origin = Eigen::Matrix4d::Identity());
  ///@}

  /// Whether a configuration variable drives this transform.
  bool isDriven() const { return !config.empty(); }
  /// The 4×4 homogeneous matrix of this transform at coordinate value `q` (ignored if constant).
  Eigen::Isometry3d evaluate(double q) const;
};

/// A point mass at a frame's origin (its centre of mass) with rotational inertia about that point
/// in the frame's own axes. Kinetic energy ½ m |v|² + ½ ω_bᵀ I ω_b.
struct Mass {
  double m = 0.0;                                      ///< mass [kg], ≥ 0
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();   ///< 3×3 symmetric PSD [kg m²] about the frame origin, frame axes
};

/// A point fixed on the body of `joint` (kWorld: fixed in the world), in that body's axes.
struct BodyPoint {
  int joint = kWorld;                                  ///< the joint whose body carries the point (kWorld: the world)
  Eigen::Vector3d local = Eigen::Vector3d::Zero();
};

/// One configuration variable and the rigid body it moves. The joint body is placed at
/// g_parent · (R0, p0) · motion(q), motion a rotation about or translation along axis `axis`.
/// (For kRotAxis / kTransAxis frames the body's axes are turned so that `axis` = z is the
/// frame's unit axis; the frame itself then sits on the body at a constant rotation.)
struct Joint {
  std::string config;      ///< configuration variable name
  std::string frame;       ///< name of the frame that carries it
  int parent = kWorld;     ///< parent joint (kWorld if the chain starts at the world)
  int subtreeEnd = 0;      ///< one past the last joint of this joint's subtree
  int depth = 0;           ///< number of joints on the path to the world, this one included
  bool revolute = true;    ///< rotation about `axis` (true) or translation along it (false)
  int axis = 2;            ///< 0 = x, 1 = y, 2 = z of the joint frame
  Eigen::Matrix3d R0 = Eigen::Matrix3d::Identity();  ///< constant placement in the parent body
  Eigen::Vector3d p0 = Eigen::Vector3d::Zero();  ///< constant offset in the parent body [m] (with R0)
  // Lumped rigid-body inertia of everything fixed to this joint's body, in the joint frame:
  double mass = 0.0;       ///< total mass fixed to the body [kg]
  Eigen::Vector3d firstMoment = Eigen::Vector3d::Zero();  ///< h = m · c (c: centre of mass)
  Eigen::Matrix3d inertiaAtOrigin = Eigen::Matrix3d::Zero();  ///< about the joint origin
};

/// Where a named frame sits: on which joint body, at which constant placement.
struct FramePlacement {
  std::string name;          ///< the frame's name (unique in the model)
  int parentFrame = kWorld;  ///< the frame tree as given
  int joint = kWorld;        ///< body the frame is fixed to
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  ///< frame axes in body axes
  Eigen::Vector3d p = Eigen::Vector3d::Zero();      ///< frame origin in body coordinates
};

/// A spring between two body points: potential V = ½ k (‖p_a − p_b‖ − x0)².
struct LinearSpring {
  ///@{
  /// The two ends (points on bodies, or in the world).
  BodyPoint a, b;
  ///@}
  ///@{
  /// Stiffness k [N/m] (≥ 0) and rest length x0 [m] (≥ 0).
  double k = 0.0, x0 = 0.0;
  ///@}
};
/// A spring on one coordinate: potential V = ½ k (q_i − q0)².
struct ConfigSpring {
  int config = 0;                ///< the coordinate i
  ///@{
  /// Stiffness k [N/m or N m/rad] and rest value q0 [m or rad].
  double k = 0.0, q0 = 0.0;
  ///@}
};
/// An input acting directly on one coordinate: Q[config] += u[input].
struct ConfigForce {
  ///@{
  /// The coordinate and the input (indices into configNames() and inputNames()).
  int config = 0, input = 0;
  ///@}
};
/// A wrench on a body: Q = J_bᵀ w, w = [f; τ] in the frame's axes at its origin, each of the six
/// entries a constant or an input.
struct BodyWrench {
  int joint = kWorld;            ///< the body it acts on
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  ///< frame axes in body axes
  Eigen::Vector3d p = Eigen::Vector3d::Zero();      ///< frame origin in body coordinates
  std::array<double, 6> constant{};                 ///< used where input[i] < 0
  std::array<int, 6> input{-1, -1, -1, -1, -1, -1};  ///< per entry: the input driving it, or −1 (constant)
};
/// A cable through points: Q = −(∂l/∂q)ᵀ u with length l = Σ‖p_{i+1} − p_i‖ and tension u ≥ 0
/// (the input; a negative u pushes, which the saturating controllers avoid).
struct Tendon {
  std::vector<BodyPoint> path;   ///< the points it runs through, in order (≥ 2)
  int input = 0;                 ///< the input giving its tension [N]
};

/// The kinds of constraint rows (docs/scene_format.md).
enum class ConstraintType {
  kDistance,      ///< h = ‖p_a − p_b‖² − d²            (holonomic, one row)
  kPoint,         ///< h = (p_a − p_b)·e_axis           (holonomic, one row)
  kPointOnPlane,  ///< h = n_w·(p_a − p_b), n_w = R_a n  (holonomic; a = plane frame, b = point)
  kKnifeEdge,     ///< e_w·ṗ_a = 0, e_w = R_a e          (nonholonomic A(q) q̇ = 0, one row)
  kCoordinateCoupling,  ///< h = q_j − m q_i − o             (holonomic, one row; URDF `<mimic>`)
};
/// Names as in scene files: distance, point, point_on_plane, knife_edge, coordinate_coupling.
inline EnumNameTable<ConstraintType> enumNames(ConstraintType) {
  static constexpr EnumName<ConstraintType> table[] = {{ConstraintType::kDistance, "distance"},
                                                       {ConstraintType::kPoint, "point"},
                                                       {ConstraintType::kPointOnPlane, "point_on_plane"},
                                                       {ConstraintType::kKnifeEdge, "knife_edge"},
                                                       {ConstraintType::kCoordinateCoupling, "coordinate_coupling"}};
  return table;
}

/// One constraint row: h(q) = 0 (holonomic) or A(q) q̇ = 0 (knife edge); see ConstraintType for
/// each kind's h, and constraint_forces.hpp for the forces Aᵀλ it exerts.
struct Constraint {
  ConstraintType type = ConstraintType::kDistance;    ///< which kind of row
  std::string name;                                   ///< for messages
  ///@{
  /// Its two points (a: frame1 / the plane frame / the knife's frame; b: frame2 / the point frame;
  /// b unused for a knife edge).
  BodyPoint a, b;
  ///@}
  double distance = 0.0;                              ///< kDistance
  int axis = 0;                                       ///< kPoint
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();  ///< kPointOnPlane normal / kKnifeEdge axis, in a's body axes
  /// kCoordinateCoupling: q_j = m q_i + o between the coordinates j = a.joint (the follower) and
  /// i = b.joint (the leader); their joints' parents and kinds (revolute or prismatic) are kept
  /// here so that the row's generalized forces can be applied as wrenches on the joints' bodies.
  struct Coupling {
    double multiplier = 1.0;   ///< m
    double offset = 0.0;       ///< o [rad or m]
    ///@{
    /// Parent joints (kWorld at the root) of the follower j and of the leader i.
    int followerParent = kWorld, leaderParent = kWorld;
    ///@}
    ///@{
    /// Whether j and i are revolute (else prismatic).
    bool followerRevolute = true, leaderRevolute = true;
    ///@}
  };
  Coupling coupling;  ///< kCoordinateCoupling: multiplier, offset, and the two joints' parents and kinds
  /// Whether the row is h(q) = 0 (all kinds but the knife edge, a velocity constraint A(q) q̇ = 0).
  bool holonomic() const { return type != ConstraintType::kKnifeEdge; }
};

/// The structure of the joint tree and of the elements that refer to it: fixed by the Model,
/// computed once by ModelBuilder::finalize (like Pinocchio's parents / supports / subtrees), read by
/// the algorithms. n = nq, nc = constraint rows. Blocks are the top-level trees (joints with
/// parent kWorld and their subtrees); M is block diagonal over them.
struct ModelTopology {
  std::vector<int> parent;      ///< n: parent joint of i (kWorld for a root); = joints()[i].parent
  /// n: first index of the unbranched run of ancestors that ends at i (in pre-order an unbranched
  /// stretch of the tree is a run of consecutive indices [runStart[i], i]).
  std::vector<int> runStart;
  std::vector<int> treeRoot;    ///< n: the top-level joint of i's tree (the start of its block)
  std::vector<int> blockStart;  ///< starts of the blocks in increasing order, then n (size blocks + 1)
  /// nc: the coordinates [rowLo[r], rowHi[r]) that row r of A can touch (the whole blocks of the
  /// constraint's two bodies; both 0 for a row that touches no coordinate).
  ///@{
  /// nc: the coordinates [rowLo[r], rowHi[r]) that row r of A can touch (see above).
  std::vector<int> rowLo, rowHi;
  ///@}
  /// Starts of the groups of consecutive constraint rows that share no block with another group,
  /// then nc (just {0} when nc = 0): A M⁻¹ Aᵀ is block diagonal over the groups.
  std::vector<int> rowGroupStart;
  /// m: the coordinate c when input k only adds unitInputGain[k]·u_k to Q_c (config forces alone),
  /// else −1; then column k of ∂q̈/∂u is a multiple of a column of M⁻¹.
  std::vector<int> unitInputConfig;
  std::vector<double> unitInputGain;  ///< m: see unitInputConfig
  /// Tendon t's path points are [tendonFirst[t], tendonFirst[t + 1]) in the flat list of all
  /// path points (size tendons + 1; the last entry is the number of points).
  std::vector<int> tendonFirst;
  ///@{
  /// Per tendon: lowest and highest joint on its path (−1 if none).
  std::vector<int> tendonJointLo, tendonJointHi;
  ///@}
  std::vector<int> tendonPointJoint;  ///< per path point (flat list): the joint body it is fixed to
  ///@{
  /// Tendon t's segments with ends on different bodies are tendonSegmentPoint[tendonSegmentStart[t]
  /// to tendonSegmentStart[t + 1]), each named by the flat index of its first end (a segment within
  /// one body exerts equal and opposite forces along one line: no net wrench).
  std::vector<int> tendonSegmentStart, tendonSegmentPoint;
  ///@}
};

/// The validated, immutable system. Built only by ModelBuilder::finalize() or loadScene().
class Model {
 public:
  int nq() const { return static_cast<int>(joints_.size()); }   ///< configuration variables
  int nu() const { return static_cast<int>(inputNames_.size()); }  ///< inputs
  int nc() const { return static_cast<int>(constraints_.size()); }  ///< constraint rows
  int nholonomic() const { return nholonomic_; }                    ///< rows of h(q) = 0
  int nframes() const { return static_cast<int>(frames_.size()); }     ///< named frames (world excluded)

  ///@{
  /// Names of the configuration variables (n, configuration order) and of the inputs (m).
  const std::vector<std::string>& configNames() const { return configNames_; }
  const std::vector<std::string>& inputNames() const { return inputNames_; }
  ///@}
  const std::string& name() const { return name_; }  ///< the model's name (may be empty)

  ///@{
  /// Index of a frame (into frames()), a configuration variable or an input, by name; throw
  /// std::out_of_range naming the missing name.
  int frameIndex(std::string_view name) const;
  int configIndex(std::string_view name) const;
  int inputIndex(std::string_view name) const;
  ///@}

  ///@{
  /// The folded description (model.hpp types): joints (n, pre-order), frames (nf), gravity (world
  /// axes, m/s²), force elements, damping c (n) and constraint rows (nc), as finalize produced them.
  const std::vector<Joint>& joints() const { return joints_; }
  const std::vector<FramePlacement>& frames() const { return frames_; }
  const Eigen::Vector3d& gravity() const { return gravity_; }
  const std::vector<LinearSpring>& linearSprings() const { return linearSprings_; }
  const std::vector<ConfigSpring>& configSprings() const { return configSprings_; }
  const std::vector<ConfigForce>& configForces() const { return configForces_; }
  ///@}
  const Eigen::VectorXd& damping() const { return damping_; }  ///< c_i per configuration
  ///@{
  /// The body wrenches, tendons and constraint rows (nc), in the order they were added.
  const std::vector<BodyWrench>& bodyWrenches() const { return bodyWrenches_; }
  const std::vector<Tendon>& tendons() const { return tendons_; }
  const std::vector<Constraint>& constraints() const { return constraints_; }
  ///@}
  /// The tree's structure and the elements' index maps, computed once at finalize.
  const ModelTopology& topology() const { return topology_; }

 private:
  friend class ModelBuilder;
  std::string name_;
  std::vector<Joint> joints_;
  std::vector<FramePlacement> frames_;
  std::vector<std::string> configNames_, inputNames_;
  Eigen::Vector3d gravity_ = Eigen::Vector3d::Zero();
  std::vector<LinearSpring> linearSprings_;
  std::vector<ConfigSpring> configSprings_;
  std::vector<ConfigForce> configForces_;
  Eigen::VectorXd damping_;
  std::vector<BodyWrench> bodyWrenches_;
  std::vector<Tendon> tendons_;
  std::vector<Constraint> constraints_;
  int nholonomic_ = 0;
  ModelTopology topology_;
};

/// The model's length scale L: the largest constant offset it is built from (joint and frame
/// placements, constraint points and distances, spring rest lengths); 1 when it has none. Scaling
/// every length of a model by s scales L by s, so a check relative to L (or to
/// coordinateScales) gives the same verdict in any unit of length.
double modelLengthScale(const Model& model);

/// Per configuration variable (n), the size of one unit of motion in the model's own terms: 1 for a
/// revolute coordinate (radians need no scale), L = modelLengthScale(model) for a prismatic one.
Eigen::VectorXd coordinateScales(const Model& model);

}  // namespace trellis
