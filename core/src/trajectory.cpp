// trajectory.cpp — validation, CSV I/O and Hermite interpolation of a nominal trajectory.
#include "trellis/core/trajectory.hpp"

#include "numeric_csv.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/io.hpp"
#include "trellis/core/model.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <istream>
#include <limits>
#include <ostream>
#include <sstream>

namespace trellis {
namespace {

// The name of an input-derivative column: "rate_" + the input's name (file comment).
const std::string kRatePrefix = "rate_";

bool isRateColumn(const std::string& name) { return name.rfind(kRatePrefix, 0) == 0; }

// The prefix of a constraint-force column (file comment): written for people and plots, skipped
// by the reader.
const std::string kForcePrefix = "lambda_";

bool isForceColumn(const std::string& name) { return name.rfind(kForcePrefix, 0) == 0; }

std::vector<std::string> columnNames(const std::vector<std::string>& configs,
                                     const std::vector<std::string>& inputs, bool rates = false) {
  std::vector<std::string> names{"t"};
  for (const auto& c : configs) names.push_back(c);
  for (const auto& c : configs) names.push_back("d" + c);
  for (const auto& u : inputs) names.push_back(u);
  if (rates) {
    for (const auto& u : inputs) names.push_back(kRatePrefix + u);
  }
  return names;
}

// Row numbering in messages: data rows from 1 (row 1 is the first knot).
std::string where(int row, int col, const std::vector<std::string>& names) {
  std::ostringstream m;
  m << "row " << row << ", column " << col + 1;
  if (col >= 0 && col < static_cast<int>(names.size())) m << " ('" << names[col] << "')";
  return m.str();
}

}  // namespace

Trajectory::Trajectory(std::vector<std::string> configNames, std::vector<std::string> inputNames,
                       Eigen::VectorXd times, Eigen::MatrixXd states, Eigen::MatrixXd inputs)
    : configNames_(std::move(configNames)),
      inputNames_(std::move(inputNames)),
      times_(std::move(times)),
      states_(std::move(states)),
      inputs_(std::move(inputs)) {
  const Eigen::Index n = nq(), m = nu(), N = times_.size();
  std::ostringstream err;
  if (N < 1) throw TrajectoryError("trajectory: no knots (need at least 1 row)");
  if (states_.rows() != 2 * n || states_.cols() != N) {
    err << "trajectory: states must be " << 2 * n << "x" << N << " (2n x knots), got "
        << states_.rows() << "x" << states_.cols();
    throw TrajectoryError(err.str());
  }
  if (inputs_.cols() == 0 && m == 0) inputs_.resize(0, N);
  if (inputs_.rows() != m || inputs_.cols() != N) {
    err << "trajectory: inputs must be " << m << "x" << N << " (m x knots), got " << inputs_.rows()
        << "x" << inputs_.cols();
    throw TrajectoryError(err.str());
  }
  const auto names = columnNames(configNames_, inputNames_);
  for (Eigen::Index k = 0; k < N; ++k) {
    const int row = static_cast<int>(k) + 1;
    if (!std::isfinite(times_(k))) {
      throw TrajectoryError("trajectory: " + where(row, 0, names) + ": time is not finite");
    }
    if (k > 0 && !(times_(k) > times_(k - 1))) {
      err << "trajectory: " << where(row, 0, names) << ": time " << times_(k)
          << " is not greater than the previous time " << times_(k - 1)
          << " (times must increase strictly)";
      throw TrajectoryError(err.str());
    }
    for (Eigen::Index i = 0; i < 2 * n; ++i) {
      if (!std::isfinite(states_(i, k))) {
        err << "trajectory: " << where(row, static_cast<int>(1 + i), names) << ": value "
            << states_(i, k) << " is not finite";
        throw TrajectoryError(err.str());
      }
    }
    for (Eigen::Index i = 0; i < m; ++i) {
      if (!std::isfinite(inputs_(i, k))) {
        err << "trajectory: " << where(row, static_cast<int>(1 + 2 * n + i), names) << ": value "
            << inputs_(i, k) << " is not finite";
        throw TrajectoryError(err.str());
      }
    }
  }
}

void Trajectory::checkCompatible(const Model& model) const {
  auto mismatch = [](const char* what, const std::vector<std::string>& got,
                     const std::vector<std::string>& want) {
    std::ostringstream m;
    m << "trajectory: " << what << " names do not match the model: trajectory has " << got.size()
      << " (";
    for (std::size_t i = 0; i < got.size(); ++i) m << (i ? "," : "") << got[i];
    m << "), model has " << want.size() << " (";
    for (std::size_t i = 0; i < want.size(); ++i) m << (i ? "," : "") << want[i];
    m << ")";
    throw TrajectoryError(m.str());
  };
  if (configNames_ != model.configNames()) mismatch("configuration", configNames_, model.configNames());
  if (inputNames_ != model.inputNames()) mismatch("input", inputNames_, model.inputNames());
}

DynamicsStatus Trajectory::tryComputeStateDerivatives(const Model& model, Data& data) {
  checkCompatible(model);
  const int n = nq();
  Eigen::MatrixXd xd(2 * n, size());
  Eigen::VectorXd q(n), dq(n), u(nu());
  for (int k = 0; k < size(); ++k) {
    q = states_.col(k).head(n);
    dq = states_.col(k).tail(n);
    u = inputs_.col(k);
    DynamicsStatus st = computeDynamics(model, data, q, dq, u);
    if (st.ok() && !data.qdd.allFinite()) st.set(DynamicsCode::kNonFinite, "q'' is not finite");
    if (!st.ok()) {
      st.t = times_(k);
      st.index = k;
      return st;
    }
    xd.col(k).head(n) = dq;
    xd.col(k).tail(n) = data.qdd;
  }
  stateDerivatives_ = std::move(xd);
  return {};
}

void Trajectory::computeStateDerivatives(const Model& model, Data& data) {
  const DynamicsStatus st = tryComputeStateDerivatives(model, data);
  if (!st.ok()) {
    std::ostringstream m;
    m << "trajectory: dynamics failed at knot " << st.index + 1 << " (t = " << st.t << "): " << st.message;
    throw TrajectoryError(m.str());
  }
}

void Trajectory::setStateDerivatives(Eigen::MatrixXd stateDerivatives) {
  if (stateDerivatives.rows() != nx() || stateDerivatives.cols() != size()) {
    std::ostringstream m;
    m << "trajectory: state derivatives must be " << nx() << "x" << size() << ", got "
      << stateDerivatives.rows() << "x" << stateDerivatives.cols();
    throw TrajectoryError(m.str());
  }
  if (!stateDerivatives.allFinite()) throw TrajectoryError("trajectory: state derivatives not finite");
  stateDerivatives_ = std::move(stateDerivatives);
}

void Trajectory::setInputDerivatives(Eigen::MatrixXd inputDerivatives) {
  if (inputDerivatives.rows() != nu() || inputDerivatives.cols() != size()) {
    std::ostringstream m;
    m << "trajectory: input derivatives must be " << nu() << "x" << size() << " (m x knots), got "
      << inputDerivatives.rows() << "x" << inputDerivatives.cols();
    throw TrajectoryError(m.str());
  }
  for (Eigen::Index k = 0; k < inputDerivatives.cols(); ++k) {
    for (Eigen::Index i = 0; i < inputDerivatives.rows(); ++i) {
      if (!std::isfinite(inputDerivatives(i, k))) {
        std::ostringstream m;
        m << "trajectory: input derivative of '" << inputNames_[static_cast<std::size_t>(i)] << "' at knot "
          << k + 1 << " (t = " << times_(k) << ") is " << inputDerivatives(i, k) << " (must be finite)";
        throw TrajectoryError(m.str());
      }
    }
  }
  inputDerivatives_ = std::move(inputDerivatives);
}

int Trajectory::intervalIndex(double& t) const {
  const double t0 = startTime(), t1 = endTime();
  const double slack = 1e-12 * std::max(1.0, std::max(std::abs(t0), std::abs(t1)));
  if (!(t >= t0 - slack && t <= t1 + slack)) {
    std::ostringstream m;
    m << "trajectory: time " << t << " is outside [" << t0 << ", " << t1 << "]";
    throw std::out_of_range(m.str());
  }
  t = std::clamp(t, t0, t1);
  if (size() == 1) return 0;
  const double* begin = times_.data();
  const double* it = std::upper_bound(begin, begin + size(), t);
  const int k = static_cast<int>(it - begin) - 1;
  return std::min(k, size() - 2);
}

template <bool kWithDerivative>
void Trajectory::interpolate(double t, Eigen::VectorXd& x, Eigen::VectorXd& u, Eigen::VectorXd* xdot) const {
  if (!hasStateDerivatives()) {
    throw std::logic_error(
        "trajectory: evaluate needs state derivatives (computeStateDerivatives or "
        "setStateDerivatives)");
  }
  const int k = intervalIndex(t);
  if (x.size() != nx()) x.resize(nx());
  if (u.size() != nu()) u.resize(nu());
  if constexpr (kWithDerivative) {
    if (xdot->size() != nx()) xdot->resize(nx());
  }
  if (size() == 1) {
    x = states_.col(0);
    u = inputs_.col(0);
    if constexpr (kWithDerivative) *xdot = stateDerivatives_.col(0);
    return;
  }
  // Cubic Hermite basis on s = (t − t_k)/h ∈ [0, 1]: p(s) = h00 p_k + h10 h ṗ_k + h01 p_{k+1} +
  // h11 h ṗ_{k+1}; dp/dt = (h00' p_k + h01' p_{k+1}) / h + h10' ṗ_k + h11' ṗ_{k+1}.
  const double h = times_(k + 1) - times_(k);
  const double s = (t - times_(k)) / h;
  const double s2 = s * s, s3 = s2 * s;
  const double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s;
  const double h01 = -2 * s3 + 3 * s2, h11 = s3 - s2;
  x = h00 * states_.col(k) + (h10 * h) * stateDerivatives_.col(k) + h01 * states_.col(k + 1) +
      (h11 * h) * stateDerivatives_.col(k + 1);
  if constexpr (kWithDerivative) {
    const double d00 = (6 * s2 - 6 * s) / h, d10 = 3 * s2 - 4 * s + 1;
    const double d01 = -d00, d11 = 3 * s2 - 2 * s;
    *xdot = d00 * states_.col(k) + d10 * stateDerivatives_.col(k) + d01 * states_.col(k + 1) +
            d11 * stateDerivatives_.col(k + 1);
  }
  if (hasInputDerivatives()) {
    u = h00 * inputs_.col(k) + (h10 * h) * inputDerivatives_.col(k) + h01 * inputs_.col(k + 1) +
        (h11 * h) * inputDerivatives_.col(k + 1);
  } else {
    u = (1.0 - s) * inputs_.col(k) + s * inputs_.col(k + 1);
  }
}

void Trajectory::evaluate(double t, Eigen::VectorXd& x, Eigen::VectorXd& u) const {
  interpolate<false>(t, x, u, nullptr);
}

void Trajectory::evaluate(double t, Eigen::VectorXd& x, Eigen::VectorXd& u, Eigen::VectorXd& xdot) const {
  interpolate<true>(t, x, u, &xdot);
}

Eigen::VectorXd Trajectory::state(double t) const {
  Eigen::VectorXd x, u;
  evaluate(t, x, u);
  return x;
}

Eigen::VectorXd Trajectory::input(double t) const {
  Eigen::VectorXd x, u;
  evaluate(t, x, u);
  return u;
}

Trajectory Trajectory::readCsv(std::istream& in, const std::string& source) {
  int n = -1;
  int rateBlock = 0;  // the number of input columns (the rate columns, if any, follow them)
  int forceColumns = 0;  // the trailing lambda_ columns, skipped
  const detail::NumericCsv csv = detail::readNumericCsv(
      in, source, [&](const std::vector<std::string>& header, int lineNo) {
        if (header[0] != "t") {
          throw TrajectoryError(source + ": line " + std::to_string(lineNo) +
                                ", column 1: header must start with 't', got '" + header[0] + "'");
        }
        for (std::size_t c = 0; c < header.size(); ++c) {
          if (header[c].empty()) {
            throw TrajectoryError(source + ": line " + std::to_string(lineNo) + ", column " +
                                  std::to_string(c + 1) + ": empty column name");
          }
        }
        // n: the first count with columns n+1..2n equal to "d" + columns 1..n.
        const int ncols = static_cast<int>(header.size()) - 1;
        for (int cand = 1; 2 * cand <= ncols && n < 0; ++cand) {
          bool match = true;
          for (int i = 0; i < cand && match; ++i) match = header[1 + cand + i] == "d" + header[1 + i];
          if (match) n = cand;
        }
        if (n < 0) {
          // Name the missing velocity column: the configurations are the columns before the
          // first name 'd' + an earlier column ("t, x, theta, dx, push": x, theta), and the first
          // of them without its 'd' column in place is the one missing ('dtheta').
          std::string missing;
          for (int c = 2; c <= ncols; ++c) {
            const std::string& name = header[c];
            if (name.size() < 2 || name[0] != 'd' ||
                std::find(header.begin() + 1, header.begin() + c, name.substr(1)) == header.begin() + c) {
              continue;
            }
            for (int i = 0; i < c - 1 && missing.empty(); ++i) {
              if (c + i > ncols || header[c + i] != "d" + header[1 + i]) missing = "d" + header[1 + i];
            }
            break;
          }
          throw TrajectoryError(source + ": line " + std::to_string(lineNo) + ": " +
                                (missing.empty() ? std::string("cannot find the velocity columns")
                                                 : "missing the velocity column '" + missing + "'") +
                                ": expected 't', the configuration names, then 'd' + each "
                                "configuration name, then the input names");
        }
        // The constraint-force block, if any, closes the row: from the first lambda_ column after
        // the states every column is one, and the reader leaves them out.
        const int first = 1 + 2 * n;
        int width = static_cast<int>(header.size());
        for (int c = first; c < width; ++c) {
          if (!isForceColumn(header[c])) continue;
          for (int j = c; j < width; ++j) {
            if (!isForceColumn(header[j])) {
              throw TrajectoryError(source + ": line " + std::to_string(lineNo) + ": column " + std::to_string(j + 1) +
                                    " ('" + header[j] + "') after the constraint-force column '" + header[c] +
                                    "' (the lambda_ columns come last; an input name must not begin with 'lambda_')");
            }
          }
          forceColumns = width - c;
          width = c;
          break;
        }
        // Inputs up to the first rate_ column; from there exactly rate_<input> for every input.
        int c = first;
        while (c < width && !isRateColumn(header[c])) ++c;
        rateBlock = c - first;
        if (c < width) {
          const int m = rateBlock;
          for (int i = 0; i < std::max(m, width - c); ++i) {
            const int col = c + i;
            const std::string want = i < m ? kRatePrefix + header[first + i] : std::string();
            const std::string got = col < width ? header[col] : std::string();
            if (got != want) {
              std::string what;
              if (col >= width) {
                what = "missing the rate column '" + want + "'";
              } else if (i >= m) {
                what = "column " + std::to_string(col + 1) + " ('" + got + "'): a rate column beyond the " +
                       std::to_string(m) + " inputs";
              } else {
                what = "column " + std::to_string(col + 1) + " ('" + got + "'): expected '" + want + "'";
              }
              throw TrajectoryError(source + ": line " + std::to_string(lineNo) + ": " + what +
                                    " (input derivative columns are rate_<input>, one per input in the "
                                    "inputs' order, after the inputs; an input name must not begin with "
                                    "'rate_')");
            }
          }
        }
      });
  const std::vector<std::string>& header = csv.header;
  std::vector<std::string> configs(header.begin() + 1, header.begin() + 1 + n);
  std::vector<std::string> inputs(header.begin() + 1 + 2 * n, header.begin() + 1 + 2 * n + rateBlock);
  const bool rates = rateBlock < static_cast<int>(header.size()) - forceColumns - 1 - 2 * n;
  const int m = static_cast<int>(inputs.size());
  const auto& rows = csv.rows;
  const int N = static_cast<int>(rows.size());
  Eigen::VectorXd t(N);
  Eigen::MatrixXd x(2 * n, N), u(m, N), du(rates ? m : 0, N);
  for (int k = 0; k < N; ++k) {
    t(k) = rows[k][0];
    for (int i = 0; i < 2 * n; ++i) x(i, k) = rows[k][1 + i];
    for (int i = 0; i < m; ++i) u(i, k) = rows[k][1 + 2 * n + i];
    if (rates) {
      for (int i = 0; i < m; ++i) du(i, k) = rows[k][1 + 2 * n + m + i];
    }
  }
  Trajectory out(std::move(configs), std::move(inputs), std::move(t), std::move(x), std::move(u));
  if (rates) out.setInputDerivatives(std::move(du));
  return out;
}

Trajectory Trajectory::readCsvFile(const std::string& path) {
  std::ifstream in;
  detail::openCsvFile(in, path, "trajectory");
  return readCsv(in, path);
}

void Trajectory::writeCsv(std::ostream& out) const {
  const bool rates = hasInputDerivatives();
  const auto names = columnNames(configNames_, inputNames_, rates);
  for (std::size_t c = 0; c < names.size(); ++c) out << (c ? "," : "") << names[c];
  out << "\n";
  out << std::setprecision(17);
  for (int k = 0; k < size(); ++k) {
    out << times_(k);
    for (int i = 0; i < nx(); ++i) out << "," << states_(i, k);
    for (int i = 0; i < nu(); ++i) out << "," << inputs_(i, k);
    if (rates) {
      for (int i = 0; i < nu(); ++i) out << "," << inputDerivatives_(i, k);
    }
    out << "\n";
  }
}

void Trajectory::writeCsvFile(const std::string& path) const {
  std::ostringstream out;
  writeCsv(out);
  writeFileAtomically(path, out.str());  // complete or absent; FileError names path and OS error
}

}  // namespace trellis
