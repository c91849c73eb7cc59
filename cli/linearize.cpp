// cli/linearize.cpp — `trellis linearize SCENE.json`: the exact linearization at the scene's state.
#include "command.hpp"
#include "json_output.hpp"

#include "trellis/core/linearization.hpp"
#include "trellis/core/scene.hpp"

#include <iostream>
#include <iterator>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis linearize [--compact] SCENE.json
       trellis linearize [--compact] -          (read the scene from standard input)

Loads a scene (SCENE_FORMAT.md, version 1) and evaluates, at the state stored in its "state"
(missing names are 0), the constrained Euler-Lagrange equations

  M(q) q'' = Q(q, q', u) + dL/dq - (d2L/dq dq') q' + J(q)^T lambda,    J q'' + J' q' = 0,

with J = dh/dq the constraint Jacobian, then prints their exact linearization

  dx' = A dx + B du,   x = [q; q'],
  A = [[0, I], [dq''/dq, dq''/dq']]   (2n x 2n),   B = [[0], [dq''/du]]   (2n x m).

The state is used as written, not projected onto the constraints: off the constraint manifold
the result depends on how a constraint is written (see h and hdot in the output).

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

options:
  --compact   print the object on one line
  -h, --help  show this help

Exit status: 0 on success; 1 if the scene cannot be read or is invalid, or if the dynamics
cannot be solved at its state (singular mass matrix, singular constraints, non-finite values);
2 on a usage error. Errors are one line on standard error and nothing on standard output.
)";

std::string statusName(DynamicsStatus::Code code) {
  switch (code) {
    case DynamicsStatus::Code::kOk: return "ok";
    case DynamicsStatus::Code::kRedundantConstraints: return "redundant_constraints";
    case DynamicsStatus::Code::kSingularMassMatrix: return "singular_mass_matrix";
    case DynamicsStatus::Code::kSingularConstraints: return "singular_constraints";
    case DynamicsStatus::Code::kNonFinite: return "non_finite";
  }
  return "unknown";
}

OutputJson names(const std::vector<std::string>& list) {
  OutputJson out = OutputJson::array();
  for (const std::string& name : list) out.push_back(name);
  return out;
}

int runLinearize(std::span<const std::string> args, std::ostream& out) {
  bool compact = false;
  std::string path;
  bool havePath = false;
  bool optionsDone = false;
  for (const std::string& arg : args) {
    if (!optionsDone && arg == "--") {
      optionsDone = true;
    } else if (!optionsDone && arg == "--compact") {
      compact = true;
    } else if (!optionsDone && arg.size() > 1 && arg[0] == '-') {
      throw UsageError("linearize: unknown option '" + arg + "'");
    } else if (havePath) {
      throw UsageError("linearize: more than one scene file ('" + path + "', '" + arg + "')");
    } else {
      path = arg;
      havePath = true;
    }
  }
  if (!havePath) throw UsageError("linearize: missing the scene file");

  const bool fromStdin = path == "-";
  Scene scene = [&] {
    if (!fromStdin) return loadScene(path);
    const std::string text{std::istreambuf_iterator<char>(std::cin), std::istreambuf_iterator<char>()};
    return parseScene(text, "<stdin>");
  }();
  if (fromStdin) path = "<stdin>";  // for the messages below
  const Model& model = scene.model;
  if (model.nq() == 0) {
    throw std::runtime_error(path + ": the scene has no configuration variables: nothing to linearize");
  }
  Data data(model);
  const DynamicsStatus status = computeLinearization(model, data, scene.q, scene.dq, scene.u);
  if (!status.ok()) {
    throw std::runtime_error(path + ": the dynamics cannot be solved at the scene's state (" +
                             statusName(status.code) + ")" +
                             (status.message.empty() ? "" : ": " + status.message));
  }
  if (!data.A.allFinite() || !data.B.allFinite() || !data.qdd.allFinite() || !data.lambda.allFinite()) {
    throw std::runtime_error(path + ": the linearization at the scene's state is not finite");
  }

  OutputJson result = OutputJson::object();
  result["status"] = statusName(status.code);
  result["configs"] = names(model.configNames());
  result["inputs"] = names(model.inputNames());
  result["q"] = toJson(scene.q);
  result["dq"] = toJson(scene.dq);
  result["u"] = toJson(scene.u);
  result["qdd"] = toJson(data.qdd);
  result["lambda"] = toJson(data.lambda);
  result["h"] = toJson(data.constraintValue);
  result["hdot"] = toJson(Eigen::VectorXd(data.constraintJacobian * scene.dq));
  result["M"] = toJson(data.M);
  result["A"] = toJson(data.A);
  result["B"] = toJson(data.B);
  writeJson(out, result, compact);
  return 0;
}

}  // namespace

const Command kLinearizeCommand{
    "linearize",
    "the exact linearization A, B of a scene at its stored state, as JSON",
    kHelp,
    &runLinearize,
};

const CommandRegistration kRegisterLinearize{kLinearizeCommand};

}  // namespace trellis::cli
