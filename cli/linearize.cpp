// cli/linearize.cpp — `trellis linearize SCENE.json`: the exact linearization at the scene's
// state, at a given state (--state) or at every knot of a trajectory (--trajectory).
#include "cli_options.hpp"
#include "command.hpp"
#include "json_output.hpp"
#include "model_questions.hpp"

#include "trellis/core/linearization.hpp"
#include "trellis/core/second_order.hpp"
#include "trellis/core/scene.hpp"

#include <optional>
#include <stdexcept>
#include <utility>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis linearize [--compact] [--second-order] [--state STATE.json] SCENE.json
       trellis linearize [--second-order] --trajectory TRAJ.csv SCENE.json
       trellis linearize [options] -          (read the scene from standard input)

Loads a scene (docs/scene_format.md) and evaluates, at the state stored in its "state" (missing
names are 0), or at the state of --state, the constrained Euler-Lagrange equations

  M(q) q'' = Q(q, q', u) + dL/dq - (d2L/dq dq') q' + J(q)^T lambda,    J q'' + J' q' = 0,

with J = dh/dq the constraint Jacobian, then prints their exact linearization

  dx' = A dx + B du,   x = [q; q'],
  A = [[0, I], [dq''/dq, dq''/dq']]   (2n x 2n),   B = [[0], [dq''/du]]   (2n x m).

The state is used as written, not projected onto the constraints: off the constraint manifold
the result depends on how a constraint is written (see h and hdot in the output; `trellis
project` moves a state onto the constraints).

Output: one JSON object on standard output, with the keys
  status    "ok", or "redundant_constraints" (J is rank deficient: q'' is exact, lambda is the
            minimum-norm choice)
  configs   the n configuration variables, in pre-order of the frame tree
  inputs    the m inputs, in the order they first appear in "forces"
  q, dq, u  the state (n, n, m numbers)
  qdd       q'' (n)
  lambda    constraint forces (nc; [] without constraints), in the order of "constraints"
  h         constraint values h(q) (nc; 0 for nonholonomic rows)
  hdot      J(q) q' (nc)
  M         the mass matrix (n x n)
  A, B      the linearization (2n x 2n, 2n x m)
Matrices are lists of rows; numbers are printed with 17 significant digits.

With --second-order: also the exact second derivatives of q'' (n outputs), output index first,
inputs in the configuration and input order (each a list of n matrices, lists of rows):
  d2qdd_dqdq    [i][j][k] = d2 q''_i / dq_j dq_k     (n x n x n)
  d2qdd_dqddq   [i][j][k] = d2 q''_i / dq_j dq'_k    (n x n x n)
  d2qdd_ddqddq  [i][j][k] = d2 q''_i / dq'_j dq'_k   (n x n x n)
  d2qdd_dudq    [i][j][k] = d2 q''_i / du_j dq_k     (n x m x n)
  d2qdd_duddq   [i][j][k] = d2 q''_i / du_j dq'_k    (n x m x n)
  d2qdd_dudu    [i][j][k] = d2 q''_i / du_j du_k     (n x m x m; 0: q'' is affine in u)

With --trajectory: the linearization at every knot of the trajectory, as JSON Lines — one object
per knot and line, in knot order, with the keys above preceded by "knot" (0-based) and "t".

options:
  --state FILE       a state object {"q": {name: value}, "dq": {...}, "u": {...}} (the form of a
                     scene's "state"); names it does not list keep the scene's stored values;
                     unknown names or keys are errors
  --trajectory FILE  a trajectory CSV: t, <configs>, d<configs>, <inputs> (the layout of
                     `trellis simulate --out`; names equal to the scene's, in order; >= 1 row)
  --compact          print the object on one line (always so with --trajectory)
  --second-order     add the six second-derivative tensors (above)
  -h, --help         show this help

Exit status: 0 on success; 1 if the scene, state or trajectory cannot be read or is invalid, or
if the dynamics cannot be solved at a state (singular mass matrix, singular constraints,
non-finite values; the message names the knot and time); 2 on a usage error. Errors are one line
on standard error and nothing on standard output.
)";

OutputJson linearizationJson(const Model& model, const Data& data, const DynamicsStatus& status,
                             const Eigen::VectorXd& q, const Eigen::VectorXd& dq, const Eigen::VectorXd& u,
                             OutputJson result) {
  result["status"] = dynamicsStatusName(status.code);
  result["configs"] = nameList(model.configNames());
  result["inputs"] = nameList(model.inputNames());
  result["q"] = toJson(q);
  result["dq"] = toJson(dq);
  result["u"] = toJson(u);
  result["qdd"] = toJson(data.qdd);
  result["lambda"] = toJson(data.lambda);
  result["h"] = toJson(data.constraintValue);
  result["hdot"] = toJson(Eigen::VectorXd(data.constraintJacobian * dq));
  result["M"] = toJson(data.M);
  result["A"] = toJson(data.A);
  result["B"] = toJson(data.B);
  return result;
}

/// The six tensors of --second-order (ws holds computeSecondOrderTensors at the same state).
void addSecondOrder(const SecondOrderWorkspace& ws, OutputJson& result) {
  using Block = SecondOrderWorkspace::Block;
  const std::pair<const char*, Block> blocks[] = {{"d2qdd_dqdq", Block::kQQ},   {"d2qdd_dqddq", Block::kQDq},
                                                  {"d2qdd_ddqddq", Block::kDqDq}, {"d2qdd_dudq", Block::kUQ},
                                                  {"d2qdd_duddq", Block::kUDq},  {"d2qdd_dudu", Block::kUU}};
  for (const auto& [key, block] : blocks) {
    OutputJson list = OutputJson::array();
    for (const Eigen::MatrixXd& slice : ws.qddBlock(block)) list.push_back(toJson(slice));
    result[key] = std::move(list);
  }
}

int runLinearize(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options("linearize", args, {{"--state", "--trajectory"}, {"--compact", "--second-order"}, {}});
  const LoadedScene loaded = loadSceneArgument(options.singlePositional("scene file"));
  const Model& model = loaded.scene.model;
  if (model.nq() == 0) {
    throw std::runtime_error(loaded.path + ": the scene has no configuration variables: nothing to linearize");
  }
  if (options.has("--state") && options.has("--trajectory")) {
    throw UsageError("linearize: give --state or --trajectory, not both");
  }
  Data data(model);
  const bool secondOrder = options.flag("--second-order");
  std::optional<SecondOrderWorkspace> ws;
  if (secondOrder) ws.emplace(model);
  // The tensors' pass computes the same linearization on the way (and returns its status).
  const auto linearize = [&](const Eigen::VectorXd& q, const Eigen::VectorXd& dq, const Eigen::VectorXd& u) {
    return secondOrder ? computeSecondOrderTensors(model, data, *ws, q, dq, u) : computeLinearization(model, data, q, dq, u);
  };
  if (const auto path = options.value("--trajectory")) {
    const Trajectory trajectory = readTrajectoryFor(loaded, *path);
    const int n = model.nq();
    for (int k = 0; k < trajectory.size(); ++k) {
      const Eigen::VectorXd q = trajectory.states().col(k).head(n), dq = trajectory.states().col(k).tail(n);
      const Eigen::VectorXd u = trajectory.inputs().col(k);
      const DynamicsStatus status = linearize(q, dq, u);
      requireLinearization(status, data,
                           *path + ": knot " + std::to_string(k) + " (t = " + formatNumber(trajectory.times()(k), 17) + ")");
      OutputJson head = OutputJson::object();
      head["knot"] = k;
      head["t"] = trajectory.times()(k);
      OutputJson result = linearizationJson(model, data, status, q, dq, u, std::move(head));
      if (secondOrder) addSecondOrder(*ws, result);
      writeJson(out, result, true);
    }
    return 0;
  }
  const ModelState state = stateFromFile(loaded, options.value("--state"));
  const DynamicsStatus status = linearize(state.q, state.dq, state.u);
  requireLinearization(status, data, loaded.path + (options.has("--state") ? " at " + *options.value("--state") : " at the scene's state"));
  OutputJson result = linearizationJson(model, data, status, state.q, state.dq, state.u, OutputJson::object());
  if (secondOrder) addSecondOrder(*ws, result);
  writeJson(out, result, options.flag("--compact"));
  return 0;
}

}  // namespace

const Command kLinearizeCommand{
    "linearize",
    "the exact linearization A, B at a state or along a trajectory, as JSON",
    kHelp,
    &runLinearize,
};

const CommandRegistration kRegisterLinearize{kLinearizeCommand};

}  // namespace trellis::cli
