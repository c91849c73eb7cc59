// cli/model_questions.cpp — see model_questions.hpp.
#include "model_questions.hpp"

#include "cli_options.hpp"
#include "command.hpp"

#include "trellis/core/equilibrium.hpp"

#include "trellis/core/io.hpp"

#include <algorithm>
#include <iostream>
#include <iterator>
#include <stdexcept>

namespace trellis::cli {
namespace {

std::vector<std::string> splitNames(const std::string& command, const std::string& option,
                                    const std::string& list) {
  std::vector<std::string> names;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = list.find(',', start);
    std::string item = list.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    if (item.empty()) throw UsageError(command + ": " + option + ": empty name in '" + list + "'");
    names.push_back(std::move(item));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return names;
}

std::string known(const std::vector<std::string>& names) {
  std::string out;
  for (std::size_t i = 0; i < names.size() && i < 12; ++i) out += (i ? ", " : "") + names[i];
  if (names.size() > 12) out += ", ...";
  return out.empty() ? "none" : out;
}

}  // namespace

LoadedScene loadSceneArgument(const std::string& path) {
  LoadedScene loaded = [&]() -> LoadedScene {
    if (path != "-") return {loadScene(path), path};
    // Bounded: an endless standard input is refused at the limit, not read to the end of memory.
    const std::string text = trellis::readTextStream(0, kMaxSceneFileBytes, "<stdin>", "scene on standard input");
    return {parseScene(text, "<stdin>"), "<stdin>"};
  }();
  // What the scene read but does not model (URDF friction with ignore_friction): on stderr, so
  // that stdout stays the command's result.
  for (const auto& w : loaded.scene.warnings) std::cerr << "trellis: warning: " << w << '\n';
  return loaded;
}

ModelState stateFromFile(const LoadedScene& loaded, const std::optional<std::string>& statePath) {
  ModelState stored = zeroState(loaded.scene.model);
  stored.q = loaded.scene.q;
  stored.dq = loaded.scene.dq;
  stored.u = loaded.scene.u;
  if (!statePath) return stored;
  return loadState(loaded.scene.model, *statePath, stored);
}

Trajectory heldPoseReference(const LoadedScene& loaded, const std::optional<std::string>& statePath, double span,
                             const std::string& what) {
  const Model& model = loaded.scene.model;
  const ModelState state = stateFromFile(loaded, statePath);
  Data data(model);
  const InverseDynamicsResult hold = computeHoldingInputs(model, data, state.q);
  if (!hold.ok()) {
    throw std::runtime_error(loaded.path + ": " + what + ": the pose cannot be held (" + hold.status.name() +
                             "): " + hold.status.message);
  }
  constexpr int kKnots = 101;
  const Eigen::VectorXd times = Eigen::VectorXd::LinSpaced(kKnots, 0.0, span);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(2 * model.nq());
  x.head(model.nq()) = state.q;
  const Trajectory pose(model.configNames(), model.inputNames(), times, x.replicate(1, kKnots),
                        hold.u.replicate(1, kKnots));
  Trajectory checked = checkReference(model, loaded.path, "the held pose", pose);
  // At rest by definition (the inputs balance the dynamics; the dynamics' q̈ at the knots is that
  // balance's rounding): ẋ = 0 at every knot makes the reference exactly constant, which the
  // sampled gains use (one exact exponential instead of an integration per interval).
  checked.setStateDerivatives(Eigen::MatrixXd::Zero(2 * model.nq(), kKnots));
  return checked;
}

Trajectory readTrajectoryFor(const LoadedScene& loaded, const std::string& trajectoryPath) {
  Trajectory trajectory = Trajectory::readCsvFile(trajectoryPath);
  try {
    trajectory.checkCompatible(loaded.scene.model);
  } catch (const TrajectoryError& e) {
    throw std::runtime_error(trajectoryPath + " does not match the scene " + loaded.path + ": " + e.what());
  }
  return trajectory;
}

std::vector<int> frameIndices(const Model& model, const std::string& command, const std::string& option,
                              const std::string& list) {
  std::vector<std::string> all;
  for (const FramePlacement& f : model.frames()) all.push_back(f.name);
  std::vector<int> out;
  for (const std::string& name : splitNames(command, option, list)) {
    const auto it = std::find(all.begin(), all.end(), name);
    if (it == all.end()) throw UsageError(command + ": " + option + ": unknown frame '" + name + "' (known: " + known(all) + ")");
    out.push_back(static_cast<int>(it - all.begin()));
  }
  return out;
}

std::vector<int> configIndices(const Model& model, const std::string& command, const std::string& option,
                               const std::string& list) {
  const std::vector<std::string>& all = model.configNames();
  std::vector<int> out;
  for (const std::string& name : splitNames(command, option, list)) {
    const auto it = std::find(all.begin(), all.end(), name);
    if (it == all.end()) {
      throw UsageError(command + ": " + option + ": unknown configuration variable '" + name + "' (known: " +
                       known(all) + ")");
    }
    out.push_back(static_cast<int>(it - all.begin()));
  }
  return out;
}

OutputJson namedValues(const std::vector<std::string>& names, const Eigen::VectorXd& values) {
  OutputJson out = OutputJson::object();
  for (std::size_t i = 0; i < names.size(); ++i) out[names[i]] = values(static_cast<Eigen::Index>(i));
  return out;
}

OutputJson nameList(const std::vector<std::string>& names) {
  OutputJson out = OutputJson::array();
  for (const std::string& name : names) out.push_back(name);
  return out;
}

OutputJson stateObject(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& dq,
                       const Eigen::VectorXd& u) {
  OutputJson out = OutputJson::object();
  out["q"] = namedValues(model.configNames(), q);
  out["dq"] = namedValues(model.configNames(), dq);
  out["u"] = namedValues(model.inputNames(), u);
  return out;
}

std::string dynamicsStatusName(DynamicsStatus::Code code) { return toString(code); }

void requireLinearization(const DynamicsStatus& status, const Data& data, const std::string& where) {
  if (!status.ok()) {
    throw std::runtime_error(where + ": the dynamics cannot be solved (" + dynamicsStatusName(status.code) + ")" +
                             (status.message.empty() ? "" : ": " + status.message));
  }
  if (!data.A.allFinite() || !data.B.allFinite() || !data.qdd.allFinite() || !data.lambda.allFinite()) {
    throw std::runtime_error(where + ": the linearization is not finite");
  }
}

}  // namespace trellis::cli
