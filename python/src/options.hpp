// python/src/options.hpp — keyword construction of the C++ options structs.
#pragma once

#include "common.hpp"

namespace trellis::python {

/// `Options(rtol=1e-6, method=...)`: default-constructs T and sets each keyword as an attribute
/// (so the field's own setter converts and checks the type); an unknown keyword is a TypeError.
template <class T>
T makeFromKwargs(const py::kwargs& kwargs) {
  py::object obj = py::cast(T{});
  for (const auto& item : kwargs) {
    const std::string key = py::str(item.first);
    if (!py::hasattr(obj, key.c_str()) || key.rfind('_', 0) == 0) {
      throw py::type_error(std::string(py::str(obj.get_type().attr("__name__"))) +
                           "() got an unexpected keyword argument '" + key + "'");
    }
    obj.attr(key.c_str()) = item.second;
  }
  return obj.cast<T>();
}

/// A repr listing the given fields: "Name(a=1, b=2)".
template <class T>
std::string reprFields(const T& value, const char* name, std::initializer_list<const char*> fields) {
  py::object obj = py::cast(value);
  std::string s = std::string(name) + "(";
  bool first = true;
  for (const char* f : fields) {
    s += (first ? "" : ", ") + std::string(f) + "=" + std::string(py::repr(obj.attr(f)));
    first = false;
  }
  return s + ")";
}

}  // namespace trellis::python
