// tests/core/test_loops_across_trees.cpp — constraint loops between two top-level trees that skip
// the blocks between them (issue 25): the hand holding a free ball (each contact row on one digit
// and the ball), a body held by two and by three arms, and two arms pinned tip to tip with a
// pendulum declared between them, and a body touched by point-on-plane contacts of 3, 2 and 1 rows. factorizeKkt and correctForConstraints walk such rows in runs
// on their two coordinate segments (DataWorkspace::rowGapLo/Hi, rowRunStart) instead of the
// group's whole range. Three legs: the run kernels against the hull kernels (the same model and
// state, ws.correctInRuns off: the path every group took before), q̈ and λ against a dense LU of
// the KKT system [M Aᵀ; A 0] (an independent factorization), and A, B against central differences
// of the dynamics.
#include <catch2/catch.hpp>

#include "support/linearization_checks.hpp"
#include "support/matrix_compare.hpp"
#include "support/random_state.hpp"
#include "support/held_models.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>

// The workspace is private to the library; this test switches its correction path (core/src on
// the path, as test_mass_factor.cpp).
#include "data_workspace.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>

#include <algorithm>
#include <limits>
#include <string>
#include <vector>

using namespace trellis;
using namespace trellis::test;

namespace {

struct AcrossCase {
  std::string name;
  Model model;
  State state;
};

std::vector<AcrossCase> acrossCases() {
  std::vector<AcrossCase> cases;
  {
    Scene scene = loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand_ball.json");
    State s;
    s.q = scene.q;
    s.dq = scene.dq;
    s.u = Eigen::VectorXd::Constant(scene.model.nu(), 3.0);
    REQUIRE(projectToConstraints(scene.model, s.q, s.dq));
    cases.push_back({"hand holding a free ball", std::move(scene.model), s});
  }
  const auto add = [&](const std::string& name, TestSystem sys, std::uint32_t seed) {
    std::mt19937 rng(seed);
    const State s = randomConsistentState(sys.model, rng, 0.5, 1.0, 1.0);
    cases.push_back({name, std::move(sys.model), s});
  };
  add("body held by three arms of 4", heldBody(3, 4), 2502);
  add("body held by two arms of 7", heldBody(2, 7), 2503);
  add("two arms of 5 pinned tip to tip, a pendulum between", twoArmClosedChain(5), 2504);
  add("body touched by contacts of 3, 2 and 1 rows", bodyHeldByContacts(), 2505);
  return cases;
}

}  // namespace

TEST_CASE("Loops across trees: rows in runs equal the hull path, a dense KKT solve and differences",
          "[kkt][across]") {
  for (AcrossCase& c : acrossCases()) {
    const Model& model = c.model;
    const State& s = c.state;
    const int n = model.nq(), nc = model.nc();
    INFO(c.name);
    Data runs(model), hull(model);
    // The new path is taken: some row skips the blocks between its two bodies' blocks.
    int skipping = 0;
    for (int r = 0; r < nc; ++r) skipping += detail::workspace(runs).rowGapHi[r] > detail::workspace(runs).rowGapLo[r];
    REQUIRE(skipping > 0);

    detail::workspace(hull).correctInRuns = false;
    REQUIRE(computeLinearization(model, runs, s.q, s.dq, s.u).ok());
    REQUIRE(computeLinearization(model, hull, s.q, s.dq, s.u).ok());

    // q̈, λ of the dense KKT system, solved by full-pivoting LU; tolerance κ·eps.
    const DenseKkt kkt = denseKktSolve(runs);
    const double kappa = kkt.condition;
    const double tol = 100.0 * kappa * std::numeric_limits<double>::epsilon();
    INFO("cond(K) = " << kappa);
    const Eigen::VectorXd& ref = kkt.solution;
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(ref.head(n)), Eigen::MatrixXd(runs.qdd), tol, Scale::kMatrix);
    // The KKT solution carries λ with the sign of M q̈ + b = Aᵀ λ.
    TRELLIS_CHECK_MATRIX(Eigen::MatrixXd(ref.tail(nc)), Eigen::MatrixXd(-runs.lambda), tol, Scale::kMatrix);

    // The same operations without the zeros in between, summed in another order: the two paths
    // differ by rounding, amplified at most by the KKT system's condition number (κ·eps; the
    // largest difference seen is 8e-12 of a column, on the hand's ball-roll column, κ = 9e6).
    const double same = std::max(1e-12, kappa * std::numeric_limits<double>::epsilon());
    TRELLIS_CHECK_MATRIX(hull.qdd, runs.qdd, same, Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(hull.lambda, runs.lambda, same, Scale::kMatrix);
    TRELLIS_CHECK_MATRIX(hull.A, runs.A, same, Scale::kColumn);
    TRELLIS_CHECK_MATRIX(hull.B, runs.B, same, Scale::kColumn);
    TRELLIS_CHECK_MATRIX(hull.dlambda_dx, runs.dlambda_dx, same, Scale::kColumn);

    // The fourth-order stencil, as test_hand_ball_scene.cpp: with κ up to 1e7 the second-order
    // stencil's error reached 1.8e-6 of the hand's ball-roll column at rest (both paths agree).
    checkLinearizationAgainstFd(model, s, kFdTolerance, 1.0, Stencil::kFourthOrder);
  }
}
