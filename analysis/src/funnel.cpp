// funnel.cpp — funnel estimates by sampling (funnel.hpp): the random streams, the level-set
// sampling, the samples on threads, and the summary.
#include "trellis/analysis/funnel.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/detail/report_json.hpp"
#include "trellis/core/model.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace trellis {

namespace {

/// SplitMix64's output function (Steele, Lea & Flood 2014): a bijection of 64-bit words whose
/// outputs for consecutive inputs pass BigCrush; used as a hash of (seed, index) and as a stream.
std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

constexpr std::uint64_t kGolden = 0x9e3779b97f4a7c15ULL;

std::string number(double v) { return formatStatusNumber(v); }

}  // namespace

Eigen::VectorXd funnelNormals(std::uint64_t seed, long g, int count) {
  // Stream key: the hash of (seed, g); then SplitMix64 steps from it.
  std::uint64_t state = mix64(mix64(seed * kGolden + 0x632be59bd9b4e019ULL) ^ static_cast<std::uint64_t>(g));
  const auto next = [&state] {
    state += kGolden;
    return mix64(state);
  };
  Eigen::VectorXd z(count);
  for (int i = 0; i < count; i += 2) {
    // u1 in (0, 1] (finite log), u2 in [0, 1): 53 bits each.
    const double u1 = (static_cast<double>(next() >> 11) + 1.0) * 0x1.0p-53;
    const double u2 = static_cast<double>(next() >> 11) * 0x1.0p-53;
    const double radius = std::sqrt(-2.0 * std::log(u1));
    z(i) = radius * std::cos(2.0 * std::numbers::pi * u2);
    if (i + 1 < count) z(i + 1) = radius * std::sin(2.0 * std::numbers::pi * u2);
  }
  return z;
}

void FunnelOptions::validate() const {
  if (levels.empty()) throw std::invalid_argument("funnel: levels: none given (at least one level rho > 0)");
  for (std::size_t j = 0; j < levels.size(); ++j) {
    if (!std::isfinite(levels[j]) || !(levels[j] > 0.0)) {
      throw std::invalid_argument("funnel: levels[" + std::to_string(j) + "] = " + number(levels[j]) +
                                  " must be finite and > 0");
    }
    if (j > 0 && !(levels[j] > levels[j - 1])) {
      throw std::invalid_argument("funnel: levels[" + std::to_string(j) + "] = " + number(levels[j]) +
                                  " must be greater than levels[" + std::to_string(j - 1) + "] = " + number(levels[j - 1]));
    }
  }
  for (std::size_t s = 0; s < startTimes.size(); ++s) {
    if (!std::isfinite(startTimes[s])) {
      throw std::invalid_argument("funnel: startTimes[" + std::to_string(s) + "] = " + number(startTimes[s]) + " is not finite");
    }
    if (s > 0 && !(startTimes[s] > startTimes[s - 1])) {
      throw std::invalid_argument("funnel: startTimes[" + std::to_string(s) + "] = " + number(startTimes[s]) +
                                  " must be greater than the previous, " + number(startTimes[s - 1]));
    }
  }
  if (samples < 1) throw std::invalid_argument("funnel: samples = " + std::to_string(samples) + " must be >= 1");
  if (!std::isfinite(goalLevel) || goalLevel < 0.0) {
    throw std::invalid_argument("funnel: goalLevel = " + number(goalLevel) + " must be finite and >= 0 (0: the smallest level)");
  }
  if (!(confidence > 0.0 && confidence < 1.0)) {
    throw std::invalid_argument("funnel: confidence = " + number(confidence) + " must be in (0, 1)");
  }
  if (threads < 0) throw std::invalid_argument("funnel: threads = " + std::to_string(threads) + " must be >= 0");
  simulation.validate();
}

long funnelSampleCount(const FunnelOptions& options) {
  options.validate();
  const long starts = std::max<long>(1, static_cast<long>(options.startTimes.size()));
  const long levels = static_cast<long>(options.levels.size());
  if (options.samples > std::numeric_limits<long>::max() / (starts * levels)) {
    throw std::invalid_argument("funnel: " + std::to_string(starts) + " start times x " + std::to_string(levels) +
                                " levels x " + std::to_string(options.samples) + " samples overflow the sample index");
  }
  return starts * levels * options.samples;
}

FunnelProblem::FunnelProblem(const Model& model, const Trajectory& reference, const GainSchedule& gains,
                             const CostToGo& costToGo, FunnelOptions options)
    : model_(&model), gains_(&gains), costToGo_(&costToGo), options_(std::move(options)) {
  count_ = funnelSampleCount(options_);
  reference.checkCompatible(model);
  const int nx = reference.nx();
  if (costToGo.size() == 0 || costToGo.nx() != nx) {
    throw TrajectoryError("funnel: the cost-to-go is " + std::to_string(costToGo.nx()) + "x" +
                          std::to_string(costToGo.nx()) + ", the scene has 2n = " + std::to_string(nx) + " states");
  }
  const double t0 = reference.startTime(), T = reference.endTime();
  const double slack = 1e-12 * std::max({1.0, std::abs(t0), std::abs(T)});
  if (costToGo.startTime() > t0 + slack || costToGo.endTime() < T - slack) {
    throw TrajectoryError("funnel: the cost-to-go covers [" + number(costToGo.startTime()) + ", " +
                          number(costToGo.endTime()) + "], the reference needs [" + number(t0) + ", " + number(T) + "]");
  }
  if (options_.startTimes.empty()) options_.startTimes = {t0};
  if (options_.goalLevel == 0.0) options_.goalLevel = options_.levels.front();

  // The reference with its state derivatives (x_ref's Hermite spline), computed once.
  Trajectory full = reference;
  if (!full.hasStateDerivatives()) {
    Data data(model);
    full.computeStateDerivatives(model, data);
  }
  const Eigen::VectorXd& times = full.times();
  for (std::size_t s = 0; s < options_.startTimes.size(); ++s) {
    const double ts = options_.startTimes[s];
    const std::string name = "funnel: start time " + std::to_string(s) + " (t = " + number(ts) + ")";
    Eigen::Index k = -1;
    for (Eigen::Index i = 0; i + 1 < times.size(); ++i)
      if (std::abs(times(i) - ts) <= slack) k = i;
    if (k < 0) {
      throw std::invalid_argument(name + " is not a knot of the reference before its end (the knots are at " +
                                  number(times(0)) + ", " + number(times(1)) + ", ..., " + number(T) + ")");
    }
    const double rate = options_.simulation.sampleRate;
    if (rate > 0.0 && k > 0) {
      const double samplesBefore = (times(k) - t0) * rate;
      if (std::abs(samplesBefore - std::round(samplesBefore)) > 1e-9) {
        throw std::invalid_argument(name + " is not a sample time of the " + number(rate) + " Hz feedback (t0 + k/" +
                                    number(rate) + "): its samples would not line up with the gains'");
      }
    }
    // The knots from t_s on: on each interval the Hermite spline uses only its end knots, so this
    // reference is the full one restricted to [t_s, T].
    const Eigen::Index cols = times.size() - k;
    Trajectory part(full.configNames(), full.inputNames(), times.segment(k, cols), full.states().middleCols(k, cols),
                    full.inputs().middleCols(k, cols));
    part.setStateDerivatives(full.stateDerivatives().middleCols(k, cols));
    if (full.hasInputDerivatives()) part.setInputDerivatives(full.inputDerivatives().middleCols(k, cols));
    options_.startTimes[s] = times(k);
    references_.push_back(std::move(part));

    // S(t_s) = U Λ Uᵀ; the level set's parametrization on the eigenvalues above 1e-10 λ_max.
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(costToGo.evaluate(times(k)));
    const Eigen::VectorXd& lambda = eigen.eigenvalues();
    const double top = lambda.maxCoeff();
    if (!(top > 0.0)) throw TrajectoryError(name + ": the cost-to-go S(t) is zero there: V has no level sets");
    std::vector<Eigen::Index> kept;
    for (Eigen::Index i = 0; i < lambda.size(); ++i)
      if (lambda(i) > 1e-10 * top) kept.push_back(i);
    Eigen::MatrixXd factor(nx, static_cast<Eigen::Index>(kept.size()));
    for (std::size_t c = 0; c < kept.size(); ++c) {
      factor.col(static_cast<Eigen::Index>(c)) = eigen.eigenvectors().col(kept[c]) / std::sqrt(lambda(kept[c]));
    }
    factors_.push_back(std::move(factor));
  }
  // Every reference part must be drivable by the gains (sizes, span): simulateClosedLoop checks
  // again, but here it fails before any thread starts.
  if (gains.size() == 0 || gains.nu() != reference.nu() || gains.nx() != nx) {
    throw TrajectoryError("funnel: the gains are " + std::to_string(gains.nu()) + "x" + std::to_string(gains.nx()) +
                          ", the scene needs m x 2n = " + std::to_string(reference.nu()) + "x" + std::to_string(nx));
  }
  if (gains.startTime() > t0 + slack || gains.endTime() < T - slack) {
    throw TrajectoryError("funnel: the gains cover [" + number(gains.startTime()) + ", " + number(gains.endTime()) +
                          "], the reference needs [" + number(t0) + ", " + number(T) + "]");
  }
  finalS_ = costToGo.evaluate(T);
  finalState_ = full.states().col(full.size() - 1);
}

Eigen::VectorXd FunnelProblem::perturbation(long g) const {
  if (g < 0 || g >= count_) {
    throw std::out_of_range("funnel: sample index " + std::to_string(g) + " is outside [0, " + std::to_string(count_) + ")");
  }
  const long levels = static_cast<long>(options_.levels.size());
  const long cell = g / options_.samples;
  const auto s = static_cast<std::size_t>(cell / levels);
  const auto j = static_cast<std::size_t>(cell % levels);
  const Eigen::MatrixXd& factor = factors_[s];
  Eigen::VectorXd z = funnelNormals(options_.seed, g, static_cast<int>(factor.cols()));
  if (!(z.norm() > 0.0)) z = Eigen::VectorXd::Unit(factor.cols(), 0);  // measure zero; no division by 0
  // z/|z| is uniform on the unit sphere; the factor maps it onto V = 1, √ρ onto V = ρ.
  return std::sqrt(options_.levels[j]) * (factor * (z / z.norm()));
}

Eigen::VectorXd FunnelProblem::extent(int start, double rho) const {
  const Eigen::MatrixXd& factor = factors_.at(static_cast<std::size_t>(start));
  return std::sqrt(rho) * factor.rowwise().norm();
}

FunnelSample FunnelProblem::run(long g) const {
  FunnelSample sample;
  sample.index = g;
  sample.dx0 = perturbation(g);
  const long levels = static_cast<long>(options_.levels.size());
  const long cell = g / options_.samples;
  sample.start = static_cast<int>(cell / levels);
  sample.level = static_cast<int>(cell % levels);
  const Trajectory& reference = references_[static_cast<std::size_t>(sample.start)];
  const Eigen::VectorXd x0 = reference.states().col(0) + sample.dx0;
  SimulationOptions simulation = options_.simulation;
  simulation.outputStep = reference.endTime() - reference.startTime();  // only the end state is needed
  const SimulationResult result = simulateClosedLoop(*model_, reference, *gains_, x0, simulation);
  sample.code = result.status.code;
  if (result.ok()) {
    const Trajectory& closed = result.trajectory;
    const Eigen::VectorXd dxT = closed.states().col(closed.size() - 1) - finalState_;
    sample.finalLevel = dxT.dot(finalS_ * dxT);
    sample.failureTime = std::numeric_limits<double>::quiet_NaN();
    sample.success = sample.finalLevel <= options_.goalLevel;
  } else {
    sample.finalLevel = std::numeric_limits<double>::quiet_NaN();
    sample.failureTime = result.status.t;
    sample.success = false;
  }
  return sample;
}

std::vector<FunnelSample> FunnelProblem::run(long first, long end, long stride) const {
  if (first < 0 || end > count_ || first > end || stride < 1) {
    throw std::out_of_range("funnel: samples " + std::to_string(first) + ", +" + std::to_string(stride) + ", ... below " +
                            std::to_string(end) + " are outside [0, " + std::to_string(count_) + ")");
  }
  const long count = (end - first + stride - 1) / stride;
  std::vector<FunnelSample> out(static_cast<std::size_t>(count));
  const int hardware = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int workers = static_cast<int>(std::min<long>(options_.threads > 0 ? options_.threads : hardware, std::max<long>(count, 1)));
  std::atomic<long> next{0};
  std::vector<std::exception_ptr> errors(static_cast<std::size_t>(workers));
  std::vector<long> failedAt(static_cast<std::size_t>(workers), -1);
  // Each worker takes the next index; every sample owns its simulation's Data and integrator, so
  // the result of sample g is the same whichever worker runs it.
  auto work = [&](int w) {
    long k = -1;
    try {
      for (k = next++; k < count; k = next++) out[static_cast<std::size_t>(k)] = run(first + k * stride);
    } catch (...) {
      errors[static_cast<std::size_t>(w)] = std::current_exception();
      failedAt[static_cast<std::size_t>(w)] = first + k * stride;
      next = count;
    }
  };
  std::vector<std::thread> pool;
  for (int w = 1; w < workers; ++w) pool.emplace_back(work, w);
  work(0);
  for (std::thread& t : pool) t.join();
  for (std::size_t w = 0; w < errors.size(); ++w) {
    if (!errors[w]) continue;
    try {
      std::rethrow_exception(errors[w]);
    } catch (const std::exception& e) {
      throw std::runtime_error("funnel: sample " + std::to_string(failedAt[w]) + ": " + e.what());
    }
  }
  return out;
}

FunnelResult FunnelProblem::summarize(std::vector<FunnelSample> samples) const {
  if (static_cast<long>(samples.size()) != count_) {
    throw std::invalid_argument("funnel: summarize: " + std::to_string(samples.size()) + " samples, expected " +
                                std::to_string(count_));
  }
  for (long g = 0; g < count_; ++g) {
    if (samples[static_cast<std::size_t>(g)].index != g) {
      throw std::invalid_argument("funnel: summarize: sample " + std::to_string(g) + " has index " +
                                  std::to_string(samples[static_cast<std::size_t>(g)].index));
    }
  }
  FunnelResult r;
  r.startTimes = options_.startTimes;
  r.levels = options_.levels;
  r.goalLevel = options_.goalLevel;
  r.confidence = options_.confidence;
  r.failureBound = -std::expm1(std::log1p(-options_.confidence) / static_cast<double>(options_.samples));
  const std::size_t S = r.startTimes.size(), L = r.levels.size();
  r.rho = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(S));
  r.worstFailure.assign(S, -1);
  for (std::size_t s = 0; s < S; ++s) {
    bool clean = true;
    for (std::size_t j = 0; j < L; ++j) {
      FunnelCell cell{r.startTimes[s], r.levels[j], options_.samples, 0};
      const long first = static_cast<long>(s * L + j) * options_.samples;
      for (long i = 0; i < options_.samples; ++i) {
        const FunnelSample& sample = samples[static_cast<std::size_t>(first + i)];
        if (sample.success) {
          ++cell.successes;
        } else if (r.worstFailure[s] < 0) {
          r.worstFailure[s] = sample.index;  // the lowest level's lowest index: levels ascend
        }
      }
      clean = clean && cell.successes == cell.samples;
      if (clean) r.rho(static_cast<Eigen::Index>(s)) = r.levels[j];
      r.cells.push_back(cell);
    }
  }
  r.samples = std::move(samples);
  return r;
}

FunnelResult estimateFunnel(const Model& model, const Trajectory& reference, const GainSchedule& gains,
                            const CostToGo& costToGo, const FunnelOptions& options) {
  const FunnelProblem problem(model, reference, gains, costToGo, options);
  try {
    return problem.summarize(problem.run(0, problem.sampleCount()));
  } catch (const std::runtime_error& e) {
    FunnelResult r;
    r.status.set(FunnelCode::kSampleError, e.what());
    return r;
  }
}

std::string FunnelResult::describe() const {
  std::ostringstream out;
  if (!ok()) return status.describe();
  out << "funnel: " << samples.size() << " closed loops, goal V(T) <= " << number(goalLevel) << "\n";
  for (std::size_t s = 0; s < startTimes.size(); ++s) {
    out << "t = " << number(startTimes[s]) << ": rho = " << number(rho(static_cast<Eigen::Index>(s)));
    for (std::size_t j = 0; j < levels.size(); ++j) {
      const FunnelCell& c = cells[s * levels.size() + j];
      out << (j == 0 ? " (" : ", ") << number(c.level) << ": " << c.successes << "/" << c.samples;
    }
    out << ")\n";
  }
  out << "a level with no failure in N = " << (cells.empty() ? 0 : cells.front().samples)
      << " samples fails from less than " << number(failureBound) << " of its level set (confidence "
      << number(confidence) << ")\n";
  return out.str();
}

std::string FunnelResult::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["start_times"] = startTimes;
  j["levels"] = levels;
  j["goal_level"] = detail::toJson(goalLevel);
  j["confidence"] = confidence;
  j["failure_bound"] = detail::toJson(failureBound);
  detail::ReportJson table = detail::ReportJson::array();
  for (const FunnelCell& c : cells) {
    detail::ReportJson row;
    row["t"] = c.t;
    row["level"] = c.level;
    row["samples"] = c.samples;
    row["successes"] = c.successes;
    table.push_back(row);
  }
  j["cells"] = table;
  j["rho"] = detail::toJson(rho);
  detail::ReportJson worst = detail::ReportJson::array();
  for (long g : worstFailure) {
    if (g < 0 || static_cast<std::size_t>(g) >= samples.size()) {
      worst.push_back(nullptr);
      continue;
    }
    const FunnelSample& s = samples[static_cast<std::size_t>(g)];
    detail::ReportJson w;
    w["index"] = s.index;
    w["level"] = levels[static_cast<std::size_t>(s.level)];
    w["code"] = toString(s.code);
    w["final_level"] = detail::toJson(s.finalLevel);
    w["failure_time"] = detail::toJson(s.failureTime);
    w["dx0"] = detail::toJson(s.dx0);
    worst.push_back(w);
  }
  j["worst_failure"] = worst;
  return j.dump();
}

}  // namespace trellis
