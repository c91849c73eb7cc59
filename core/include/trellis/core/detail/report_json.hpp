// trellis/core/detail/report_json.hpp — building the json() reports of results (library sources
// only: includes nlohmann/json, which public headers do not show).
//
//   ReportJson j = statusJson(result.status);   // {"status": "ok", "message": "", "t": …, "index": …}
//   j["steps"] = result.steps;
//   j["K"] = toJson(result.K);                  // a matrix as a list of rows
//   return j.dump();
// Keys keep the order in which they are added; non-finite numbers are written as null (JSON has
// no NaN or Inf), which every reader of our reports treats as "not available".
#pragma once

#include "trellis/core/status.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cmath>

namespace trellis::detail {

using ReportJson = nlohmann::ordered_json;

inline ReportJson toJson(double value) {
  return std::isfinite(value) ? ReportJson(value) : ReportJson(nullptr);
}

/// A vector (one column at compile time) as a list of numbers; any other matrix as a list of rows
/// (a matrix with no columns gives empty rows).
template <class Derived>
ReportJson toJson(const Eigen::MatrixBase<Derived>& m) {
  ReportJson out = ReportJson::array();
  if constexpr (Derived::ColsAtCompileTime == 1) {
    for (Eigen::Index i = 0; i < m.size(); ++i) out.push_back(toJson(static_cast<double>(m(i))));
  } else {
    for (Eigen::Index i = 0; i < m.rows(); ++i) {
      ReportJson row = ReportJson::array();
      for (Eigen::Index j = 0; j < m.cols(); ++j) row.push_back(toJson(static_cast<double>(m(i, j))));
      out.push_back(std::move(row));
    }
  }
  return out;
}

/// {"status": name, "ok": bool, "message": text, "t": t or null, "index": i or null}
template <NamedEnum Code>
ReportJson statusJson(const Status<Code>& status) {
  ReportJson j;
  j["status"] = status.name();
  j["ok"] = status.ok();
  j["message"] = status.message;
  j["t"] = toJson(status.t);
  j["index"] = status.index >= 0 ? ReportJson(status.index) : ReportJson(nullptr);
  return j;
}

}  // namespace trellis::detail
