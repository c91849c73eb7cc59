// bench/closed_loop_bench.cpp — what a closing constraint costs, measured against the same model
// without it, interleaved in one process (issue 25).
//
//   trellis_bench_closed [rounds] [runs] [target_ms] [label]   (label: only the pairs whose name contains it)
//
// Each pair is a free model and the same model with constraint rows added: the synthetic chains
// and hand of bench/models.hpp (one tip row, the tip pinned, the planar tip pinned with its
// redundant z row, the hand's fingertip), the Panda of tests/data/robots with its tool centre
// point pinned, the hand scene (examples/scenes/hand.json, five pads on a ball) and the hand with
// a free ball (hand_ball.json) against the same scenes without their constraints, and a free box
// held by two or three arms (loops across the tree). In each round the free and the constrained computation are timed alternately,
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

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
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
/// dq ← its part in the null space of the constraint Jacobian A(q) of `closed` (the velocity
/// the constraints allow; their rows at q must already hold).
void removeConstraintVelocity(const trellis::Model& closed, const Eigen::VectorXd& q, Eigen::VectorXd& dq) {
  trellis::Data cd(closed);
  trellis::computeConstraints(closed, cd, q, dq);
  const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(cd.constraintJacobian.transpose());
  Eigen::VectorXd t = cod.householderQ().adjoint() * dq;
  t.tail(dq.size() - cod.rank()).setZero();
  dq -= cod.householderQ() * t;
}

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
  removeConstraintVelocity(closed, q, dq);
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

/// `arms` 3D arms of `links` revolute joints (rz, ry, rx in turn, 0.3 m links, 1 kg each) around
/// a free box (tx, ty, tz, rz, ry, rx; 2 kg, declared after the arms), free and with each arm's
/// tip pinned to the box (3 point rows per arm, at the box point where the tip is at a seeded
/// random q; q̇ projected onto the null space of the rows): a floating body held by several
/// limbs, each loop between one arm's tree and the box's, skipping the arms between.
std::pair<trellis::bench::BenchModel, trellis::bench::BenchModel> heldBoxPair(int arms, int links) {
  const auto build = [&](const std::vector<Eigen::Vector3d>* grips) {
    trellis::ModelBuilder b("held box");
    const Eigen::Matrix3d linkInertia = Eigen::Vector3d(0.01, 0.012, 0.008).asDiagonal();
    for (int a = 0; a < arms; ++a) {
      const std::string arm = "arm" + std::to_string(a) + "_";
      const double angle = 2.0 * 3.14159265358979 * a / arms;
      Eigen::Matrix4d base = Eigen::Matrix4d::Identity();
      base.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      base.topRightCorner<3, 1>() << 0.8 * std::cos(angle), 0.8 * std::sin(angle), 0.0;
      b.addFrame(arm + "base", "world", trellis::Transform::constSE3(base));
      std::string parent = arm + "base";
      for (int k = 0; k < links; ++k) {
        const std::string j = arm + std::to_string(k);
        b.addFrame(j, parent, k % 3 == 0 ? trellis::Transform::rz(j) : k % 3 == 1 ? trellis::Transform::ry(j) : trellis::Transform::rx(j),
                   trellis::Mass{1.0, linkInertia});
        Eigen::Matrix4d link = Eigen::Matrix4d::Identity();
        link.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1.0, 0.5, -0.3).normalized()).toRotationMatrix();
        link.topRightCorner<3, 1>() << -0.3, 0.05, 0.02;
        b.addFrame(j + "_end", j, trellis::Transform::constSE3(link));
        parent = j + "_end";
      }
      b.addConfigForce(arm + "0", arm + "tau");
    }
    b.addFrame("box_x", "world", trellis::Transform::tx("box_x"));
    b.addFrame("box_y", "box_x", trellis::Transform::ty("box_y"));
    b.addFrame("box_z", "box_y", trellis::Transform::tz("box_z"));
    b.addFrame("box_yaw", "box_z", trellis::Transform::rz("box_yaw"));
    b.addFrame("box_pitch", "box_yaw", trellis::Transform::ry("box_pitch"));
    b.addFrame("box", "box_pitch", trellis::Transform::rx("box_roll"),
               trellis::Mass{2.0, Eigen::Matrix3d(Eigen::Vector3d(0.02, 0.03, 0.025).asDiagonal())});
    b.addGravity(Eigen::Vector3d(0.0, 0.0, -9.81));
    if (grips)
      for (int a = 0; a < arms; ++a) {
        const std::string arm = "arm" + std::to_string(a) + "_";
        Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
        g.topRightCorner<3, 1>() = (*grips)[static_cast<size_t>(a)];
        b.addFrame(arm + "grip", "box", trellis::Transform::constSE3(g));
        for (int axis = 0; axis < 3; ++axis) b.addPointConstraint(arm + std::to_string(links - 1) + "_end", arm + "grip", axis);
      }
    return std::move(b).finalize();
  };
  trellis::Model free = build(nullptr);
  const int n = free.nq();
  std::mt19937 rng(20261202u);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(n), dq(n), u(free.nu());
  for (int i = 0; i < n - 6; ++i) q[i] = unit(rng);  // the box at the origin, unrotated
  for (int i = 0; i < n; ++i) dq[i] = unit(rng);
  for (int i = 0; i < u.size(); ++i) u[i] = unit(rng);
  trellis::Data fd(free);
  trellis::computeKinematics(free, fd, q, dq);
  std::vector<Eigen::Vector3d> grips;
  for (int a = 0; a < arms; ++a)
    grips.push_back(fd.framePose[free.frameIndex("arm" + std::to_string(a) + "_" + std::to_string(links - 1) + "_end")].translation());
  trellis::Model closed = build(&grips);
  removeConstraintVelocity(closed, q, dq);
  return {trellis::bench::BenchModel{std::move(free), q, dq, u, "held box"},
          trellis::bench::BenchModel{std::move(closed), q, dq, u, "held box"}};
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
  const std::string only = argc > 4 ? argv[4] : "";  // run only the pairs whose label contains it
  if (rounds < 1 || runs < 1 || !(targetMs > 0)) {
    std::fprintf(stderr, "usage: %s [rounds >= 1] [runs >= 1] [target_ms > 0] [label]\n", argv[0]);
    return 2;
  }
  struct Pair {
    ModelSpec free, closed;
    /// 1: the Panda pinned, 2: the hand scene, 3: the hand with a free ball, 4 / 5: a box held by
    /// two arms of 7 / three arms of 4 (specs unused)
    int real = 0;
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
      {{}, {}, 4},
      {{}, {}, 5},
  };
  std::printf("# trellis_bench_closed: %d rounds x %d runs per side, batches of ~%.2f ms\n", rounds, runs, targetMs);
  std::printf("%-36s %-4s %10s %10s %8s %8s %8s\n", "constrained model", "alg", "free us", "closed us", "ratio",
              "q10", "q90");
  int status = 0;
  for (const Pair& p : pairs) {
    const std::string label = p.real == 1   ? "panda tcp xyz"
                              : p.real == 2 ? "hand scene (15 rows)"
                              : p.real == 3 ? "hand, free ball (15 rows)"
                              : p.real == 4 ? "box held by 2 arms of 7 (6 rows)"
                              : p.real == 5 ? "box held by 3 arms of 4 (9 rows)"
                                            : name(p.closed);
    if (!only.empty() && label.find(only) == std::string::npos) continue;
    try {
      std::pair<trellis::bench::BenchModel, trellis::bench::BenchModel> models =
          p.real == 1 ? pandaPair() : p.real == 2 ? handScenePair("hand.json") : p.real == 3 ? handScenePair("hand_ball.json")
          : p.real == 4 ? heldBoxPair(2, 7) : p.real == 5 ? heldBoxPair(3, 4)
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
