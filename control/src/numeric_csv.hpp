// numeric_csv.hpp (internal) — the CSV reader shared by trajectory and gain-schedule files: a
// header row of names, then rows of finite numbers whose first column (time) increases strictly.
// Every error is a TrajectoryError naming the source, the data row (1-based), the file line and
// the column (1-based, with its header name).
#pragma once

#include "trellis/control/trajectory.hpp"

#include <cmath>
#include <cstdlib>
#include <functional>
#include <iomanip>
#include <istream>
#include <sstream>
#include <string>
#include <vector>

namespace trellis::detail {

inline std::string trimCsvField(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

/// Fields of one line, trimmed; a trailing comma gives a last empty field.
inline std::vector<std::string> splitCsvLine(const std::string& line) {
  std::vector<std::string> out;
  std::string field;
  std::istringstream ss(line);
  while (std::getline(ss, field, ',')) out.push_back(trimCsvField(field));
  if (!line.empty() && line.back() == ',') out.push_back("");
  return out;
}

struct NumericCsv {
  std::vector<std::string> header;
  int headerLine = 0;                      ///< file line of the header (1-based)
  std::vector<std::vector<double>> rows;   ///< each of header.size() values; rows[k][0] = time
  std::vector<std::string> comments;       ///< lines before the header starting with '#' ('#' removed)
};

/// Reads the header (the first non-empty line not starting with '#'; such comment lines before it
/// are kept in `comments`) and passes it to checkHeader(header, headerLine),
/// which throws TrajectoryError if the names are wrong; then the data rows (blank lines skipped).
/// Throws for an empty file, no data rows, a wrong column count, a field that is not a number or
/// not finite, and a time not greater than the previous one.
inline NumericCsv readNumericCsv(
    std::istream& in, const std::string& source,
    const std::function<void(const std::vector<std::string>&, int)>& checkHeader) {
  NumericCsv csv;
  std::string line;
  int lineNo = 0;
  while (std::getline(in, line)) {
    ++lineNo;
    const std::string trimmed = trimCsvField(line);
    if (!trimmed.empty() && trimmed[0] == '#') {
      csv.comments.push_back(trimmed.substr(1));
      continue;
    }
    if (!trimmed.empty()) {
      csv.header = splitCsvLine(line);
      csv.headerLine = lineNo;
      break;
    }
  }
  if (csv.header.empty()) throw TrajectoryError(source + ": empty file (expected a header row)");
  checkHeader(csv.header, csv.headerLine);
  const int width = static_cast<int>(csv.header.size());
  int row = 0;
  while (std::getline(in, line)) {
    ++lineNo;
    if (trimCsvField(line).empty()) continue;
    ++row;
    const auto fields = splitCsvLine(line);
    const std::string at =
        source + ": row " + std::to_string(row) + " (line " + std::to_string(lineNo) + ")";
    if (static_cast<int>(fields.size()) != width) {
      throw TrajectoryError(at + ": expected " + std::to_string(width) + " columns, got " +
                            std::to_string(fields.size()));
    }
    std::vector<double> values(width);
    for (int c = 0; c < width; ++c) {
      const std::string& f = fields[c];
      const std::string col = ", column " + std::to_string(c + 1) + " ('" + csv.header[c] + "')";
      char* end = nullptr;
      const double v = f.empty() ? 0.0 : std::strtod(f.c_str(), &end);
      if (f.empty() || end != f.c_str() + f.size()) {
        throw TrajectoryError(at + col + ": '" + f + "' is not a number");
      }
      if (!std::isfinite(v)) throw TrajectoryError(at + col + ": value '" + f + "' is not finite");
      values[c] = v;
    }
    if (!csv.rows.empty() && !(values[0] > csv.rows.back()[0])) {
      std::ostringstream m;
      m << std::setprecision(17) << at << ", column 1 ('t'): time " << values[0]
        << " is not greater than the previous time " << csv.rows.back()[0];
      throw TrajectoryError(m.str());
    }
    csv.rows.push_back(std::move(values));
  }
  if (csv.rows.empty()) throw TrajectoryError(source + ": no data rows after the header");
  return csv;
}

}  // namespace trellis::detail
