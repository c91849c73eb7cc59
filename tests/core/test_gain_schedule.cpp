// Tests for trellis/core/gain_schedule.hpp: validation, interpolation, sampling, CSV I/O.
#include <trellis/core/gain_schedule.hpp>
#include <trellis/core/trajectory.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Core>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <sstream>
#include <string>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::GainSchedule;
using trellis::TrajectoryError;

namespace {

// K(t) = K0 + t K1: linear in t, so piecewise-linear interpolation must reproduce it.
MatrixXd linearGain(double t) {
  MatrixXd K0(2, 3), K1(2, 3);
  K0 << 1.0, -2.0, 0.5, 3.0, 0.25, -1.5;
  K1 << 0.3, 1.1, -0.7, -2.0, 0.9, 0.05;
  return K0 + t * K1;
}

GainSchedule randomSchedule(std::mt19937& rng, int N, int m, int nx) {
  std::normal_distribution<double> normal(0.0, 10.0);
  std::uniform_real_distribution<double> gap(1e-3, 1.0);
  VectorXd t(N);
  std::vector<MatrixXd> K;
  double now = -0.37;
  for (int k = 0; k < N; ++k) {
    now += gap(rng);
    t(k) = now;
    MatrixXd G(m, nx);
    for (int j = 0; j < nx; ++j) {
      for (int i = 0; i < m; ++i) G(i, j) = normal(rng) * std::pow(10.0, (i + j) % 7 - 3);
    }
    K.push_back(G);
  }
  return GainSchedule(t, K);
}

std::string errorOf(const std::string& csv) {
  std::istringstream in(csv);
  try {
    GainSchedule::readCsv(in, "gains.csv");
  } catch (const TrajectoryError& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace

TEST_CASE("gain schedule: construction validates and names the offending index",
          "[gain_schedule]") {
  const VectorXd t = (VectorXd(3) << 0.0, 0.5, 1.0).finished();
  const std::vector<MatrixXd> K{linearGain(0.0), linearGain(0.5), linearGain(1.0)};
  const GainSchedule g(t, K);
  CHECK(g.nu() == 2);
  CHECK(g.nx() == 3);
  CHECK(g.size() == 3);
  CHECK(g.startTime() == 0.0);
  CHECK(g.endTime() == 1.0);

  SECTION("non-increasing time") {
    const VectorXd bad = (VectorXd(3) << 0.0, 0.5, 0.5).finished();
    REQUIRE_THROWS_AS(GainSchedule(bad, K), TrajectoryError);
    REQUIRE_THROWS_WITH(GainSchedule(bad, K), Catch::Contains("time 2"));
  }
  SECTION("non-finite time") {
    VectorXd bad = t;
    bad(1) = std::numeric_limits<double>::quiet_NaN();
    REQUIRE_THROWS_WITH(GainSchedule(bad, K), Catch::Contains("time 1"));
  }
  SECTION("count mismatch") {
    REQUIRE_THROWS_WITH(GainSchedule(t, {K[0], K[1]}), Catch::Contains("3 times but 2 gains"));
  }
  SECTION("size mismatch") {
    std::vector<MatrixXd> bad = K;
    bad[2] = MatrixXd::Zero(3, 2);
    REQUIRE_THROWS_WITH(GainSchedule(t, bad), Catch::Contains("gain 2 is 3x2"));
  }
  SECTION("non-finite entry") {
    std::vector<MatrixXd> bad = K;
    bad[1](1, 2) = std::numeric_limits<double>::infinity();
    REQUIRE_THROWS_WITH(GainSchedule(t, bad),
                        Catch::Contains("gain 1") && Catch::Contains("(1,2)"));
  }
  SECTION("empty") { REQUIRE_THROWS_AS(GainSchedule(VectorXd(0), {}), TrajectoryError); }
}

TEST_CASE("gain schedule: interpolation is exact for gains linear in t", "[gain_schedule]") {
  // Uneven spacing so that a wrong interval or weight cannot pass by symmetry.
  const VectorXd t = (VectorXd(5) << -1.0, -0.3, 0.2, 1.7, 2.0).finished();
  const GainSchedule g = GainSchedule::sample(linearGain, t);
  MatrixXd K;
  for (double s : {-1.0, -0.99, -0.3, 0.0, 0.19, 0.2, 1.0, 1.7, 1.95, 2.0}) {
    g.evaluate(s, K);
    // Rounding only: (1 − s)K_k + sK_{k+1} with |K| ≤ 5 and a few flops, so ~1e-15; 1e-13 leaves a
    // margin.
    CHECK((K - linearGain(s)).cwiseAbs().maxCoeff() < 1e-13);
  }
  // At the knots the stored gain comes back exactly.
  for (int k = 0; k < t.size(); ++k) CHECK(g.evaluate(t(k)) == g.gains()[k]);
  // A gain that is not linear (quadratic) is interpolated, not reproduced: midpoint error
  // h²/4·|K''|/2.
  const GainSchedule q =
      GainSchedule::sample([](double s) { return MatrixXd::Constant(1, 1, s * s); },
                           (VectorXd(2) << 0.0, 1.0).finished());
  CHECK(q.evaluate(0.5)(0, 0) == Approx(0.5).epsilon(1e-15));  // chord, not 0.25

  SECTION("outside the span throws, the relative slack is clamped") {
    CHECK_THROWS_AS(g.evaluate(2.0 + 1e-9, K), std::out_of_range);
    CHECK_THROWS_AS(g.evaluate(-1.0 - 1e-9, K), std::out_of_range);
    CHECK_NOTHROW(g.evaluate(2.0 + 1e-13, K));
    CHECK((K - linearGain(2.0)).cwiseAbs().maxCoeff() < 1e-13);
  }
  SECTION("a single time is a constant gain") {
    const GainSchedule one((VectorXd(1) << 3.0).finished(), {linearGain(3.0)});
    CHECK(one.evaluate(3.0) == linearGain(3.0));
    CHECK_THROWS_AS(one.evaluate(3.1), std::out_of_range);
  }
  SECTION("an empty schedule throws") {
    CHECK_THROWS_AS(GainSchedule().evaluate(0.0, K), std::logic_error);
  }
}

TEST_CASE("gain schedule: CSV round trip is exact", "[gain_schedule]") {
  std::mt19937 rng(20261122);
  for (auto [m, nx] : {std::pair{1, 1}, std::pair{1, 4}, std::pair{2, 3}, std::pair{3, 12}}) {
    const GainSchedule g = randomSchedule(rng, 7, m, nx);
    std::stringstream ss;
    g.writeCsv(ss);
    const GainSchedule back = GainSchedule::readCsv(ss);
    REQUIRE(back.nu() == m);
    REQUIRE(back.nx() == nx);
    REQUIRE(back.size() == g.size());
    CHECK(back.times() == g.times());  // 17 significant digits: bit-exact doubles
    for (int k = 0; k < g.size(); ++k) CHECK(back.gains()[k] == g.gains()[k]);
  }
  SECTION("header layout") {
    const GainSchedule g((VectorXd(1) << 0.0).finished(), {MatrixXd::Zero(2, 2)});
    std::ostringstream out;
    g.writeCsv(out);
    // A metadata line (sizes, continuous), then the unnamed header.
    const std::string text = out.str();
    const auto first = text.find('\n');
    CHECK(text.substr(0, first) == "# trellis gain schedule: m=2 nx=2 continuous (K(t) linear between rows)");
    CHECK(text.substr(first + 1, text.find('\n', first + 1) - first - 1) == "t,K_0_0,K_0_1,K_1_0,K_1_1");
  }
  SECTION("file round trip") {
    const GainSchedule g = randomSchedule(rng, 3, 2, 2);
    const std::string path = "trellis_test_gain_schedule_roundtrip.csv";
    g.writeCsvFile(path);
    const GainSchedule back = GainSchedule::readCsvFile(path);
    std::remove(path.c_str());
    CHECK(back.times() == g.times());
    CHECK(back.gains()[2] == g.gains()[2]);
    CHECK_THROWS_WITH(GainSchedule::readCsvFile("/nonexistent/dir/gains.csv"),
                      Catch::Contains("cannot open"));
  }
}

TEST_CASE("gain schedule: CSV errors name the row and the column", "[gain_schedule]") {
  const std::string header = "t,K_0_0,K_0_1,K_1_0,K_1_1\n";
  // A valid file parses (so the failures below come from the one defect each introduces).
  CHECK(errorOf(header + "0,1,2,3,4\n1,5,6,7,8\n") == "no error");

  CHECK_THAT(errorOf(""), Catch::Contains("empty file"));
  CHECK_THAT(errorOf("time,K_0_0\n0,1\n"),
             Catch::Contains("column 1") && Catch::Contains("'time'"));
  CHECK_THAT(errorOf("t\n0\n"), Catch::Contains("no gain columns"));
  CHECK_THAT(errorOf("t,K_1_0\n0,1\n"), Catch::Contains("column 2") && Catch::Contains("K_0_0"));
  // Column-major order is rejected: after K_0_0, K_0_1 (nx = 2) the next column must be K_1_0.
  CHECK_THAT(errorOf("t,K_0_0,K_0_1,K_1_1,K_1_0\n0,1,2,3,4\n"),
             Catch::Contains("column 4") && Catch::Contains("'K_1_1'") &&
                 Catch::Contains("expected 'K_1_0'"));
  CHECK_THAT(errorOf("t,K_0_0,K_0_1,K_1_0\n0,1,2,3\n"),
             Catch::Contains("not a multiple") && Catch::Contains("K_1_1"));
  CHECK_THAT(errorOf("t,K_0_0,K_0_1,gain\n0,1,2,3\n"),
             Catch::Contains("column 4") && Catch::Contains("'gain'"));

  CHECK_THAT(errorOf(header + "0,1,2,3,4\n1,5,x6,7,8\n"),
             Catch::Contains("row 2") && Catch::Contains("column 3") &&
                 Catch::Contains("'K_0_1'") && Catch::Contains("not a number"));
  CHECK_THAT(errorOf(header + "0,1,2,nan,4\n"), Catch::Contains("row 1") &&
                                                    Catch::Contains("column 4") &&
                                                    Catch::Contains("not finite"));
  CHECK_THAT(errorOf(header + "0,1,2,3,4\n1,5,6,,8\n"), Catch::Contains("row 2") &&
                                                            Catch::Contains("column 4") &&
                                                            Catch::Contains("not a number"));
  CHECK_THAT(errorOf(header + "0,1,2,3,4\n0,5,6,7,8\n"), Catch::Contains("row 2") &&
                                                             Catch::Contains("column 1") &&
                                                             Catch::Contains("not greater"));
  CHECK_THAT(errorOf(header + "0,1,2,3,4\n1,5,6,7\n"),
             Catch::Contains("row 2") && Catch::Contains("expected 5 columns, got 4"));
  CHECK_THAT(errorOf(header), Catch::Contains("no data rows"));
  // The file line is named too (blank lines are skipped but counted).
  CHECK_THAT(errorOf(header + "\n0,1,2,3,4\n\n1,5,6,7,bad\n"),
             Catch::Contains("row 2 (line 5)") && Catch::Contains("column 5"));
}

TEST_CASE("gain schedule: the cubic rule (parabola slopes from the table)", "[gain]") {
  // Non-uniform times; K(t) = quadratic entry by entry, reproduced exactly by the cubic rule.
  VectorXd t(5);
  t << 0.0, 0.3, 0.5, 1.2, 2.0;
  auto quad = [](double s) {
    MatrixXd K(2, 3);
    K << 1 + s, 2 * s * s - s, -3.0, s * s, 0.5 - s * s, 4 * s;
    return K;
  };
  std::vector<MatrixXd> gains;
  for (int k = 0; k < t.size(); ++k) gains.push_back(quad(t(k)));
  GainSchedule g(t, gains);
  REQUIRE(g.interpolation() == trellis::GainInterpolation::kLinear);
  const double tm = 0.8;
  CHECK((g.evaluate(tm) - quad(tm)).cwiseAbs().maxCoeff() > 1e-2);  // linear misses the parabola
  g.setInterpolation(trellis::GainInterpolation::kCubic);
  SECTION("exact on quadratics, equal to the rows at the rows") {
    for (double s : {0.0, 0.1, 0.3, 0.41, 0.8, 1.2, 1.9, 2.0}) {
      INFO("t = " << s);
      CHECK((g.evaluate(s) - quad(s)).cwiseAbs().maxCoeff() < 1e-13);
    }
    for (int k = 0; k < t.size(); ++k) CHECK(g.evaluate(t(k)) == gains[static_cast<std::size_t>(k)]);
  }
  SECTION("C1 at the rows on data that is not a polynomial") {
    std::vector<MatrixXd> wiggly;
    for (int k = 0; k < t.size(); ++k) wiggly.push_back(MatrixXd::Constant(1, 1, std::sin(5 * t(k)) + k % 2));
    GainSchedule w(t, wiggly);
    w.setInterpolation(trellis::GainInterpolation::kCubic);
    for (int k = 1; k + 1 < t.size(); ++k) {
      const double e = 1e-7, tk = t(k);
      const double left = (w.evaluate(tk)(0, 0) - w.evaluate(tk - e)(0, 0)) / e;
      const double right = (w.evaluate(tk + e)(0, 0) - w.evaluate(tk)(0, 0)) / e;
      INFO("row " << k << ": slope " << w.slopes()[static_cast<std::size_t>(k)](0, 0) << ", left " << left
                  << ", right " << right);
      // One-sided quotients with e = 1e-7: error ~ e·|K̈| (|K̈| ≲ 1e2 here) ~ 1e-5.
      CHECK(std::abs(left - right) < 1e-4);
      CHECK(std::abs(left - w.slopes()[static_cast<std::size_t>(k)](0, 0)) < 1e-4);
    }
    // The linear rule has a kink there.
    GainSchedule lin(t, wiggly);
    const double e = 1e-7, tk = t(2);
    const double left = (lin.evaluate(tk)(0, 0) - lin.evaluate(tk - e)(0, 0)) / e;
    const double right = (lin.evaluate(tk + e)(0, 0) - lin.evaluate(tk)(0, 0)) / e;
    CHECK(std::abs(left - right) > 1.0);
  }
  SECTION("third order on a smooth gain") {
    // Max error of K(t) = sin(3t) on uniform grids of N and 2N rows: ratio ≈ 8 (third order).
    auto maxError = [](int rows) {
      VectorXd tt = VectorXd::LinSpaced(rows, 0.0, 2.0);
      std::vector<MatrixXd> k;
      for (int i = 0; i < rows; ++i) k.push_back(MatrixXd::Constant(1, 1, std::sin(3 * tt(i))));
      GainSchedule s(tt, k);
      s.setInterpolation(trellis::GainInterpolation::kCubic);
      double worst = 0.0;
      for (int j = 0; j <= 2000; ++j) {
        const double x = 2.0 * j / 2000;
        worst = std::max(worst, std::abs(s.evaluate(x)(0, 0) - std::sin(3 * x)));
      }
      return worst;
    };
    const double e1 = maxError(21), e2 = maxError(41);
    INFO("errors " << e1 << ", " << e2);
    CHECK(e1 / e2 > 6.0);
    CHECK(e1 / e2 < 20.0);
  }
  SECTION("CSV round trip keeps the rule; a file without it is linear; a bad rule is refused") {
    std::stringstream ss;
    g.writeCsv(ss);
    CHECK(ss.str().find("interpolation=cubic") != std::string::npos);
    const GainSchedule back = GainSchedule::readCsv(ss, "mem");
    CHECK(back.interpolation() == trellis::GainInterpolation::kCubic);
    CHECK((back.evaluate(0.8) - g.evaluate(0.8)).cwiseAbs().maxCoeff() == 0.0);
    GainSchedule plain(t, gains);
    std::stringstream ps;
    plain.writeCsv(ps);
    CHECK(ps.str().find("interpolation") == std::string::npos);
    CHECK(GainSchedule::readCsv(ps, "mem").interpolation() == trellis::GainInterpolation::kLinear);
    std::istringstream bad("# trellis gain schedule: m=1 nx=1 continuous interpolation=spline\nt,K_0_0\n0,1\n");
    CHECK_THROWS_WITH(GainSchedule::readCsv(bad, "g.csv"),
                      Catch::Matchers::Contains("g.csv") && Catch::Matchers::Contains("interpolation=spline"));
  }
}

TEST_CASE("gain schedule: held feed-forward and the K[<input>|<state>] columns", "[gain_schedule]") {
  // Sampled gains at 10 Hz over [0, 0.3]: rows at 0, 0.1, 0.2, 0.3 (the last repeats).
  const VectorXd t = (VectorXd(4) << 0.0, 0.1, 0.2, 0.3).finished();
  std::vector<MatrixXd> K(4, MatrixXd::Constant(1, 2, 1.5));
  GainSchedule g(t, K);
  const std::vector<VectorXd> uff = {VectorXd::Constant(1, 1.0), VectorXd::Constant(1, 2.0),
                                     VectorXd::Constant(1, 3.0), VectorXd::Constant(1, 3.0)};
  SECTION("only for sampled gains, one finite m-vector per row") {
    CHECK_THROWS_WITH(g.setFeedforward(uff), Catch::Contains("needs sampled gains"));
    g.setSampleRate(10.0);
    CHECK_THROWS_WITH(g.setFeedforward({uff[0]}), Catch::Contains("1 feed-forward rows for 4 gain rows"));
    std::vector<VectorXd> bad = uff;
    bad[2] = VectorXd::Constant(2, 0.0);
    CHECK_THROWS_WITH(g.setFeedforward(bad), Catch::Contains("row 2 has 2 entries, expected m = 1"));
    bad[2] = VectorXd::Constant(1, std::numeric_limits<double>::quiet_NaN());
    CHECK_THROWS_WITH(g.setFeedforward(bad), Catch::Contains("row 2 (t = 0.2), entry 0 is nan"));
    CHECK_FALSE(g.hasFeedforward());
  }
  SECTION("the sample interval holding t: a sample time 1e-12 early still selects its own row") {
    g.setSampleRate(10.0);
    g.setFeedforward(uff);
    VectorXd u(1);
    const double h = 0.1;
    for (int k = 0; k < 3; ++k) {
      // t0 + k·h computed elsewhere may round below times(k): the 1e-9-of-a-period tolerance.
      g.evaluateFeedforward(k * h - 1e-12, u);
      CHECK(u(0) == uff[static_cast<std::size_t>(k)](0));
      g.evaluateFeedforward(k * h + 0.5 * h, u);
      CHECK(u(0) == uff[static_cast<std::size_t>(k)](0));
    }
    CHECK(g.rowAt(0.3) == 3);
    CHECK_THROWS_AS(g.rowAt(0.31), std::out_of_range);
    g.setSampleRate(10.0);  // the same rate keeps it
    CHECK(g.hasFeedforward());
    g.setSampleRate(20.0);  // another rate drops it (computed for 10 Hz)
    CHECK_FALSE(g.hasFeedforward());
    CHECK_THROWS_AS(g.evaluateFeedforward(0.0, u), std::logic_error);
  }
  SECTION("CSV round trip, named: K[<input>|<state>] then uff[<input>]") {
    g.setSampleRate(10.0);
    // State names with '_' and '|' are fine; the input's '|' would make the split ambiguous.
    CHECK_THROWS_WITH(g.setColumnNames({"a|b"}, {"q_1", "dq_1"}),
                      Catch::Contains("input name 'a|b' contains '|'"));
    g.setColumnNames({"push_x"}, {"q_1", "d|q"});
    g.setFeedforward(uff);
    std::stringstream ss;
    g.writeCsv(ss);
    const std::string text = ss.str();
    INFO(text);
    CHECK(text.find("apply u_k = uff_k - K_k (x(t_k) - x_ref(t_k))") != std::string::npos);
    CHECK(text.find("\nt,K[push_x|q_1],K[push_x|d|q],uff[push_x]\n") != std::string::npos);
    const GainSchedule back = GainSchedule::readCsv(ss, "mem");
    REQUIRE(back.hasFeedforward());
    CHECK(back.feedforward()[1](0) == 2.0);
    CHECK(back.sampleRate() == 10.0);
    CHECK_NOTHROW(back.checkNames({"push_x"}, {"q_1", "d|q"}, "mem"));
    CHECK_THROWS_WITH(back.checkNames({"push_y"}, {"q_1", "d|q"}, "mem"),
                      Catch::Contains("column 2 is 'K[push_x|q_1]'"));
  }
  SECTION("unnamed: uff_<i>; a file without it is read without a feed-forward") {
    g.setSampleRate(10.0);
    g.setFeedforward(uff);
    std::stringstream ss;
    g.writeCsv(ss);
    CHECK(ss.str().find("\nt,K_0_0,K_0_1,uff_0\n") != std::string::npos);
    const GainSchedule back = GainSchedule::readCsv(ss, "mem");
    CHECK(back.hasFeedforward());
    CHECK(back.columnNames().empty());
    std::stringstream older("# trellis gain schedule: m=1 nx=2 sample_rate_hz=10\nt,K_0_0,K_0_1\n0,1,2\n0.1,1,2\n");
    CHECK_FALSE(GainSchedule::readCsv(older, "older").hasFeedforward());
  }
  SECTION("the older named form K_<input>_<state> is read and checked by position") {
    // 'a_b' × 'c' and 'a' × 'b_c' give the same older name: only the position tells them apart.
    std::stringstream older("# trellis gain schedule: m=1 nx=2 sample_rate_hz=10\nt,K_a_b_c,K_a_b_dc\n0,1,2\n0.1,1,2\n");
    const GainSchedule back = GainSchedule::readCsv(older, "older");
    CHECK_NOTHROW(back.checkNames({"a_b"}, {"c", "dc"}, "older"));
    CHECK_THROWS_WITH(back.checkNames({"a_b"}, {"d", "dd"}, "older"),
                      Catch::Contains("column 2 is 'K_a_b_c', but the scene's gain column there is 'K_a_b_d'"));
    std::stringstream mixed("# trellis gain schedule: m=1 nx=2 sample_rate_hz=10\nt,K[a|c],K_a_dc\n0,1,2\n");
    CHECK_THROWS_WITH(GainSchedule::readCsv(mixed, "mixed"),
                      Catch::Contains("column 3 ('K_a_dc'): expected a gain name K[<input>|<state>]"));
    std::stringstream noUff("# trellis gain schedule: m=1 nx=2 sample_rate_hz=10\nt,K[a|c],K[a|dc],v\n0,1,2,3\n");
    CHECK_THROWS_WITH(GainSchedule::readCsv(noUff, "noUff"),
                      Catch::Contains("column 4 ('v'): expected a feed-forward name uff[<input>]"));
  }
}
