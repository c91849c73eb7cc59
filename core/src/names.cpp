// names.cpp — see trellis/core/names.hpp.
#include "trellis/core/names.hpp"

#include "trellis/core/model_builder.hpp"

#include <cstdio>
#include <map>

namespace trellis {
namespace {

/// Length of the valid UTF-8 sequence at s[i] (1–4), or 0 if the bytes there are not one
/// (overlong forms, surrogates and values above U+10FFFF included).
std::size_t utf8Length(std::string_view s, std::size_t i) {
  const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = byte(i);
  if (c < 0x80) return 1;
  std::size_t length = 0;
  unsigned int code = 0, minimum = 0;
  if ((c & 0xE0) == 0xC0) length = 2, code = c & 0x1Fu, minimum = 0x80;
  else if ((c & 0xF0) == 0xE0) length = 3, code = c & 0x0Fu, minimum = 0x800;
  else if ((c & 0xF8) == 0xF0) length = 4, code = c & 0x07u, minimum = 0x10000;
  else return 0;
  if (i + length > s.size()) return 0;
  for (std::size_t k = 1; k < length; ++k) {
    if ((byte(i + k) & 0xC0) != 0x80) return 0;
    code = (code << 6) | (byte(i + k) & 0x3Fu);
  }
  if (code < minimum || code > 0x10FFFF || (code >= 0xD800 && code <= 0xDFFF)) return 0;
  return length;
}

}  // namespace

std::size_t invalidUtf8Offset(std::string_view text) {
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t length = utf8Length(text, i);
    if (length == 0) return i;
    i += length;
  }
  return std::string_view::npos;
}

std::string printableName(std::string_view name) {
  std::string out;
  for (std::size_t i = 0; i < name.size();) {
    const std::size_t length = utf8Length(name, i);
    const auto c = static_cast<unsigned char>(name[i]);
    if (length == 0 || c < 0x20 || c == 0x7F) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned>(c));
      out += hex;
      ++i;
    } else {
      out.append(name.substr(i, length));
      i += length;
    }
  }
  return out;
}

std::string nameProblem(std::string_view name) {
  if (name.empty()) return "empty name";
  for (std::size_t i = 0; i < name.size();) {
    const std::size_t length = utf8Length(name, i);
    if (length == 0) return "name '" + printableName(name) + "' is not valid UTF-8 (byte " + std::to_string(i + 1) + ")";
    const char c = name[i];
    if (length == 1 && (static_cast<unsigned char>(c) < 0x20 || c == 0x7F))
      return "name '" + printableName(name) + "' holds a control character (a newline or tab would break a CSV line)";
    if (c == ',' || c == '"')
      return std::string("name '") + printableName(name) + "' holds '" + c +
             "' (CSV files separate and quote fields with it; the name could not be read back)";
    i += length;
  }
  const auto blank = [](char c) { return c == ' '; };
  if (blank(name.front()) || blank(name.back()))
    return "name '" + printableName(name) + "' begins or ends with a blank (CSV readers trim fields; it would not read back)";
  return "";
}

void checkColumnNames(const std::vector<std::string>& configNames, const std::vector<std::string>& inputNames) {
  const std::string rate = "rate_";
  // The reader finds n as the first count whose next n columns (after the time column) are d<c>:
  // the configurations and their velocity columns must be distinct names. (A configuration may
  // be named t: the time column is always the first.)
  std::map<std::string, std::string> columns;
  const auto add = [&](const std::string& column, const std::string& what) {
    const auto [it, inserted] = columns.emplace(column, what);
    if (!inserted) {
      throw ModelError(what + " and " + it->second + " share the CSV column name '" + printableName(column) +
                       "'; a trajectory file could not tell them apart (rename one)");
    }
  };
  for (const std::string& c : configNames) add(c, "configuration '" + printableName(c) + "'");
  for (const std::string& c : configNames) add("d" + c, "the velocity column 'd" + printableName(c) + "' of configuration '" + printableName(c) + "'");
  // Inputs are read by position after the 2n state columns, so they may repeat a column name (a
  // URDF robot's joint inputs are named as the joints); only the rate_ prefix marks a column kind.
  for (const std::string& u : inputNames) {
    if (u.rfind(rate, 0) == 0)
      throw ModelError("input '" + printableName(u) + "': names beginning with 'rate_' are reserved for the "
                       "input-derivative columns of trajectory files");
  }
}

}  // namespace trellis
