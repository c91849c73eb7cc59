// bench/robots_bench.cpp — the real robots of tests/data/robots (URDF) and the arbitrary-axis joint.
//
//   RobotLinearization/<robot>     computeLinearization at a seeded random state (A, B exact)
//   RobotLinearizationFD/<robot>   central differences of computeDynamics (2(2n+m) evaluations)
//   AxisChain/<kind>/N:20          computeLinearization of a 20-joint chain of tilted r_axis joints
//                                  (kind "r_axis") or of the same joints built as const_se3 · rz ·
//                                  const_se3 sandwiches (kind "sandwich")
// Counters: nq, nu; on the exact rows ref_err (against one Richardson step on central differences,
// the measure of finite_differences.hpp), on the FD rows max_rel_err (against the exact result);
// on AxisChain/sandwich max_diff, max |A_axis − A_sandwich| / max(1, max|A_axis|).
#include "finite_differences.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model_builder.hpp"
#include "trellis/core/urdf.hpp"

#include <benchmark/benchmark.h>

#include <Eigen/Geometry>

#include <cmath>
#include <limits>
#include <random>
#include <string>

namespace {

const double kEps = std::numeric_limits<double>::epsilon();

struct Fixture {
  trellis::Model model;
  Eigen::VectorXd q, dq, u;
};

Fixture withState(trellis::Model model, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-1.0, 1.0);
  Fixture f{std::move(model), {}, {}, {}};
  const int n = f.model.nq(), m = f.model.nu();
  f.q = Eigen::VectorXd::NullaryExpr(n, [&] { return d(rng); });
  f.dq = Eigen::VectorXd::NullaryExpr(n, [&] { return d(rng); });
  f.u = Eigen::VectorXd::NullaryExpr(m, [&] { return 0.1 * d(rng); });
  return f;
}

Eigen::MatrixXd exactJ(const Fixture& f, trellis::Data& data) {
  const int n = f.model.nq(), m = f.model.nu();
  trellis::computeLinearization(f.model, data, f.q, f.dq, f.u);
  Eigen::MatrixXd J(n, 2 * n + m);
  J << data.dqdd_dq, data.dqdd_ddq, data.dqdd_du;
  return J;
}

void robotExact(benchmark::State& state, const std::string& file) {
  const Fixture f = withState(trellis::loadUrdf(std::string(TRELLIS_ROBOTS_DIR) + "/" + file).model, 7);
  trellis::Data data(f.model);
  for (auto _ : state) {
    trellis::computeLinearization(f.model, data, f.q, f.dq, f.u);
    benchmark::DoNotOptimize(data.A.data());
  }
  const Eigen::MatrixXd J = exactJ(f, data);
  trellis::bench::FdWorkspace ws(f.model);
  Eigen::MatrixXd ref(J.rows(), J.cols());
  trellis::bench::richardsonDifferences(f.model, data, f.q, f.dq, f.u, std::pow(kEps, 0.2), ws, ref);
  state.counters["nq"] = f.model.nq();
  state.counters["nu"] = f.model.nu();
  state.counters["ref_err"] = trellis::bench::maxRelativeError(J, ref);
}

void robotFd(benchmark::State& state, const std::string& file) {
  const Fixture f = withState(trellis::loadUrdf(std::string(TRELLIS_ROBOTS_DIR) + "/" + file).model, 7);
  trellis::Data data(f.model);
  trellis::bench::FdWorkspace ws(f.model);
  Eigen::MatrixXd J(f.model.nq(), 2 * f.model.nq() + f.model.nu());
  for (auto _ : state) {
    trellis::bench::centralDifferences(f.model, data, f.q, f.dq, f.u, std::cbrt(kEps), ws, J);
    benchmark::DoNotOptimize(J.data());
  }
  state.counters["nq"] = f.model.nq();
  state.counters["nu"] = f.model.nu();
  state.counters["max_rel_err"] = trellis::bench::maxRelativeError(J, exactJ(f, data));
}

/// 20 joints about tilted unit axes, each followed by a link frame with a mass; as r_axis frames or
/// as const_se3(Ra) · rz · const_se3(Raᵀ) sandwiches.
trellis::Model axisChain(bool sandwich, int n = 20) {
  trellis::ModelBuilder b;
  std::string parent = "world";
  for (int i = 0; i < n; ++i) {
    const std::string k = std::to_string(i), joint = "j" + k, link = "l" + k, q = "q" + k;
    const Eigen::Vector3d axis = Eigen::Vector3d(std::sin(0.7 * i), std::cos(1.3 * i), 0.5).normalized();
    if (!sandwich) {
      b.addFrame(joint, parent, trellis::Transform::rotAxis(axis, q));
    } else {
      Eigen::Matrix4d Ra = Eigen::Matrix4d::Identity();
      Ra.topLeftCorner<3, 3>() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), axis).toRotationMatrix();
      b.addFrame(joint + "_pre", parent, trellis::Transform::constSE3(Ra));
      b.addFrame(joint + "_rz", joint + "_pre", trellis::Transform::rz(q));
      b.addFrame(joint, joint + "_rz", trellis::Transform::constSE3(Ra.transpose()));
    }
    trellis::Mass m{1.0, Eigen::Vector3d(0.02, 0.001, 0.02).asDiagonal()};
    b.addFrame(link, joint, trellis::Transform::ty(-0.5), m);
    b.addConfigForce(q, "u" + k);
    parent = link;
  }
  b.addGravity({0.0, 0.0, -9.81});
  return b.finalize();
}

void axisBench(benchmark::State& state, bool sandwich) {
  const Fixture f = withState(axisChain(sandwich), 11);
  trellis::Data data(f.model);
  for (auto _ : state) {
    trellis::computeLinearization(f.model, data, f.q, f.dq, f.u);
    benchmark::DoNotOptimize(data.A.data());
  }
  state.counters["nq"] = f.model.nq();
  if (sandwich) {
    const Fixture g = withState(axisChain(false), 11);
    trellis::Data dg(g.model);
    trellis::computeLinearization(g.model, dg, g.q, g.dq, g.u);
    state.counters["max_diff"] = (data.A - dg.A).cwiseAbs().maxCoeff() / std::max(1.0, dg.A.cwiseAbs().maxCoeff());
  }
}

const char* kRobots[] = {"double_pendulum_continuous.urdf", "panda.urdf", "solo12.urdf", "leap_hand_right.urdf"};

[[maybe_unused]] const bool kRegistered = [] {
  for (const char* r : kRobots) {
    const std::string name(r);
    const std::string label = name.substr(0, name.find('.'));
    benchmark::RegisterBenchmark(("RobotLinearization/" + label).c_str(), robotExact, name);
    benchmark::RegisterBenchmark(("RobotLinearizationFD/" + label).c_str(), robotFd, name);
  }
  benchmark::RegisterBenchmark("AxisChain/r_axis/N:20", axisBench, false);
  benchmark::RegisterBenchmark("AxisChain/sandwich/N:20", axisBench, true);
  return true;
}();

}  // namespace

BENCHMARK_MAIN();
