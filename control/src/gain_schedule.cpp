// gain_schedule.cpp — validation, interpolation and CSV I/O of a tabulated gain K(t).
#include "trellis/control/gain_schedule.hpp"

#include "trellis/control/trajectory.hpp"

#include "numeric_csv.hpp"

#include "trellis/core/io.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <istream>
#include <ostream>
#include <sstream>
#include <stdexcept>

namespace trellis {
namespace {

std::string gainName(int i, int j) { return "K_" + std::to_string(i) + "_" + std::to_string(j); }

// Parses "K_<i>_<j>" (decimal, no sign); false for anything else.
bool parseGainName(const std::string& s, int& i, int& j) {
  if (s.size() < 5 || s[0] != 'K' || s[1] != '_') return false;
  const auto sep = s.find('_', 2);
  if (sep == std::string::npos) return false;
  auto parseIndex = [](const std::string& d, int& v) {
    if (d.empty() || d.size() > 9 ||
        !std::all_of(d.begin(), d.end(), [](unsigned char ch) { return std::isdigit(ch) != 0; }))
      return false;
    v = std::stoi(d);
    return true;
  };
  return parseIndex(s.substr(2, sep - 2), i) && parseIndex(s.substr(sep + 1), j);
}

}  // namespace

GainSchedule::GainSchedule(Eigen::VectorXd times, std::vector<Eigen::MatrixXd> gains)
    : times_(std::move(times)), gains_(std::move(gains)) {
  std::ostringstream m;
  if (times_.size() < 1) throw TrajectoryError("gain schedule: no times (need at least 1)");
  if (static_cast<Eigen::Index>(gains_.size()) != times_.size()) {
    m << "gain schedule: " << times_.size() << " times but " << gains_.size() << " gains";
    throw TrajectoryError(m.str());
  }
  nu_ = static_cast<int>(gains_[0].rows());
  nx_ = static_cast<int>(gains_[0].cols());
  if (nu_ < 1 || nx_ < 1) {
    m << "gain schedule: gain 0 is " << nu_ << "x" << nx_ << " (need at least 1x1)";
    throw TrajectoryError(m.str());
  }
  for (Eigen::Index k = 0; k < times_.size(); ++k) {
    if (!std::isfinite(times_(k))) {
      m << "gain schedule: time " << k << " is " << times_(k) << " (must be finite)";
      throw TrajectoryError(m.str());
    }
    if (k > 0 && !(times_(k) > times_(k - 1))) {
      m << "gain schedule: time " << k << " = " << times_(k) << " is not greater than time "
        << k - 1 << " = " << times_(k - 1) << " (times must increase strictly)";
      throw TrajectoryError(m.str());
    }
    const Eigen::MatrixXd& K = gains_[k];
    if (K.rows() != nu_ || K.cols() != nx_) {
      m << "gain schedule: gain " << k << " is " << K.rows() << "x" << K.cols() << ", expected "
        << nu_ << "x" << nx_ << " (the size of gain 0)";
      throw TrajectoryError(m.str());
    }
    for (Eigen::Index j = 0; j < nx_; ++j) {
      for (Eigen::Index i = 0; i < nu_; ++i) {
        if (!std::isfinite(K(i, j))) {
          m << "gain schedule: gain " << k << " (t = " << times_(k) << "), entry (" << i << "," << j
            << ") is " << K(i, j) << " (must be finite)";
          throw TrajectoryError(m.str());
        }
      }
    }
  }
}

double GainSchedule::startTime() const {
  if (size() == 0) throw std::logic_error("gain schedule: empty");
  return times_(0);
}

double GainSchedule::endTime() const {
  if (size() == 0) throw std::logic_error("gain schedule: empty");
  return times_(times_.size() - 1);
}

void GainSchedule::evaluate(double t, Eigen::MatrixXd& K) const {
  if (size() == 0) throw std::logic_error("gain schedule: evaluate on an empty schedule");
  const double t0 = startTime(), t1 = endTime();
  const double slack = 1e-12 * std::max({1.0, std::abs(t0), std::abs(t1)});
  if (!(t >= t0 - slack && t <= t1 + slack)) {
    std::ostringstream m;
    m << "gain schedule: time " << t << " is outside [" << t0 << ", " << t1 << "]";
    throw std::out_of_range(m.str());
  }
  if (K.rows() != nu_ || K.cols() != nx_) K.resize(nu_, nx_);
  if (size() == 1) {
    K = gains_[0];
    return;
  }
  t = std::clamp(t, t0, t1);
  const double* begin = times_.data();
  const int k = std::min(static_cast<int>(std::upper_bound(begin, begin + size(), t) - begin) - 1,
                         size() - 2);
  const double s = (t - times_(k)) / (times_(k + 1) - times_(k));
  K = (1.0 - s) * gains_[k] + s * gains_[k + 1];
}

Eigen::MatrixXd GainSchedule::evaluate(double t) const {
  Eigen::MatrixXd K;
  evaluate(t, K);
  return K;
}

GainSchedule GainSchedule::sample(const std::function<Eigen::MatrixXd(double)>& gain,
                                  const Eigen::VectorXd& times) {
  if (!gain) throw std::invalid_argument("GainSchedule::sample: empty gain function");
  std::vector<Eigen::MatrixXd> gains;
  gains.reserve(static_cast<std::size_t>(times.size()));
  for (Eigen::Index k = 0; k < times.size(); ++k) gains.push_back(gain(times(k)));
  return GainSchedule(times, std::move(gains));
}

GainSchedule GainSchedule::readCsv(std::istream& in, const std::string& source) {
  int m = 0, nx = 0;
  const detail::NumericCsv csv = detail::readNumericCsv(
      in, source, [&](const std::vector<std::string>& header, int lineNo) {
        const std::string hat = source + ": header (line " + std::to_string(lineNo) + ")";
        if (header[0] != "t") {
          throw TrajectoryError(hat + ", column 1: must be 't', got '" + header[0] + "'");
        }
        const int ncols = static_cast<int>(header.size()) - 1;
        if (ncols < 1) throw TrajectoryError(hat + ": no gain columns after 't' (expected K_0_0, ...)");
        // nx = the number of leading K_0_j columns; then every column must be K_{c / nx}_{c % nx}.
        for (int c = 0; c < ncols; ++c) {
          int i = -1, j = -1;
          if (!parseGainName(header[1 + c], i, j) || i != 0 || j != c) break;
          ++nx;
        }
        if (nx == 0) {
          throw TrajectoryError(hat + ", column 2 ('" + header[1] + "'): expected 'K_0_0'");
        }
        m = (ncols + nx - 1) / nx;
        for (int c = 0; c < ncols; ++c) {
          const std::string want = gainName(c / nx, c % nx);
          if (header[1 + c] != want) {
            throw TrajectoryError(hat + ", column " + std::to_string(c + 2) + " ('" + header[1 + c] +
                                  "'): expected '" + want + "' (row-major K_i_j, " +
                                  std::to_string(nx) + " state columns from the K_0_j names)");
          }
        }
        if (ncols != m * nx) {
          throw TrajectoryError(hat + ": " + std::to_string(ncols) +
                                " gain columns is not a multiple of " + std::to_string(nx) +
                                " (missing '" + gainName(m - 1, ncols % nx) + "' onwards)");
        }
      });
  std::vector<double> times;
  std::vector<Eigen::MatrixXd> gains;
  for (const std::vector<double>& values : csv.rows) {
    times.push_back(values[0]);
    // Row-major K_i_j after t: the m×nx gain of this row.
    gains.push_back(Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
        values.data() + 1, m, nx));
  }
  return GainSchedule(
      Eigen::Map<const Eigen::VectorXd>(times.data(), static_cast<Eigen::Index>(times.size())),
      std::move(gains));
}

GainSchedule GainSchedule::readCsvFile(const std::string& path) {
  std::ifstream in;
  detail::openCsvFile(in, path, "gain schedule");
  return readCsv(in, path);
}

void GainSchedule::writeCsv(std::ostream& out) const {
  if (size() == 0) throw TrajectoryError("gain schedule: cannot write an empty schedule");
  out << "t";
  for (int i = 0; i < nu_; ++i) {
    for (int j = 0; j < nx_; ++j) out << "," << gainName(i, j);
  }
  out << "\n";
  const auto oldPrecision = out.precision(17);
  for (int k = 0; k < size(); ++k) {
    out << times_(k);
    for (int i = 0; i < nu_; ++i) {
      for (int j = 0; j < nx_; ++j) out << "," << gains_[k](i, j);
    }
    out << "\n";
  }
  out.precision(oldPrecision);
}

void GainSchedule::writeCsvFile(const std::string& path) const {
  std::ostringstream out;
  writeCsv(out);
  writeFileAtomically(path, out.str());  // complete or absent; FileError names path and OS error
}

}  // namespace trellis
