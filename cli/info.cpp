// cli/info.cpp — `trellis info SCENE.json`: what a model contains (configuration variables, inputs,
// frames, masses, forces, constraints) and its tangent dimension at the stored state.
#include "cli_options.hpp"
#include "command.hpp"
#include "json_output.hpp"
#include "model_questions.hpp"

#include "trellis/core/linearization.hpp"

#include <iomanip>
#include <sstream>

namespace trellis::cli {
namespace {

constexpr std::string_view kHelp = R"(usage: trellis info [--json] [--state STATE.json] SCENE.json

Describes the model of a scene (docs/scene_format.md) as the algorithms see it:
  configs      the n configuration variables in order: the frame that carries each, the joint
               kind (rx..rz rotation about, tx..tz translation along the frame's own x/y/z axis
               after its constant placement) and the parent joint
  inputs       the m inputs in order, with the forces that use them
  frames       every frame: its parent frame, the body (joint) it is fixed to, its transform
               ("joint <config>" for a frame driven by a variable, else "fixed"), and its origin
               in that body's coordinates
  bodies       per joint body: the lumped mass and centre of mass (joint-frame coordinates)
  forces       gravity, springs, configuration forces, damping, body wrenches, tendons
  constraints  each row: its name (type and frames) and whether it is holonomic
  tangent      at the stored state (or --state): the dimension d = 2n - rank d[h; A q']/dx of
               the tangent space of the constraint manifold (the state dimension LQR works in),
               and the dynamics status there

options:
  --json             one JSON object instead of text (keys as the headings above)
  --state FILE       evaluate the tangent dimension at this state (see `trellis linearize --help`)
  -h, --help         show this help

Exit status: 0 on success; 1 if the scene or state cannot be read; 2 on a usage error.
)";

std::string jointKind(const Joint& joint) {
  return std::string(joint.revolute ? "r" : "t") + "xyz"[joint.axis];
}

std::string vec(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s << "[" << formatNumber(v.x()) << ", " << formatNumber(v.y()) << ", " << formatNumber(v.z()) << "]";
  return s.str();
}

OutputJson vecJson(const Eigen::Vector3d& v) { return OutputJson::array({v.x(), v.y(), v.z()}); }

std::string bodyName(const Model& model, int joint) {
  return joint == kWorld ? "world" : model.joints()[joint].config;
}

int runInfo(std::span<const std::string> args, std::ostream& out) {
  const ParsedOptions options("info", args, {{"--state"}, {"--json"}, {}});
  const LoadedScene loaded = loadSceneArgument(options.singlePositional("scene file"));
  const Model& model = loaded.scene.model;
  const ModelState state = stateFromFile(loaded, options.value("--state"));
  const auto& joints = model.joints();
  const auto& frames = model.frames();

  OutputJson info = OutputJson::object();
  info["name"] = model.name();
  info["n"] = model.nq();
  info["m"] = model.nu();
  info["nc"] = model.nc();
  info["holonomic"] = model.nholonomic();

  OutputJson configs = OutputJson::array();
  for (const Joint& j : joints) {
    configs.push_back({{"name", j.config}, {"frame", j.frame}, {"kind", jointKind(j)},
                       {"parent", j.parent == kWorld ? "world" : joints[j.parent].config}});
  }
  info["configs"] = configs;

  // Which forces use each input.
  std::vector<std::vector<std::string>> users(model.nu());
  for (const ConfigForce& f : model.configForces())
    users[f.input].push_back("config_force on " + model.configNames()[f.config]);
  for (const BodyWrench& w : model.bodyWrenches())
    for (int i = 0; i < 6; ++i)
      if (w.input[i] >= 0)
        users[w.input[i]].push_back(std::string("body_wrench ") + "fx fy fz tx ty tz"[3 * i] +
                                    "fx fy fz tx ty tz"[3 * i + 1] + " on body " + bodyName(model, w.joint));
  for (const Tendon& t : model.tendons())
    users[t.input].push_back("tendon through " + std::to_string(t.path.size()) + " points");
  OutputJson inputs = OutputJson::array();
  for (int i = 0; i < model.nu(); ++i) inputs.push_back({{"name", model.inputNames()[i]}, {"used_by", users[i]}});
  info["inputs"] = inputs;

  std::vector<std::string> drivenBy(frames.size());
  for (const Joint& j : joints) drivenBy[model.frameIndex(j.frame)] = j.config;
  OutputJson frameList = OutputJson::array();
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const FramePlacement& p = frames[f];
    frameList.push_back({{"name", p.name},
                         {"parent", p.parentFrame == kWorld ? "world" : frames[p.parentFrame].name},
                         {"body", bodyName(model, p.joint)},
                         {"transform", drivenBy[f].empty() ? "fixed" : "joint " + drivenBy[f]},
                         {"origin_in_body", vecJson(p.p)}});
  }
  info["frames"] = frameList;

  OutputJson bodies = OutputJson::array();
  double totalMass = 0.0;
  for (const Joint& j : joints) {
    const Eigen::Vector3d com = j.mass > 0.0 ? Eigen::Vector3d(j.firstMoment / j.mass) : Eigen::Vector3d::Zero();
    bodies.push_back({{"config", j.config}, {"mass", j.mass}, {"com", vecJson(com)}});
    totalMass += j.mass;
  }
  info["bodies"] = bodies;
  info["total_moving_mass"] = totalMass;

  OutputJson forces = OutputJson::array();
  if (!model.gravity().isZero(0.0)) forces.push_back({{"type", "gravity"}, {"g", vecJson(model.gravity())}});
  for (const LinearSpring& s : model.linearSprings())
    forces.push_back({{"type", "linear_spring"}, {"k", s.k}, {"x0", s.x0},
                      {"bodies", {bodyName(model, s.a.joint), bodyName(model, s.b.joint)}}});
  for (const ConfigSpring& s : model.configSprings())
    forces.push_back({{"type", "config_spring"}, {"config", model.configNames()[s.config]}, {"k", s.k}, {"q0", s.q0}});
  for (const ConfigForce& f : model.configForces())
    forces.push_back({{"type", "config_force"}, {"config", model.configNames()[f.config]},
                      {"input", model.inputNames()[f.input]}});
  for (int i = 0; i < model.nq(); ++i)
    if (model.damping().size() > i && model.damping()(i) != 0.0)
      forces.push_back({{"type", "damping"}, {"config", model.configNames()[i]}, {"c", model.damping()(i)}});
  for (const BodyWrench& w : model.bodyWrenches())
    forces.push_back({{"type", "body_wrench"}, {"body", bodyName(model, w.joint)}});
  for (const Tendon& t : model.tendons())
    forces.push_back({{"type", "tendon"}, {"input", model.inputNames()[t.input]}, {"points", t.path.size()}});
  info["forces"] = forces;

  OutputJson constraints = OutputJson::array();
  for (const Constraint& c : model.constraints())
    constraints.push_back({{"name", c.name}, {"holonomic", c.holonomic()}});
  info["constraints"] = constraints;

  Data data(model);
  OutputJson tangent = OutputJson::object();
  tangent["at"] = options.has("--state") ? *options.value("--state") : "the scene's state";
  if (model.nq() > 0) {
    const DynamicsStatus status = computeLinearization(model, data, state.q, state.dq, state.u);
    tangent["status"] = dynamicsStatusName(status.code);
    if (status.ok()) {
      tangent["dimension"] = computeConstraintTangentBasis(model, data);
    } else {
      tangent["dimension"] = nullptr;
      tangent["message"] = status.message;
    }
  } else {
    tangent["status"] = "ok";
    tangent["dimension"] = 0;
  }
  tangent["state_dimension"] = 2 * model.nq();
  info["tangent"] = tangent;

  if (options.flag("--json")) {
    writeJson(out, info, false);
    return 0;
  }
  // ---- text ----
  out << "model " << (model.name().empty() ? "(unnamed)" : model.name()) << " from " << loaded.path << ": n = "
      << model.nq() << " configuration variables, m = " << model.nu() << " inputs, nc = " << model.nc()
      << " constraint rows (" << model.nholonomic() << " holonomic)\n";
  out << "\nconfiguration variables (order of q):\n";
  for (const auto& c : info["configs"])
    out << "  " << c["name"].get<std::string>() << ": " << c["kind"].get<std::string>() << " of frame '"
        << c["frame"].get<std::string>() << "', parent joint " << c["parent"].get<std::string>() << "\n";
  out << "\ninputs (order of u):\n";
  if (model.nu() == 0) out << "  none\n";
  for (const auto& i : info["inputs"]) {
    out << "  " << i["name"].get<std::string>() << ":";
    for (const auto& u : i["used_by"]) out << " " << u.get<std::string>() << ";";
    out << "\n";
  }
  out << "\nframes (parent -> name: transform, body, origin in body):\n";
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const auto& fr = info["frames"][f];
    out << "  " << fr["parent"].get<std::string>() << " -> " << fr["name"].get<std::string>() << ": "
        << fr["transform"].get<std::string>() << ", body " << fr["body"].get<std::string>() << ", at "
        << vec(frames[f].p) << "\n";
  }
  out << "\nbodies (lumped mass, centre of mass in the joint frame):\n";
  for (const Joint& j : joints) {
    const Eigen::Vector3d com = j.mass > 0.0 ? Eigen::Vector3d(j.firstMoment / j.mass) : Eigen::Vector3d::Zero();
    out << "  " << j.config << ": m = " << formatNumber(j.mass) << ", com " << vec(com) << "\n";
  }
  out << "  total moving mass " << formatNumber(totalMass) << "\n";
  out << "\nforces and potentials:\n";
  if (forces.empty()) out << "  none\n";
  for (const auto& f : forces) out << "  " << f.dump() << "\n";
  out << "\nconstraints:\n";
  if (model.nc() == 0) out << "  none\n";
  for (const Constraint& c : model.constraints())
    out << "  " << c.name << (c.holonomic() ? ": holonomic" : ": nonholonomic") << "\n";
  out << "\ntangent space at " << tangent["at"].get<std::string>() << ": dimension ";
  if (tangent["dimension"].is_null()) {
    out << "unknown (dynamics status " << tangent["status"].get<std::string>() << ")";
  } else {
    out << tangent["dimension"].get<int>() << " of " << 2 * model.nq() << " (dynamics status "
        << tangent["status"].get<std::string>() << ")";
  }
  out << "\n";
  return 0;
}

}  // namespace

const Command kInfoCommand{
    "info",
    "what a model contains: variables, inputs, frames, masses, forces, constraints",
    kHelp,
    &runInfo,
};

const CommandRegistration kRegisterInfo{kInfoCommand};

}  // namespace trellis::cli
