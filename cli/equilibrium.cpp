// cli/equilibrium.cpp — `trellis equilibrium SCENE.json`: a configuration at rest under given
// inputs (core/equilibrium.hpp), or with --hold the inputs that hold a given pose.
#include "cli_options.hpp"
#include "command.hpp"
#include "model_questions.hpp"

#include "trellis/core/equilibrium.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis equilibrium [--state STATE.json] [--inputs a=1,b=2] [options] SCENE.json
       trellis equilibrium --hold [--state STATE.json] [--allow-residual] SCENE.json

Without --hold: searches a static equilibrium, a q with q' = 0 and q''(q, 0, u) = 0 on the
holonomic constraints h(q) = 0, under fixed inputs u, by Gauss-Newton on F(q) = [q''; h] with
the exact Jacobian [dq''/dq; dh/dq] of the linearization and a backtracking line search. The
start is q of the scene's stored state (or --state); u is the state's u with --inputs applied.
Output keys (the library's report, then the names and the state): status ("ok"), ok, message,
t, index (null), iterations, qdd_residual (max |q''|), h_residual (max |h|), jacobian_rank,
isolated (false: a continuum of equilibria passes through q, e.g. a free coordinate),
max_real_eigenvalue (largest real part of the eigenvalues of the linearization on the
constraint tangent space: < 0 asymptotically stable, > 0 unstable, ~0 marginal — an undamped
stable equilibrium has eigenvalues +- i w), q, u, lambda, configs, inputs, state (a state object
--state reads back), outside_limits (the coordinates beyond a URDF joint's <limit lower upper>,
as name = value (limits [lower, upper]); the search does not enforce the limits, so an answer
outside them fails the command unless --ignore-limits).

With --hold: the inputs that hold the pose q (of the state) still, i.e. inverse dynamics with
q' = 0, q'' = 0: B_u u + A^T lambda = b(q) (the generalized forces of gravity, springs and
constant wrenches at rest, with the sign of M q'' + b = Q_u + A^T lambda), least squares of
minimum norm. With --effort-bounds the inputs of a URDF robot's joints are bounded by the
joints' <limit effort> (|u| <= effort; bounded least squares): a pose that needs more fails
(input_bounds, naming the input, its bound and the excess).
A floating base (URDF floating joint, or urdf_options floating_root) without contacts cannot be
held under gravity: the command fails and names the base coordinates nothing acts on (add
contacts: docs/urdf.md, "Floating bases and contacts").
Output keys: status ("ok", or "unreachable" with --allow-residual when no inputs can hold the
pose), ok, message, t, index, residual (max |B_u u + A^T lambda - r|, generalized forces),
constraint_residual, rank, unique, bound_iterations, u, lambda, bound_excess, inputs, state.

options:
  --state FILE           the start (or the pose to hold); see `trellis linearize --help`
  --inputs LIST          name=value,... overrides of the inputs (not with --hold)
  --hold                 the inputs that hold the pose instead of a pose for the inputs
  --allow-residual       with --hold: print the least-squares inputs (exit 0) when no inputs hold
                         the pose exactly
  --effort-bounds        with --hold: bound each URDF joint's input by its <limit effort>
  --ignore-limits        without --hold: accept an equilibrium outside the URDF joint limits
  --tolerance TOL        on max |q''| and max |h| (default 1e-10)
  --max-iterations N     Newton iterations (default 50)
  --compact              print the object on one line
  -h, --help             show this help

Exit status: 0 on success; 1 if the scene or state cannot be read, the search does not converge
or the dynamics fail (the message gives the residuals), or with --hold when the pose cannot be
held (without --allow-residual); 2 on a usage error.
)";

Eigen::VectorXd applyInputs(const Model& model, const ParsedOptions& options, Eigen::VectorXd u) {
  const auto list = options.value("--inputs");
  if (!list) return u;
  std::size_t start = 0;
  while (start <= list->size()) {
    const std::size_t comma = list->find(',', start);
    const std::string item = list->substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw UsageError("equilibrium: --inputs: '" + item + "' is not name=value");
    }
    const std::string name = item.substr(0, eq);
    const auto& names = model.inputNames();
    const auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) {
      throw UsageError("equilibrium: --inputs: unknown input '" + name + "' (known: " + joinNames(names) + ")");
    }
    u(it - names.begin()) = options.number("--inputs", item.substr(eq + 1));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return u;
}

/// The coordinates of q outside the scene's URDF position limits, as "name = value (limits [lo, hi])".
std::vector<std::string> limitViolations(const Scene& scene, const Eigen::VectorXd& q) {
  std::vector<std::string> out;
  if (scene.lowerLimit.size() != q.size()) return out;
  for (int i = 0; i < q.size(); ++i) {
    if (q[i] >= scene.lowerLimit[i] && q[i] <= scene.upperLimit[i]) continue;
    std::ostringstream s;
    s.precision(6);
    s << scene.model.configNames()[i] << " = " << q[i] << " (limits [" << scene.lowerLimit[i] << ", "
      << scene.upperLimit[i] << "])";
    out.push_back(s.str());
  }
  return out;
}

/// Why a pose cannot be held when coordinates are free: no input and no constraint acts on them
/// (their rows of [B_u Aᵀ] are zero) while the pose needs a force there, e.g. a floating base
/// without contacts under gravity. Empty when there is no such coordinate.
std::string unheldReason(const Model& model, const Data& data, const InverseDynamicsResult& r) {
  if (r.status.code != InverseDynamicsCode::kUnreachable || r.residual.size() != model.nq()) return "";
  std::vector<std::string> free, loaded;
  double need = 0.0;
  for (int i = 0; i < model.nq(); ++i) {
    const bool noInput = model.nu() == 0 || data.inputMatrix.row(i).isZero(0.0);
    const bool noConstraint = model.nc() == 0 || data.constraintJacobian.col(i).isZero(0.0);
    if (!noInput || !noConstraint) continue;
    free.push_back(model.configNames()[i]);
    if (r.residual[i] != 0.0) {
      loaded.push_back(model.configNames()[i]);
      need = std::max(need, std::abs(r.residual[i]));
    }
  }
  if (loaded.empty()) return "";
  std::ostringstream s;
  s.precision(4);
  s << "; no input and no constraint acts on " << joinNames(free) << ", yet the pose needs a generalized force of up to "
    << need << " on " << joinNames(loaded) << ": a floating base without contacts cannot be held (nothing holds it up). Add contacts: "
    << "point constraints from the feet to the ground in a scene that includes the URDF (docs/urdf.md, "
    << "\"Floating bases and contacts\"); or, to push the base by forces from nowhere, urdf_options "
    << "{\"base_inputs\": true}";
  return s.str();
}

int runEquilibrium(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options("equilibrium", args,
                              {{"--state", "--inputs", "--tolerance", "--max-iterations"},
                               {"--hold", "--allow-residual", "--compact", "--ignore-limits", "--effort-bounds"}, {}});
  const LoadedScene loaded = loadSceneArgument(options.singlePositional("scene file"));
  const Model& model = loaded.scene.model;
  const ModelState state = stateFromFile(loaded, options.value("--state"));
  Data data(model);
  OutputJson result = OutputJson::object();
  if (options.flag("--hold")) {
    for (const char* o : {"--inputs", "--max-iterations", "--ignore-limits"})
      if (options.has(o)) throw UsageError(std::string("equilibrium: ") + o + " does not apply to --hold");
    InverseDynamicsOptions io;
    if (options.flag("--effort-bounds")) {
      // |u_j| ≤ effort of the joint whose name the input carries (URDF joint inputs); others free.
      const Scene& sc = loaded.scene;
      if (sc.effortLimit.size() != model.nq())
        throw UsageError("equilibrium: --effort-bounds needs a URDF robot (its <limit effort>)");
      const double inf = std::numeric_limits<double>::infinity();
      io.lowerBound = Eigen::VectorXd::Constant(model.nu(), -inf);
      io.upperBound = Eigen::VectorXd::Constant(model.nu(), inf);
      for (int k = 0; k < model.nu(); ++k) {
        const auto& names = model.configNames();
        const auto it = std::find(names.begin(), names.end(), model.inputNames()[k]);
        if (it == names.end()) continue;
        const double e = sc.effortLimit[it - names.begin()];
        io.lowerBound[k] = -e;
        io.upperBound[k] = e;
      }
    }
    if (const auto v = options.value("--tolerance"))
      io.tolerance = options.numberInRange("--tolerance", *v, 1e-16, 0.1,
                                           "relative to the forces compared: above, any answer would pass");
    const InverseDynamicsResult r = computeHoldingInputs(model, data, state.q, io);
    const bool accepted = r.ok() || (r.status.code == InverseDynamicsCode::kUnreachable && options.flag("--allow-residual"));
    if (!accepted) {
      throw std::runtime_error(loaded.path + ": the pose cannot be held (" + r.status.name() + "): " + r.status.message +
                               unheldReason(model, data, r));
    }
    if (r.ok()) {
      // The pose must lie on the constraints, as `gains --hold` requires: inverse dynamics at an
      // infeasible q answers a question about a configuration the system cannot take.
      Eigen::VectorXd x = Eigen::VectorXd::Zero(2 * model.nq());
      x.head(model.nq()) = state.q;
      checkReference(model, loaded.path, "the pose to hold",
                     Trajectory(model.configNames(), model.inputNames(), Eigen::Vector2d(0.0, 1.0),
                                x.replicate(1, 2), r.u.replicate(1, 2)));
    }
    // The library's report (InverseDynamicsResult::json), then the names and the state object.
    result = OutputJson::parse(r.json());
    result["inputs"] = nameList(model.inputNames());
    result["state"] = stateObject(model, state.q, Eigen::VectorXd::Zero(model.nq()), r.u);
  } else {
    if (options.flag("--allow-residual")) throw UsageError("equilibrium: --allow-residual needs --hold");
    if (options.flag("--effort-bounds")) throw UsageError("equilibrium: --effort-bounds needs --hold");
    EquilibriumOptions eo;
    if (const auto v = options.value("--tolerance"))
      eo.tolerance = options.numberInRange("--tolerance", *v, 1e-300, 1e-3,
                                           "the residual [q''; h] at the answer as a configuration change (radians, or "
                                           "model lengths): above, not an equilibrium");
    if (const auto v = options.value("--max-iterations")) {
      eo.maxIterations = options.integer<int>("--max-iterations", *v, 1, 100000);
    }
    if (model.nq() == 0) throw std::runtime_error(loaded.path + ": the scene has no configuration variables");
    const Eigen::VectorXd u = applyInputs(model, options, state.u);
    const EquilibriumResult r = findEquilibrium(model, data, state.q, u, eo);
    if (!r.ok()) {
      throw std::runtime_error(loaded.path + ": no equilibrium found (" + r.status.name() + "): " + r.status.message);
    }
    // The search is unconstrained: an equilibrium beyond a URDF joint's <limit> (a wrist at 73.9 rad)
    // is one of the model, not of the robot. Refused unless --ignore-limits; listed either way.
    const std::vector<std::string> outside = limitViolations(loaded.scene, r.q);
    if (!outside.empty() && !options.flag("--ignore-limits")) {
      throw std::runtime_error(loaded.path + ": the equilibrium found lies outside the URDF joint limits: " +
                               joinNames(outside) +
                               " (the search does not enforce them; start inside with --state, or accept it with "
                               "--ignore-limits)");
    }
    // The library's report (EquilibriumResult::json), then the names and the state object.
    result = OutputJson::parse(r.json());
    result["configs"] = nameList(model.configNames());
    result["inputs"] = nameList(model.inputNames());
    result["state"] = stateObject(model, r.q, Eigen::VectorXd::Zero(model.nq()), r.u);
    result["outside_limits"] = nameList(outside);
  }
  writeJson(out, result, options.flag("--compact"));
  return 0;
}

}  // namespace

const Command kEquilibriumCommand{
    "equilibrium",
    "a configuration at rest under given inputs, or (--hold) the inputs that hold a pose",
    kHelp,
    &runEquilibrium,
};

const CommandRegistration kRegisterEquilibrium{kEquilibriumCommand};

}  // namespace trellis::cli
