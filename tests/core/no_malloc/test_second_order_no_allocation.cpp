// tests/core/no_malloc/test_second_order_no_allocation.cpp — the second-order functions allocate
// nothing through Eigen after the workspace is built and one warm-up call (see
// test_no_allocation.cpp for the mechanism: an allocation under the guard aborts the program).
#ifndef EIGEN_RUNTIME_NO_MALLOC
#error "must be compiled with EIGEN_RUNTIME_NO_MALLOC (see tests/CMakeLists.txt)"
#endif

#include <catch2/catch.hpp>

#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>
#include <trellis/core/second_order.hpp>

#include <initializer_list>
#include <string>
#include <vector>

using namespace trellis;
using namespace trellis::test;

namespace {

class MallocGuard {
 public:
  MallocGuard() { Eigen::internal::set_is_malloc_allowed(false); }
  ~MallocGuard() { Eigen::internal::set_is_malloc_allowed(true); }
  MallocGuard(const MallocGuard&) = delete;
  MallocGuard& operator=(const MallocGuard&) = delete;
};

void checkNoAllocation(const Model& model, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<State> states;
  for (int k = 0; k < 3; ++k) states.push_back(randomState(model, rng));
  const int n = model.nq(), N = 2 * n + model.nu();
  Data data(model);
  SecondOrderWorkspace ws(model);
  const Eigen::VectorXd w = uniformVector(rng, n, -1.0, 1.0), rho = uniformVector(rng, model.nc(), -1.0, 1.0);
  const Eigen::VectorXd none;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(N, N);
  computeSecondOrderTensors(model, data, ws, states[0].q, states[0].dq, states[0].u);  // warm-up
  computeSecondOrderContraction(model, data, ws, states[0].q, states[0].dq, states[0].u, w, rho, H);
  std::vector<DynamicsStatus::Code> codes;
  codes.reserve(2 * states.size() + 2);
  {
    MallocGuard guard;
    for (const State& s : states) {
      codes.push_back(computeSecondOrderTensors(model, data, ws, s.q, s.dq, s.u).code);
      codes.push_back(computeSecondOrderContraction(model, data, ws, s.q, s.dq, s.u, w, rho, H).code);
      computeSecondOrderContraction(model, data, ws, s.q, s.dq, s.u, w, none, H);
    }
  }
  for (const auto c : codes) CHECK(c != DynamicsStatus::Code::kNonFinite);
  CHECK(H.allFinite());
}

}  // namespace

TEST_CASE("No allocation after warm-up: second derivatives, every element, unconstrained",
          "[no_malloc][second_order]") {
  checkNoAllocation(kitchenSink(3, false).model, 71);
}

TEST_CASE("No allocation after warm-up: second derivatives with every constraint kind",
          "[no_malloc][second_order]") {
  checkNoAllocation(kitchenSink(3, true).model, 72);
}

TEST_CASE("No allocation after warm-up: second derivatives with redundant constraints",
          "[no_malloc][second_order]") {
  checkNoAllocation(paperPendulum(2).model, 73);  // the pseudo-inverse path
}

TEST_CASE("No allocation after warm-up: second derivatives with coordinate couplings (mimic)",
          "[no_malloc][second_order]") {
  checkNoAllocation(mimicChain(), 74);
}

TEST_CASE("No allocation after warm-up: second derivatives on the tree pass", "[no_malloc][second_order]") {
  // planarChain(18): q blocks and q̇ blocks of 16 and 4 lanes each (two of each pass, and the
  // per-call values); transformChain: 4-lane blocks alone.
  checkNoAllocation(planarChain(18, 0.5, 1.0).model, 75);
  checkNoAllocation(transformChain(TransformType::kRotAxis).model, 76);
}

namespace {

/// Chains of `links` joints each hanging from the world (alternating rz, rx; a 0.2 kg bob per
/// joint, 0.4 below it; frames c<links>_<k>, c<links>_<k>_bob), each driven at its first joint.
void addChains(SystemBuilder& s, std::initializer_list<int> chains) {
  for (const int links : chains) {
    std::string parent = "world";
    const std::string prefix = std::string("c").append(std::to_string(links)).append("_");
    for (int k = 0; k < links; ++k) {
      const std::string joint = std::string(prefix).append(std::to_string(k));
      s.frame(joint, parent, k % 2 == 0 ? Transform::rz(std::string("q_").append(joint)) : Transform::rx(std::string("q_").append(joint)));
      s.frame(std::string(joint).append("_bob"), joint, Transform::ty(-0.4), Mass{0.2, Eigen::Matrix3d::Identity() * 1e-3});
      parent = std::string(joint).append("_bob");
    }
    s.b.addConfigForce(std::string("q_").append(prefix).append("0"), std::string("u_").append(prefix));
  }
}

}  // namespace

TEST_CASE("No allocation after warm-up: second derivatives on the tree pass of a forest", "[no_malloc][second_order]") {
  // Three chains hanging from the world (3, 5 and 18 joints): the tree pass's blocks per
  // subtree, the 18-joint one in two blocks of each pass.
  SystemBuilder s;
  addChains(s, {3, 5, 18});
  s.b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
  checkNoAllocation(std::move(s).finish().model, 77);
}

TEST_CASE("No allocation after warm-up: second derivatives on the tree pass with point rows and a tendon",
          "[no_malloc][second_order]") {
  // Two chains (4 and 18 joints) whose tips are held together by two point rows (one component,
  // two blocks of each pass), a 3-joint chain with its tip pinned to the world (three rows), and a
  // tendon from the world across the 3- and 4-joint chains: the tree pass with its site terms.
  SystemBuilder s;
  addChains(s, {3, 4, 18});
  s.frame("anchor", "world", Transform::ty(-1.0));
  for (int axis = 0; axis < 3; ++axis) s.b.addPointConstraint("c3_2_bob", "anchor", axis);
  s.b.addPointConstraint("c4_3_bob", "c18_17_bob", 0);
  s.b.addPointConstraint("c4_3_bob", "c18_17_bob", 2);
  s.b.addTendon({"anchor", "c3_0_bob", "c3_1_bob", "c4_2_bob"}, "u_tendon");  // joins the 3- and 4-chains
  s.b.addGravity(Eigen::Vector3d(0.0, -9.81, 0.0));
  checkNoAllocation(std::move(s).finish().model, 78);
}
