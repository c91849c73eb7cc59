// trellis/analysis/cost_to_go.hpp — the Riccati cost-to-go S(t) of a gain schedule, tabulated at
// times, and the Lyapunov candidate V(t, δx) = δxᵀ S(t) δx that funnels are measured in.
//
// S_k (nx×nx, symmetric positive semidefinite) at N ≥ 1 strictly increasing times t_k; between two
// times S(t) = (1 − s) S_k + s S_{k+1}, s = (t − t_k)/(t_{k+1} − t_k): a convex combination, so
// S(t) stays symmetric PSD. For a scene with constraints the TV-LQR's S = T Sr Tᵀ has rank d (the
// tangent space's dimension): V ignores deviations that leave the constraint manifold, as the
// gain does.
//
// CSV form (what `trellis gains --cost-to-go FILE` writes beside the gains), 17 significant
// digits, one row per time, the upper triangle row by row (nx(nx+1)/2 columns):
//   # trellis cost-to-go: nx=<nx>
//   t,S[<state>|<state>],…          e.g. t,S[x|x],S[x|theta],…,S[dtheta|dtheta]
// State names are those of x = [q; q̇]: the configuration names, then "d" + each. Without names
// the columns are S[<i>|<j>] (indices).
#pragma once

#include <Eigen/Core>

#include <iosfwd>
#include <string>
#include <vector>

namespace trellis {

/// S(t) tabulated (file comment); V(t, δx) = δxᵀ S(t) δx.
class CostToGo {
 public:
  CostToGo() = default;
  /// times strictly increasing and finite; S.size() == times.size(); each S_k nx×nx, finite and
  /// symmetric within 1e-9 relative to its largest entry (then symmetrized). Throws TrajectoryError
  /// naming the row and the entry.
  CostToGo(Eigen::VectorXd times, std::vector<Eigen::MatrixXd> S);

  int nx() const { return nx_; }                                ///< nx (rows and columns of S)
  int size() const { return static_cast<int>(times_.size()); }  ///< N
  const Eigen::VectorXd& times() const { return times_; }       ///< N times, strictly increasing
  const std::vector<Eigen::MatrixXd>& matrices() const { return S_; }  ///< N matrices S_k
  double startTime() const;  ///< t_0; throws std::logic_error when empty
  double endTime() const;    ///< t_{N−1}; throws std::logic_error when empty

  /// Names the states (nx names) for the CSV header; throws std::invalid_argument for a wrong count.
  void setStateNames(std::vector<std::string> names);
  const std::vector<std::string>& stateNames() const { return stateNames_; }  ///< empty when unnamed
  /// Throws TrajectoryError (starting with `source`) unless nx == names.size() and, when the table
  /// has names, they equal `names` in order (the first mismatch is named).
  void checkNames(const std::vector<std::string>& names, const std::string& source) const;

  /// S(t) (nx×nx) by the linear rule; t outside [t_0, t_{N−1}] beyond 1e-12 relative throws
  /// std::out_of_range (inside the slack t is clamped). No allocation when S is nx×nx already.
  void evaluate(double t, Eigen::MatrixXd& S) const;
  Eigen::MatrixXd evaluate(double t) const;  ///< S(t) as a new matrix
  /// V(t, δx) = δxᵀ S(t) δx (δx: nx).
  double level(double t, const Eigen::VectorXd& dx) const;

  /// Reads the CSV form. Throws TrajectoryError naming the line and column of a bad header, a
  /// value that is not a finite number, a time not greater than the previous, a wrong column
  /// count, or an S_k that is not symmetric.
  static CostToGo readCsv(std::istream& in, const std::string& source = "<stream>");
  /// readCsv of the file at `path` (TrajectoryError naming the path when it cannot be read).
  static CostToGo readCsvFile(const std::string& path);
  /// The CSV form (17 digits); throws TrajectoryError when empty.
  void writeCsv(std::ostream& out) const;
  /// writeCsv to `path` atomically (io.hpp); throws FileError, TrajectoryError.
  void writeCsvFile(const std::string& path) const;

 private:
  int nx_ = 0;
  Eigen::VectorXd times_;
  std::vector<Eigen::MatrixXd> S_;
  std::vector<std::string> stateNames_;
};

}  // namespace trellis
