// trellis/core/enum_names.hpp — one mechanism for the names of the library's enums.
//
// Every public enum whose values a person reads or types (statuses, methods, schemes) declares its
// table once, beside the enum, as a constexpr function found by argument-dependent lookup:
//
//   enum class RiccatiStatus { kOk, kBlowUp };
//   inline EnumNameTable<RiccatiStatus> enumNames(RiccatiStatus) {
//     static constexpr EnumName<RiccatiStatus> table[] = {{RiccatiStatus::kOk, "ok"},
//                                                         {RiccatiStatus::kBlowUp, "blow_up"}};
//     return table;
//   }
//
// and then, for every such enum, in C++, the CLI and Python alike:
//   toString(RiccatiStatus::kBlowUp)           → "blow_up" ("unknown" for a value not in the table)
//   parseEnum<RiccatiStatus>("blow_up", "status") → the value; otherwise std::invalid_argument
//                                               "status 'x' is not one of ok, blow_up"
//   enumNameList<RiccatiStatus>()              → "ok, blow_up"
// Names are lower_snake_case, stable across versions (they appear in files and JSON reports).
#pragma once

#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>

namespace trellis {

/// One entry of an enum's name table: the enumerator and its name (snake_case, as in files and
/// JSON reports).
template <class E>
struct EnumName {
  E value;           ///< the enumerator
  const char* name;  ///< its name (a string literal)
};

/// The table's entries (a static array), in the order a person should read them (success first).
template <class E>
using EnumNameTable = std::span<const EnumName<E>>;

/// Enums that declare a table with `enumNames(E)`.
template <class E>
concept NamedEnum = std::is_enum_v<E> && requires(E e) { enumNames(e); };

/// The value's name, or "unknown" for a value outside the table.
template <NamedEnum E>
const char* toString(E value) {
  for (const EnumName<E>& entry : enumNames(E{})) {
    if (entry.value == value) return entry.name;
  }
  return "unknown";
}

/// "a, b, c": every name of the table, for messages and help texts.
template <NamedEnum E>
std::string enumNameList() {
  std::string names;
  for (const EnumName<E>& entry : enumNames(E{})) {
    if (!names.empty()) names += ", ";
    names += entry.name;
  }
  return names;
}

/// The value named `text`. Throws std::invalid_argument "<what> '<text>' is not one of <names>",
/// `what` naming the field in the user's terms (e.g. "--method", "RiccatiOptions.method").
template <NamedEnum E>
E parseEnum(std::string_view text, std::string_view what) {
  for (const EnumName<E>& entry : enumNames(E{})) {
    if (text == entry.name) return entry.value;
  }
  throw std::invalid_argument(std::string(what) + " '" + std::string(text) + "' is not one of " +
                              enumNameList<E>());
}

}  // namespace trellis
