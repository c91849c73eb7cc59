// trellis/analysis/detail/option_check.hpp (internal to trellis's libraries) — the "Options.field =
// value must be rule" errors of the option checks of analysis/ and control/, and the enum ↔ text
// tables of their older enums (SimulationStatus, IntegrationMethod, RiccatiMethod, …; new enums
// declare core's enumNames table, trellis/core/enum_names.hpp, which is to replace these).
//
//   constexpr EnumName<IntegrationMethod> kMethods[] = {{IntegrationMethod::kAdams, "adams"}, …};
//   nameOf(kMethods, m)                  → "adams" ("unknown" for a value not in the table)
//   parseName(kMethods, text)            → the value, or std::invalid_argument
//                                          "'TEXT' is not one of adams, bdf"
//   badOption("SimulationOptions", "rtol", v, "> 0 and finite")  → throws std::invalid_argument
#pragma once

#include <cstddef>
#include <sstream>
#include <stdexcept>
#include <string>

namespace trellis::detail {

template <class E>
struct EnumName {
  E value;
  const char* name;
};

template <class E, std::size_t N>
const char* nameOf(const EnumName<E> (&table)[N], E value) {
  for (const EnumName<E>& e : table) {
    if (e.value == value) return e.name;
  }
  return "unknown";
}

template <class E, std::size_t N>
E parseName(const EnumName<E> (&table)[N], const std::string& text) {
  for (const EnumName<E>& e : table) {
    if (text == e.name) return e.value;
  }
  std::string names;
  for (const EnumName<E>& e : table) names += (names.empty() ? "" : ", ") + std::string(e.name);
  throw std::invalid_argument("'" + text + "' is not one of " + names);
}

/// Throws std::invalid_argument "<owner>.<field> = <value> must be <rule>".
[[noreturn]] inline void badOption(const char* owner, const std::string& field, double value,
                                   const char* rule) {
  std::ostringstream m;
  m << owner << "." << field << " = " << value << " must be " << rule;
  throw std::invalid_argument(m.str());
}

}  // namespace trellis::detail
