// trellis/control/gain_schedule.hpp — feedback gains K(t) tabulated at times, for u = u_ref − K δx.
//
// Layout: N ≥ 1 times t_0 < t_1 < … < t_{N-1}, each with a gain K_k (m×nx). Between two times the
// gain is interpolated linearly entry by entry,
//   K(t) = (1 − s) K_k + s K_{k+1},   s = (t − t_k) / (t_{k+1} − t_k),
// so a gain that is linear in t is reproduced exactly and K(t_k) = K_k.
//
// CSV form, one row per time, 17 significant digits (round trip exact):
//   t,K_0_0,K_0_1,…,K_0_{nx-1},K_1_0,…,K_{m-1}_{nx-1}
// i.e. row-major: column K_i_j holds K(i, j) (i: input row, j: state column).
#pragma once

#include <Eigen/Core>

#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

namespace trellis {

/// Feedback gains K(t) (m × nx each) at ascending times; piecewise-linear in between.
class GainSchedule {
 public:
  GainSchedule() = default;

  /// times strictly increasing & finite, gains.size() == times.size(), all m×nx & finite (the
  /// size of gains[0] sets m and nx). Throws TrajectoryError naming the offending index.
  GainSchedule(Eigen::VectorXd times, std::vector<Eigen::MatrixXd> gains);

  int nu() const { return nu_; }                                ///< m (rows of K)
  int nx() const { return nx_; }                                ///< nx (columns of K)
  int size() const { return static_cast<int>(times_.size()); }  ///< N
  double startTime() const;  ///< t_0; throws std::logic_error when empty
  double endTime() const;    ///< t_{N-1}; throws std::logic_error when empty

  const Eigen::VectorXd& times() const { return times_; }
  const std::vector<Eigen::MatrixXd>& gains() const { return gains_; }

  /// K(t) by linear interpolation (m×nx). t outside [start, end] beyond a relative slack of 1e-12
  /// throws std::out_of_range (inside the slack t is clamped). No allocation when K is already
  /// m×nx. Throws std::logic_error on an empty schedule.
  void evaluate(double t, Eigen::MatrixXd& K) const;
  Eigen::MatrixXd evaluate(double t) const;

  /// Samples any gain function (e.g. RiccatiSolution::K) at the given times (strictly increasing).
  /// Exceptions of `gain` propagate; its results are validated as in the constructor.
  static GainSchedule sample(const std::function<Eigen::MatrixXd(double)>& gain,
                             const Eigen::VectorXd& times);

  /// Reads the CSV layout above; m and nx are inferred from the header, which must be exactly
  /// t, K_i_j for i < m, j < nx, row-major. Throws TrajectoryError naming the row (1-based data row
  /// and file line) and column (1-based and its header name) for a bad header, a value that is not
  /// a number or not finite, a time not greater than the previous one, or a wrong column count.
  static GainSchedule readCsv(std::istream& in, const std::string& source = "<stream>");
  static GainSchedule readCsvFile(const std::string& path);
  /// Writes the CSV layout with 17 significant digits. Throws TrajectoryError on an empty schedule.
  void writeCsv(std::ostream& out) const;
  void writeCsvFile(const std::string& path) const;

 private:
  int nu_ = 0, nx_ = 0;
  Eigen::VectorXd times_;
  std::vector<Eigen::MatrixXd> gains_;
};

}  // namespace trellis
