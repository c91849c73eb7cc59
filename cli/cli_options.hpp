// cli/cli_options.hpp — option parsing shared by the subcommands that take many options
// (`trellis gains`, `trellis simulate`): `--name VALUE` or `--name=VALUE`, flags, positional
// arguments, "--" to end the options; numbers and number lists checked with messages that name
// the command, the option and the offending text.
#pragma once

#include <Eigen/Core>

#include <charconv>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace trellis {
class Model;
class Trajectory;
}  // namespace trellis

namespace trellis::cli {

/// Limits on the sizes a command-line option controls (a step of 1e-12 s must not fill memory):
/// rows of an output file, and samples of a sampled feedback.
inline constexpr long long kMaxOutputRows = 1'000'000;
inline constexpr long long kMaxFeedbackSamples = 100'000'000;

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
  /// number() within [min, max], else UsageError "COMMAND: OPTION: TEXT is outside [min, max]
  /// (WHY)": a value outside a meaningful range (an absolute tolerance of 1e300) is refused, not
  /// passed on to a solver that would return a meaningless result.
  double numberInRange(const std::string& option, const std::string& text, double min, double max,
                       const std::string& why) const;
  /// The one integer parser of the command line: `text` as an integer of type T (decimal, an
  /// optional sign) within [min, max], which default to T's own range, so that a count never wraps
  /// around ("--max-iter 4294967296" is refused, not read as 0). UsageError naming the option,
  /// the text and the range otherwise.
  template <class T>
  T integer(const std::string& option, const std::string& text, T min = std::numeric_limits<T>::min(),
            T max = std::numeric_limits<T>::max()) const {
    static_assert(std::is_integral_v<T>);
    std::string_view digits = text;
    if (!digits.empty() && digits.front() == '+') digits.remove_prefix(1);
    T value{};
    const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    const bool whole = !digits.empty() && end == digits.data() + digits.size();
    const bool negativeForUnsigned = std::is_unsigned_v<T> && digits.size() > 1 && digits.front() == '-' &&
                                     digits.find_first_not_of("0123456789", 1) == std::string_view::npos;
    if (negativeForUnsigned || (whole && error == std::errc::result_out_of_range) ||
        (whole && error == std::errc() && (value < min || value > max))) {
      integerOutOfRange(option, text, std::to_string(min), std::to_string(max));
    }
    if (!whole || error != std::errc()) notAnInteger(option, text);
    return value;
  }
  /// An integrator's relative tolerance: [1e-14, 0.1] (below, round-off; above, no accuracy).
  double relativeTolerance(const std::string& option, const std::string& text) const {
    return numberInRange(option, text, 1e-14, 0.1, "a relative tolerance: below, round-off; above, no accuracy");
  }
  /// An integrator's absolute tolerance: [1e-20, 1] (the results are compared with it; beyond 1
  /// an error-free step is accepted whatever it computes).
  double absoluteTolerance(const std::string& option, const std::string& text) const {
    return numberInRange(option, text, 1e-20, 1.0, "an absolute tolerance: larger values accept any step");
  }
  /// A grid of steps `step` over a span `span` (output rows, feedback samples): the number of
  /// points it implies, or UsageError naming the option and that number if it exceeds `limit`
  /// (the work and memory grow with it: `--dt 1e-12` must not run until memory is exhausted).
  long long gridPoints(const std::string& option, double step, double span, long long limit,
                       const std::string& what) const;
  /// "a" or "a,b,c": a list of finite numbers (empty items are errors).
  std::vector<double> numberList(const std::string& option, const std::string& text) const;
  /// A number (broadcast to `size`) or a list of exactly `size` numbers; `what` names the entries
  /// ("inputs") in the length message.
  Eigen::VectorXd broadcastList(const std::string& option, const std::string& text, int size,
                                const std::string& what) const;

 private:
  [[noreturn]] void integerOutOfRange(const std::string& option, const std::string& text,
                                      const std::string& min, const std::string& max) const;
  [[noreturn]] void notAnInteger(const std::string& option, const std::string& text) const;

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
/// of `scenePath`, that it has ≥ 2 knots and, for a scene with constraints, that every knot
/// satisfies them (the library's checkReferenceOnConstraints, core/reference.hpp: |h(q)| and
/// |A(q) q'| within kReferenceConstraintTolerance relative to the size of their terms, so that the
/// verdict does not change with the model's units), and computes its state derivatives. Throws std::runtime_error naming the
/// file and the problem (exit status 1): a reference off the constraint manifold has no
/// meaningful linearization and would be tracked with a drift as large as its violation.
Trajectory loadReference(const Model& model, const std::string& scenePath,
                         const std::string& trajectoryPath);
/// loadReference's checks on a trajectory made in memory; `trajectoryPath` names it in messages.
Trajectory checkReference(const Model& model, const std::string& scenePath, const std::string& trajectoryPath,
                          const Trajectory& trajectory);

/// The bound of loadReference's constraint check: 1e-6 relative (written trajectories carry 17
/// digits; an optimized or integrated one satisfies its constraints to its solver's tolerance).
inline constexpr double kReferenceConstraintTolerance = 1e-6;

/// "a, b, c" for messages.
std::string joinNames(const std::vector<std::string>& names);

/// Throws UsageError when the output `outPath` of `--out` is one of the command's inputs (the
/// same file: equal device and inode, through links, or the same path): writing it would destroy
/// the input. `inputs` pairs an option name ("--trajectory") with its path. Streams (/dev/stdout,
/// "-") and devices are never inputs.
void checkOutputIsNotInput(const std::string& command, const std::string& outPath,
                           const std::vector<std::pair<std::string, std::string>>& inputs);

}  // namespace trellis::cli
