// trellis/core/json_integer.hpp — an integer field of a JSON file, range-checked against the
// type it is stored in (a count like "knots": 4294967298 must not wrap around to 2).
//
// Header-only and generic in the JSON type (nlohmann::json or ordered_json), so that core's
// public headers do not depend on the JSON library.
#pragma once

#include <cstdint>
#include <string>

namespace trellis {

/// The integer `value` if it is a JSON integer in [min, max]. Otherwise returns false and sets
/// `problem` to what is wrong, for a message that the caller prefixes with the file and field:
/// "expected an integer, got 2.5", "4294967298 is out of the range [2, 100000]".
template <class Json>
bool jsonInteger(const Json& value, long long min, long long max, long long& out, std::string& problem) {
  const std::string range = "[" + std::to_string(min) + ", " + std::to_string(max) + "]";
  if (value.is_number_unsigned()) {
    const auto v = value.template get<std::uint64_t>();
    if (max < 0 || v > static_cast<std::uint64_t>(max)) {
      problem = std::to_string(v) + " is out of the range " + range;
      return false;
    }
    out = static_cast<long long>(v);
  } else if (value.is_number_integer()) {
    out = value.template get<std::int64_t>();
  } else {
    // A float (2.5, 1e3) or an integer too large for 64 bits, which the parser stores as a float.
    problem = "expected an integer in " + range + ", got " + value.dump();
    return false;
  }
  if (out < min || out > max) {
    problem = std::to_string(out) + " is out of the range " + range;
    return false;
  }
  return true;
}

}  // namespace trellis
