// cli/json_output.hpp — results as JSON: Eigen values to JSON, and a printer that keeps each row
// of a matrix on one line.
#pragma once

#include <nlohmann/json.hpp>

#include <Eigen/Core>

#include <ostream>

namespace trellis::cli {

/// Keys stay in the order they are added.
using OutputJson = nlohmann::ordered_json;

/// A vector as a list of numbers.
OutputJson toJson(const Eigen::VectorXd& v);
/// A matrix as a list of rows (rows × [cols numbers]; a matrix with no columns gives empty rows).
OutputJson toJson(const Eigen::MatrixXd& m);

/// Prints `value` followed by a newline. Compact: one line. Otherwise an object gets one key per
/// line and a list of lists one row per line. Doubles keep 17 significant digits (round trip).
void writeJson(std::ostream& out, const OutputJson& value, bool compact);

}  // namespace trellis::cli
