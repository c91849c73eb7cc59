// trellis/analysis/detail/option_check.hpp (internal to trellis's libraries) — the "Options.field =
// value must be rule" errors of the option checks of analysis/ and control/. (Enum names have one
// mechanism: trellis/core/enum_names.hpp.)
//
//   badOption("SimulationOptions", "rtol", v, "> 0 and finite")  → throws std::invalid_argument
#pragma once

#include <cstddef>
#include <sstream>
#include <stdexcept>
#include <string>

namespace trellis::detail {

/// Throws std::invalid_argument "<owner>.<field> = <value> must be <rule>".
[[noreturn]] inline void badOption(const char* owner, const std::string& field, double value,
                                   const char* rule) {
  std::ostringstream m;
  m << owner << "." << field << " = " << value << " must be " << rule;
  throw std::invalid_argument(m.str());
}

}  // namespace trellis::detail
