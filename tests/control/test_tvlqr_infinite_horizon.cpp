// test_tvlqr_infinite_horizon.cpp — TvlqrOptions::infiniteHorizon (issue 27 part 2): on a held
// pose Qf := S∞ makes every row the stationary gain, continuous (CARE) and sampled (DARE), on the
// constraint manifold's tangent space when there are constraints; a moving reference is refused.
#include "control_test_support.hpp"

#include <trellis/control/care.hpp>
#include <trellis/control/tvlqr.hpp>
#include <trellis/core/data.hpp>
#include <trellis/core/model.hpp>
#include <trellis/core/trajectory.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Core>

#include <cmath>

using Eigen::MatrixXd;
using Eigen::VectorXd;
using trellis::Trajectory;

namespace {

Trajectory heldPose(const trellis::Model& model, double T) {
  const int nx = 2 * model.nq();
  Trajectory ref(model.configNames(), model.inputNames(), (VectorXd(3) << 0.0, 0.5 * T, T).finished(),
                 MatrixXd::Zero(nx, 3), MatrixXd::Zero(model.nu(), 3));
  ref.setStateDerivatives(MatrixXd::Zero(nx, 3));
  return ref;
}

}  // namespace

TEST_CASE("infinite horizon on a held pose: every row is the stationary gain", "[tvlqr][infinite_horizon]") {
  SECTION("constrained: two carts moving together, the CARE of the tangent double integrator") {
    // Tangent coordinates (orthonormal): z1 = (x1 + x2)/√2, z2 its rate; z̈1 = u/√2 (mass 2), so
    // with Q = I, R = 1 the CARE of ż = [[0,1],[0,0]] z + [0; b] u, b = 1/√2, has the closed form
    // K = [1, √(2/b + 1)]: a common shift δ of both carts (|z1| = √2 δ) is met by K·(1,1,0,0) = √2,
    // a common velocity by √2 √(2√2 + 1).
    const trellis::Model model = trellis::ctest::makeConstrainedCarts();
    trellis::LqrWeights w;
    w.Q = MatrixXd::Identity(4, 4);
    w.R = MatrixXd::Identity(1, 1);
    w.Qf = 1e3 * w.Q;  // not used: replaced by S∞
    trellis::TvlqrOptions opt;
    opt.infiniteHorizon = true;
    opt.riccati.rtol = 1e-11;
    opt.riccati.atol = 1e-12;
    const trellis::TvlqrSolution sol = trellis::solveTvlqr(model, heldPose(model, 5.0), w, opt);
    REQUIRE(sol.ok());
    CHECK(sol.infiniteHorizon);
    CHECK(sol.constrained);
    INFO(sol.summary());
    // The Riccati ODE started at its fixed point stays there to its tolerance (measured ~1e-10).
    CHECK(sol.maxGainDeviation < 1e-8);
    const VectorXd shift = (VectorXd(4) << 1.0, 1.0, 0.0, 0.0).finished();
    const VectorXd drift = (VectorXd(4) << 0.0, 0.0, 1.0, 1.0).finished();
    for (const MatrixXd& K : sol.gains.gains()) {
      CHECK((K * shift)(0) == Approx(std::sqrt(2.0)).epsilon(1e-8));
      CHECK((K * drift)(0) == Approx(std::sqrt(2.0) * std::sqrt(2.0 * std::sqrt(2.0) + 1.0)).epsilon(1e-8));
    }
    CHECK(sol.summary().find("infinite horizon: Qf = S_inf of the CARE: ok") != std::string::npos);
  }
  SECTION("sampled: the DARE gain at every sample, the finite horizon's last row differs") {
    const trellis::Model model = trellis::ctest::makeCartPole();
    trellis::LqrWeights w;
    w.Q = MatrixXd::Identity(4, 4);
    w.R = MatrixXd::Identity(1, 1);
    w.Qf = w.Q;
    trellis::TvlqrOptions opt;
    opt.sampleRate = 50.0;
    const trellis::TvlqrSolution finite = trellis::solveTvlqr(model, heldPose(model, 4.0), w, opt);
    opt.infiniteHorizon = true;
    const trellis::TvlqrSolution inf = trellis::solveTvlqr(model, heldPose(model, 4.0), w, opt);
    REQUIRE(finite.ok());
    REQUIRE(inf.ok());
    CHECK(inf.maxGainDeviation < 1e-12);  // the recursion from its fixed point: rounding only
    const MatrixXd& Kinf = inf.gains.gains().front();
    CHECK((inf.gains.gains().back() - Kinf).norm() < 1e-12 * Kinf.norm());
    // Without it, the terminal layer: the last sample's gain is far from the stationary one
    // (the control that shows the check can fail).
    const MatrixXd& Klast = finite.gains.gains()[static_cast<std::size_t>(finite.gains.size() - 2)];
    CHECK((Klast - Kinf).norm() > 0.1 * Kinf.norm());
  }
  SECTION("a moving reference or time-varying weights are refused") {
    const trellis::Model model = trellis::ctest::makeCartPole();
    trellis::LqrWeights w;
    w.Q = MatrixXd::Identity(4, 4);
    w.R = MatrixXd::Identity(1, 1);
    w.Qf = w.Q;
    trellis::TvlqrOptions opt;
    opt.infiniteHorizon = true;
    Trajectory moving = heldPose(model, 1.0);
    MatrixXd X = moving.states();
    X(1, 2) = 0.1;
    Trajectory tilted(model.configNames(), model.inputNames(), moving.times(), X, moving.inputs());
    CHECK_THROWS_WITH(trellis::solveTvlqr(model, tilted, w, opt),
                      Catch::Contains("needs a held pose") && Catch::Contains("knot 2 (t = 1)"));
    w.Qfun = [](double, MatrixXd& Q) { Q = MatrixXd::Identity(4, 4); };
    CHECK_THROWS_WITH(trellis::solveTvlqr(model, heldPose(model, 1.0), w, opt),
                      Catch::Contains("needs constant weights"));
  }
}
