// trellis/core/scene.hpp — scene files (../shared/SCENE_FORMAT.md, version 1, JSON).
#pragma once

#include "trellis/core/model_builder.hpp"

#include <string>

namespace trellis {

/// A model together with the state stored in its scene file (missing names are 0).
struct Scene {
  Model model;
  Eigen::VectorXd q, dq, u;  ///< n, n, m
  std::string name, description;
};

/// Parses a scene from JSON text. `source` names the file in messages. Throws ModelError whose
/// message names the element (frame name or list position), the field and the offending value.
Scene parseScene(const std::string& jsonText, const std::string& source = "<scene>");

/// Reads and parses a scene file; throws ModelError (also when the file cannot be read).
Scene loadScene(const std::string& path);

}  // namespace trellis
