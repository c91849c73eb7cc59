// trellis/core/status.hpp — the one shape of a numerical outcome.
//
// Every public result of numerical work (dynamics, projection, equilibrium, Riccati, simulation,
// optimization, …) carries a `Status<Code>`: a code from that computation's own enum, named through
// enum_names.hpp, a message for a person, and where it happened — the time t and an index (a knot,
// a constraint row, a step or an iteration; each result documents which). Success is the enum's
// first value (value 0, by convention `kOk`) unless the enum declares others with
// `constexpr bool isSuccess(Code)` (found by argument-dependent lookup).
//
// Two channels, as in the house style: bad input (sizes, option values, files) throws an exception
// whose message names the element, field and value; a numerical failure is returned as a status
// and never thrown. Every result also offers describe() (one line for a person) and json() (a
// compact JSON object built with the JSON library), which the CLI and Python print as they are.
#pragma once

#include "trellis/core/enum_names.hpp"

#include <cmath>
#include <limits>
#include <string>
#include <utility>

namespace trellis {

namespace detail {
template <class Code>
constexpr bool defaultSuccess(Code code) {
  return code == Code{};
}
}  // namespace detail

/// Code values that mean success: `isSuccess(code)` when the enum declares it, else code == Code{}.
template <NamedEnum Code>
constexpr bool statusSucceeded(Code code) {
  if constexpr (requires { isSuccess(code); }) {
    return isSuccess(code);
  } else {
    return detail::defaultSuccess(code);
  }
}

/// The outcome of a numerical computation (file comment): its code, a message for a person, and
/// where it happened (time t, index). ok() when the code is a success; describe() and json() as
/// every result offers them.
template <NamedEnum Code>
struct Status {
  Code code{};          ///< the computation's own code; value-initialized: success
  std::string message;  ///< empty on success; else what failed, with the values that show it
  /// When it happened (seconds of the model's time), NaN where time means nothing.
  double t = std::numeric_limits<double>::quiet_NaN();
  /// Where it happened: knot, constraint row, step or iteration (the result says which); −1: none.
  long index = -1;

  /// True when the result it belongs to is valid and complete.
  constexpr bool ok() const { return statusSucceeded(code); }
  /// The code's name, e.g. "ok", "blow_up".
  const char* name() const { return toString(code); }
  /// One line: "ok", or "<name>[ at t = <t>][ (index <i>)]: <message>".
  std::string describe() const {
    std::string line = name();
    if (!std::isnan(t)) line += " at t = " + formatNumber(t);
    if (index >= 0) line += " (index " + std::to_string(index) + ")";
    if (!message.empty()) line += ": " + message;
    return line;
  }

  /// Sets code, message, t and index at once (a failure's record in one statement).
  Status& set(Code c, std::string text, double time = std::numeric_limits<double>::quiet_NaN(),
              long where = -1) {
    code = c;
    message = std::move(text);
    t = time;
    index = where;
    return *this;
  }

 private:
  static std::string formatNumber(double value);
};

/// Shortest round-trip decimal form ("%.17g" trimmed): the number a person can paste back.
std::string formatStatusNumber(double value);

template <NamedEnum Code>
std::string Status<Code>::formatNumber(double value) {
  return formatStatusNumber(value);
}

}  // namespace trellis
