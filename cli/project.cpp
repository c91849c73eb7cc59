// cli/project.cpp — `trellis project SCENE.json`: a state moved onto the constraints h(q) = 0,
// A(q) q' = 0 (core/projection.hpp), printed as JSON and as a state object --state reads back.
#include "cli_options.hpp"
#include "command.hpp"
#include "model_questions.hpp"

#include "trellis/core/projection.hpp"

#include <stdexcept>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis project [--state STATE.json] [--fix a,b,...] [options] SCENE.json

Projects a state x = [q; q'] of the scene (its stored state, or --state) onto the constraint
manifold {h(q) = 0, A(q) q' = 0}, in the metric of the mass matrix M:
  positions   q* = argmin (q - q0)^T M(q0) (q - q0)  subject to h(q) = 0 (holonomic rows):
              minimum-norm Newton steps onto h = 0, then descent along the manifold to the
              closest point (core/include/trellis/core/projection.hpp);
  velocities  q'* = q' - M^-1 A^T (A M^-1 A^T)^+ A q' at q* (all rows, nonholonomic included): the
              correction of least kinetic energy.
Coordinates listed in --fix keep their value and velocity (the others move). Without
constraints the state is printed unchanged. Where M is not positive definite the Euclidean
metric is used ("mass_weighted": false).

Output: one JSON object, the library's report and then the names and the state, with the keys
  status, ok             "ok", true (always, on exit 0)
  message, t, index      "", null, null
  iterations             Newton steps onto h = 0, in all
  h_before, h_after      max |h(q)| over the holonomic rows, before and after
  velocity_before, velocity_after   max |A q'| over all rows, before and after
  last_step              max |dq| of the last accepted descent step
  mass_weighted          whether the metric was M
  q, dq, configs         the projected state as lists
  state                  {"q": {...}, "dq": {...}, "u": {...}}: the projected state as --state reads
                         it (u unchanged)

options:
  --state FILE           the state to project (see `trellis linearize --help`)
  --fix LIST             comma-separated configuration variables held fixed
  --positions-only       leave q' unchanged
  --tolerance TOL        max |h| accepted (default 1e-12; units of h)
  --max-iterations N     Newton steps per restoration, and descent steps (default 50)
  --compact              print the object on one line
  -h, --help             show this help

Exit status: 0 when the projection converged; 1 if the scene or state cannot be read or the
projection fails (not converged: the message gives |h| and the last step); 2 on a usage error.
)";

int runProject(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options("project", args,
                              {{"--state", "--fix", "--tolerance", "--max-iterations"},
                               {"--positions-only", "--compact"}, {}});
  const LoadedScene loaded = loadSceneArgument(options.singlePositional("scene file"));
  const Model& model = loaded.scene.model;
  const ModelState state = stateFromFile(loaded, options.value("--state"));
  ProjectionOptions po;
  if (const auto v = options.value("--fix")) po.fixed = configIndices(model, "project", "--fix", *v);
  if (const auto v = options.value("--tolerance"))
    po.tolerance = options.numberInRange("--tolerance", *v, 1e-300, 1e-3,
                                         "max |h| in the units of h: above, a state off the constraints passes");
  if (const auto v = options.value("--max-iterations")) {
    po.maxIterations = options.integer<int>("--max-iterations", *v, 1, 100000);
  }
  po.velocities = !options.flag("--positions-only");
  Data data(model);
  const ProjectionResult r = projectState(model, data, state.q, state.dq, po);
  if (!r.ok()) {
    throw std::runtime_error(loaded.path + ": the projection failed (" + r.status.name() + "): " + r.status.message);
  }
  // The library's report (ProjectionResult::json), then the names and the state object.
  OutputJson result = OutputJson::parse(r.json());
  result["configs"] = nameList(model.configNames());
  result["state"] = stateObject(model, r.q, r.dq, state.u);
  writeJson(out, result, options.flag("--compact"));
  return 0;
}

}  // namespace

const Command kProjectCommand{
    "project",
    "a state moved onto the constraints (mass-weighted closest point), as JSON",
    kHelp,
    &runProject,
};

const CommandRegistration kRegisterProject{kProjectCommand};

}  // namespace trellis::cli
