// cli/inverse_dynamics.cpp — `trellis inverse-dynamics SCENE.json`: the inputs and constraint forces
// that produce given accelerations (core/inverse_dynamics.hpp), at a state or along a trajectory.
#include "cli_options.hpp"
#include "command.hpp"
#include "model_questions.hpp"

#include "trellis/core/inverse_dynamics.hpp"

#include <cstdio>
#include <stdexcept>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis inverse-dynamics [--state STATE.json | --trajectory ACC.csv] [--allow-residual] SCENE.json

The inputs u and constraint forces lambda that produce the acceleration q'' at (q, q'): the
equations of motion M q'' + b(q, q') = B_u(q) u + A^T lambda (b: every force at u = 0, with the
sign of the inverse dynamics) solved for z = [u; lambda] by least squares of minimum norm. Exact
when the motion is feasible; for an under-actuated system and an infeasible q'' the residual
says by how much the equations miss. q'' must satisfy A q'' + A' q' = 0 on a constrained scene.

Input: the scene's stored state with --state's "ddq" ({"q": .., "dq": .., "ddq": {name: value}};
missing ddq names are 0), or --trajectory, a CSV with one row per knot
  t, <configs>, d<configs>, dd<configs>          (e.g. t,x,theta,dx,dtheta,ddx,ddtheta)

Output: CSV on standard output, one row per knot (t = 0 for a state):
  t, <inputs>, lambda_0 .. lambda_{nc-1}, residual, constraint_residual, status
residual = max |B_u u + A^T lambda - M q'' - b| (generalized forces), constraint_residual =
max |A q'' + A' q'|, status ok / unreachable / inadmissible_acceleration. Numbers have 17
significant digits.

options:
  --state FILE          q, q', q'' by name
  --trajectory FILE     the CSV above
  --allow-residual      print unreachable knots (status "unreachable") and exit 0; otherwise an
                        unreachable knot is an error
  --tolerance TOL       relative tolerance of "exact" (default 1e-9)
  -h, --help            show this help

Exit status: 0 on success; 1 if the scene, state or trajectory cannot be read, a q'' violates
the constraints, or (without --allow-residual) no inputs produce it; 2 on a usage error.
)";

std::string num(double x) {
  char buffer[40];
  std::snprintf(buffer, sizeof buffer, "%.17g", x);
  return buffer;
}

int runInverseDynamics(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options("inverse-dynamics", args,
                              {{"--state", "--trajectory", "--tolerance"}, {"--allow-residual"}, {}});
  if (options.has("--state") && options.has("--trajectory")) {
    throw UsageError("inverse-dynamics: give --state or --trajectory, not both");
  }
  const LoadedScene loaded = loadSceneArgument(options.singlePositional("scene file"));
  const Model& model = loaded.scene.model;
  const int n = model.nq();
  InverseDynamicsOptions io;
  if (const auto v = options.value("--tolerance"))
    io.tolerance = options.numberInRange("--tolerance", *v, 1e-16, 0.1,
                                         "relative to the forces compared: above, any answer would pass");

  Eigen::VectorXd times;
  Eigen::MatrixXd q, dq, ddq;
  std::string source;
  if (const auto path = options.value("--trajectory")) {
    source = *path;
    const Trajectory t = Trajectory::readCsvFile(*path);
    std::vector<std::string> expected;
    for (const std::string& c : model.configNames()) expected.push_back("dd" + c);
    if (t.configNames() != model.configNames() || t.inputNames() != expected) {
      std::string header = "t";
      for (const std::string& c : model.configNames()) header += "," + c;
      for (const std::string& c : model.configNames()) header += ",d" + c;
      for (const std::string& c : expected) header += "," + c;
      throw std::runtime_error(*path + ": the header must be '" + header + "' for the scene " + loaded.path);
    }
    times = t.times();
    q = t.states().topRows(n);
    dq = t.states().bottomRows(n);
    ddq = t.inputs();
  } else {
    source = options.value("--state").value_or(loaded.path);
    const ModelState state = stateFromFile(loaded, options.value("--state"));
    times = Eigen::VectorXd::Zero(1);
    q = state.q;
    dq = state.dq;
    ddq = state.ddq;
  }

  out << "t";
  for (const std::string& u : model.inputNames()) out << ',' << u;
  for (int c = 0; c < model.nc(); ++c) out << ",lambda_" << c;
  out << ",residual,constraint_residual,status\n";
  Data data(model);
  for (Eigen::Index k = 0; k < times.size(); ++k) {
    const InverseDynamicsResult r = computeInverseDynamics(model, data, q.col(k), dq.col(k), ddq.col(k), io);
    const bool accepted = r.ok() || (r.status.code == InverseDynamicsCode::kUnreachable && options.flag("--allow-residual"));
    if (!accepted) {
      throw std::runtime_error(source + ": knot " + std::to_string(k) + " (t = " + num(times(k)) + "): " +
                               r.status.name() + ": " + r.status.message);
    }
    out << num(times(k));
    for (Eigen::Index i = 0; i < r.u.size(); ++i) out << ',' << num(r.u(i));
    for (Eigen::Index i = 0; i < r.lambda.size(); ++i) out << ',' << num(r.lambda(i));
    out << ',' << num(r.residualNorm) << ',' << num(r.constraintResidual) << ',' << r.status.name() << '\n';
  }
  return 0;
}

}  // namespace

const Command kInverseDynamicsCommand{
    "inverse-dynamics",
    "the inputs and constraint forces that produce given accelerations, as CSV",
    kHelp,
    &runInverseDynamics,
};

const CommandRegistration kRegisterInverseDynamics{kInverseDynamicsCommand};

}  // namespace trellis::cli
