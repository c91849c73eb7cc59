// cli/model_questions.hpp — what the commands that ask questions of a model share (`linearize`,
// `info`, `kinematics`, `project`, `equilibrium`, `inverse-dynamics`): reading the model argument,
// a state file (--state) or a trajectory (--trajectory) checked against the model, name lists
// (--frames, --fix), and the JSON forms of a state.
#pragma once

#include "json_output.hpp"

#include "trellis/core/trajectory.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/scene.hpp"
#include "trellis/core/state.hpp"

#include <optional>
#include <string>
#include <vector>

namespace trellis::cli {

/// The scene of the MODEL argument ("-": standard input, named "<stdin>" in messages).
struct LoadedScene {
  Scene scene;
  std::string path;
};
LoadedScene loadSceneArgument(const std::string& path);

/// The scene's stored state, overridden by the names in the --state file if one is given
/// (names checked against the model: unknown ones are errors naming them).
ModelState stateFromFile(const LoadedScene& loaded, const std::optional<std::string>& statePath);

/// A trajectory CSV (t, <configs>, d<configs>, <inputs>; ≥ 1 knot) whose names equal the model's.
Trajectory readTrajectoryFor(const LoadedScene& loaded, const std::string& trajectoryPath);

/// The reference of --hold (gains, simulate): the pose q of the scene's stored state (or of the
/// --state file; its velocities are ignored) at rest over [0, span], with the inputs that hold it
/// (computeHoldingInputs: least squares of minimum norm, refused unless they hold it exactly),
/// 101 knots, zero state derivatives (exactly constant); checked as a reference file is (on the
/// constraints). Errors start with `what` (e.g. "gains --hold").
Trajectory heldPoseReference(const LoadedScene& loaded, const std::optional<std::string>& statePath, double span,
                             const std::string& what);

/// "a,b,c" → frame (or configuration) indices of the model; unknown names are a UsageError naming
/// the name, the option and the known names.
std::vector<int> frameIndices(const Model& model, const std::string& command, const std::string& option,
                              const std::string& list);
std::vector<int> configIndices(const Model& model, const std::string& command, const std::string& option,
                               const std::string& list);

/// {"q": {name: value}, "dq": {...}, "u": {...}}: the form --state reads back.
OutputJson stateObject(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                       const Eigen::VectorXd& u);
/// {name: value} for the model's configuration variables (or inputs).
OutputJson namedValues(const std::vector<std::string>& names, const Eigen::VectorXd& values);
OutputJson nameList(const std::vector<std::string>& names);

/// "ok", "redundant_constraints", "singular_mass_matrix", ...
std::string dynamicsStatusName(DynamicsStatus::Code code);

/// Throws std::runtime_error "<where>: the dynamics cannot be solved (<status>): <message>" unless
/// `status` is ok and A, B, q̈, λ are finite.
void requireLinearization(const DynamicsStatus& status, const Data& data, const std::string& where);

}  // namespace trellis::cli
