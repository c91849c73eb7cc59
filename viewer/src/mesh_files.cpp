// mesh_files.cpp — see mesh_files.hpp.
#include "mesh_files.hpp"

#include "trellis/core/io.hpp"
#include "trellis/viewer/view.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sstream>

namespace trellis {
namespace {

namespace fs = std::filesystem;
constexpr std::size_t kMaxMeshBytes = std::size_t{256} << 20;

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::vector<std::string> splitColon(const char* text) {
  std::vector<std::string> parts;
  if (!text) return parts;
  std::string item;
  for (const char* c = text;; ++c) {
    if (*c == ':' || *c == '\0') {
      if (!item.empty()) parts.push_back(item);
      item.clear();
      if (*c == '\0') break;
    } else {
      item += *c;
    }
  }
  return parts;
}

std::string joinPaths(const std::vector<std::string>& paths) {
  std::string s;
  for (const std::string& p : paths) s += (s.empty() ? "" : ", ") + p;
  return s;
}

/// Binary STL: 80-byte header, uint32 triangle count, 50 bytes per triangle (normal, three
/// vertices as float32, a 16-bit attribute). Recognized by its exact size.
bool readBinaryStl(const std::string& bytes, std::vector<float>& triangles) {
  if (bytes.size() < 84) return false;
  std::uint32_t count = 0;
  std::memcpy(&count, bytes.data() + 80, 4);
  if (bytes.size() != 84 + 50 * static_cast<std::size_t>(count)) return false;
  triangles.resize(9 * static_cast<std::size_t>(count));
  for (std::size_t t = 0; t < count; ++t) std::memcpy(&triangles[9 * t], bytes.data() + 84 + 50 * t + 12, 36);
  return true;
}

/// ASCII STL: "solid …", then facets whose "vertex x y z" lines are collected in order.
void readAsciiStl(const std::string& text, std::vector<float>& triangles, const std::string& where) {
  std::istringstream in(text);
  std::string word;
  in >> word;
  if (lower(word) != "solid") throw ViewError(where + ": neither binary STL (size ≠ 84 + 50 × triangle count) nor ASCII STL (no 'solid')");
  while (in >> word) {
    if (lower(word) != "vertex") continue;
    double v[3];
    for (double& c : v) {
      if (!(in >> c) || !std::isfinite(c)) throw ViewError(where + ": ASCII STL: a 'vertex' without three finite numbers");
    }
    triangles.insert(triangles.end(), {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])});
  }
  if (triangles.size() % 9 != 0) throw ViewError(where + ": ASCII STL: the vertex count is not a multiple of 3");
}

}  // namespace

std::vector<std::string> meshCandidates(const std::string& filename, const MeshSearch& search) {
  std::vector<std::string> out;
  const fs::path base = search.baseDirectory.empty() ? fs::path(".") : fs::path(search.baseDirectory);
  if (filename.rfind("package://", 0) == 0) {
    const std::string rest = filename.substr(10);
    const std::size_t slash = rest.find('/');
    const std::string package = rest.substr(0, slash);
    const std::string inside = slash == std::string::npos ? std::string() : rest.substr(slash + 1);
    std::vector<std::string> dirs = search.packagePath;
    for (const std::string& d : splitColon(std::getenv("ROS_PACKAGE_PATH"))) dirs.push_back(d);
    for (const std::string& d : dirs) out.push_back((fs::path(d) / package / inside).string());
    for (fs::path p = fs::absolute(base).lexically_normal(); p.has_relative_path(); p = p.parent_path()) {
      if (p.filename() == package) out.push_back((p / inside).string());
    }
  } else if (filename.rfind("file://", 0) == 0) {
    out.push_back(filename.substr(7));
  } else if (fs::path(filename).is_absolute()) {
    out.push_back(filename);
  } else {
    out.push_back((base / filename).string());
  }
  return out;
}

MeshShape loadMeshShape(const std::string& filename, const MeshSearch& search, const std::string& element) {
  MeshShape shape;
  const std::vector<std::string> candidates = meshCandidates(filename, search);
  for (const std::string& c : candidates) {
    std::error_code error;
    if (fs::is_regular_file(c, error)) {
      shape.path = c;
      break;
    }
  }
  if (shape.path.empty()) {
    throw ViewError(element + ": file not found (looked for " +
                    (candidates.empty() ? std::string("nothing: no package path") : joinPaths(candidates)) +
                    "; package:// names are searched in --package-path directories, ROS_PACKAGE_PATH and the "
                    "URDF's ancestor directories)");
  }
  const std::string extension = lower(fs::path(shape.path).extension().string());
  std::string bytes;
  try {
    bytes = readTextFile(shape.path, kMaxMeshBytes, "mesh file");
  } catch (const FileError& e) {
    throw ViewError(element + ": " + e.what());
  }
  const std::string where = element + " (" + shape.path + ")";
  if (extension == ".stl") {
    if (!readBinaryStl(bytes, shape.triangles)) readAsciiStl(bytes, shape.triangles, where);
    if (shape.triangles.empty()) throw ViewError(where + ": the STL file has no triangles");
    for (float v : shape.triangles) {
      if (!std::isfinite(v)) throw ViewError(where + ": a vertex coordinate is not finite");
    }
    return shape;
  }
  if (extension == ".obj") {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
    std::istringstream in(bytes);
    std::string line;
    while (std::getline(in, line)) {
      if (line.size() < 2 || line[0] != 'v' || (line[1] != ' ' && line[1] != '\t')) continue;
      std::istringstream v(line.substr(1));
      Eigen::Vector3d p;
      if (v >> p(0) >> p(1) >> p(2) && p.allFinite()) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
      }
    }
    if (lo.allFinite() && hi.allFinite()) {
      shape.lo = lo;
      shape.hi = hi;
      shape.warning = where + ": OBJ meshes are not drawn; shown as their bounding box";
      return shape;
    }
    shape.warning = where + ": OBJ mesh without vertices; shown as a 5 cm stand-in cube";
    return shape;
  }
  shape.warning = where + ": mesh format '" + extension + "' is not supported (STL is); shown as a 5 cm stand-in cube";
  return shape;
}

}  // namespace trellis
