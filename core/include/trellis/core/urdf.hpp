// trellis/core/urdf.hpp — URDF robots as trellis models (docs/urdf.md).
//
// The root link is the world (a fixed base), unless UrdfOptions::floatingRoot puts a floating
// joint between the world and it. A joint whose parent is an undeclared link named `world` hangs
// from the world (as Drake and Pinocchio read it). Every link becomes a frame named as the link; a
// revolute, continuous or prismatic joint becomes one frame of type r_axis / t_axis (its origin
// and unit axis) driven by a configuration variable named as the joint; a fixed joint a constant
// frame (folded away by the builder); <inertial> a mass; <dynamics damping> damping. floating and
// planar joints become documented sequences of primitive coordinates, unactuated by default (a
// base moves by contacts, not by forces from nowhere). A <mimic> joint is coupled to its leader
// by a holonomic constraint q_j = multiplier · q_i + offset (and gets no input of its); Coulomb
// friction is refused unless UrdfOptions::ignoreFriction (then dropped with a warning). Parsed with
// tinyxml2, so every message carries the line number.
#pragma once

#include "trellis/core/scene.hpp"

#include <string>
#include <vector>

namespace trellis {

/// How importUrdf turns a robot into a model.
struct UrdfOptions {
  /// Gravity in the root link's (= world) axes; zero adds none.
  Eigen::Vector3d gravity = Eigen::Vector3d(0.0, 0.0, -9.81);
  /// A generalized-force input per configuration variable, named as it (for a revolute,
  /// continuous or prismatic joint: the joint's name), so that B = [0; M⁻¹] without constraints.
  bool jointInputs = true;
  /// With jointInputs: inputs on the coordinates of floating and planar joints too (a base
  /// pushed by six generalized forces from nowhere). Off by default: a floating base is moved by
  /// its contacts (constraints added in a scene, docs/urdf.md "Floating bases and contacts").
  bool baseInputs = false;
  /// Makes the root link a floating body: a floating joint named `floating_base` (coordinates
  /// floating_base.x … .roll) between the world and the root link, whose `<inertial>` then counts.
  /// For a file whose root is `world` with a single fixed joint to the base, that joint becomes
  /// the floating one. The file need not be edited (legged robots ship with the trunk as root).
  bool floatingRoot = false;
  /// Drops nonzero Coulomb `<dynamics friction>` (and `<joint_properties friction>`) instead of
  /// refusing the file; each dropped value is listed in UrdfImport::warnings.
  bool ignoreFriction = false;
};

/// A movable URDF joint as read (its `<limit>` is kept as metadata; trellis does not enforce it).
struct UrdfJoint {
  ///@{
  /// The joint's name and its type as written: revolute, continuous, prismatic, planar, floating.
  std::string name, type;
  ///@}
  std::vector<std::string> configs;    ///< its configuration variables (one, or 3/6 for planar/floating)
  bool hasLimits = false;              ///< whether the joint has a `<limit>` element
  ///@{
  /// The `<limit>` attributes as written: lower and upper position [rad or m], effort [N m or N],
  /// velocity [rad/s or m/s]; 0 when absent.
  double lower = 0.0, upper = 0.0, effort = 0.0, velocity = 0.0;
  ///@}
};

/// A URDF robot as builder calls, ready for more elements (constraints, forces) or finalize().
struct UrdfImport {
  ModelBuilder builder;             ///< the frames, masses, damping and joint inputs, not yet finalized
  ///@{
  /// The `<robot name>` and the root link (the world).
  std::string robotName, rootLink;
  ///@}
  std::vector<std::string> frames;  ///< every frame added: the links, "<link>:inertial" frames
                                    ///< and the intermediate frames of planar/floating joints
  std::vector<std::string> configs; ///< every configuration variable, in the order of the file
  std::vector<UrdfJoint> joints;    ///< the movable joints
  std::vector<VisualGeometry> visuals;  ///< the links' `<visual>` geometry, in the order of the file
  /// What was read but not modelled, one line each with file and line (UrdfOptions::ignoreFriction).
  std::vector<std::string> warnings;
};

/// Reads URDF XML text. `source` names the file in messages ("<source>:<line>: joint 'j':
/// attribute 'xyz': value '1 2' ..."). Throws ModelError on malformed XML, a missing or bad
/// element or attribute, a link with two parents, several roots or a cycle, and on unsupported
/// features (mimic on a compound joint or of a missing joint, nonzero friction unless
/// options.ignoreFriction, damping on planar/floating
/// joints), and on floatingRoot when the root is `world` without a single fixed child joint.
UrdfImport importUrdf(const std::string& xmlText, const std::string& source = "<urdf>",
                      const UrdfOptions& options = {});

/// Reads a URDF file into a Scene (state all zero, visuals kept). Throws ModelError.
Scene loadUrdf(const std::string& path, const UrdfOptions& options = {});

/// Fills scene.lowerLimit, upperLimit and effortLimit (Scene) from an import's joints, matched by
/// configuration name (the scene's other coordinates unlimited).
void setUrdfLimits(Scene& scene, const std::vector<UrdfJoint>& joints);

/// The finalized scene of an import (state all zero; the import's warnings kept in Scene::warnings).
Scene sceneFromUrdf(UrdfImport&& robot);

}  // namespace trellis
