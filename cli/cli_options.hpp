// cli/cli_options.hpp — option parsing shared by the subcommands that take many options
// (`trellis gains`, `trellis simulate`): `--name VALUE` or `--name=VALUE`, flags, positional
// arguments, "--" to end the options; numbers and number lists checked with messages that name
// the command, the option and the offending text.
#pragma once

#include <Eigen/Core>

#include <map>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <vector>

namespace trellis {
class Model;
class Trajectory;
}  // namespace trellis

namespace trellis::cli {

/// What a command accepts. Options listed in `repeatable` may be given more than once (their
/// values are kept in order); any other option given twice is a usage error.
struct OptionSpec {
  std::set<std::string> valued;      ///< "--trajectory", ... (take one value)
  std::set<std::string> flags;       ///< "--no-project", ... (take none)
  std::set<std::string> repeatable;  ///< subset of `valued`
};

class ParsedOptions {
 public:
  /// Parses `args` (after the command name). Throws UsageError ("COMMAND: ...") for an unknown
  /// option, a missing value, a flag given a value or a non-repeatable option given twice.
  ParsedOptions(std::string command, std::span<const std::string> args, const OptionSpec& spec);

  const std::string& command() const { return command_; }
  const std::vector<std::string>& positionals() const { return positionals_; }
  bool has(const std::string& option) const { return values_.count(option) > 0 || flags_.count(option) > 0; }
  bool flag(const std::string& option) const { return flags_.count(option) > 0; }
  /// The value of a single-valued option, if given.
  std::optional<std::string> value(const std::string& option) const;
  /// Every value of a repeatable option, in command-line order (empty if not given).
  std::vector<std::string> values(const std::string& option) const;
  /// The value, or UsageError "COMMAND: missing OPTION (WHAT)".
  std::string required(const std::string& option, const std::string& what) const;

  /// The one positional argument (the scene), or UsageError naming what is missing or extra.
  std::string singlePositional(const std::string& what) const;

  /// A finite number, else UsageError "COMMAND: OPTION: 'TEXT' is not a number".
  double number(const std::string& option, const std::string& text) const;
  /// number() that must be > 0 (or ≥ 0 when allowZero).
  double positiveNumber(const std::string& option, const std::string& text, bool allowZero = false) const;
  /// A non-negative integer (seeds, step counts).
  unsigned long long count(const std::string& option, const std::string& text) const;
  /// "a" or "a,b,c": a list of finite numbers (empty items are errors).
  std::vector<double> numberList(const std::string& option, const std::string& text) const;
  /// A number (broadcast to `size`) or a list of exactly `size` numbers; `what` names the entries
  /// ("inputs") in the length message.
  Eigen::VectorXd broadcastList(const std::string& option, const std::string& text, int size,
                                const std::string& what) const;

 private:
  std::string command_;
  std::vector<std::string> positionals_;
  std::map<std::string, std::vector<std::string>> values_;
  std::set<std::string> flags_;
};

/// "a" or "a,b,c" as a list of finite numbers, for `option` of `command`; an empty or malformed
/// item throws UsageError naming its position and text.
std::vector<double> parseNumberList(const std::string& command, const std::string& option,
                                    const std::string& text);

/// `value` with `digits` significant digits (printf %g), for messages and summaries.
std::string formatNumber(double value, int digits = 6);

/// Reads the reference trajectory CSV at `trajectoryPath`, checks that its names match the model
/// of `scenePath` and that it has ≥ 2 knots, and computes its state derivatives. Throws
/// std::runtime_error naming the file and the problem (exit status 1).
Trajectory loadReference(const Model& model, const std::string& scenePath,
                         const std::string& trajectoryPath);

/// "a, b, c" for messages.
std::string joinNames(const std::vector<std::string>& names);

}  // namespace trellis::cli
