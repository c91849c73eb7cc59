// tests/core/no_malloc/test_no_allocation.cpp — after set-up and one warm-up call, no algorithm
// allocates (STYLE.md "No allocation after set-up, and a test that proves it").
//
// This program links a copy of trellis::core compiled with EIGEN_RUNTIME_NO_MALLOC and with
// assertions on (tests/CMakeLists.txt). While Eigen::internal::set_is_malloc_allowed(false) is in
// force, any heap allocation through Eigen fails an eigen_assert, which aborts the program: the
// test program then exits non-zero and CTest reports the failure, with the assertion text naming
// the allocation on stderr. (An abort rather than a Catch2 failure is accepted: eigen_assert is
// compiled into the library, where the test cannot intercept it.) Allocations through std::string
// or std::vector are not seen by Eigen's guard; the workspace's Eigen buffers are what it checks.
//
// Every state, input and output vector is created before the guard goes up, and results are
// checked after it comes down, so nothing in the test itself allocates inside the guarded region.
#ifndef EIGEN_RUNTIME_NO_MALLOC
#error \
    "test_no_allocation.cpp must be compiled with EIGEN_RUNTIME_NO_MALLOC (see tests/CMakeLists.txt)"
#endif

#include <catch2/catch.hpp>

#include "support/random_state.hpp"
#include "support/held_models.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>
#include <trellis/core/numdiff.hpp>

#include <array>
#include <string>
#include <vector>

using namespace trellis;
using namespace trellis::test;

namespace {

/// Lifts Eigen's malloc guard for the lifetime of the object (also if a REQUIRE throws).
class MallocGuard {
 public:
  MallocGuard() { Eigen::internal::set_is_malloc_allowed(false); }
  ~MallocGuard() { Eigen::internal::set_is_malloc_allowed(true); }
  MallocGuard(const MallocGuard&) = delete;
  MallocGuard& operator=(const MallocGuard&) = delete;
};

constexpr int kStates = 4;
constexpr int kRepeats = 5;

std::vector<State> makeStates(const Model& model, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<State> states;
  for (int k = 0; k < kStates; ++k) states.push_back(randomState(model, rng));
  return states;
}

/// One call of every algorithm (the warm-up), so that any lazily sized buffer has its size.
void warmUp(const Model& model, Data& data, const State& s) {
  computeKinematics(model, data, s.q, s.dq);
  computeMassMatrix(model, data, s.q);
  computeConstraints(model, data, s.q, s.dq);
  computeInputMatrix(model, data, s.q);
  computeDynamics(model, data, s.q, s.dq, s.u);
  computeEnergy(model, data, s.q, s.dq);
  computeNonConservativePower(model, data, s.q, s.dq, s.u);
  computeLinearization(model, data, s.q, s.dq, s.u);
}

/// The hot calls, repeatedly, at several states, under the guard. Returns how many calls reported
/// a status that is not ok (checked by the caller outside the guarded region).
int runGuarded(const Model& model, Data& data, const std::vector<State>& states) {
  int notOk = 0;
  double sink = 0.0;
  {
    MallocGuard guard;
    for (int r = 0; r < kRepeats; ++r) {
      for (const State& s : states) {
        computeKinematics(model, data, s.q, s.dq);
        if (!computeDynamics(model, data, s.q, s.dq, s.u).ok()) ++notOk;
        if (!computeLinearization(model, data, s.q, s.dq, s.u).ok()) ++notOk;
        computeMassMatrix(model, data, s.q);
        computeConstraints(model, data, s.q, s.dq);
        computeInputMatrix(model, data, s.q);
        sink += computeEnergy(model, data, s.q, s.dq).total();
        sink += computeNonConservativePower(model, data, s.q, s.dq, s.u);
      }
    }
  }
  (void)sink;
  return notOk;
}

}  // namespace

// One TEST_CASE per path, so that CTest (one process per test case) reports each separately: an
// abort in one does not hide the others.
TEST_CASE("No allocation after warm-up: every element type, unconstrained", "[no_malloc]") {
  const Model model = kitchenSink(3, false).model;
  const std::vector<State> states = makeStates(model, 4101);
  Data data(model);
  warmUp(model, data, states[0]);
  CHECK(runGuarded(model, data, states) == 0);
  CHECK(Eigen::internal::is_malloc_allowed());
}

TEST_CASE("No allocation after warm-up: holonomic and nonholonomic constraints", "[no_malloc]") {
  const Model model = kitchenSink(3, true).model;
  const std::vector<State> states = makeStates(model, 4102);
  Data data(model);
  warmUp(model, data, states[0]);
  CHECK(runGuarded(model, data, states) == 0);
  CHECK(data.status.code == DynamicsStatus::Code::kOk);
}

TEST_CASE("No allocation after warm-up: coordinate couplings (URDF mimic)", "[no_malloc]") {
  const Model model = mimicChain();
  const std::vector<State> states = makeStates(model, 4108);
  Data data(model);
  warmUp(model, data, states[0]);
  CHECK(runGuarded(model, data, states) == 0);
}

TEST_CASE("No allocation after warm-up: redundant constraints (rank-deficient solve)",
          "[no_malloc]") {
  const Model model = paperPendulum(2).model;
  const std::vector<State> states = makeStates(model, 4103);
  Data data(model);
  warmUp(model, data, states[0]);
  // Redundant constraints are reported (kRedundantConstraints, not ok) but solved: every
  // dynamics and linearization call returns that status, none allocates.
  CHECK(runGuarded(model, data, states) == 2 * kRepeats * static_cast<int>(states.size()));
  CHECK(data.status.code == DynamicsStatus::Code::kRedundantConstraints);
}

TEST_CASE("No allocation after warm-up: tangent basis", "[no_malloc][tangent]") {
  const Model model = kitchenSink(3, true).model;
  std::mt19937 rng(4201);
  std::vector<State> states;
  for (int k = 0; k < kStates; ++k) states.push_back(randomConsistentState(model, rng));
  Data data(model);
  warmUp(model, data, states[0]);
  computeConstraintTangentBasis(model, data);
  std::array<int, kStates> dims{};
  {
    MallocGuard guard;
    for (int k = 0; k < kStates; ++k) {
      computeLinearization(model, data, states[static_cast<std::size_t>(k)].q,
                           states[static_cast<std::size_t>(k)].dq,
                           states[static_cast<std::size_t>(k)].u);
      dims[static_cast<std::size_t>(k)] = computeConstraintTangentBasis(model, data);
    }
  }
  for (int d : dims) CHECK(d == 2 * model.nq() - 2 * 3 - 1);
}

TEST_CASE("no allocation: finite differences of the dynamics (numdiff)", "[no_malloc][numdiff]") {
  // differenceDynamics is the optimizer's finite-difference mode at every collocation point: its
  // workspace and J are sized once, then every scheme runs with the guard up.
  const TestSystem sys = paperPendulum();
  const Model& model = sys.model;
  Data data(model);
  NumDiffWorkspace ws(model);
  Eigen::MatrixXd J(model.nq(), 2 * model.nq() + model.nu());
  const std::vector<State> states = makeStates(model, 515);
  bool ok = true;
  for (const DifferenceScheme scheme :
       {DifferenceScheme::kForward, DifferenceScheme::kCentral, DifferenceScheme::kCentralFourthOrder}) {
    NumDiffOptions o;
    o.scheme = scheme;
    ok = differenceDynamics(model, data, states[0].q, states[0].dq, states[0].u, o, ws, J).ok() && ok;
    MallocGuard guard;
    for (const State& s : states) ok = differenceDynamics(model, data, s.q, s.dq, s.u, o, ws, J).ok() && ok;
  }
  CHECK(ok);
  CHECK(J.allFinite());
}

TEST_CASE("No allocation after warm-up: a long chain (dense Cholesky block)", "[no_malloc]") {
  // 14 joints in one unbranched block: the mass matrix goes through the dense-chain path.
  const Model model = planarChain(14).model;
  const std::vector<State> states = makeStates(model, 4104);
  Data data(model);
  warmUp(model, data, states[0]);
  CHECK(runGuarded(model, data, states) == 0);
}

TEST_CASE("No allocation after warm-up: the hand scene (tree blocks, tendons, grouped rows)",
          "[no_malloc][hand]") {
  // Five digit blocks factored along the tree, 23 tendons, 15 constraint rows in five groups of
  // A M⁻¹ Aᵀ; the stored state lies on the constraint manifold.
  const Scene scene = loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand.json");
  const Model& model = scene.model;
  std::vector<State> states(2);
  states[0].q = scene.q;
  states[0].dq = scene.dq;
  states[0].u = Eigen::VectorXd::Constant(model.nu(), 2.0);
  states[1] = states[0];
  states[1].u = Eigen::VectorXd::Constant(model.nu(), 5.0);
  Data data(model);
  warmUp(model, data, states[0]);
  CHECK(runGuarded(model, data, states) == 0);
}

TEST_CASE("No allocation after warm-up: loops across top-level trees (rows in runs)", "[no_malloc][across]") {
  // The hand holding a free ball (15 rows, each on one digit's block and the ball's, one group)
  // and a body held by three arms: the correction walks the rows in runs on their two segments.
  const Scene scene = loadScene(std::string(TRELLIS_SOURCE_DIR) + "/examples/scenes/hand_ball.json");
  std::vector<State> ball(2);
  ball[0].q = scene.q;
  ball[0].dq = scene.dq;
  ball[0].u = Eigen::VectorXd::Constant(scene.model.nu(), 2.0);
  ball[1] = ball[0];
  ball[1].u = Eigen::VectorXd::Constant(scene.model.nu(), 5.0);
  Data ballData(scene.model);
  warmUp(scene.model, ballData, ball[0]);
  CHECK(runGuarded(scene.model, ballData, ball) == 0);

  const Model held = heldBody(3, 4).model;
  std::mt19937 rng(4105);
  std::vector<State> states;
  for (int k = 0; k < 2; ++k) states.push_back(randomConsistentState(held, rng, 0.5));
  Data data(held);
  warmUp(held, data, states[0]);
  CHECK(runGuarded(held, data, states) == 0);
}
