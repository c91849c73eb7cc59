// cli/view.cpp — `trellis view SCENE|ROBOT.urdf [--state S] [--trajectory T ...] --out view.html`:
// a self-contained HTML page that shows the model in 3D in a browser (trellis/viewer/view.hpp).
#include "cli_options.hpp"
#include "command.hpp"
#include "model_questions.hpp"

#include "trellis/core/io.hpp"
#include "trellis/viewer/view.hpp"

#include <nlohmann/json.hpp>

#include <cctype>
#include <cstdio>
#include <filesystem>
#include <iostream>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis view SCENE.json|ROBOT.urdf [--state STATE.json] [--trajectory TRAJ.csv ...]
                    [--rate HZ] [--title TEXT] [--package-path DIR ...] [--all-solid] [--exact-ghosts]
                    [--no-forces]
                    --out VIEW.html

Writes one self-contained HTML page (three.js included, with its licence notice) that opens offline
from disk in a current browser and shows the model in 3D: a sphere per body at its centre of mass
(volume proportional to its mass), the links between frames as capsules, URDF visual geometry (box,
cylinder, sphere, STL meshes; other mesh formats as their bounding box or a stand-in, with a
warning), constraints as red lines between their points, tendons as green polylines through their
path points, world axes and a ground grid perpendicular to gravity; with trajectories of a model with
constraints, the constraint forces on the bodies as arrows (λ from the forward dynamics at every
sample, one arrow per constraint point, the scale in the legend). Orbit with the mouse (left:
rotate, right: pan, wheel: zoom).

With trajectories the page has a time slider, play/pause, speed and looping. The first trajectory is
drawn solid, the others ghosted (translucent; --all-solid draws every one solid). Poses are the
library's kinematics (the numbers `trellis kinematics` prints), sampled at every knot and at --rate
samples per second; the page only interpolates between samples. See docs/viewer.md.

options:
  --out FILE           the page to write (required); written atomically: complete or absent
  --state FILE         a state object (see `trellis linearize --help`); the pose shown without
                       trajectories (default: the scene's stored state)
  --trajectory FILE    a trajectory CSV (t, <configs>, d<configs>, <inputs>), repeatable
  --rate HZ            display samples per second besides the knots (default 60)
  --title TEXT         the page's title (default: the scene's name)
  --package-path DIR   where package://PKG/... meshes are looked for (DIR/PKG/...), repeatable;
                       then ROS_PACKAGE_PATH, then the URDF's ancestor directories named PKG
  --all-solid          draw every trajectory solid, none ghosted
  --exact-ghosts       store ghosted trajectories in float64 like solid ones (default float32:
                       half the size; a ghost sampled at the first trajectory's times is stored
                       as its difference from it, rounded by ~6e-8 of the difference, others
                       by ~6e-8 relative)
  --no-forces          draw no constraint force arrows
  -h, --help           show this help

Environment: TRELLIS_THREE_DIR, a directory holding three.min.js and
examples/js/controls/OrbitControls.js (default: Debian's libjs-three, /usr/share/javascript/three).

Prints one line (file, size, samples); warnings go to standard error as "trellis: warning: ...".
Exit status: 0 on success; 1 if the scene, state, a trajectory, a mesh or three.js cannot be read or
does not match (nothing is written); 2 on a usage error.
)";

std::string lowerCase(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

/// The directory relative URDF mesh names are resolved against: the URDF's own directory (given
/// directly, or through a scene's "urdf" include, which is relative to the scene file).
std::string meshBaseDirectory(const LoadedScene& loaded) {
  namespace fs = std::filesystem;
  if (loaded.scene.visuals.empty() || loaded.path == "-") return ".";
  const fs::path scenePath(loaded.path);
  const fs::path directory = scenePath.has_parent_path() ? scenePath.parent_path() : fs::path(".");
  if (lowerCase(scenePath.extension().string()) == ".json") {
    // A scene that includes a URDF: {"urdf": "arm.urdf", ...}.
    const nlohmann::json top = nlohmann::json::parse(readTextFile(loaded.path, std::size_t{256} << 20, "scene file"),
                                                     nullptr, false);
    if (top.is_object() && top.contains("urdf") && top["urdf"].is_string()) {
      const fs::path urdf = directory / top["urdf"].get<std::string>();
      return urdf.has_parent_path() ? urdf.parent_path().string() : ".";
    }
  }
  return directory.string();
}

std::string megabytes(std::size_t bytes) {
  char text[32];
  std::snprintf(text, sizeof text, "%.2f MB", static_cast<double>(bytes) / 1e6);
  return text;
}

int runView(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options(
      "view", args,
      {{"--out", "--state", "--trajectory", "--rate", "--title", "--package-path"}, {"--all-solid", "--exact-ghosts", "--no-forces"},
       {"--trajectory", "--package-path"}});
  const std::string path = options.required("--out", "the HTML file to write");
  if (options.has("--state") && options.has("--trajectory")) {
    // With a trajectory the page shows its pose at every time: a state would never be seen.
    throw UsageError("view: give --state or --trajectory, not both");
  }
  ViewOptions view;
  if (const auto rate = options.value("--rate")) view.displayRate = options.numberInRange("--rate", *rate, 1e-3, 1e4, "samples per second");
  if (const auto title = options.value("--title")) view.title = *title;
  view.packagePath = options.values("--package-path");
  view.exactGhosts = options.flag("--exact-ghosts");
  view.constraintForces = !options.flag("--no-forces");

  const LoadedScene loaded = loadSceneArgument(options.singlePositional("scene file"));
  view.meshBaseDirectory = meshBaseDirectory(loaded);
  const ModelState state = stateFromFile(loaded, options.value("--state"));
  std::vector<ViewTrajectory> trajectories;
  for (const std::string& file : options.values("--trajectory")) {
    ViewTrajectory t;
    t.name = std::filesystem::path(file).stem().string();
    t.trajectory = readTrajectoryFor(loaded, file);
    t.ghost = !trajectories.empty() && !options.flag("--all-solid");
    trajectories.push_back(std::move(t));
  }
  const ViewReport report = writeView(path, loaded.scene, state.q, trajectories, view);
  for (const std::string& w : report.warnings) std::cerr << "trellis: warning: " << w << '\n';
  out << path << ": " << megabytes(report.bytes) << ", " << trajectories.size() << " trajector"
      << (trajectories.size() == 1 ? "y" : "ies") << ", " << report.samples << " pose samples of "
      << loaded.scene.model.nq() << " bodies, " << report.warnings.size() << " warning"
      << (report.warnings.size() == 1 ? "" : "s") << '\n';
  return 0;
}

}  // namespace

const Command kViewCommand{
    "view",
    "a self-contained HTML page showing the model, a state or trajectories in 3D (three.js)",
    kHelp,
    &runView,
};

const CommandRegistration kRegisterView{kViewCommand};

}  // namespace trellis::cli
