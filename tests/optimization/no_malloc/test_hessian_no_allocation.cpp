// tests/optimization/no_malloc/test_hessian_no_allocation.cpp — Transcription::evalHessian
// allocates nothing through Eigen after construction and one warm-up call: the transcription and
// the core are compiled with EIGEN_RUNTIME_NO_MALLOC (tests/optimization/CMakeLists.txt), and an
// allocation while the guard is up aborts the program.
#ifndef EIGEN_RUNTIME_NO_MALLOC
#error "must be compiled with EIGEN_RUNTIME_NO_MALLOC (see tests/optimization/CMakeLists.txt)"
#endif

#include <catch2/catch.hpp>

#include "../skate_model.hpp"
#include <trellis/optimization/transcription.hpp>

#include <random>
#include <string>

namespace {

class MallocGuard {
 public:
  MallocGuard() { Eigen::internal::set_is_malloc_allowed(false); }
  ~MallocGuard() { Eigen::internal::set_is_malloc_allowed(true); }
  MallocGuard(const MallocGuard&) = delete;
  MallocGuard& operator=(const MallocGuard&) = delete;
};

}  // namespace

TEST_CASE("no_malloc: the Lagrangian Hessian's values allocate nothing", "[no_malloc][hessian]") {
  for (const char* name : {"acrobot_swingup", "paper_pendulum_transfer"}) {
    for (const bool freeHorizon : {false, true}) {
      for (const bool implicitForm : {false, true}) {
        DYNAMIC_SECTION(name << (freeHorizon ? " free T" : " fixed T") << (implicitForm ? " implicit" : " explicit")) {
          trellis::OptimalControlProblem p =
              trellis::loadProblem(std::string(TRELLIS_SOURCE_DIR) + "/examples/problems/" + name + ".json");
          p.knots = 5;
          if (p.model->nc() > 0) {
            p.forceUpper(0) = 100.0;  // the constraint-force rows (ρ) too
            trellis::OptimalControlProblem::ForceCombination c;  // and a combination (ρ = Cᵀ·multipliers)
            c.name = "combination";
            c.coefficients = Eigen::VectorXd::Constant(p.model->nc(), -0.5);
            c.upper = 1.0;
            p.forceCombinations.push_back(c);
          }
          if (freeHorizon) {
            p.minHorizon = 0.5 * p.horizon;
            p.maxHorizon = 2.0 * p.horizon;
          }
          if (implicitForm) {
            p.dynamics = trellis::DynamicsForm::kImplicit;
            p.accelerationWeights = Eigen::VectorXd::Constant(p.nq(), 0.01);  // the smoothness term
          }
          trellis::Transcription t(p);
          std::mt19937 rng(11);
          std::uniform_real_distribution<double> d(-0.2, 0.2);
          Eigen::VectorXd z = t.initialGuess(), z2 = z, mu(t.numConstraints());
          for (int i = 0; i < z.size(); ++i) z2(i) += d(rng);
          for (int i = 0; i < mu.size(); ++i) mu(i) = d(rng);
          Eigen::VectorXd values(t.hessianRows().size()), gradient(t.numVariables());
          REQUIRE(t.evalHessian(z.data(), 1.0, mu.data(), values.data()));  // warm-up
          bool ok = false;
          double cost = 0.0;
          {
            const MallocGuard guard;
            ok = t.evalHessian(z2.data(), 0.5, mu.data(), values.data());  // new iterate: dynamics too
            ok = ok && t.evalHessian(z2.data(), 1.0, mu.data(), values.data());  // cached dynamics
            ok = ok && t.evalCost(z2.data(), cost) && t.evalCostGradient(z2.data(), gradient.data());
          }
          CHECK(ok);
          CHECK(values.allFinite());
        }
      }
    }
  }
}

TEST_CASE("no_malloc: the Hessian with a knife edge beside a distance row allocates nothing",
          "[no_malloc][hessian][knife_edge]") {
  // The nonholonomic row's third-derivative terms come from the recorded implicit residual.
  const auto model = trellis::test::skateModel(true);
  for (const bool implicitForm : {false, true}) {
    DYNAMIC_SECTION((implicitForm ? "implicit" : "explicit")) {
      trellis::OptimalControlProblem p(model);
      p.knots = 4;
      p.setFixedHorizon(2.0);
      p.initialFixed.assign(p.nx(), false);
      p.finalFixed.assign(p.nx(), false);
      if (implicitForm) p.dynamics = trellis::DynamicsForm::kImplicit;
      trellis::Transcription t(p);
      std::mt19937 rng(5);
      std::uniform_real_distribution<double> d(-0.3, 0.3);
      Eigen::VectorXd z = t.initialGuess(), z2 = z, mu(t.numConstraints());
      for (int i = 0; i < z.size(); ++i) {
        z(i) += d(rng);
        z2(i) = z(i) + d(rng);
      }
      for (int i = 0; i < mu.size(); ++i) mu(i) = d(rng);
      Eigen::VectorXd values(t.hessianRows().size());
      REQUIRE(t.evalHessian(z.data(), 1.0, mu.data(), values.data()));  // warm-up
      bool ok = false;
      {
        const MallocGuard guard;
        ok = t.evalHessian(z2.data(), 0.5, mu.data(), values.data());
        ok = ok && t.evalHessian(z2.data(), 1.0, mu.data(), values.data());
      }
      CHECK(ok);
      CHECK(values.allFinite());
    }
  }
}
