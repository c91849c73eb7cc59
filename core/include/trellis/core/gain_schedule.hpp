// trellis/core/gain_schedule.hpp — feedback gains K(t) tabulated at times, for u = u_ref − K δx.
//
// Layout: N ≥ 1 times t_0 < t_1 < … < t_{N-1}, each with a gain K_k (m×nx). Between two times the
// gain is interpolated linearly entry by entry,
//   K(t) = (1 − s) K_k + s K_{k+1},   s = (t − t_k) / (t_{k+1} − t_k),
// so a gain that is linear in t is reproduced exactly and K(t_k) = K_k (second order: the error
// against a smooth K*(t) is ≤ h² max|K̈*| / 8). This is the default and the meaning of a file
// without an interpolation= item.
//
// C¹ rule (setInterpolation(GainInterpolation::kCubic), or `interpolation=cubic` in the metadata
// line): between two times K(t) is the cubic Hermite spline through (K_k, K̇_k) with the slopes
// taken from the table — at an interior time the derivative of the parabola through the rows
// k − 1, k, k + 1,
//   K̇_k = (h_k Δ_{k−1} + h_{k−1} Δ_k) / (h_{k−1} + h_k),  Δ_j = (K_{j+1} − K_j) / h_j,
// and at the ends the derivative of the parabola through the first (last) three rows (two rows:
// the secant). K(t) is then continuous with a continuous derivative at every row (a closed loop
// need not restart there), quadratics in t are reproduced exactly, and the error against a
// smooth K*(t) is O(h³) (the slopes are second-order accurate; with exact slopes it would be
// O(h⁴)). The slopes are computed once, when the rule is chosen; evaluation does not allocate.
//
// Discrete (zero-order-hold) gains: sampleRate() = f > 0 says the gains were computed for a
// controller that samples at t_k = t0 + k/f and holds u until the next sample; K_k is the row at
// t_k (the last row, at the end time, repeats the last sample's gain). Applying them continuously
// or at another rate is not what they were designed for (trellis simulate refuses it).
// sampleRate() = 0: continuous gains (K(t) along the horizon; sampling them is an approximation).
//
// Feed-forward of sampled gains (setFeedforward): per sample k the held input ū_k that the
// controller applies with the feedback, u_k = ū_k − K_k (x(t_k) − x_ref(t_k)), held on
// [t_k, t_{k+1}) (the last row, at the end time, repeats the last sample's). Without it a sampled
// controller applies u_ref(t_k) (the reference's input sampled at t_k; what older files mean).
// solveTvlqr (control/tvlqr.hpp) computes the ū_k that carries x_ref(t_k) to x_ref(t_{k+1})
// through the exact dynamics as closely as one held input can.
//
// CSV form, one row per time, 17 significant digits (round trip exact):
//   # trellis gain schedule: m=<m> nx=<nx> sample_rate_hz=<f>   (or: continuous)
//     [interpolation=cubic]   (absent or interpolation=linear: the linear rule)
//   t,K[<input>|<state>],…[,uff[<input>],…]   (K row-major: input by input, the states [q; dq]
//                                              in order; then the m feed-forward columns)
// e.g. `t,K[push|x],K[push|theta],K[push|dx],K[push|dtheta],uff[push]`. The separator '|' is
// refused in input names (setColumnNames), so a column splits at its first '|' whatever the
// names hold. The older form K_<input>_<state> (ambiguous to split when names contain '_') is
// still read: against a scene it is checked column by column (checkNames), by position, which is
// unambiguous. Without names (setColumnNames not called) the columns are K_<i>_<j> (i: input
// row, j: state column) and uff_<i>; such files without the metadata line (the older layout) are
// read as continuous gains.
#pragma once

#include "trellis/core/enum_names.hpp"

#include <Eigen/Core>

#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

namespace trellis {

/// The rule for K(t) between the tabulated times (file comment).
enum class GainInterpolation {
  kLinear,  ///< piecewise linear (C⁰), second order; the default
  kCubic,   ///< cubic Hermite with parabola slopes from the table (C¹), third order
};

/// Names as in the CSV metadata line (interpolation=…) and the CLI: linear, cubic.
inline EnumNameTable<GainInterpolation> enumNames(GainInterpolation) {
  static constexpr EnumName<GainInterpolation> table[] = {{GainInterpolation::kLinear, "linear"},
                                                          {GainInterpolation::kCubic, "cubic"}};
  return table;
}

/// Feedback gains K(t) (m × nx each) at ascending times; piecewise-linear (or cubic) in between.
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

  const Eigen::VectorXd& times() const { return times_; }             ///< N knot times, strictly increasing [s]
  const std::vector<Eigen::MatrixXd>& gains() const { return gains_; }  ///< N gains K_k, each m×nx

  /// 0: continuous gains; f > 0: zero-order-hold gains for a controller sampling at f Hz.
  double sampleRate() const { return sampleRate_; }
  bool isSampled() const { return sampleRate_ > 0.0; }  ///< sampleRate() > 0
  /// Throws std::invalid_argument unless hz is finite and ≥ 0. A new rate drops the held
  /// feed-forward (it was computed for the old one).
  void setSampleRate(double hz);

  /// Column names (m·nx, row-major), `K[<input>|<state>]` (or the older `K_<input>_<state>` of
  /// a file read); empty when unnamed.
  const std::vector<std::string>& columnNames() const { return columnNames_; }
  /// Names the columns `K[<input>|<state>]` (inputs: m names; states: nx names, e.g. the
  /// configuration names then "d" + each). Throws std::invalid_argument for wrong counts and for
  /// an input name containing '|' (the separator: the column would not split back).
  void setColumnNames(const std::vector<std::string>& inputNames,
                      const std::vector<std::string>& stateNames);
  /// The state names of a model's x = [q; dq]: configuration names, then "d" + each.
  static std::vector<std::string> stateNames(const std::vector<std::string>& configNames);
  /// Throws TrajectoryError (naming `source`, the first mismatching column and both names) unless
  /// K is (inputNames.size()) × (stateNames.size()) and, when the schedule has column names, they
  /// are `K[<input>|<state>]` (or all the older `K_<input>_<state>`) for these names, and the
  /// feed-forward columns `uff[<input>]`. Unnamed (older) schedules pass on sizes alone.
  void checkNames(const std::vector<std::string>& inputNames,
                  const std::vector<std::string>& stateNames, const std::string& source) const;

  /// Sets the held feed-forward ū_k (file comment): one m-vector per row (the last row repeats
  /// the last sample's). Throws std::invalid_argument unless the schedule is sampled, the count is
  /// size() and every vector has m finite entries (naming the row and entry).
  void setFeedforward(std::vector<Eigen::VectorXd> uff);
  bool hasFeedforward() const { return !feedforward_.empty(); }  ///< setFeedforward was called
  /// ū_k per row (empty without a feed-forward).
  const std::vector<Eigen::VectorXd>& feedforward() const { return feedforward_; }
  /// The row k of the sample interval holding t: the last k with t_k ≤ t (within 1e-9 of a period
  /// for sampled gains, 1e-12 relative otherwise), clamped to [0, size() − 1]. Throws
  /// std::out_of_range outside [start, end] (as evaluate) and std::logic_error when empty.
  int rowAt(double t) const;
  /// ū of the sample interval holding t (rowAt); u must be m (no allocation then). Throws
  /// std::logic_error without a feed-forward.
  void evaluateFeedforward(double t, Eigen::VectorXd& u) const;

  GainInterpolation interpolation() const { return interpolation_; }  ///< the rule between rows (file comment)
  /// Chooses the rule between rows (file comment); kCubic computes the slopes here.
  void setInterpolation(GainInterpolation rule);
  /// The slopes K̇_k of the cubic rule (N matrices m×nx; empty for the linear rule).
  const std::vector<Eigen::MatrixXd>& slopes() const { return slopes_; }

  /// K(t) by the interpolation rule (m×nx). t outside [start, end] beyond a relative slack of 1e-12
  /// throws std::out_of_range (inside the slack t is clamped). No allocation when K is already
  /// m×nx. Throws std::logic_error on an empty schedule.
  void evaluate(double t, Eigen::MatrixXd& K) const;
  /// K(t) as a new matrix (allocating); see evaluate(double, Eigen::MatrixXd&).
  Eigen::MatrixXd evaluate(double t) const;

  /// Samples any gain function (e.g. RiccatiSolution::K) at the given times (strictly increasing).
  /// Exceptions of `gain` propagate; its results are validated as in the constructor.
  static GainSchedule sample(const std::function<Eigen::MatrixXd(double)>& gain,
                             const Eigen::VectorXd& times);

  /// Reads the CSV layout above. m, nx and the rate come from the metadata line; without it the
  /// header must be exactly t, K_i_j for i < m, j < nx, row-major (m and nx inferred). Throws TrajectoryError naming the row (1-based data row
  /// and file line) and column (1-based and its header name) for a bad header, a value that is not
  /// a number or not finite, a time not greater than the previous one, or a wrong column count.
  static GainSchedule readCsv(std::istream& in, const std::string& source = "<stream>");
  /// readCsv on the file at `path`; a directory or a file that cannot be opened throws
  /// TrajectoryError naming the path and the reason (and as readCsv for its content).
  static GainSchedule readCsvFile(const std::string& path);
  /// Writes the CSV layout with 17 significant digits. Throws TrajectoryError on an empty schedule.
  void writeCsv(std::ostream& out) const;
  /// writeCsv to `path`, atomically (io.hpp: complete or absent); throws FileError, TrajectoryError.
  void writeCsvFile(const std::string& path) const;

 private:
  int nu_ = 0, nx_ = 0;
  double sampleRate_ = 0.0;
  GainInterpolation interpolation_ = GainInterpolation::kLinear;
  std::vector<std::string> columnNames_, feedforwardNames_;
  Eigen::VectorXd times_;
  std::vector<Eigen::MatrixXd> gains_, slopes_;
  std::vector<Eigen::VectorXd> feedforward_;
};

class Model;
class Trajectory;

/// Whether `gains` can drive u = u_ref − K δx along `reference` for `model` with feedback at
/// `sampleRate` Hz (0: continuous feedback) — the one check the CLI and Python apply before a
/// closed-loop simulation. Throws TrajectoryError, the message starting with `source`, when:
/// the columns do not match the model (checkNames); sampled gains are applied continuously or at
/// another rate (within 1e-12 relative); sampled gains do not start at the reference's start
/// (within 1e-9 of a period: the samples would not line up); the gains do not cover the
/// reference's span (1e-12 relative slack, as evaluate). Returns a note for a person when the
/// gains apply but were not designed for this use (continuous gains sampled at a rate), else "".
std::string checkGainScheduleApplies(const GainSchedule& gains, const Model& model,
                                     const Trajectory& reference, double sampleRate,
                                     const std::string& source);

}  // namespace trellis
