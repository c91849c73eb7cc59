// gain_schedule.cpp — validation, interpolation and CSV I/O of a tabulated gain K(t).
#include "trellis/core/gain_schedule.hpp"

#include "trellis/core/model.hpp"
#include "trellis/core/status.hpp"
#include "trellis/core/trajectory.hpp"

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

// t within [t0, t1] up to a slack of 1e-12 of the larger end's size (a time computed elsewhere
// may round just outside), which it returns; throws std::out_of_range naming t and the span.
double requireWithin(double t, double t0, double t1) {
  const double slack = 1e-12 * std::max({1.0, std::abs(t0), std::abs(t1)});
  if (t >= t0 - slack && t <= t1 + slack) return slack;
  std::ostringstream m;
  m << "gain schedule: time " << t << " is outside [" << t0 << ", " << t1 << "]";
  throw std::out_of_range(m.str());
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
  requireWithin(t, t0, t1);
  if (K.rows() != nu_ || K.cols() != nx_) K.resize(nu_, nx_);
  if (size() == 1) {
    K = gains_[0];
    return;
  }
  t = std::clamp(t, t0, t1);
  const double* begin = times_.data();
  const int k = std::min(static_cast<int>(std::upper_bound(begin, begin + size(), t) - begin) - 1,
                         size() - 2);
  const double h = times_(k + 1) - times_(k);
  const double s = (t - times_(k)) / h;
  if (interpolation_ == GainInterpolation::kCubic) {
    const double s2 = s * s, s3 = s2 * s;
    K = (2 * s3 - 3 * s2 + 1) * gains_[k] + ((s3 - 2 * s2 + s) * h) * slopes_[k] +
        (-2 * s3 + 3 * s2) * gains_[k + 1] + ((s3 - s2) * h) * slopes_[k + 1];
  } else {
    K = (1.0 - s) * gains_[k] + s * gains_[k + 1];
  }
}

void GainSchedule::setInterpolation(GainInterpolation rule) {
  interpolation_ = rule;
  slopes_.clear();
  if (rule != GainInterpolation::kCubic) return;
  const int N = size();
  slopes_.assign(static_cast<std::size_t>(N), Eigen::MatrixXd::Zero(nu_, nx_));
  if (N < 2) return;
  // Secants Δ_j and spacings h_j; slopes from the parabola through three neighbouring rows.
  auto secant = [&](int j) -> Eigen::MatrixXd { return (gains_[j + 1] - gains_[j]) / (times_(j + 1) - times_(j)); };
  auto spacing = [&](int j) { return times_(j + 1) - times_(j); };
  if (N == 2) {
    slopes_[0] = slopes_[1] = secant(0);
    return;
  }
  for (int k = 1; k + 1 < N; ++k) {
    const double hl = spacing(k - 1), hr = spacing(k);
    slopes_[k] = (hr * secant(k - 1) + hl * secant(k)) / (hl + hr);
  }
  {
    const double h0 = spacing(0), h1 = spacing(1);
    const Eigen::MatrixXd c = (secant(1) - secant(0)) / (h0 + h1);
    slopes_[0] = secant(0) - h0 * c;
  }
  {
    const double ha = spacing(N - 3), hb = spacing(N - 2);
    const Eigen::MatrixXd c = (secant(N - 2) - secant(N - 3)) / (ha + hb);
    slopes_[N - 1] = secant(N - 2) + hb * c;
  }
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

void GainSchedule::setSampleRate(double hz) {
  if (!(hz >= 0.0) || !std::isfinite(hz)) {
    throw std::invalid_argument("gain schedule: sample rate " + std::to_string(hz) + " (must be finite and >= 0)");
  }
  // A held feed-forward belongs to the rate it was computed for.
  if (hz != sampleRate_) feedforward_.clear();
  sampleRate_ = hz;
}

std::vector<std::string> GainSchedule::stateNames(const std::vector<std::string>& configNames) {
  std::vector<std::string> names = configNames;
  for (const std::string& c : configNames) names.push_back("d" + c);
  return names;
}

namespace {
// K[<input>|<state>]: input names hold no '|' (setColumnNames), so the first '|' splits.
std::vector<std::string> namedColumns(const std::vector<std::string>& inputs,
                                      const std::vector<std::string>& states) {
  std::vector<std::string> cols;
  for (const std::string& in : inputs) {
    for (const std::string& st : states) cols.push_back("K[" + in + "|" + st + "]");
  }
  return cols;
}
// The older form, read only: K_<input>_<state>.
std::vector<std::string> olderNamedColumns(const std::vector<std::string>& inputs,
                                           const std::vector<std::string>& states) {
  std::vector<std::string> cols;
  for (const std::string& in : inputs) {
    for (const std::string& st : states) cols.push_back("K_" + in + "_" + st);
  }
  return cols;
}
std::vector<std::string> feedforwardColumns(const std::vector<std::string>& inputs) {
  std::vector<std::string> cols;
  for (const std::string& in : inputs) cols.push_back("uff[" + in + "]");
  return cols;
}
std::string feedforwardIndexName(int i) { return "uff_" + std::to_string(i); }
}  // namespace

void GainSchedule::setColumnNames(const std::vector<std::string>& inputNames,
                                  const std::vector<std::string>& stateNames) {
  if (static_cast<int>(inputNames.size()) != nu_ || static_cast<int>(stateNames.size()) != nx_) {
    throw std::invalid_argument("gain schedule: " + std::to_string(inputNames.size()) + " input and " +
                                std::to_string(stateNames.size()) + " state names for K of size " +
                                std::to_string(nu_) + "x" + std::to_string(nx_));
  }
  for (const std::string& in : inputNames) {
    if (in.find('|') != std::string::npos) {
      throw std::invalid_argument("gain schedule: input name '" + in +
                                  "' contains '|', the separator of the gain columns K[<input>|<state>] "
                                  "(the column would not split back into input and state)");
    }
  }
  columnNames_ = namedColumns(inputNames, stateNames);
  feedforwardNames_ = feedforwardColumns(inputNames);
}

void GainSchedule::setFeedforward(std::vector<Eigen::VectorXd> uff) {
  if (!isSampled()) {
    throw std::invalid_argument("gain schedule: a held feed-forward needs sampled gains (set the sample rate first)");
  }
  if (static_cast<int>(uff.size()) != size()) {
    throw std::invalid_argument("gain schedule: " + std::to_string(uff.size()) + " feed-forward rows for " +
                                std::to_string(size()) + " gain rows");
  }
  for (std::size_t k = 0; k < uff.size(); ++k) {
    if (uff[k].size() != nu_) {
      throw std::invalid_argument("gain schedule: feed-forward row " + std::to_string(k) + " has " +
                                  std::to_string(uff[k].size()) + " entries, expected m = " + std::to_string(nu_));
    }
    for (int i = 0; i < nu_; ++i) {
      if (!std::isfinite(uff[k](i))) {
        std::ostringstream m;
        m << "gain schedule: feed-forward row " << k << " (t = " << times_(static_cast<Eigen::Index>(k))
          << "), entry " << i << " is " << uff[k](i) << " (must be finite)";
        throw std::invalid_argument(m.str());
      }
    }
  }
  feedforward_ = std::move(uff);
}

int GainSchedule::rowAt(double t) const {
  if (size() == 0) throw std::logic_error("gain schedule: rowAt on an empty schedule");
  const double t0 = startTime(), t1 = endTime();
  const double slack = requireWithin(t, t0, t1);
  // A sample time computed as t0 + k/f elsewhere may differ from times_(k) by rounding: the same
  // 1e-9-of-a-period tolerance as the sample grid (sampleTimes) and checkGainScheduleApplies.
  const double tol = sampleRate_ > 0.0 ? 1e-9 / sampleRate_ : slack;
  const double* begin = times_.data();
  const int k = static_cast<int>(std::upper_bound(begin, begin + size(), t + tol) - begin) - 1;
  return std::clamp(k, 0, size() - 1);
}

void GainSchedule::evaluateFeedforward(double t, Eigen::VectorXd& u) const {
  if (!hasFeedforward()) throw std::logic_error("gain schedule: no feed-forward to evaluate");
  u = feedforward_[static_cast<std::size_t>(rowAt(t))];
}

void GainSchedule::checkNames(const std::vector<std::string>& inputNames,
                              const std::vector<std::string>& stateNames, const std::string& source) const {
  if (static_cast<int>(inputNames.size()) != nu_ || static_cast<int>(stateNames.size()) != nx_) {
    throw TrajectoryError(source + ": K is " + std::to_string(nu_) + " x " + std::to_string(nx_) +
                          ", but the scene needs m x 2n = " + std::to_string(inputNames.size()) + " x " +
                          std::to_string(stateNames.size()));
  }
  if (columnNames_.empty()) return;
  // New form, or (a file written before it) the older K_<input>_<state> in every column.
  const bool older = !columnNames_.empty() && columnNames_[0].rfind("K[", 0) != 0;
  const std::vector<std::string> want =
      older ? olderNamedColumns(inputNames, stateNames) : namedColumns(inputNames, stateNames);
  for (std::size_t c = 0; c < want.size(); ++c) {
    if (columnNames_[c] != want[c]) {
      throw TrajectoryError(source + ": column " + std::to_string(c + 2) + " is '" + columnNames_[c] +
                            "', but the scene's gain column there is '" + want[c] +
                            "' (a gain file for another scene?)");
    }
  }
  if (feedforwardNames_.empty()) return;
  const std::vector<std::string> wantFf = feedforwardColumns(inputNames);
  for (std::size_t i = 0; i < wantFf.size(); ++i) {
    if (feedforwardNames_[i] != wantFf[i]) {
      throw TrajectoryError(source + ": column " + std::to_string(want.size() + i + 2) + " is '" +
                            feedforwardNames_[i] + "', but the scene's feed-forward column there is '" +
                            wantFf[i] + "' (a gain file for another scene?)");
    }
  }
}

namespace {
// "# trellis gain schedule: m=1 nx=4 sample_rate_hz=100" → m, nx, rate; false if not that line.
bool parseMetadata(const std::string& comment, int& m, int& nx, double& rate, bool& continuous,
                   std::string& interpolation) {
  const std::string key = "trellis gain schedule:";
  const auto at = comment.find(key);
  if (at == std::string::npos) return false;
  std::istringstream ss(comment.substr(at + key.size()));
  std::string item;
  bool haveM = false, haveNx = false, haveRate = false;
  continuous = false;
  while (ss >> item) {
    const auto eq = item.find('=');
    const std::string name = item.substr(0, eq == std::string::npos ? item.size() : eq);
    const std::string value = eq == std::string::npos ? "" : item.substr(eq + 1);
    char* end = nullptr;
    if (name == "m" || name == "nx") {
      const long v = std::strtol(value.c_str(), &end, 10);
      if (value.empty() || *end != '\0' || v < 1 || v > 100000) return false;
      (name == "m" ? m : nx) = static_cast<int>(v);
      (name == "m" ? haveM : haveNx) = true;
    } else if (name == "sample_rate_hz") {
      rate = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0' || !std::isfinite(rate) || !(rate > 0.0)) return false;
      haveRate = true;
    } else if (name == "continuous") {
      continuous = true;
    } else if (name == "interpolation") {
      interpolation = value;
    } else if (item == "(" || item.front() == '(') {
      break;  // free text follows
    }
  }
  return haveM && haveNx && (haveRate || continuous);
}
}  // namespace

GainSchedule GainSchedule::readCsv(std::istream& in, const std::string& source) {
  int m = 0, nx = 0;
  double rate = 0.0;
  bool haveMetadata = false;
  std::string interpolation;
  GainInterpolation interpolationRule = GainInterpolation::kLinear;
  std::vector<std::string> names, ffNames;
  bool withFeedforward = false;
  const detail::NumericCsv csv = detail::readNumericCsv(
      in, source, [&](const std::vector<std::string>& comments, const std::vector<std::string>& header, int lineNo) {
        // The metadata line ('# trellis gain schedule: m=.. nx=.. ...') is among the comments.
        for (const std::string& comment : comments) {
          int mm = 0, nn = 0;
          double r = 0.0;
          bool cont = false;
          std::string rule;
          if (parseMetadata(comment, mm, nn, r, cont, rule)) {
            haveMetadata = true;
            m = mm;
            nx = nn;
            rate = cont ? 0.0 : r;
            interpolation = rule;
          }
        }
        const std::string hat = source + ": header (line " + std::to_string(lineNo) + ")";
        if (!interpolation.empty()) {
          try {
            interpolationRule = parseEnum<GainInterpolation>(interpolation, "interpolation");
          } catch (const std::invalid_argument&) {
            throw TrajectoryError(source + ": the metadata line before " + "line " + std::to_string(lineNo) +
                                  ": interpolation=" + interpolation + " (expected one of " +
                                  enumNameList<GainInterpolation>() + ")");
          }
        }
        if (header[0] != "t") {
          throw TrajectoryError(hat + ", column 1: must be 't', got '" + header[0] + "'");
        }
        const int ncols = static_cast<int>(header.size()) - 1;
        if (ncols < 1) throw TrajectoryError(hat + ": no gain columns after 't' (expected K_0_0, ...)");
        if (haveMetadata) {
          const long long nK = static_cast<long long>(m) * nx;
          // m·nx gain columns, then (sampled gains with a held feed-forward) m uff columns.
          withFeedforward = rate > 0.0 && ncols == nK + m;
          if (ncols != nK && !withFeedforward) {
            throw TrajectoryError(hat + ": " + std::to_string(ncols) + " gain columns, but the metadata line says m=" +
                                  std::to_string(m) + " nx=" + std::to_string(nx) + " (" + std::to_string(nK) +
                                  " columns" + (rate > 0.0 ? ", or " + std::to_string(nK + m) + " with the feed-forward" : "") +
                                  ")");
          }
          const bool newForm = header[1].rfind("K[", 0) == 0;
          for (int c = 0; c < nK; ++c) {
            const std::string& h = header[1 + c];
            const bool fits = newForm ? h.rfind("K[", 0) == 0 && h.back() == ']' && h.find('|') != std::string::npos
                                      : h.rfind("K_", 0) == 0;
            if (!fits) {
              throw TrajectoryError(hat + ", column " + std::to_string(c + 2) + " ('" + h +
                                    "'): expected a gain name " +
                                    (newForm ? "K[<input>|<state>] (as column 2)" : "K_<input>_<state> (as column 2)"));
            }
          }
          for (int i = 0; withFeedforward && i < m; ++i) {
            const std::string& h = header[1 + nK + i];
            if (h.rfind("uff", 0) != 0) {
              throw TrajectoryError(hat + ", column " + std::to_string(nK + i + 2) + " ('" + h +
                                    "'): expected a feed-forward name uff[<input>] (the last m = " +
                                    std::to_string(m) + " columns)");
            }
          }
          // Index names K_i_j (uff_i) are the unnamed layout; anything else is kept as column names.
          bool indexed = true;
          for (int c = 0; c < nK && indexed; ++c) indexed = header[1 + c] == gainName(c / nx, c % nx);
          for (int i = 0; withFeedforward && i < m && indexed; ++i) indexed = header[1 + nK + i] == feedforwardIndexName(i);
          if (!indexed) {
            names.assign(header.begin() + 1, header.begin() + 1 + nK);
            if (withFeedforward) ffNames.assign(header.begin() + 1 + nK, header.end());
          }
          return;
        }
        // No metadata line (the older layout): nx = the number of leading K_0_j columns; then every
        // column must be K_{c / nx}_{c % nx}.
        for (int c = 0; c < ncols; ++c) {
          int i = -1, j = -1;
          if (!parseGainName(header[1 + c], i, j) || i != 0 || j != c) break;
          ++nx;
        }
        if (nx == 0) {
          throw TrajectoryError(hat + ", column 2 ('" + header[1] +
                                "'): expected 'K_0_0' (files with named columns K_<input>_<state> need the "
                                "'# trellis gain schedule: m=.. nx=..' line that trellis gains writes)");
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
  std::vector<Eigen::VectorXd> feedforward;
  for (const std::vector<double>& values : csv.rows) {
    times.push_back(values[0]);
    // Row-major K_i_j after t: the m×nx gain of this row.
    gains.push_back(Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
        values.data() + 1, m, nx));
    if (withFeedforward) feedforward.push_back(Eigen::Map<const Eigen::VectorXd>(values.data() + 1 + m * nx, m));
  }
  GainSchedule schedule(
      Eigen::Map<const Eigen::VectorXd>(times.data(), static_cast<Eigen::Index>(times.size())),
      std::move(gains));
  schedule.sampleRate_ = rate;
  schedule.columnNames_ = std::move(names);
  schedule.feedforwardNames_ = std::move(ffNames);
  if (withFeedforward) schedule.feedforward_ = std::move(feedforward);  // finite: the reader checked
  if (interpolationRule == GainInterpolation::kCubic) schedule.setInterpolation(interpolationRule);
  return schedule;
}

GainSchedule GainSchedule::readCsvFile(const std::string& path) {
  std::ifstream in;
  detail::openCsvFile(in, path, "gain schedule");
  return readCsv(in, path);
}

void GainSchedule::writeCsv(std::ostream& out) const {
  if (size() == 0) throw TrajectoryError("gain schedule: cannot write an empty schedule");
  const auto oldPrecision = out.precision(17);
  out << "# trellis gain schedule: m=" << nu_ << " nx=" << nx_;
  if (sampleRate_ > 0.0) {
    out << " sample_rate_hz=" << sampleRate_ << " (zero-order-hold gains: at t_k = t0 + k/" << sampleRate_
        << " apply u_k = " << (hasFeedforward() ? "uff_k" : "u_ref(t_k)")
        << " - K_k (x(t_k) - x_ref(t_k)) and hold it until the next sample)\n";
  } else if (interpolation_ == GainInterpolation::kCubic) {
    out << " continuous interpolation=cubic (K(t) cubic Hermite between rows, slopes of the parabola "
           "through neighbouring rows)\n";
  } else {
    out << " continuous (K(t) linear between rows)\n";
  }
  out << "t";
  for (int i = 0; i < nu_; ++i) {
    for (int j = 0; j < nx_; ++j) {
      out << "," << (columnNames_.empty() ? gainName(i, j) : columnNames_[static_cast<std::size_t>(i * nx_ + j)]);
    }
  }
  for (int i = 0; hasFeedforward() && i < nu_; ++i) {
    out << "," << (feedforwardNames_.empty() ? feedforwardIndexName(i) : feedforwardNames_[static_cast<std::size_t>(i)]);
  }
  out << "\n";
  for (int k = 0; k < size(); ++k) {
    out << times_(k);
    for (int i = 0; i < nu_; ++i) {
      for (int j = 0; j < nx_; ++j) out << "," << gains_[k](i, j);
    }
    for (int i = 0; hasFeedforward() && i < nu_; ++i) out << "," << feedforward_[static_cast<std::size_t>(k)](i);
    out << "\n";
  }
  out.precision(oldPrecision);
}

void GainSchedule::writeCsvFile(const std::string& path) const {
  std::ostringstream out;
  writeCsv(out);
  writeFileAtomically(path, out.str());  // complete or absent; FileError names path and OS error
}

std::string checkGainScheduleApplies(const GainSchedule& gains, const Model& model,
                                     const Trajectory& reference, double sampleRate,
                                     const std::string& source) {
  const auto num = [](double v) { return formatStatusNumber(v); };
  gains.checkNames(model.inputNames(), GainSchedule::stateNames(model.configNames()), source);
  if (gains.size() == 0) throw TrajectoryError(source + ": the gain schedule is empty");
  if (reference.size() == 0) throw TrajectoryError(source + ": the reference is empty");
  if (!(sampleRate >= 0.0) || !std::isfinite(sampleRate)) {
    throw std::invalid_argument("checkGainScheduleApplies: sampleRate = " + num(sampleRate) +
                                " must be >= 0 and finite");
  }
  std::string note;
  // Discrete gains are for one rate only; continuous gains at a rate are an approximation.
  if (gains.isSampled()) {
    const double rate = gains.sampleRate();
    if (sampleRate == 0.0) {
      throw TrajectoryError(source + ": zero-order-hold gains for a controller sampling at " + num(rate) +
                            " Hz cannot be applied continuously: sample at " + num(rate) + " Hz");
    }
    if (std::abs(sampleRate - rate) > 1e-12 * rate) {
      throw TrajectoryError(source + ": zero-order-hold gains for " + num(rate) + " Hz cannot be applied at " +
                            num(sampleRate) + " Hz (compute them for that rate)");
    }
    if (std::abs(gains.startTime() - reference.startTime()) > 1e-9 / rate) {
      throw TrajectoryError(source + ": the sampled gains start at t = " + num(gains.startTime()) +
                            ", but the reference starts at t = " + num(reference.startTime()) +
                            " (the samples would not line up)");
    }
  } else if (sampleRate > 0.0) {
    note = source + " holds continuous gains K(t); at " + num(sampleRate) +
           " Hz they are only sampled (not designed for a sampled controller)";
  }
  // The same relative slack as GainSchedule::evaluate.
  const double slack =
      1e-12 * std::max({1.0, std::abs(reference.startTime()), std::abs(reference.endTime())});
  if (gains.startTime() > reference.startTime() + slack || gains.endTime() < reference.endTime() - slack) {
    throw TrajectoryError(source + ": the gains cover [" + num(gains.startTime()) + ", " + num(gains.endTime()) +
                          "], but the reference spans [" + num(reference.startTime()) + ", " +
                          num(reference.endTime()) + "]");
  }
  return note;
}

}  // namespace trellis
