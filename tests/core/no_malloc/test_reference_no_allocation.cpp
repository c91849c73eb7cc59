// tests/core/no_malloc/test_reference_no_allocation.cpp — ReferenceEvaluator's queries allocate
// nothing after its construction (see test_no_allocation.cpp for how the guard works).
#ifndef EIGEN_RUNTIME_NO_MALLOC
#error "compile with EIGEN_RUNTIME_NO_MALLOC (see tests/CMakeLists.txt)"
#endif

#include <catch2/catch.hpp>

#include "support/test_models.hpp"

#include <trellis/core.hpp>

#include <cmath>

using namespace trellis;

TEST_CASE("no allocation: ReferenceEvaluator::evaluate and linearize", "[no_malloc][reference]") {
  const test::TestSystem system = test::kitchenSink();
  const Model& model = system.model;
  const int n = model.nq(), m = model.nu(), N = 7;
  Eigen::VectorXd times = Eigen::VectorXd::LinSpaced(N, 0.0, 0.3);
  Eigen::MatrixXd x(2 * n, N), u(m, N), du(m, N);
  for (int k = 0; k < N; ++k) {
    for (int i = 0; i < 2 * n; ++i) x(i, k) = 0.1 * std::sin(0.7 * i + 3.0 * times(k));
    for (int i = 0; i < m; ++i) u(i, k) = 0.2 * std::cos(0.3 * i + 2.0 * times(k));
    for (int i = 0; i < m; ++i) du(i, k) = -0.4 * std::sin(0.3 * i + 2.0 * times(k));
  }
  // Supplied state derivatives: the kitchen sink's constraints need not hold at these states.
  Trajectory traj(model.configNames(), model.inputNames(), times, x, u);
  traj.setStateDerivatives(Eigen::MatrixXd::Constant(2 * n, N, 0.1));
  for (const bool cubicInput : {false, true}) {
    Trajectory t = traj;
    if (cubicInput) t.setInputDerivatives(du);
    ReferenceEvaluator ref(model, t);
    ref.linearize(0.01);  // warm-up: the workspace's lazily sized buffers
    int failures = 0;
    double sink = 0.0;
    Eigen::internal::set_is_malloc_allowed(false);
    for (int j = 0; j <= 40; ++j) {
      const double tj = 0.3 * j / 40.0;
      ref.evaluate(tj);
      sink += ref.xdot()(0) + ref.u()(0);
      if (!ref.linearize(tj).ok()) ++failures;
      sink += ref.A()(0, 0) + ref.B()(0, 0);
    }
    Eigen::internal::set_is_malloc_allowed(true);
    INFO("cubic input " << cubicInput << ", failures " << failures);
    CHECK(std::isfinite(sink));
  }
}
