// trellis/analysis/funnel.hpp — how far the feedback holds: a funnel (region of attraction along a
// reference) estimated by simulating many perturbed starts in the nonlinear closed loop.
//
// Lyapunov candidate. V(t, δx) = δxᵀ S(t) δx with S the Riccati cost-to-go of the gains
// (cost_to_go.hpp); for a constrained scene S = T Sr Tᵀ lives on the tangent space of the
// constraint manifold.
//
// Sampling. For each start time t_s (the reference's start, or later reference knots) and each
// tested level ρ_j, `samples` starts x0 = x_ref(t_s) + δx are drawn on the level set V(t_s, δx) = ρ_j:
// with S(t_s) = U Λ Uᵀ restricted to its r eigenvalues above 1e-10·λ_max,
//   δx = √ρ · U_r Λ_r^{-1/2} z/|z|,   z ~ N(0, I_r),
// i.e. a direction uniform on the unit sphere of the S-metric (on the tangent space when S has
// rank d < nx; the simulation then projects x0 onto the constraints, which moves V by a term of
// second order in δx). Each start is simulated in the nonlinear closed loop
// u = sat(u_ref − K(t) δx) (analysis/simulation.hpp, input limits clipped, constraint drift
// bounded by the projection's tolerance) from t_s to the reference's end T.
//
// Success. A start succeeds when the simulation is ok (no integrator failure, non-finite state or
// constraint drift beyond the tolerance) and it ends inside the goal level set,
// V(T, x(T) − x_ref(T)) ≤ ρ_f (goalLevel; default the smallest tested level).
//
// Random streams. Sample g (global index, below) draws its normals from a counter-based generator
// keyed by (seed, g) only: SplitMix64's finalizer of (seed·φ + g) seeds a SplitMix64 stream; two
// 53-bit uniforms give two normals by Box–Muller. Nothing depends on which thread or process runs
// sample g, so results are bit-identical for any thread count and any split of the indices over
// processes (MPI ranks), on the same build.
//
// Index. g = (s·L + j)·N + i for start time s < S, level j < L, sample i < N; total S·L·N.
//
// Estimate. ρ(t_s) = the largest tested level ρ_j such that no sample failed at ρ_j or at any lower
// tested level (0 when the lowest tested level has a failure). Confidence: a level with N samples
// and no failure has a failing fraction p (of its level set, under the sampling distribution)
// with p < 1 − (1 − c)^{1/N} at confidence c (c = 0.95: ≈ 3/N, the rule of three). That bounds
// each tested level set, not the whole sublevel set.
#pragma once

#include "trellis/analysis/cost_to_go.hpp"
#include "trellis/analysis/simulation.hpp"
#include "trellis/core/status.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace trellis {

class Model;

/// Options of estimateFunnel (defaults documented per field).
struct FunnelOptions {
  std::vector<double> levels;      ///< tested levels ρ_j (finite, > 0, strictly increasing; ≥ 1)
  /// Start times t_s: reference knot times inside [t0, T) (strictly increasing); empty: {t0}.
  std::vector<double> startTimes;
  long samples = 100;              ///< N starts per (start time, level), ≥ 1
  std::uint64_t seed = 1;          ///< the random streams' key (with the sample index)
  double goalLevel = 0.0;          ///< ρ_f: success needs V(T, δx(T)) ≤ ρ_f; 0: levels.front()
  double confidence = 0.95;        ///< c of the stated failure bound, in (0, 1)
  int threads = 0;                 ///< worker threads; 0: one per hardware thread
  SimulationOptions simulation;    ///< the closed loop (input limits, rate, tolerances, method)
  /// Throws std::invalid_argument naming the field and its value.
  void validate() const;
};

/// Outcome code of a funnel run: the estimate is complete, or a sample could not be run at all
/// (an exception in a worker: memory, a solver that could not be created); failing starts are
/// data (FunnelSample), not a failed run.
enum class FunnelCode {
  kOk,
  kSampleError,  ///< a sample threw; the message names its global index and the cause
};

/// Names: ok, sample_error.
inline EnumNameTable<FunnelCode> enumNames(FunnelCode) {
  static constexpr EnumName<FunnelCode> table[] = {{FunnelCode::kOk, "ok"},
                                                   {FunnelCode::kSampleError, "sample_error"}};
  return table;
}

/// One simulated start.
struct FunnelSample {
  long index = 0;               ///< global index g (file comment)
  int start = 0;                ///< start-time index s
  int level = 0;                ///< level index j
  Eigen::VectorXd dx0;          ///< the drawn δx (nx), V(t_s, δx) = ρ_j (before any projection)
  bool success = false;         ///< the simulation is ok and V(T, δx(T)) ≤ ρ_f
  SimulationCode code = SimulationCode::kOk;  ///< the simulation's status code
  double finalLevel = 0.0;      ///< V(T, δx(T)) (NaN when the simulation did not reach T)
  double failureTime = 0.0;     ///< the simulation's failure time (NaN when it was ok)
};

/// Counts of one (start time, level) cell.
struct FunnelCell {
  double t = 0.0;       ///< the start time t_s
  double level = 0.0;   ///< ρ_j
  long samples = 0;     ///< N
  long successes = 0;   ///< starts that succeeded
};

/// The funnel's estimate: counts per cell, ρ(t_s), the worst failing start per start time, and
/// every sample (sorted by index).
struct FunnelResult {
  Status<FunnelCode> status;     ///< ok, or kSampleError (the message names the sample)
  std::vector<double> startTimes;  ///< t_s
  std::vector<double> levels;      ///< ρ_j
  double goalLevel = 0.0;          ///< ρ_f used
  double confidence = 0.95;        ///< c
  /// 1 − (1 − c)^{1/N}: the bound on a failure-free level's failing fraction at confidence c.
  double failureBound = 0.0;
  std::vector<FunnelCell> cells;   ///< start-major, levels ascending (S·L cells)
  Eigen::VectorXd rho;             ///< ρ(t_s) per start time (file comment)
  /// Per start time: the global index of the failing sample at the lowest level (the lowest index
  /// among those), −1 when no sample failed.
  std::vector<long> worstFailure;
  std::vector<FunnelSample> samples;  ///< every sample, by global index
  bool ok() const { return status.ok(); }  ///< the run is complete
  /// A few lines for people: the table, ρ(t), the bound, the worst failures.
  std::string describe() const;
  /// One JSON object: status, start_times, levels, goal_level, confidence, failure_bound, cells
  /// (t, level, samples, successes), rho, worst_failure (per start: null or index, level, dx0,
  /// code, final_level).
  std::string json() const;
};

/// S·L·N, the number of samples (throws std::invalid_argument for bad options, as validate).
long funnelSampleCount(const FunnelOptions& options);

/// What the samples need, prepared once and shared read-only by every worker: the options
/// checked against the model, the reference, the gains and S; one reference per start time (the
/// knots from t_s on); S(t_s)'s range factor U_r Λ_r^{-1/2}; S(T). It keeps references to the
/// model, the gains and the cost-to-go (they must outlive it) and copies the reference.
class FunnelProblem {
 public:
  /// Throws std::invalid_argument (options, sizes, a start time that is not a knot, sampled
  /// feedback whose samples would not line up with a later start time) or TrajectoryError
  /// (reference against the model, gains or S not covering the reference's span, S of the wrong
  /// size, S(t_s) zero).
  FunnelProblem(const Model& model, const Trajectory& reference, const GainSchedule& gains,
                const CostToGo& costToGo, FunnelOptions options);

  const FunnelOptions& options() const { return options_; }  ///< options with the defaults resolved
  long sampleCount() const { return count_; }                 ///< S·L·N
  /// δx of sample g (nx): V(t_s, δx) = ρ_j. Throws std::out_of_range for g outside [0, count).
  Eigen::VectorXd perturbation(long g) const;
  /// Per state i, the largest |δx_i| on the level set V(t_s, δx) = ρ of start time s:
  /// √ρ · ‖row_i(U_r Λ_r^{-1/2})‖ (the projection of the ellipsoid onto coordinate i; nx).
  Eigen::VectorXd extent(int start, double rho) const;
  /// The reference from start time s on (its first knot is t_s).
  const Trajectory& reference(int start) const { return references_.at(static_cast<std::size_t>(start)); }
  /// Simulates sample g (thread-safe: only const state is shared).
  FunnelSample run(long g) const;
  /// Simulates the samples first, first + stride, … below end on options().threads threads; the
  /// result in that order. An exception in a worker stops the others and is rethrown (as
  /// std::runtime_error) prefixed with the sample's index. Processes that split the indices by
  /// stride (first = rank, stride = ranks) share the expensive samples: their cost grows with the
  /// level, and the levels are contiguous in the index.
  std::vector<FunnelSample> run(long first, long end, long stride = 1) const;
  /// The estimate from all samples (count of them, by index: from run(0, count) or gathered from
  /// several processes). Throws std::invalid_argument when samples are missing or out of order.
  FunnelResult summarize(std::vector<FunnelSample> samples) const;

 private:
  const Model* model_;
  const GainSchedule* gains_;
  const CostToGo* costToGo_;
  FunnelOptions options_;
  long count_ = 0;
  std::vector<Trajectory> references_;   // per start time: the knots from t_s on
  std::vector<Eigen::MatrixXd> factors_;  // per start time: U_r Λ_r^{-1/2} (nx × r)
  Eigen::MatrixXd finalS_;
  Eigen::VectorXd finalState_;
};

/// FunnelProblem(...).summarize(run(0, count)): the whole estimate in this process. An exception
/// in a sample becomes status kSampleError (no partial estimate is returned as complete).
FunnelResult estimateFunnel(const Model& model, const Trajectory& reference, const GainSchedule& gains,
                            const CostToGo& costToGo, const FunnelOptions& options);

/// The k-th standard normal pair's generator of sample g (file comment), exposed for tests:
/// `count` normals of stream (seed, g).
Eigen::VectorXd funnelNormals(std::uint64_t seed, long g, int count);

}  // namespace trellis
