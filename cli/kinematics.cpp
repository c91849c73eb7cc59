// cli/kinematics.cpp — `trellis kinematics SCENE.json`: world poses of frames at a state or along a
// trajectory, as CSV (the input to a plot or a viewer).
#include "cli_options.hpp"
#include "command.hpp"
#include "model_questions.hpp"

#include "trellis/core/kinematics.hpp"

#include <cstdio>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis kinematics [--state STATE.json | --trajectory TRAJ.csv] [--frames a,b,...]
                          [--rotation quaternion|matrix] SCENE.json

World poses g_world,k(q) of the scene's frames (docs/scene_format.md), at the scene's stored state,
at the state of --state, or at every knot of --trajectory, as CSV on standard output:

  t, then per frame F (in the order of --frames, default every frame in tree order):
    F.x, F.y, F.z                 the origin in world coordinates
    F.qw, F.qx, F.qy, F.qz        the orientation as a unit quaternion (w, x, y, z) rotating frame
                                  axes into world axes, with qw >= 0 (the sign of q is free); or,
                                  with --rotation matrix,
    F.R00, F.R01, ..., F.R22      the rotation matrix R (frame axes in world coordinates as its
                                  columns), row-major

One row per knot (a single row with t = 0 for a state). Numbers have 17 significant digits.

options:
  --state FILE       a state object (see `trellis linearize --help`); only q matters here
  --trajectory FILE  a trajectory CSV: t, <configs>, d<configs>, <inputs> (names as the scene's)
  --frames LIST      comma-separated frame names (default: all)
  --rotation KIND    quaternion (default) or matrix
  -h, --help         show this help

Exit status: 0 on success; 1 if the scene, state or trajectory cannot be read or does not match;
2 on a usage error (also an unknown frame name).
)";

std::string num(double x) {
  char buffer[40];
  std::snprintf(buffer, sizeof buffer, "%.17g", x);
  return buffer;
}

int runKinematics(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options("kinematics", args, {{"--state", "--trajectory", "--frames", "--rotation"}, {}, {}});
  const std::string rotation = options.value("--rotation").value_or("quaternion");
  if (rotation != "quaternion" && rotation != "matrix") {
    throw UsageError("kinematics: --rotation: '" + rotation + "' is not quaternion or matrix");
  }
  if (options.has("--state") && options.has("--trajectory")) {
    throw UsageError("kinematics: give --state or --trajectory, not both");
  }
  const LoadedScene loaded = loadSceneArgument(options.singlePositional("scene file"));
  const Model& model = loaded.scene.model;
  std::vector<int> frames;
  if (const auto list = options.value("--frames")) {
    frames = frameIndices(model, "kinematics", "--frames", *list);
  } else {
    for (int f = 0; f < model.nframes(); ++f) frames.push_back(f);
  }
  const int n = model.nq();
  Eigen::VectorXd times;
  Eigen::MatrixXd qs;
  if (const auto path = options.value("--trajectory")) {
    const Trajectory trajectory = readTrajectoryFor(loaded, *path);
    times = trajectory.times();
    qs = trajectory.states().topRows(n);
  } else {
    const ModelState state = stateFromFile(loaded, options.value("--state"));
    times = Eigen::VectorXd::Zero(1);
    qs = state.q;
  }

  out << "t";
  for (int f : frames) {
    const std::string& name = model.frames()[f].name;
    for (const char* c : {"x", "y", "z"}) out << ',' << name << '.' << c;
    if (rotation == "quaternion") {
      for (const char* c : {"qw", "qx", "qy", "qz"}) out << ',' << name << '.' << c;
    } else {
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) out << ',' << name << ".R" << i << j;
    }
  }
  out << '\n';
  Data data(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  for (Eigen::Index k = 0; k < times.size(); ++k) {
    const Eigen::VectorXd q = qs.col(k);
    computeKinematics(model, data, q, zero);
    // A pose that overflowed (a coordinate near the largest double) is an error, never "inf" in
    // a CSV with exit status 0.
    for (int f : frames) {
      if (!data.framePose[f].matrix().allFinite()) {
        throw std::runtime_error(loaded.path + ": the pose of frame '" + model.frames()[f].name + "' at t = " +
                                 num(times(k)) + " (knot " + std::to_string(k + 1) +
                                 ") is not finite: the configuration is too large to place it");
      }
    }
    out << num(times(k));
    for (int f : frames) {
      const Eigen::Isometry3d& g = data.framePose[f];
      for (int i = 0; i < 3; ++i) out << ',' << num(g.translation()(i));
      const Eigen::Matrix3d R = g.linear();
      if (rotation == "quaternion") {
        Eigen::Quaterniond quat(R);
        quat.normalize();
        if (quat.w() < 0.0) quat.coeffs() = -quat.coeffs();
        out << ',' << num(quat.w()) << ',' << num(quat.x()) << ',' << num(quat.y()) << ',' << num(quat.z());
      } else {
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) out << ',' << num(R(i, j));
      }
    }
    out << '\n';
  }
  return 0;
}

}  // namespace

const Command kKinematicsCommand{
    "kinematics",
    "world positions and orientations of frames at a state or along a trajectory, as CSV",
    kHelp,
    &runKinematics,
};

const CommandRegistration kRegisterKinematics{kKinematicsCommand};

}  // namespace trellis::cli
