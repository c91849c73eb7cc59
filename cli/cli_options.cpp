// cli/cli_options.cpp — see cli_options.hpp.
#include "cli_options.hpp"

#include "command.hpp"

#include "trellis/control/tvlqr.hpp"
#include "trellis/core/io.hpp"
#include "trellis/core/reference.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/model.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include <sys/stat.h>

namespace trellis::cli {
namespace {

/// The whole of `text` as a finite double (leading '+' allowed), or nothing.
std::optional<double> parseDouble(std::string_view text) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  if (text.empty()) return std::nullopt;
  double value = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size() || !std::isfinite(value)) {
    return std::nullopt;
  }
  return value;
}

}  // namespace

ParsedOptions::ParsedOptions(std::string command, std::span<const std::string> args,
                             const OptionSpec& spec)
    : command_(std::move(command)) {
  bool optionsDone = false;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (optionsDone || arg == "-" || arg.size() < 2 || arg[0] != '-') {
      positionals_.push_back(arg);
      continue;
    }
    if (arg == "--") {
      optionsDone = true;
      continue;
    }
    const std::size_t equals = arg.find('=');
    const std::string name = arg.substr(0, equals);
    if (spec.flags.count(name)) {
      if (equals != std::string::npos) {
        throw UsageError(command_ + ": option '" + name + "' takes no value");
      }
      flags_.insert(name);
      continue;
    }
    if (!spec.valued.count(name)) {
      throw UsageError(command_ + ": unknown option '" + name + "'");
    }
    std::string value;
    if (equals != std::string::npos) {
      value = arg.substr(equals + 1);
    } else if (i + 1 < args.size()) {
      value = args[++i];
    } else {
      throw UsageError(command_ + ": option '" + name + "' needs a value");
    }
    std::vector<std::string>& list = values_[name];
    if (!list.empty() && !spec.repeatable.count(name)) {
      throw UsageError(command_ + ": option '" + name + "' given more than once");
    }
    list.push_back(std::move(value));
  }
}

std::optional<std::string> ParsedOptions::value(const std::string& option) const {
  const auto it = values_.find(option);
  if (it == values_.end()) return std::nullopt;
  return it->second.front();
}

std::vector<std::string> ParsedOptions::values(const std::string& option) const {
  const auto it = values_.find(option);
  return it == values_.end() ? std::vector<std::string>{} : it->second;
}

std::string ParsedOptions::required(const std::string& option, const std::string& what) const {
  const std::optional<std::string> v = value(option);
  if (!v) throw UsageError(command_ + ": missing " + option + " " + what);
  return *v;
}

std::string ParsedOptions::singlePositional(const std::string& what) const {
  if (positionals_.empty()) throw UsageError(command_ + ": missing the " + what);
  if (positionals_.size() > 1) {
    throw UsageError(command_ + ": more than one " + what + " ('" + positionals_[0] + "', '" +
                     positionals_[1] + "')");
  }
  return positionals_[0];
}

double ParsedOptions::number(const std::string& option, const std::string& text) const {
  const std::optional<double> v = parseDouble(text);
  if (!v) throw UsageError(command_ + ": " + option + ": '" + text + "' is not a finite number");
  return *v;
}

double ParsedOptions::positiveNumber(const std::string& option, const std::string& text,
                                     bool allowZero) const {
  const double v = number(option, text);
  if (v < 0.0 || (v == 0.0 && !allowZero)) {
    throw UsageError(command_ + ": " + option + ": " + text + " must be " +
                     (allowZero ? ">= 0" : "> 0"));
  }
  return v;
}

double ParsedOptions::numberInRange(const std::string& option, const std::string& text, double min,
                                    double max, const std::string& why) const {
  const double v = number(option, text);
  if (!(v >= min && v <= max)) {
    throw UsageError(command_ + ": " + option + ": " + text + " is outside [" + formatNumber(min) + ", " +
                     formatNumber(max) + "] (" + why + ")");
  }
  return v;
}

void ParsedOptions::integerOutOfRange(const std::string& option, const std::string& text,
                                      const std::string& min, const std::string& max) const {
  throw UsageError(command_ + ": " + option + ": '" + text + "' is out of the range [" + min + ", " + max + "]");
}

void ParsedOptions::notAnInteger(const std::string& option, const std::string& text) const {
  throw UsageError(command_ + ": " + option + ": '" + text + "' is not an integer");
}

long long ParsedOptions::gridPoints(const std::string& option, double step, double span, long long limit,
                                    const std::string& what) const {
  // span/step + 1 points (the end closes the grid); computed in double, so a huge count is
  // compared, never converted.
  const double points = std::floor(span / step) + 2.0;
  if (!(points <= static_cast<double>(limit))) {
    throw UsageError(command_ + ": " + option + ": a step of " + formatNumber(step) + " over " +
                     formatNumber(span) + " gives " + formatNumber(points, 3) + " " + what +
                     "; the limit is " + std::to_string(limit) + " (use a larger step)");
  }
  return static_cast<long long>(points);
}

std::vector<double> parseNumberList(const std::string& command, const std::string& option,
                                    const std::string& text) {
  std::vector<double> list;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    const std::string item = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    const std::optional<double> v = parseDouble(item);
    if (!v) {
      throw UsageError(command + ": " + option + ": item " + std::to_string(list.size() + 1) + " of '" +
                       text + "' ('" + item + "') is not a finite number");
    }
    list.push_back(*v);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return list;
}

std::vector<double> ParsedOptions::numberList(const std::string& option, const std::string& text) const {
  return parseNumberList(command_, option, text);
}

Eigen::VectorXd ParsedOptions::broadcastList(const std::string& option, const std::string& text,
                                             int size, const std::string& what) const {
  const std::vector<double> list = numberList(option, text);
  if (list.size() == 1) return Eigen::VectorXd::Constant(size, list[0]);
  if (static_cast<int>(list.size()) != size) {
    throw UsageError(command_ + ": " + option + ": '" + text + "' has " + std::to_string(list.size()) +
                     " numbers; expected one or " + std::to_string(size) + " (" + what + ")");
  }
  return Eigen::Map<const Eigen::VectorXd>(list.data(), size);
}

std::string formatNumber(double value, int digits) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*g", digits, value);
  return buffer;
}

Trajectory loadReference(const Model& model, const std::string& scenePath,
                         const std::string& trajectoryPath) {
  return checkReference(model, scenePath, trajectoryPath, Trajectory::readCsvFile(trajectoryPath));
}

Trajectory checkReference(const Model& model, const std::string& scenePath, const std::string& trajectoryPath,
                          const Trajectory& file) {
  try {
    file.checkCompatible(model);
  } catch (const TrajectoryError& e) {
    throw std::runtime_error(trajectoryPath + " does not match the scene " + scenePath + ": " + e.what());
  }
  if (file.size() < 2) {
    throw std::runtime_error(trajectoryPath + ": a reference needs at least 2 knots, got " +
                             std::to_string(file.size()));
  }
  // The library's check (core/reference.hpp): each residual relative to the size of its terms.
  const ReferenceConstraintCheck onManifold =
      checkReferenceOnConstraints(model, file, kReferenceConstraintTolerance);
  if (!onManifold.ok()) {
    const Constraint& c = model.constraints()[static_cast<std::size_t>(onManifold.constraint)];
    throw std::runtime_error(
        trajectoryPath + ": row " + std::to_string(onManifold.status.index + 1) + " (t = " +
        formatNumber(onManifold.status.t) + ") violates the constraint '" + c.name + "' of " + scenePath +
        ": " + (onManifold.position ? "h(q) = " : "A(q) q' = ") + formatNumber(onManifold.value, 3) +
        " (size of its terms " + formatNumber(onManifold.scale, 3) + ", tolerance " +
        formatNumber(kReferenceConstraintTolerance, 3) + " relative); a reference must lie on the constraints");
  }
  // The file's meaning: knot derivatives from the scene's dynamics (the failing knot named),
  // the file's input rule (linear, or cubic Hermite with rate_<input> columns).
  ReferenceOptions checks;
  checks.stateDerivatives = ReferenceOptions::StateDerivatives::kFromDynamics;
  checks.minimumKnots = 2;
  try {
    return ReferenceEvaluator(model, file, checks).trajectory();
  } catch (const TrajectoryError& e) {
    throw std::runtime_error(trajectoryPath + ": " + e.what());
  }
}

void checkOutputIsNotInput(const std::string& command, const std::string& outPath,
                           const std::vector<std::pair<std::string, std::string>>& inputs) {
  if (isStreamPath(outPath)) return;
  struct stat out {};
  const bool outExists = ::stat(outPath.c_str(), &out) == 0;
  if (outExists && !S_ISREG(out.st_mode)) return;  // a device or FIFO is written in place
  for (const auto& [option, path] : inputs) {
    struct stat in {};
    if (::stat(path.c_str(), &in) != 0) continue;  // not a file ("--Q 10"), or one that will fail to load
    const bool same = path == outPath || (outExists && in.st_dev == out.st_dev && in.st_ino == out.st_ino);
    if (same) {
      throw UsageError(command + ": --out '" + outPath + "' is the " + option + " input '" + path +
                       "'; writing it would destroy the input (name another file)");
    }
  }
}

std::string joinNames(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

}  // namespace trellis::cli
