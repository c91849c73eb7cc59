// trellis/core/state.hpp — a state of a model given by names, as in a scene file's "state":
//   {"q": {name: value}, "dq": {name: value}, "u": {name: value}, "ddq": {name: value}}
// (the same reader the scene loader uses, so a state file and a scene's "state" mean the same).
#pragma once

#include "trellis/core/model.hpp"

#include <Eigen/Core>

#include <string>

namespace trellis {

/// q, q̇ (n), u (m) and, for inverse dynamics, q̈ (n).
struct ModelState {
  ///@{
  /// The configuration q (n), velocities q̇ (n), inputs u (m) and accelerations q̈ (n).
  Eigen::VectorXd q, dq, u, ddq;
  ///@}
  bool hasAcceleration = false;  ///< "ddq" was present in the parsed text
};

/// Zeros of the model's sizes (q, dq, ddq: n; u: m).
ModelState zeroState(const Model& model);

/// Parses a JSON state object. Names not listed keep their value in `defaults` (which must have
/// the model's sizes; e.g. a scene's stored state, or zeroState). Every name must be a
/// configuration variable ("q", "dq", "ddq") or an input ("u") of the model, every value a finite
/// number, and only the keys q, dq, u, ddq may appear. Throws ModelError
/// "<source>: state: field 'q.theta9': unknown configuration variable "theta9" (known: ...)".
ModelState parseState(const Model& model, const std::string& jsonText, const std::string& source,
                      const ModelState& defaults);

/// parseState of a file's contents; throws ModelError also when the file cannot be read.
ModelState loadState(const Model& model, const std::string& path, const ModelState& defaults);

}  // namespace trellis
