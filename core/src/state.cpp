// State objects by name (state.hpp, state_json.hpp).
#include "state_json.hpp"

#include "trellis/core/io.hpp"
#include "trellis/core/model_builder.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace trellis {
namespace {
constexpr std::size_t kMaxStateFileBytes = std::size_t{64} << 20;  // a state is a few numbers per coordinate
}  // namespace
namespace detail {
namespace {

using Json = nlohmann::json;

}  // namespace

std::string showJson(const Json& value) {
  std::string text = value.dump(-1, ' ', false, Json::error_handler_t::replace);
  constexpr std::size_t kMax = 80;
  if (text.size() > kMax) text = text.substr(0, kMax - 3) + "...";
  return text;
}

std::string listNames(const std::vector<std::string>& names) {
  if (names.empty()) return "none";
  std::string out;
  constexpr std::size_t kMax = 12;
  for (std::size_t i = 0; i < names.size() && i < kMax; ++i) out += (i ? ", " : "") + names[i];
  if (names.size() > kMax) out += ", ...";
  return out;
}

void readStateObject(const Model& model, const Json& object, const std::string& label, bool strict,
                     bool allowAcceleration, ModelState& state) {
  const auto fail = [&label](const std::string& field, const std::string& problem) {
    throw ModelError(label + ": field '" + field + "': " + problem);
  };
  if (!object.is_object()) throw ModelError(label + ": must be a JSON object, not " + showJson(object));
  if (strict) {
    for (const auto& [key, value] : object.items()) {
      if (key == "q" || key == "dq" || key == "u" || (key == "ddq" && allowAcceleration)) continue;
      fail(key, std::string("unknown key (expected q, dq, u") + (allowAcceleration ? ", ddq" : "") + ")");
    }
  }
  const auto readValues = [&](const char* key, const std::vector<std::string>& names, const char* what,
                              Eigen::VectorXd& out) {
    const auto found = object.find(key);
    if (found == object.end()) return false;
    if (!found->is_object()) fail(key, showJson(*found) + " must be an object");
    for (const auto& [name, value] : found->items()) {
      const std::string field = std::string(key) + "." + name;
      const auto it = std::find(names.begin(), names.end(), name);
      if (it == names.end()) {
        fail(field, "unknown " + std::string(what) + " " + showJson(Json(name)) + " (known: " + listNames(names) + ")");
      }
      if (!value.is_number()) fail(field, showJson(value) + " must be a number");
      const double x = value.get<double>();
      if (!std::isfinite(x)) fail(field, showJson(value) + " must be finite");
      out[it - names.begin()] = x;
    }
    return true;
  };
  readValues("q", model.configNames(), "configuration variable", state.q);
  readValues("dq", model.configNames(), "configuration variable", state.dq);
  readValues("u", model.inputNames(), "input", state.u);
  if (allowAcceleration && readValues("ddq", model.configNames(), "configuration variable", state.ddq)) {
    state.hasAcceleration = true;
  }
}

}  // namespace detail

ModelState zeroState(const Model& model) {
  ModelState s;
  s.q = s.dq = s.ddq = Eigen::VectorXd::Zero(model.nq());
  s.u = Eigen::VectorXd::Zero(model.nu());
  return s;
}

ModelState parseState(const Model& model, const std::string& jsonText, const std::string& source,
                      const ModelState& defaults) {
  const int n = model.nq(), m = model.nu();
  if (defaults.q.size() != n || defaults.dq.size() != n || defaults.u.size() != m ||
      (defaults.ddq.size() != n && defaults.ddq.size() != 0)) {
    throw std::invalid_argument("parseState: the defaults do not have the model's sizes (n = " +
                                std::to_string(n) + ", m = " + std::to_string(m) + ")");
  }
  ModelState state = defaults;
  if (state.ddq.size() == 0) state.ddq = Eigen::VectorXd::Zero(n);
  state.hasAcceleration = false;
  try {
    nlohmann::json root;
    try {
      root = nlohmann::json::parse(jsonText);
    } catch (const nlohmann::json::exception& e) {
      throw ModelError(std::string("invalid JSON: ") + e.what());
    }
    detail::readStateObject(model, root, "state", true, true, state);
  } catch (const ModelError& e) {
    throw ModelError(source + ": " + e.what());
  }
  return state;
}

ModelState loadState(const Model& model, const std::string& path, const ModelState& defaults) {
  std::string text;
  try {
    text = readTextFile(path, kMaxStateFileBytes, "state file");  // "/dev/zero" is refused
  } catch (const FileError& e) {
    throw ModelError(e.what());
  }
  return parseState(model, text, path, defaults);
}

}  // namespace trellis
