// numeric_csv.hpp (internal) — the CSV reader shared by trajectory and gain-schedule files: a
// header row of names, then rows of finite numbers whose first column (time) increases strictly.
// Every error is a TrajectoryError naming the source, the data row (1-based), the file line and
// the column (1-based, with its header name).
//
// Limits keep an endless or hostile stream (/dev/zero, a file of blank lines) from growing memory
// or time without bound: a line is at most kMaxCsvLineLength characters, a file at most
// kMaxCsvLines lines and kMaxCsvValues numbers (8 bytes each: 512 MiB).
#pragma once

#include "trellis/core/trajectory.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iomanip>
#include <istream>
#include <sstream>
#include <string>
#include <vector>

namespace trellis::detail {

inline constexpr std::size_t kMaxCsvLineLength = std::size_t{1} << 20;  // 1 MiB
inline constexpr long long kMaxCsvLines = 10'000'000;
inline constexpr long long kMaxCsvValues = 64'000'000;

/// Opens `path` for reading, or TrajectoryError naming it, what it should be, and the reason
/// (the OS error, or that it is a directory).
inline void openCsvFile(std::ifstream& in, const std::string& path, const std::string& what) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    throw TrajectoryError(path + ": is a directory, not a " + what + " CSV file");
  }
  errno = 0;
  in.open(path);
  if (!in) {
    const int error = errno;
    throw TrajectoryError(path + ": cannot open the " + what + " file for reading" +
                          (error != 0 ? " (" + std::string(std::strerror(error)) + ")" : std::string()));
  }
}

/// std::getline with a length limit: false at the end of the stream; TrajectoryError naming the
/// source and line number for a line longer than kMaxCsvLineLength or beyond kMaxCsvLines.
inline bool readCsvLine(std::istream& in, std::string& line, long long& lineNo, const std::string& source) {
  line.clear();
  if (++lineNo > kMaxCsvLines && in.rdbuf()->sgetc() != std::char_traits<char>::eof()) {
    throw TrajectoryError(source + ": more than " + std::to_string(kMaxCsvLines) + " lines (the limit)");
  }
  std::streambuf* buffer = in.rdbuf();
  while (true) {
    const int c = buffer->sbumpc();
    if (c == std::char_traits<char>::eof()) {
      if (line.empty()) in.setstate(std::ios::eofbit);
      return !line.empty();
    }
    if (c == '\n') return true;
    if (line.size() >= kMaxCsvLineLength) {
      throw TrajectoryError(source + ": line " + std::to_string(lineNo) + " is longer than " +
                            std::to_string(kMaxCsvLineLength) + " characters (the limit)");
    }
    line.push_back(static_cast<char>(c));
  }
}

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
/// are kept in `comments`) and passes it to checkHeader(comments, header, headerLine),
/// which throws TrajectoryError if the names are wrong; then the data rows (blank lines skipped).
/// Throws for an empty file, no data rows, a wrong column count, a field that is not a number or
/// not finite, and a time not greater than the previous one. The stream is read line by line
/// within the limits above (never slurped whole: it may be endless).
inline NumericCsv readNumericCsv(
    std::istream& in, const std::string& source,
    const std::function<void(const std::vector<std::string>&, const std::vector<std::string>&, int)>&
        checkHeader) {
  NumericCsv csv;
  std::string line;
  long long lineNo = 0;
  while (readCsvLine(in, line, lineNo, source)) {
    const std::string trimmed = trimCsvField(line);
    if (!trimmed.empty() && trimmed[0] == '#') {
      csv.comments.push_back(trimmed.substr(1));
      continue;
    }
    if (!trimmed.empty()) {
      csv.header = splitCsvLine(line);
      csv.headerLine = static_cast<int>(lineNo);
      break;
    }
  }
  if (csv.header.empty()) throw TrajectoryError(source + ": empty file (expected a header row)");
  checkHeader(csv.comments, csv.header, csv.headerLine);
  const int width = static_cast<int>(csv.header.size());
  int row = 0;
  while (readCsvLine(in, line, lineNo, source)) {
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
    if (static_cast<long long>(csv.rows.size() + 1) * width > kMaxCsvValues) {
      throw TrajectoryError(at + ": more than " + std::to_string(kMaxCsvValues) + " numbers in the file (the limit)");
    }
    csv.rows.push_back(std::move(values));
  }
  if (csv.rows.empty()) throw TrajectoryError(source + ": no data rows after the header");
  return csv;
}

/// The same without comments for the header check (trajectory files).
inline NumericCsv readNumericCsv(
    std::istream& in, const std::string& source,
    const std::function<void(const std::vector<std::string>&, int)>& checkHeader) {
  return readNumericCsv(in, source,
                        [&checkHeader](const std::vector<std::string>&, const std::vector<std::string>& header,
                                       int line) { checkHeader(header, line); });
}

}  // namespace trellis::detail
