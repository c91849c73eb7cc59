// cli/json_output.cpp
#include "json_output.hpp"

#include <string>

namespace trellis::cli {

OutputJson toJson(const Eigen::VectorXd& v) {
  OutputJson list = OutputJson::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) list.push_back(v[i]);
  return list;
}

OutputJson toJson(const Eigen::MatrixXd& m) {
  OutputJson rows = OutputJson::array();
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    OutputJson row = OutputJson::array();
    for (Eigen::Index j = 0; j < m.cols(); ++j) row.push_back(m(i, j));
    rows.push_back(std::move(row));
  }
  return rows;
}

namespace {

/// A list on one line, with a space after each comma.
std::string inlineList(const OutputJson& list) {
  std::string text = "[";
  bool first = true;
  for (const auto& item : list) {
    if (!first) text += ", ";
    text += item.is_array() ? inlineList(item) : item.dump();
    first = false;
  }
  return text + "]";
}

bool isMatrix(const OutputJson& value) {
  if (!value.is_array() || value.empty()) return false;
  for (const auto& row : value)
    if (!row.is_array()) return false;
  return true;
}

void writeValue(std::ostream& out, const OutputJson& value, const std::string& indent) {
  if (isMatrix(value)) {
    out << "[\n";
    for (std::size_t i = 0; i < value.size(); ++i) {
      out << indent << "  " << inlineList(value[i]) << (i + 1 < value.size() ? ",\n" : "\n");
    }
    out << indent << "]";
  } else if (value.is_array()) {
    out << inlineList(value);
  } else if (value.is_object() && !value.empty()) {
    out << "{\n";
    std::size_t i = 0;
    for (const auto& [key, item] : value.items()) {
      out << indent << "  " << OutputJson(key).dump() << ": ";
      writeValue(out, item, indent + "  ");
      out << (++i < value.size() ? ",\n" : "\n");
    }
    out << indent << "}";
  } else {
    out << value.dump();
  }
}

}  // namespace

void writeJson(std::ostream& out, const OutputJson& value, bool compact) {
  if (compact) {
    out << value.dump() << '\n';
  } else {
    writeValue(out, value, "");
    out << '\n';
  }
}

}  // namespace trellis::cli
