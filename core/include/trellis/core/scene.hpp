// trellis/core/scene.hpp — scene files (docs/scene_format.md, JSON).
#pragma once

#include "trellis/core/model_builder.hpp"

#include <string>
#include <vector>

namespace trellis {

/// Visual geometry of a frame (kept from URDF `<visual>` elements for viewers; no effect on the
/// dynamics). `size`: box: edge lengths; cylinder: (radius, length, 0); sphere: (radius, 0, 0);
/// mesh: scale. `pose`: the shape's placement in the frame's axes.
struct VisualGeometry {
  /// The URDF geometry kinds (`<box>`, `<cylinder>` along z, `<sphere>`, `<mesh>`).
  enum class Shape { kBox, kCylinder, kSphere, kMesh };
  std::string frame;                                   ///< the frame (link) it is drawn on
  Shape shape = Shape::kBox;                           ///< which geometry
  Eigen::Vector3d size = Eigen::Vector3d::Zero();      ///< [m] or, for a mesh, the scale (see above)
  std::string mesh;  ///< file name as written (kMesh only)
  Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();  ///< 4×4 placement in the frame's axes (`<origin>`)
};

/// A model together with the state stored in its scene file (missing names are 0).
struct Scene {
  Model model;               ///< the validated model
  ///@{
  /// The stored state: q (n), q̇ (n), u (m); names the file omits are 0.
  Eigen::VectorXd q, dq, u;
  ///@}
  ///@{
  /// The scene's "name" and "description" (may be empty).
  std::string name, description;
  ///@}
  std::vector<VisualGeometry> visuals;  ///< from an imported URDF; empty otherwise
  ///@{
  /// Position limits per configuration variable (n each, [rad or m]) from a URDF's `<limit lower
  /// upper>` on revolute and prismatic joints; −∞/+∞ where there is none (continuous joints, floating
  /// bases, frames of the scene itself, a limit with lower ≥ upper). Empty when the scene has no URDF.
  /// trellis's dynamics do not enforce them; the CLI checks answers against them.
  Eigen::VectorXd lowerLimit, upperLimit;
  ///@}
  /// Effort limit per configuration variable (n, [N m or N]) from `<limit effort>`, +∞ where there
  /// is none or it is 0; empty without a URDF. It bounds the joint's own input (named as the joint).
  Eigen::VectorXd effortLimit;
  /// What was read but not modelled (e.g. URDF friction dropped by "ignore_friction"), one line
  /// each naming file, line and value; callers show them (the CLI prints them on stderr).
  std::vector<std::string> warnings;
};

/// Parses a scene from JSON text. `source` names the file in messages (and, when it is a path,
/// the directory a "urdf" include is relative to). Text whose first non-blank character is '<'
/// is read as a URDF robot with the default UrdfOptions (trellis/core/urdf.hpp). Throws
/// ModelError whose message names the element (frame name or list position), the field and the
/// offending value.
Scene parseScene(const std::string& jsonText, const std::string& source = "<scene>");

/// The largest scene (or URDF) text read, in bytes (256 MiB): readers refuse more before allocating.
inline constexpr std::size_t kMaxSceneFileBytes = std::size_t{256} << 20;

/// Reads and parses a scene file or a URDF file (as parseScene); throws ModelError (also when the
/// file cannot be read, or is larger than kMaxSceneFileBytes: /dev/zero is refused, not read to
/// the end of memory).
Scene loadScene(const std::string& path);

}  // namespace trellis
