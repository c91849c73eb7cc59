// mesh_files.hpp — URDF mesh files for the viewer: where a file name points (relative, absolute,
// file://, package://) and its triangles (STL, binary or ASCII) or, for a format the viewer does
// not draw, its bounding box (OBJ) or a stand-in cube.
#pragma once

#include <Eigen/Core>

#include <string>
#include <vector>

namespace trellis {

struct MeshSearch {
  std::string baseDirectory;              ///< relative names; empty: the working directory
  std::vector<std::string> packagePath;   ///< package://PKG/PATH → DIR/PKG/PATH
};

struct MeshShape {
  std::string path;                ///< the resolved file
  std::vector<float> triangles;    ///< 9 per triangle (three vertices); empty: not drawable
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(-0.025), hi = Eigen::Vector3d::Constant(0.025);
  std::string warning;             ///< set when the mesh is drawn as its bounding box or a stand-in
};

/// Every place `filename` may be (in search order); package:// names: each DIR of
/// search.packagePath, then of $ROS_PACKAGE_PATH (':'-separated), as DIR/PKG/PATH, then each
/// ancestor directory of baseDirectory whose name is PKG, as ANCESTOR/PATH.
std::vector<std::string> meshCandidates(const std::string& filename, const MeshSearch& search);

/// Resolves and reads a mesh. STL (by extension, case-insensitive): every triangle; a file that
/// cannot be found or read, or is not valid STL, is a ViewError naming `element`, the file and the
/// paths tried. OBJ: its bounding box from the 'v' lines, with a warning. Another extension: a
/// stand-in cube of 5 cm (times the visual's scale), with a warning (the file must still exist).
MeshShape loadMeshShape(const std::string& filename, const MeshSearch& search, const std::string& element);

}  // namespace trellis
