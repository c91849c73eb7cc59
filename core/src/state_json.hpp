// Reading a state object {"q": {...}, "dq": {...}, "u": {...}} from JSON: shared by scene.cpp
// (a scene's "state") and state.cpp (a state file). Not installed: nlohmann::json stays private.
#pragma once

#include "trellis/core/state.hpp"

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace trellis::detail {

/// The value as it appears in the file, shortened for messages (at most 80 characters).
std::string showJson(const nlohmann::json& value);

/// "a, b, c" (at most 12 names, then "...") for "known: ..." hints; "none" when empty.
std::string listNames(const std::vector<std::string>& names);

/// Overwrites the entries of `state` named in `object` (a JSON object). `label` names the object
/// in messages ("state"). strict: keys other than q, dq, u (and ddq when allowAcceleration) are
/// errors; otherwise they are ignored (a scene's "state" as SCENE_FORMAT.md specifies).
/// Throws ModelError "<label>: field 'q.NAME': ..." naming the field and the value.
void readStateObject(const Model& model, const nlohmann::json& object, const std::string& label,
                     bool strict, bool allowAcceleration, ModelState& state);

}  // namespace trellis::detail
