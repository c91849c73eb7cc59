// cost_to_go.cpp — S(t) tabulated: construction, evaluation, and the CSV form (cost_to_go.hpp).
#include "trellis/analysis/cost_to_go.hpp"

#include "trellis/core/io.hpp"
#include "trellis/core/status.hpp"
#include "trellis/core/trajectory.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

namespace {

std::string entryName(const std::vector<std::string>& names, int i, int j) {
  if (names.empty()) return "S[" + std::to_string(i) + "|" + std::to_string(j) + "]";
  return "S[" + names[static_cast<std::size_t>(i)] + "|" + names[static_cast<std::size_t>(j)] + "]";
}

std::vector<std::string> splitCommas(const std::string& line) {
  std::vector<std::string> items;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    items.push_back(line.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  for (std::string& item : items) {
    const auto first = item.find_first_not_of(" \t\r");
    const auto last = item.find_last_not_of(" \t\r");
    item = first == std::string::npos ? std::string() : item.substr(first, last - first + 1);
  }
  return items;
}

}  // namespace

CostToGo::CostToGo(Eigen::VectorXd times, std::vector<Eigen::MatrixXd> S)
    : times_(std::move(times)), S_(std::move(S)) {
  if (times_.size() == 0) throw TrajectoryError("cost-to-go: no rows");
  if (static_cast<std::size_t>(times_.size()) != S_.size()) {
    throw TrajectoryError("cost-to-go: " + std::to_string(times_.size()) + " times but " +
                          std::to_string(S_.size()) + " matrices");
  }
  nx_ = static_cast<int>(S_[0].rows());
  for (int k = 0; k < size(); ++k) {
    const std::string row = "cost-to-go: row " + std::to_string(k + 1) + " (t = " + formatStatusNumber(times_(k)) + ")";
    if (!std::isfinite(times_(k))) throw TrajectoryError(row + ": the time is not finite");
    if (k > 0 && !(times_(k) > times_(k - 1))) {
      throw TrajectoryError(row + ": the time is not greater than the previous row's " +
                            formatStatusNumber(times_(k - 1)));
    }
    Eigen::MatrixXd& Sk = S_[static_cast<std::size_t>(k)];
    if (Sk.rows() != nx_ || Sk.cols() != nx_) {
      throw TrajectoryError(row + ": S is " + std::to_string(Sk.rows()) + "x" + std::to_string(Sk.cols()) +
                            ", expected " + std::to_string(nx_) + "x" + std::to_string(nx_));
    }
    for (int i = 0; i < nx_; ++i) {
      for (int j = 0; j < nx_; ++j) {
        if (!std::isfinite(Sk(i, j))) {
          throw TrajectoryError(row + ": " + entryName({}, i, j) + " = " + formatStatusNumber(Sk(i, j)) +
                                " is not finite");
        }
      }
    }
    // Symmetric to the rounding of a Riccati solution; a larger asymmetry is a wrong file.
    const double scale = std::max(Sk.cwiseAbs().maxCoeff(), std::numeric_limits<double>::min());
    for (int i = 0; i < nx_; ++i) {
      for (int j = i + 1; j < nx_; ++j) {
        if (std::abs(Sk(i, j) - Sk(j, i)) > 1e-9 * scale) {
          throw TrajectoryError(row + ": S is not symmetric: " + entryName({}, i, j) + " = " +
                                formatStatusNumber(Sk(i, j)) + ", " + entryName({}, j, i) + " = " +
                                formatStatusNumber(Sk(j, i)));
        }
      }
    }
    Sk = (0.5 * (Sk + Sk.transpose())).eval();
  }
}

double CostToGo::startTime() const {
  if (size() == 0) throw std::logic_error("CostToGo::startTime: empty");
  return times_(0);
}

double CostToGo::endTime() const {
  if (size() == 0) throw std::logic_error("CostToGo::endTime: empty");
  return times_(times_.size() - 1);
}

void CostToGo::setStateNames(std::vector<std::string> names) {
  if (static_cast<int>(names.size()) != nx_) {
    throw std::invalid_argument("CostToGo::setStateNames: " + std::to_string(names.size()) + " names for nx = " +
                                std::to_string(nx_) + " states");
  }
  stateNames_ = std::move(names);
}

void CostToGo::checkNames(const std::vector<std::string>& names, const std::string& source) const {
  if (static_cast<int>(names.size()) != nx_) {
    throw TrajectoryError(source + ": the cost-to-go is " + std::to_string(nx_) + "x" + std::to_string(nx_) +
                          ", the scene has " + std::to_string(names.size()) + " states");
  }
  if (stateNames_.empty()) return;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (stateNames_[i] != names[i]) {
      throw TrajectoryError(source + ": state " + std::to_string(i + 1) + " of the cost-to-go is '" + stateNames_[i] +
                            "', the scene's is '" + names[i] + "' (a cost-to-go of another scene?)");
    }
  }
}

void CostToGo::evaluate(double t, Eigen::MatrixXd& S) const {
  if (size() == 0) throw std::logic_error("CostToGo::evaluate: empty");
  const double t0 = startTime(), t1 = endTime();
  const double slack = 1e-12 * std::max({1.0, std::abs(t0), std::abs(t1)});
  if (!(t >= t0 - slack && t <= t1 + slack)) {
    throw std::out_of_range("cost-to-go: t = " + formatStatusNumber(t) + " is outside [" + formatStatusNumber(t0) +
                            ", " + formatStatusNumber(t1) + "]");
  }
  t = std::clamp(t, t0, t1);
  S.resize(nx_, nx_);
  if (size() == 1) {
    S = S_[0];
    return;
  }
  // The interval [t_k, t_{k+1}] holding t (the last one for t = t_{N−1}).
  const double* begin = times_.data();
  const auto k = static_cast<Eigen::Index>(
      std::clamp<std::ptrdiff_t>(std::upper_bound(begin, begin + times_.size(), t) - begin - 1, 0, times_.size() - 2));
  const double s = (t - times_(k)) / (times_(k + 1) - times_(k));
  S = (1.0 - s) * S_[static_cast<std::size_t>(k)] + s * S_[static_cast<std::size_t>(k + 1)];
}

Eigen::MatrixXd CostToGo::evaluate(double t) const {
  Eigen::MatrixXd S;
  evaluate(t, S);
  return S;
}

double CostToGo::level(double t, const Eigen::VectorXd& dx) const {
  if (dx.size() != nx_) {
    throw std::invalid_argument("cost-to-go: dx has " + std::to_string(dx.size()) + " entries, expected " +
                                std::to_string(nx_));
  }
  return dx.dot(evaluate(t) * dx);
}

CostToGo CostToGo::readCsv(std::istream& in, const std::string& source) {
  std::string line;
  int lineNo = 0, nx = -1;
  std::vector<std::string> header;
  std::vector<double> times;
  std::vector<Eigen::MatrixXd> matrices;
  std::vector<std::string> names;
  while (std::getline(in, line)) {
    ++lineNo;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    const std::string at = source + ": line " + std::to_string(lineNo);
    if (line[0] == '#') {
      const std::string tag = "# trellis cost-to-go: nx=";
      if (line.rfind(tag, 0) == 0) {
        const std::string rest = line.substr(tag.size());
        int value = 0;
        const auto [end, error] = std::from_chars(rest.data(), rest.data() + rest.size(), value);
        if (error != std::errc() || value < 1) throw TrajectoryError(at + ": nx in the metadata line is not a positive integer");
        nx = value;
      }
      continue;
    }
    if (header.empty()) {
      if (nx < 1) throw TrajectoryError(at + ": expected the metadata line '# trellis cost-to-go: nx=<nx>' before the header");
      header = splitCommas(line);
      const std::size_t entries = static_cast<std::size_t>(nx) * (static_cast<std::size_t>(nx) + 1) / 2;
      if (header.size() != entries + 1) {
        throw TrajectoryError(at + " (header): " + std::to_string(header.size() - 1) + " columns after t, expected nx(nx+1)/2 = " +
                              std::to_string(entries) + " for nx=" + std::to_string(nx));
      }
      if (header[0] != "t") throw TrajectoryError(at + " (header), column 1: must be 't', got '" + header[0] + "'");
      // Names from the diagonal entries S[a|a]; every column must then be S[row|col] of them.
      std::size_t c = 1;
      for (int i = 0; i < nx; ++i) {
        const std::string& diag = header[c];
        if (diag.size() < 4 || diag.rfind("S[", 0) != 0 || diag.back() != ']' || diag.find('|') == std::string::npos) {
          throw TrajectoryError(at + " (header), column " + std::to_string(c + 1) + ": '" + diag + "' is not S[<state>|<state>]");
        }
        names.push_back(diag.substr(2, diag.find('|') - 2));
        c += static_cast<std::size_t>(nx - i);
      }
      c = 1;
      for (int i = 0; i < nx; ++i) {
        for (int j = i; j < nx; ++j, ++c) {
          const std::string expected = entryName(names, i, j);
          if (header[c] != expected) {
            throw TrajectoryError(at + " (header), column " + std::to_string(c + 1) + ": expected '" + expected +
                                  "', got '" + header[c] + "'");
          }
        }
      }
      continue;
    }
    const std::vector<std::string> cells = splitCommas(line);
    if (cells.size() != header.size()) {
      throw TrajectoryError(at + ": " + std::to_string(cells.size()) + " columns, the header has " + std::to_string(header.size()));
    }
    std::vector<double> values(cells.size());
    for (std::size_t c = 0; c < cells.size(); ++c) {
      const std::string& text = cells[c];
      const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), values[c]);
      if (text.empty() || error != std::errc() || end != text.data() + text.size() || !std::isfinite(values[c])) {
        throw TrajectoryError(at + ", column " + std::to_string(c + 1) + " (" + header[c] + "): '" + text +
                              "' is not a finite number");
      }
    }
    times.push_back(values[0]);
    Eigen::MatrixXd S(nx, nx);
    std::size_t c = 1;
    for (int i = 0; i < nx; ++i) {
      for (int j = i; j < nx; ++j, ++c) S(i, j) = S(j, i) = values[c];
    }
    matrices.push_back(std::move(S));
  }
  if (header.empty()) throw TrajectoryError(source + ": no header (not a cost-to-go file)");
  if (times.empty()) throw TrajectoryError(source + ": no data rows");
  try {
    CostToGo table(Eigen::Map<const Eigen::VectorXd>(times.data(), static_cast<Eigen::Index>(times.size())),
                   std::move(matrices));
    // Index names ("S[0|0]") are the unnamed form.
    bool indexed = true;
    for (int i = 0; i < nx; ++i) indexed = indexed && names[static_cast<std::size_t>(i)] == std::to_string(i);
    if (!indexed) table.setStateNames(names);
    return table;
  } catch (const TrajectoryError& e) {
    throw TrajectoryError(source + ": " + e.what());
  }
}

CostToGo CostToGo::readCsvFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw TrajectoryError(path + ": cannot open the cost-to-go file");
  return readCsv(in, path);
}

void CostToGo::writeCsv(std::ostream& out) const {
  if (size() == 0) throw TrajectoryError("cost-to-go: cannot write an empty table");
  const auto oldPrecision = out.precision(17);
  out << "# trellis cost-to-go: nx=" << nx_ << "\n";
  out << "t";
  for (int i = 0; i < nx_; ++i)
    for (int j = i; j < nx_; ++j) out << "," << entryName(stateNames_, i, j);
  out << "\n";
  for (int k = 0; k < size(); ++k) {
    out << times_(k);
    const Eigen::MatrixXd& S = S_[static_cast<std::size_t>(k)];
    for (int i = 0; i < nx_; ++i)
      for (int j = i; j < nx_; ++j) out << "," << S(i, j);
    out << "\n";
  }
  out.precision(oldPrecision);
}

void CostToGo::writeCsvFile(const std::string& path) const {
  std::ostringstream out;
  writeCsv(out);
  writeFileAtomically(path, out.str());
}

}  // namespace trellis
