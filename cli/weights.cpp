// cli/weights.cpp — see weights.hpp.
#include "weights.hpp"

#include "cli_options.hpp"
#include "command.hpp"

#include "trellis/control/riccati.hpp"
#include "trellis/core/io.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace trellis::cli {
namespace {

bool looksNumeric(const std::string& text) {
  if (text.empty()) return false;
  for (const char c : text) {
    const bool allowed = (c >= '0' && c <= '9') || c == '+' || c == '-' || c == '.' || c == 'e' ||
                         c == 'E' || c == ',' || c == ' ' || c == '\t';
    if (!allowed) return false;
  }
  return true;
}

/// nlohmann's message without its "[json.exception.KIND.ID] " prefix.
std::string jsonErrorText(const nlohmann::json::exception& e) {
  std::string what = e.what();
  if (const auto end = what.find("] "); what.rfind("[json.exception.", 0) == 0 && end != std::string::npos) {
    what.erase(0, end + 2);
  }
  return what;
}

std::string stripBlanks(const std::string& text) {
  std::string out;
  for (const char c : text)
    if (c != ' ' && c != '\t') out += c;
  return out;
}

Eigen::MatrixXd readWeightFile(const std::string& option, const std::string& path, int size,
                               const std::string& sizeMeaning) {
  const std::string where = option + ": weight file '" + path + "'";
  std::string text;
  try {
    text = readTextFile(path, std::size_t{64} << 20, "weight file");
  } catch (const FileError& e) {
    throw std::runtime_error(where + " cannot be opened or read: " + e.what() +
                             " (a weight is a number, a comma-separated diagonal or a JSON file)");
  }
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    // parse_error (syntax) and out_of_range.406 (a number such as 1e999 that overflows a double).
    throw std::runtime_error(where + " is not valid JSON: " + jsonErrorText(e));
  }
  const std::string expected = "a list of " + std::to_string(size) + " rows of " +
                               std::to_string(size) + " numbers (" + sizeMeaning + ")";
  if (!json.is_array() || static_cast<int>(json.size()) != size) {
    throw std::runtime_error(where + ": expected " + expected + ", got " +
                             (json.is_array() ? std::to_string(json.size()) + " rows" : std::string(json.type_name())));
  }
  Eigen::MatrixXd W(size, size);
  for (int i = 0; i < size; ++i) {
    const nlohmann::json& row = json[static_cast<std::size_t>(i)];
    if (!row.is_array() || static_cast<int>(row.size()) != size) {
      throw std::runtime_error(where + ": row " + std::to_string(i + 1) + " has " +
                               (row.is_array() ? std::to_string(row.size()) + " entries" : "no list") +
                               "; expected " + expected + " (the matrix must be square)");
    }
    for (int j = 0; j < size; ++j) {
      const nlohmann::json& entry = row[static_cast<std::size_t>(j)];
      if (!entry.is_number() || !std::isfinite(entry.get<double>())) {
        throw std::runtime_error(where + ": entry (" + std::to_string(i + 1) + ", " +
                                 std::to_string(j + 1) + ") is not a finite number: " + entry.dump());
      }
      W(i, j) = entry.get<double>();
    }
  }
  for (int i = 0; i < size; ++i) {
    for (int j = i + 1; j < size; ++j) {
      const double scale = std::max({1.0, std::abs(W(i, j)), std::abs(W(j, i))});
      if (std::abs(W(i, j) - W(j, i)) > 1e-10 * scale) {
        throw std::runtime_error(where + ": the matrix is not symmetric: entry (" + std::to_string(i + 1) +
                                 ", " + std::to_string(j + 1) + ") = " + formatNumber(W(i, j), 17) +
                                 " but (" + std::to_string(j + 1) + ", " + std::to_string(i + 1) +
                                 ") = " + formatNumber(W(j, i), 17));
      }
    }
  }
  return W;
}

}  // namespace

Eigen::MatrixXd parseWeight(const std::string& command, const std::string& option,
                            const std::string& text, int size, const std::string& sizeMeaning,
                            WeightKind kind) {
  const bool definite = kind == WeightKind::kDefinite;
  Eigen::MatrixXd W;
  if (looksNumeric(text)) {
    const std::vector<double> list = parseNumberList(command, option, stripBlanks(text));
    if (list.size() != 1 && static_cast<int>(list.size()) != size) {
      throw UsageError(command + ": " + option + ": '" + text + "' has " + std::to_string(list.size()) +
                       " numbers; expected 1 (a multiple of the identity) or " + std::to_string(size) +
                       " (the diagonal: " + sizeMeaning + ")");
    }
    W = Eigen::MatrixXd::Zero(size, size);
    for (int i = 0; i < size; ++i) {
      const double value = list.size() == 1 ? list[0] : list[static_cast<std::size_t>(i)];
      if (value < 0.0 || (definite && value == 0.0)) {
        throw UsageError(command + ": " + option + ": diagonal entry " + std::to_string(i + 1) + " = " +
                         formatNumber(value, 17) + " must be " + (definite ? "> 0" : ">= 0") +
                         (definite ? " (R must be positive definite)" : " (the weight must be positive semidefinite)"));
      }
      W(i, i) = value;
    }
    return W;
  }
  W = readWeightFile(option, text, size, sizeMeaning);
  try {
    checkWeightMatrix(W, "the matrix", size, definite);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(option + ": weight file '" + text + "': " + e.what());
  }
  return W;
}

}  // namespace trellis::cli
