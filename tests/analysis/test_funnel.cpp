// Tests for trellis/analysis/funnel.hpp and cost_to_go.hpp: the cost-to-go table (round trip,
// refusals), the random streams and the level-set sampling, determinism across threads and
// index splits, and a known answer: the torque-limited inverted pendulum, whose region of
// attraction is measured another way (bisection along rays of the S-metric).
#include <trellis/analysis/cost_to_go.hpp>
#include <trellis/analysis/funnel.hpp>
#include <trellis/control/tvlqr.hpp>
#include <trellis/core.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::CostToGo;
using trellis::FunnelOptions;
using trellis::FunnelProblem;
using trellis::FunnelResult;
using trellis::FunnelSample;
using trellis::GainSchedule;
using trellis::Model;
using trellis::Trajectory;

namespace {

constexpr double kGravity = 9.81;

/// A point mass 1 kg at 1 m ABOVE its pivot (θ = 0 upright, unstable), torque input "tau".
Model makeInvertedPendulum() {
  trellis::ModelBuilder b("inverted_pendulum");
  b.addFrame("arm", "world", trellis::Transform::rz("theta"));
  b.addFrame("bob", "arm", trellis::Transform::ty(1.0), trellis::Mass{1.0, Eigen::Matrix3d::Zero()});
  b.addGravity({0.0, -kGravity, 0.0});
  b.addConfigForce("theta", "tau");
  return std::move(b).finalize();
}

/// Upright at rest over [0, T] with no torque (an equilibrium), `knots` knots.
Trajectory upright(const Model& model, double T, int knots) {
  const VectorXd times = VectorXd::LinSpaced(knots, 0.0, T);
  return Trajectory(model.configNames(), model.inputNames(), times, MatrixXd::Zero(2, knots), MatrixXd::Zero(1, knots));
}

struct Setup {
  Model model = makeInvertedPendulum();
  Trajectory reference;
  GainSchedule gains;
  CostToGo costToGo;
  Setup(double T = 2.0) : reference(upright(model, T, 21)) {
    trellis::LqrWeights weights;
    weights.Q = MatrixXd::Identity(2, 2);
    weights.R = MatrixXd::Identity(1, 1);
    weights.Qf = 10.0 * MatrixXd::Identity(2, 2);
    const trellis::TvlqrSolution solution = trellis::solveTvlqr(model, reference, weights);
    REQUIRE(solution.ok());
    gains = solution.gains;
    costToGo = CostToGo(solution.gains.times(), solution.S);
  }
};

bool sameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

bool sameSample(const FunnelSample& a, const FunnelSample& b) {
  if (a.index != b.index || a.start != b.start || a.level != b.level || a.success != b.success || a.code != b.code) return false;
  if (!(sameBits(a.finalLevel, b.finalLevel) && sameBits(a.failureTime, b.failureTime))) return false;
  if (a.dx0.size() != b.dx0.size()) return false;
  for (Eigen::Index i = 0; i < a.dx0.size(); ++i)
    if (!sameBits(a.dx0(i), b.dx0(i))) return false;
  return true;
}

}  // namespace

TEST_CASE("cost-to-go: CSV round trip, evaluation, refusals", "[funnel]") {
  MatrixXd S0(2, 2), S1(2, 2);
  S0 << 2.0, 0.5, 0.5, 1.0;
  S1 << 4.0, 1.0 / 3.0, 1.0 / 3.0, 3.0;
  CostToGo table(VectorXd::LinSpaced(2, 0.0, 1.0), {S0, S1});
  table.setStateNames({"theta", "dtheta"});

  SECTION("round trip: bit-identical, names kept") {
    std::stringstream text;
    table.writeCsv(text);
    REQUIRE(text.str().rfind("# trellis cost-to-go: nx=2\nt,S[theta|theta],S[theta|dtheta],S[dtheta|dtheta]\n", 0) == 0);
    const CostToGo back = CostToGo::readCsv(text, "mem");
    REQUIRE(back.stateNames() == table.stateNames());
    for (int k = 0; k < 2; ++k) REQUIRE((back.matrices()[static_cast<std::size_t>(k)].array() == table.matrices()[static_cast<std::size_t>(k)].array()).all());
  }
  SECTION("linear between rows; V = dx^T S dx") {
    const MatrixXd mid = table.evaluate(0.25);
    REQUIRE((mid - (0.75 * S0 + 0.25 * S1)).cwiseAbs().maxCoeff() < 1e-15);
    const VectorXd dx = VectorXd::Ones(2);
    REQUIRE(table.level(1.0, dx) == Approx(4.0 + 2.0 / 3.0 + 3.0).epsilon(1e-14));
    REQUIRE_THROWS_AS(table.evaluate(1.5), std::out_of_range);
  }
  SECTION("a table of another scene, an asymmetric S, a bad value are refused by name") {
    REQUIRE_THROWS_WITH(table.checkNames({"x", "dx"}, "S.csv"), Catch::Contains("'theta'") && Catch::Contains("'x'"));
    MatrixXd bad = S0;
    bad(0, 1) = 0.6;
    REQUIRE_THROWS_WITH(CostToGo(VectorXd::Zero(1), {bad}), Catch::Contains("not symmetric") && Catch::Contains("S[0|1]"));
    std::stringstream text("# trellis cost-to-go: nx=1\nt,S[a|a]\n0,nan\n");
    REQUIRE_THROWS_WITH(CostToGo::readCsv(text, "f.csv"), Catch::Contains("f.csv: line 3, column 2") && Catch::Contains("'nan'"));
  }
}

TEST_CASE("funnel: random streams depend on (seed, index) only; starts lie on the level set", "[funnel]") {
  // The stream is a function of its key: the same numbers every call, others for another key.
  const VectorXd a = trellis::funnelNormals(7, 12345, 5), b = trellis::funnelNormals(7, 12345, 5);
  REQUIRE((a.array() == b.array()).all());
  REQUIRE((a.array() != trellis::funnelNormals(8, 12345, 5).array()).all());
  REQUIRE((a.array() != trellis::funnelNormals(7, 12346, 5).array()).all());
  // Moments over 20000 draws: mean 0 ± 4σ/√n, variance 1 ± 4·√(2/n).
  const int n = 20000;
  double sum = 0.0, squares = 0.0;
  for (int g = 0; g < n; ++g) {
    const double z = trellis::funnelNormals(1, g, 1)(0);
    sum += z;
    squares += z * z;
  }
  REQUIRE(std::abs(sum / n) < 4.0 / std::sqrt(n));
  REQUIRE(std::abs(squares / n - 1.0) < 4.0 * std::sqrt(2.0 / n));

  Setup setup;
  FunnelOptions options;
  options.levels = {0.5, 2.0};
  options.samples = 5;
  options.startTimes = {0.0, 1.0};
  const FunnelProblem problem(setup.model, setup.reference, setup.gains, setup.costToGo, options);
  REQUIRE(problem.sampleCount() == 2 * 2 * 5);
  for (long g = 0; g < problem.sampleCount(); ++g) {
    const long cell = g / 5;
    const double t = options.startTimes[static_cast<std::size_t>(cell / 2)];
    const double rho = options.levels[static_cast<std::size_t>(cell % 2)];
    REQUIRE(setup.costToGo.level(t, problem.perturbation(g)) == Approx(rho).epsilon(1e-12));
  }
}

TEST_CASE("funnel: the same samples for 1 and 2 threads and for any split of the indices", "[funnel]") {
  Setup setup;
  FunnelOptions options;
  options.levels = {1.0, 20.0};
  options.samples = 4;
  options.startTimes = {0.0, 0.5};
  options.simulation.inputLower = VectorXd::Constant(1, -6.0);
  options.simulation.inputUpper = VectorXd::Constant(1, 6.0);
  options.threads = 1;
  const FunnelResult one = trellis::estimateFunnel(setup.model, setup.reference, setup.gains, setup.costToGo, options);
  REQUIRE(one.ok());
  options.threads = 2;
  const FunnelProblem problem(setup.model, setup.reference, setup.gains, setup.costToGo, options);
  // As three processes run them (every third index from 0, 1, 2), then sorted and summarized;
  // and as uneven blocks.
  std::vector<FunnelSample> joined, blocks;
  for (long r = 0; r < 3; ++r) {
    for (FunnelSample& s : problem.run(r, 16, 3)) joined.push_back(std::move(s));
  }
  std::sort(joined.begin(), joined.end(), [](const FunnelSample& a, const FunnelSample& b) { return a.index < b.index; });
  for (auto [b, e] : {std::pair<long, long>{0, 5}, {5, 6}, {6, 16}}) {
    for (FunnelSample& s : problem.run(b, e)) blocks.push_back(std::move(s));
  }
  for (std::size_t k = 0; k < blocks.size(); ++k) REQUIRE(sameSample(blocks[k], joined[k]));
  const FunnelResult split = problem.summarize(std::move(joined));
  REQUIRE(split.samples.size() == one.samples.size());
  for (std::size_t k = 0; k < one.samples.size(); ++k) REQUIRE(sameSample(one.samples[k], split.samples[k]));
  REQUIRE(one.json() == split.json());
  // Missing samples are refused, not summarized as a complete estimate.
  REQUIRE_THROWS_WITH(problem.summarize(problem.run(0, 5)), Catch::Contains("5 samples, expected 16"));
}

TEST_CASE("funnel: bad input is refused by name before any simulation", "[funnel]") {
  Setup setup;
  FunnelOptions options;
  options.levels = {1.0, std::nan("")};
  REQUIRE_THROWS_WITH(FunnelProblem(setup.model, setup.reference, setup.gains, setup.costToGo, options),
                      Catch::Contains("levels[1] = nan"));
  options.levels = {1.0};
  options.samples = 0;
  REQUIRE_THROWS_WITH(FunnelProblem(setup.model, setup.reference, setup.gains, setup.costToGo, options),
                      Catch::Contains("samples = 0"));
  options.samples = 3;
  options.startTimes = {0.05};
  REQUIRE_THROWS_WITH(FunnelProblem(setup.model, setup.reference, setup.gains, setup.costToGo, options),
                      Catch::Contains("is not a knot"));
  options.startTimes = {};
  const CostToGo wrong(VectorXd::LinSpaced(2, 0.0, 2.0), {MatrixXd::Identity(4, 4), MatrixXd::Identity(4, 4)});
  REQUIRE_THROWS_WITH(FunnelProblem(setup.model, setup.reference, setup.gains, wrong, options),
                      Catch::Contains("cost-to-go is 4x4") && Catch::Contains("2n = 2"));
  const CostToGo shorter(VectorXd::LinSpaced(2, 0.0, 1.0), {MatrixXd::Identity(2, 2), MatrixXd::Identity(2, 2)});
  REQUIRE_THROWS_WITH(FunnelProblem(setup.model, setup.reference, setup.gains, shorter, options),
                      Catch::Contains("covers [0, 1]"));
}

// Known answer. The inverted pendulum θ̈ = g sin θ + τ (m = L = 1) with |τ| ≤ τ_max cannot be held
// beyond sin θ = τ_max/g at all, and the saturated LQR's region of attraction (here: the starts
// that reach V(T) ≤ ρ_f by T) is a bounded set around the origin. Computed another way: along
// each of 72 rays δx(φ, r) = r L^{-T} (cos φ, sin φ) (S(0) = L Lᵀ, the Cholesky factor, so that
// V = r²), bisect the radius r*(φ) where success turns into failure. The funnel's directions are
// uniform in φ (a Gaussian z/|z| in the eigenbasis is uniform on the circle, and L^{-T} maps the
// circle to the same ellipse); so at level ρ the failing fraction is p(ρ) = #{φ: r*(φ)² < ρ}/72,
// and the sampled failures at ρ must be Binomial(N, p(ρ)): none below min r*², within
// 4 standard deviations (+1 for the 72-ray discretization of p) elsewhere.
TEST_CASE("funnel: torque-limited inverted pendulum against a bisection along rays", "[funnel]") {
  Setup setup(2.0);
  FunnelOptions options;
  const double tauMax = 4.0;  // sin θ_max = 4/9.81: held up to 0.42 rad at rest
  options.simulation.inputLower = VectorXd::Constant(1, -tauMax);
  options.simulation.inputUpper = VectorXd::Constant(1, tauMax);
  options.simulation.rtol = 1e-7;
  options.simulation.atol = 1e-9;
  options.goalLevel = 0.05;
  const trellis::SimulationOptions& sim = options.simulation;

  const MatrixXd S0 = setup.costToGo.evaluate(0.0), ST = setup.costToGo.evaluate(2.0);
  const Eigen::LLT<MatrixXd> llt(S0);
  INFO("S(0) = " << S0);
  const auto succeeds = [&](const VectorXd& dx) {
    const trellis::SimulationResult r = trellis::simulateClosedLoop(setup.model, setup.reference, setup.gains, dx, sim);
    if (!r.ok()) return false;
    const VectorXd end = r.trajectory.states().col(r.trajectory.size() - 1);
    return end.dot(ST * end) <= options.goalLevel;
  };
  // ρ*: along 72 rays the first failure (a geometric scan in r, ratio 1.1, then 24 bisections
  // between the last success and the first failure). The success set is not star-shaped far out
  // (a start that swings through the bottom can come back up), so only the first failure counts.
  constexpr int kRays = 72;
  const auto ray = [&](double phi) {
    return VectorXd(llt.matrixU().solve(VectorXd((VectorXd(2) << std::cos(phi), std::sin(phi)).finished())));
  };
  double rhoTrue = std::numeric_limits<double>::infinity();
  for (int k = 0; k < kRays; ++k) {
    const VectorXd unit = ray(2.0 * std::numbers::pi * k / kRays);
    double lo = 0.0, hi = 0.05;
    while (succeeds(hi * unit)) {
      lo = hi;
      hi *= 1.1;
      REQUIRE(hi < 100.0);  // V = 10^4: far outside any torque-limited hold
    }
    for (int it = 0; it < 24; ++it) {
      const double mid = 0.5 * (lo + hi);
      (succeeds(mid * unit) ? lo : hi) = mid;
    }
    rhoTrue = std::min(rhoTrue, lo * lo);
  }
  INFO("rho* = " << rhoTrue);
  options.levels = {0.5 * rhoTrue, 0.95 * rhoTrue, 1.5 * rhoTrue, 3.0 * rhoTrue};
  options.samples = 60;
  options.threads = 2;
  const FunnelResult result = trellis::estimateFunnel(setup.model, setup.reference, setup.gains, setup.costToGo, options);
  REQUIRE(result.ok());
  for (std::size_t j = 0; j < options.levels.size(); ++j) {
    const double rho = options.levels[j];
    // p(ρ): the failing fraction of 360 evenly spaced directions at exactly V = ρ.
    int failing = 0;
    for (int k = 0; k < 360; ++k) failing += succeeds(std::sqrt(rho) * ray(2.0 * std::numbers::pi * k / 360)) ? 0 : 1;
    const double p = failing / 360.0;
    const trellis::FunnelCell& cell = result.cells[j];
    const double failures = static_cast<double>(cell.samples - cell.successes);
    const double N = static_cast<double>(cell.samples);
    INFO("level " << rho << ": " << failures << " failures of " << cell.samples << ", p from 360 directions " << p);
    if (rho < rhoTrue) {
      REQUIRE(failures == 0);
    } else {
      REQUIRE(p > 0.1);  // the levels beyond ρ* are clearly outside: the estimate must see them
      REQUIRE(std::abs(failures - N * p) <= 4.0 * std::sqrt(N * p * (1.0 - p)) + 1.0);
    }
  }
  // The estimate: the two levels inside are clean, the levels beyond are not: ρ̂ = 0.95 ρ*.
  REQUIRE(result.rho(0) == options.levels[1]);
  REQUIRE(result.failureBound == Approx(1.0 - std::pow(0.05, 1.0 / 60.0)));
  REQUIRE(result.worstFailure[0] >= 2 * 60);
}
