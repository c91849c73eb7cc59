// bench/closed_loop_bench.cpp — what a closing constraint costs, measured against the same model
// without it, interleaved in one process (issue 25).
//
//   trellis_bench_closed [rounds] [runs] [target_ms]
//
// Each pair is a free model and the same model with constraint rows added: the synthetic chains
// and hand of bench/models.hpp (one tip row, the tip pinned, the planar tip pinned with its
// redundant z row, the hand's fingertip), the Panda of tests/data/robots with its tool centre
// point pinned, and the hand scene (examples/scenes/hand.json, five pads on a ball) against the
// same scene without its constraints. In each round the free and the constrained computation are timed alternately,
// `runs` batches each (free, constrained, free, constrained, …; the batch size is calibrated once
// so that a free batch takes about target_ms), and the round's figure is the ratio of the two
// fastest batches: the minimum removes the batches another process interrupted, the alternation
// makes both sides see the same machine. Reported per pair and computation (dyn =
// computeDynamics, lin = computeLinearization): the median ratio over the rounds with its 10 %
// and 90 % quantiles, and the median per-call times. Times are wall-clock (steady_clock); run
// under `taskset -c K` to keep the process on one CPU. Exit status 1 if a model fails to build
// or a computation does not return ok.
#include "models.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/kinematics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/scene.hpp"
#include "trellis/core/urdf.hpp"

#include <Eigen/QR>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace {

using trellis::bench::ModelKind;
using trellis::bench::ModelSpec;
using trellis::bench::TipRows;

struct Case {
  explicit Case(const ModelSpec& spec) : bm(trellis::bench::makeBenchModel(spec)), data(bm.model) {}
  explicit Case(trellis::bench::BenchModel model) : bm(std::move(model)), data(bm.model) {}
  trellis::bench::BenchModel bm;
  trellis::Data data;
  /// One call; false when the status is not ok.
  bool call(bool lin) {
    const trellis::DynamicsStatus s = lin ? trellis::computeLinearization(bm.model, data, bm.q, bm.dq, bm.u)
                                          : trellis::computeDynamics(bm.model, data, bm.q, bm.dq, bm.u);
    return s.ok();
  }
  /// Seconds per call over a batch of `iterations` calls.
  double time(bool lin, long iterations) {
    const auto t0 = std::chrono::steady_clock::now();
    for (long k = 0; k < iterations; ++k) {
      call(lin);
      asm volatile("" : : "g"(data.A.data()), "g"(data.qdd.data()) : "memory");
    }
    const auto t1 = std::chrono::steady_clock::now();
    return std::chrono::duration<double>(t1 - t0).count() / static_cast<double>(iterations);
  }
};

double quantile(std::vector<double> x, double p) {
  std::sort(x.begin(), x.end());
  const double pos = p * static_cast<double>(x.size() - 1);
  const size_t i = static_cast<size_t>(pos);
  const double f = pos - static_cast<double>(i);
  return i + 1 < x.size() ? x[i] * (1.0 - f) + x[i + 1] * f : x[i];
}

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// The Panda arm (tests/data/robots/panda.urdf: 7 revolute joints and two prismatic fingers, a
/// tree) free and with its tool centre point pinned (x, y, z on a world point placed where the
/// point is at a seeded random q; q̇ projected onto the null space of the rows).
std::pair<trellis::bench::BenchModel, trellis::bench::BenchModel> pandaPair() {
  const std::string path = std::string(TRELLIS_ROBOTS_DIR) + "/panda.urdf";
  trellis::UrdfImport robot = trellis::importUrdf(readFile(path), path);
  trellis::Model free = robot.builder.finalize();
  const int n = free.nq();
  std::mt19937 rng(20100503u);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::VectorXd q(n), dq(n), u(free.nu());
  for (int i = 0; i < n; ++i) q[i] = free.configNames()[i].find("finger") != std::string::npos ? 0.02 : unit(rng);
  for (int i = 0; i < n; ++i) dq[i] = unit(rng);
  for (int i = 0; i < u.size(); ++i) u[i] = unit(rng);
  trellis::Data fd(free);
  trellis::computeKinematics(free, fd, q, dq);
  Eigen::Matrix4d anchor = Eigen::Matrix4d::Identity();
  anchor.topRightCorner<3, 1>() = fd.framePose[free.frameIndex("panda_hand_tcp")].translation();
  robot.builder.addFrame("anchor", robot.rootLink, trellis::Transform::constSE3(anchor));
  for (int axis = 0; axis < 3; ++axis) robot.builder.addPointConstraint("panda_hand_tcp", "anchor", axis);
  trellis::Model closed = std::move(robot.builder).finalize();
  if (closed.configNames() != free.configNames()) throw std::runtime_error("panda: the constraint changed the configuration");
  trellis::Data cd(closed);
  trellis::computeConstraints(closed, cd, q, dq);
  const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(cd.constraintJacobian.transpose());
  Eigen::VectorXd t = cod.householderQ().adjoint() * dq;
  t.tail(n - cod.rank()).setZero();
  dq -= cod.householderQ() * t;
  return {trellis::bench::BenchModel{std::move(free), q, dq, u, "panda"},
          trellis::bench::BenchModel{std::move(closed), q, dq, u, "panda"}};
}

/// A hand scene at its stored state, and the same scene without its constraints: hand.json (20
/// joints, 23 tendons, 15 rows pinning the five pads to a ball fixed to the world) or
/// hand_ball.json (the same pads stuck to a free ball: 26 coordinates, the rows across the tree).
std::pair<trellis::bench::BenchModel, trellis::bench::BenchModel> handScenePair(const char* file) {
  const std::string path = std::string(TRELLIS_SCENES_DIR) + "/" + file;
  const std::string text = readFile(path);
  nlohmann::json j = nlohmann::json::parse(text);
  j.erase("constraints");
  trellis::Scene closed = trellis::parseScene(text, path), free = trellis::parseScene(j.dump(), path);
  if (closed.model.configNames() != free.model.configNames()) throw std::runtime_error("hand scene: configurations differ");
  return {trellis::bench::BenchModel{std::move(free.model), closed.q, closed.dq, closed.u, "hand scene"},
          trellis::bench::BenchModel{std::move(closed.model), closed.q, closed.dq, closed.u, "hand scene"}};
}

std::string name(const ModelSpec& spec) {
  std::string s = std::string(trellis::bench::kindName(spec.kind)) + " " + std::to_string(spec.links);
  if (spec.kind == ModelKind::kHandTree) s = "hand 20";
  if (!spec.constrained) return s + " free";
  if (spec.kind == ModelKind::kHandTree) return s + " fingertip xyz";
  switch (spec.tip) {
    case TipRows::kOne: return s + (spec.kind == ModelKind::kPlanarChain ? " tip x" : " tip z");
    case TipRows::kPinned: return s + (spec.kind == ModelKind::kPlanarChain ? " tip xy" : " tip xyz");
    case TipRows::kRedundant: return s + " tip xyz (z redundant)";
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  const int rounds = argc > 1 ? std::atoi(argv[1]) : 41;
  const int runs = argc > 2 ? std::atoi(argv[2]) : 11;
  const double targetMs = argc > 3 ? std::atof(argv[3]) : 0.5;
  if (rounds < 1 || runs < 1 || !(targetMs > 0)) {
    std::fprintf(stderr, "usage: %s [rounds >= 1] [runs >= 1] [target_ms > 0]\n", argv[0]);
    return 2;
  }
  struct Pair {
    ModelSpec free, closed;
    int real = 0;  ///< 1: the Panda pinned, 2: the hand scene, 3: the hand with a free ball (specs unused)
  };
  const auto chain = [](ModelKind k, int n, TipRows t) {
    return Pair{{k, n, false, TipRows::kOne}, {k, n, true, t}};
  };
  const std::vector<Pair> pairs = {
      chain(ModelKind::kSpatialChain, 20, TipRows::kPinned), chain(ModelKind::kSpatialChain, 40, TipRows::kPinned),
      chain(ModelKind::kSpatialChain, 5, TipRows::kPinned),  chain(ModelKind::kSpatialChain, 10, TipRows::kPinned),
      chain(ModelKind::kSpatialChain, 20, TipRows::kOne),    chain(ModelKind::kSpatialChain, 40, TipRows::kOne),
      chain(ModelKind::kPlanarChain, 40, TipRows::kPinned),  chain(ModelKind::kPlanarChain, 40, TipRows::kRedundant),
      chain(ModelKind::kPlanarChain, 20, TipRows::kPinned),  chain(ModelKind::kPlanarChain, 20, TipRows::kRedundant),
      {{ModelKind::kHandTree, 20, false}, {ModelKind::kHandTree, 20, true}},
      {{}, {}, 1},
      {{}, {}, 2},
      {{}, {}, 3},
  };
  std::printf("# trellis_bench_closed: %d rounds x %d runs per side, batches of ~%.2f ms\n", rounds, runs, targetMs);
  std::printf("%-36s %-4s %10s %10s %8s %8s %8s\n", "constrained model", "alg", "free us", "closed us", "ratio",
              "q10", "q90");
  int status = 0;
  for (const Pair& p : pairs) {
    const std::string label = p.real == 1   ? "panda tcp xyz"
                              : p.real == 2 ? "hand scene (15 rows)"
                              : p.real == 3 ? "hand, free ball (15 rows)"
                                            : name(p.closed);
    try {
      std::pair<trellis::bench::BenchModel, trellis::bench::BenchModel> models =
          p.real == 1 ? pandaPair() : p.real == 2 ? handScenePair("hand.json") : p.real == 3 ? handScenePair("hand_ball.json")
                                    : std::make_pair(trellis::bench::makeBenchModel(p.free), trellis::bench::makeBenchModel(p.closed));
      Case fr(std::move(models.first)), cl(std::move(models.second));
      for (bool lin : {false, true}) {
        // The model with the redundant row reports it (a degenerate row): not ok, but exact.
        const bool redundant = p.real == 0 && p.closed.tip == TipRows::kRedundant;
        if (!fr.call(lin) || (!cl.call(lin) && !redundant)) {
          std::fprintf(stderr, "%s: %s did not return ok: %s\n", label.c_str(), lin ? "lin" : "dyn",
                       (fr.data.status.ok() ? cl : fr).data.status.message.c_str());
          status = 1;
          continue;
        }
        const double once = fr.time(lin, 50);
        const long iterations = std::max(1L, static_cast<long>(targetMs * 1e-3 / once));
        std::vector<double> ratio, tf, tc;
        for (int r = 0; r < rounds; ++r) {
          double bf = 1e300, bc = 1e300;
          for (int k = 0; k < runs; ++k) {
            // Alternate which side goes first, so that neither always follows the other.
            if ((r + k) % 2 == 0) {
              bf = std::min(bf, fr.time(lin, iterations));
              bc = std::min(bc, cl.time(lin, iterations));
            } else {
              bc = std::min(bc, cl.time(lin, iterations));
              bf = std::min(bf, fr.time(lin, iterations));
            }
          }
          ratio.push_back(bc / bf);
          tf.push_back(bf);
          tc.push_back(bc);
        }
        std::printf("%-36s %-4s %10.2f %10.2f %8.3f %8.3f %8.3f\n", label.c_str(), lin ? "lin" : "dyn",
                    1e6 * quantile(tf, 0.5), 1e6 * quantile(tc, 0.5), quantile(ratio, 0.5), quantile(ratio, 0.1),
                    quantile(ratio, 0.9));
        std::fflush(stdout);
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "%s: %s\n", label.c_str(), e.what());
      status = 1;
    }
  }
  return status;
}
