// problem.cpp — OptimalControlProblem: defaults, validation, and the JSON problem file.
#include "trellis/optimization/problem.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/io.hpp"
#include "trellis/core/json_integer.hpp"
#include "trellis/core/scene.hpp"

#include <nlohmann/json.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <type_traits>

namespace trellis {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

[[noreturn]] void fail(const std::string& message) { throw ProblemError(message); }

std::string str(double v) {
  std::ostringstream s;
  s.precision(12);
  s << v;
  return s.str();
}

void checkSize(const Eigen::VectorXd& v, int size, const char* field) {
  if (v.size() != size) {
    fail(std::string("problem: ") + field + " has " + std::to_string(v.size()) +
         " entries, expected " + std::to_string(size));
  }
}

void checkWeight(const Eigen::MatrixXd& W, int size, const char* field) {
  if (W.rows() != size || W.cols() != size) {
    fail(std::string("problem: ") + field + " is " + std::to_string(W.rows()) + "x" +
         std::to_string(W.cols()) + ", expected " + std::to_string(size) + "x" + std::to_string(size));
  }
  if (size == 0) return;
  if (!W.allFinite()) fail(std::string("problem: ") + field + " has a non-finite entry");
  const double scale = std::max(1.0, W.cwiseAbs().maxCoeff());
  if ((W - W.transpose()).cwiseAbs().maxCoeff() > 1e-12 * scale) {
    fail(std::string("problem: ") + field + " is not symmetric");
  }
  const double lmin =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(W, Eigen::EigenvaluesOnly).eigenvalues()(0);
  if (lmin < -1e-12 * scale) {
    fail(std::string("problem: ") + field + " is not positive semidefinite (smallest eigenvalue " +
         str(lmin) + ")");
  }
}

}  // namespace

OptimalControlProblem::OptimalControlProblem(std::shared_ptr<const Model> m) : model(std::move(m)) {
  if (!model) fail("problem: model is null");
  const int nxs = nx(), m_ = nu();
  initialState = Eigen::VectorXd::Zero(nxs);
  finalState = Eigen::VectorXd::Zero(nxs);
  initialFixed.assign(nxs, true);
  finalFixed.assign(nxs, true);
  stateLower = Eigen::VectorXd::Constant(nxs, -kInf);
  stateUpper = Eigen::VectorXd::Constant(nxs, kInf);
  inputLower = Eigen::VectorXd::Constant(m_, -kInf);
  inputUpper = Eigen::VectorXd::Constant(m_, kInf);
  forceLower = Eigen::VectorXd::Constant(model->nc(), -kInf);
  forceUpper = Eigen::VectorXd::Constant(model->nc(), kInf);
  R = Eigen::MatrixXd::Identity(m_, m_);
  Q = Eigen::MatrixXd::Zero(nxs, nxs);
  Qf = Eigen::MatrixXd::Zero(nxs, nxs);
  goalState = Eigen::VectorXd::Zero(nxs);
}

int OptimalControlProblem::nq() const { return model ? model->nq() : 0; }
int OptimalControlProblem::nu() const { return model ? model->nu() : 0; }

std::vector<std::string> OptimalControlProblem::stateNames() const {
  std::vector<std::string> names;
  if (!model) return names;
  for (const std::string& c : model->configNames()) names.push_back(c);
  for (const std::string& c : model->configNames()) names.push_back("d" + c);
  return names;
}

Eigen::VectorXd OptimalControlProblem::meshFractions() const {
  if (mesh.size() > 0) return mesh;
  return Eigen::VectorXd::LinSpaced(std::max(knots, 2), 0.0, 1.0);
}

namespace {

/// A fixed boundary state must lie on the constraint manifold: checked before the NLP is built,
/// so that a wrong fixed entry is named instead of surfacing as a generic Ipopt "infeasible".
void checkBoundaryOnManifold(const OptimalControlProblem& p, const Eigen::VectorXd& x,
                             const std::vector<bool>& fixed, const char* which, const char* freeField) {
  const Model& model = *p.model;
  const int n = model.nq();
  if (model.nc() == 0) return;
  bool configFixed = true, allFixed = true;
  for (int i = 0; i < n; ++i) configFixed = configFixed && fixed[i];
  for (int i = 0; i < 2 * n; ++i) allFixed = allFixed && fixed[i];
  if (!configFixed) return;
  Data data(model);
  computeConstraints(model, data, x.head(n), x.tail(n));
  const Eigen::VectorXd velocity = data.constraintJacobian * x.tail(n);
  const double tol = OptimalControlProblem::kBoundaryTolerance;
  for (int r = 0; r < model.nc(); ++r) {
    const Constraint& c = model.constraints()[r];
    const std::string name = "constraint '" + (c.name.empty() ? "#" + std::to_string(r) : c.name) +
                             "' (row " + std::to_string(r) + ")";
    if (c.holonomic() && !(std::abs(data.constraintValue(r)) <= tol)) {
      fail(std::string("problem: the fixed ") + which + " configuration violates " + name +
           ": h = " + str(data.constraintValue(r)) + " (tolerance " + str(tol) +
           "); give a configuration on the constraint manifold or leave the dependent entries "
           "free (" + freeField + ")");
    }
    if (allFixed && !(std::abs(velocity(r)) <= tol)) {
      fail(std::string("problem: the fixed ") + which + " velocity violates " + name +
           ": A q' = " + str(velocity(r)) + " (tolerance " + str(tol) +
           "); give a velocity tangent to the constraints or leave entries free (" + freeField + ")");
    }
  }
}

}  // namespace

void OptimalControlProblem::validate() const {
  if (!model) fail("problem: model is null");
  if (model->nq() == 0) fail("problem: the model has no configuration variables");
  const int nxs = nx(), m = nu();
  if (knots < 2) fail("problem: knots = " + std::to_string(knots) + " must be >= 2");
  if (mesh.size() > 0) {
    if (mesh.size() != knots) {
      fail("problem: mesh has " + std::to_string(mesh.size()) + " entries, expected knots = " +
           std::to_string(knots));
    }
    if (mesh(0) != 0.0 || mesh(knots - 1) != 1.0) fail("problem: mesh must start at 0 and end at 1");
    for (int k = 0; k + 1 < knots; ++k) {
      if (!(mesh(k + 1) > mesh(k))) {
        fail("problem: mesh is not strictly increasing at entry " + std::to_string(k + 1) + " (" +
             str(mesh(k + 1)) + " after " + str(mesh(k)) + ")");
      }
    }
  }
  if (!(minHorizon > 0.0) || !std::isfinite(minHorizon)) {
    fail("problem: minHorizon = " + str(minHorizon) + " must be > 0 and finite");
  }
  if (!(maxHorizon >= minHorizon) || !std::isfinite(maxHorizon)) {
    fail("problem: maxHorizon = " + str(maxHorizon) + " must be finite and >= minHorizon = " +
         str(minHorizon));
  }
  if (!(horizon >= minHorizon && horizon <= maxHorizon)) {
    fail("problem: horizon = " + str(horizon) + " must lie in [minHorizon, maxHorizon] = [" +
         str(minHorizon) + ", " + str(maxHorizon) + "]");
  }
  checkSize(initialState, nxs, "initialState");
  checkSize(finalState, nxs, "finalState");
  checkSize(goalState, nxs, "goalState");
  checkSize(stateLower, nxs, "stateLower");
  checkSize(stateUpper, nxs, "stateUpper");
  checkSize(inputLower, m, "inputLower");
  checkSize(inputUpper, m, "inputUpper");
  if (static_cast<int>(initialFixed.size()) != nxs) fail("problem: initialFixed has the wrong size");
  if (static_cast<int>(finalFixed.size()) != nxs) fail("problem: finalFixed has the wrong size");
  const std::vector<std::string> names = stateNames();
  for (int i = 0; i < nxs; ++i) {
    if (!std::isfinite(initialState(i))) fail("problem: initialState." + names[i] + " is not finite");
    if (!std::isfinite(finalState(i))) fail("problem: finalState." + names[i] + " is not finite");
    if (!std::isfinite(goalState(i))) fail("problem: goalState." + names[i] + " is not finite");
    if (std::isnan(stateLower(i)) || std::isnan(stateUpper(i)) || stateLower(i) > stateUpper(i)) {
      fail("problem: state bounds of '" + names[i] + "' [" + str(stateLower(i)) + ", " +
           str(stateUpper(i)) + "] are empty or NaN");
    }
    if (initialFixed[i] && (initialState(i) < stateLower(i) || initialState(i) > stateUpper(i))) {
      fail("problem: initialState." + names[i] + " = " + str(initialState(i)) +
           " is fixed outside its bounds [" + str(stateLower(i)) + ", " + str(stateUpper(i)) + "]");
    }
    if (finalFixed[i] && (finalState(i) < stateLower(i) || finalState(i) > stateUpper(i))) {
      fail("problem: finalState." + names[i] + " = " + str(finalState(i)) +
           " is fixed outside its bounds [" + str(stateLower(i)) + ", " + str(stateUpper(i)) + "]");
    }
  }
  for (int j = 0; j < m; ++j) {
    if (std::isnan(inputLower(j)) || std::isnan(inputUpper(j)) || inputLower(j) > inputUpper(j)) {
      fail("problem: input bounds of '" + model->inputNames()[j] + "' [" + str(inputLower(j)) +
           ", " + str(inputUpper(j)) + "] are empty or NaN");
    }
  }
  checkSize(forceLower, model->nc(), "forceLower");
  checkSize(forceUpper, model->nc(), "forceUpper");
  for (int r = 0; r < model->nc(); ++r) {
    if (std::isnan(forceLower(r)) || std::isnan(forceUpper(r)) || forceLower(r) > forceUpper(r)) {
      fail("problem: constraint force bounds of '" + model->constraints()[r].name + "' (row " +
           std::to_string(r) + ") [" + str(forceLower(r)) + ", " + str(forceUpper(r)) + "] are empty or NaN");
    }
  }
  for (std::size_t k = 0; k < forceCombinations.size(); ++k) {
    const ForceCombination& c = forceCombinations[k];
    const std::string what = "problem: forceCombinations[" + std::to_string(k) + "] ('" + c.name + "')";
    if (c.coefficients.size() != model->nc()) {
      fail(what + ": coefficients has " + std::to_string(c.coefficients.size()) +
           " entries, expected nc = " + std::to_string(model->nc()));
    }
    if (!c.coefficients.allFinite() || c.coefficients.isZero(0.0)) {
      fail(what + ": coefficients must be finite and not all zero");
    }
    if (std::isnan(c.lower) || std::isnan(c.upper) || c.lower > c.upper ||
        (!std::isfinite(c.lower) && !std::isfinite(c.upper))) {
      fail(what + ": bounds [" + str(c.lower) + ", " + str(c.upper) +
           "] are empty, NaN or both infinite");
    }
  }
  checkWeight(R, m, "R");
  checkWeight(Q, nxs, "Q");
  checkWeight(Qf, nxs, "Qf");
  if (!(timeWeight >= 0.0) || !std::isfinite(timeWeight)) {
    fail("problem: timeWeight = " + str(timeWeight) + " must be >= 0 and finite");
  }
  for (const auto* flags : {&initialAccelerationFixed, &finalAccelerationFixed}) {
    const std::string name = flags == &initialAccelerationFixed ? "initialAccelerationFixed" : "finalAccelerationFixed";
    if (flags->empty()) continue;
    if (static_cast<int>(flags->size()) != nq()) {
      fail("problem: " + name + " has " + std::to_string(flags->size()) + " flags, the model has " +
           std::to_string(nq()) + " coordinates");
    }
    if (dynamics != DynamicsForm::kImplicit) fail("problem: " + name + " needs dynamics = implicit (q̈ is a variable only there)");
  }
  if (accelerationWeights.size() > 0) {
    const int n = nq();
    if (accelerationWeights.size() != n) {
      fail("problem: accelerationWeights has " + std::to_string(accelerationWeights.size()) + " entries, the model has " +
           std::to_string(n) + " coordinates");
    }
    for (int i = 0; i < n; ++i) {
      if (!(accelerationWeights(i) >= 0.0) || !std::isfinite(accelerationWeights(i))) {
        fail("problem: accelerationWeights[" + std::to_string(i) + "] (" + model->configNames()[i] +
             ") = " + str(accelerationWeights(i)) + " must be >= 0 and finite");
      }
    }
    if (dynamics != DynamicsForm::kImplicit) {
      fail("problem: accelerationWeights needs dynamics = implicit (q̈ is a variable only there)");
    }
  }
  if (initialGuess) {
    try {
      initialGuess->checkCompatible(*model);
    } catch (const std::exception& e) {
      fail(std::string("problem: initialGuess: ") + e.what());
    }
  }
  checkBoundaryOnManifold(*this, initialState, initialFixed, "initial", "free_initial");
  checkBoundaryOnManifold(*this, finalState, finalFixed, "final", "free_final");
}

// ---- Problem file -----------------------------------------------------------------------------

namespace {

using Json = nlohmann::json;

// The knots a problem file may ask for (the same bound as `trellis optimize --knots`): the NLP
// grows linearly with them, and a count beyond the range of int must not wrap around.
constexpr int kMaxKnots = 100000;

class FileParser {
 public:
  FileParser(std::string source, std::string baseDir)
      : source_(std::move(source)), baseDir_(std::move(baseDir)) {}

  [[noreturn]] void bad(const std::string& path, const std::string& what) const {
    fail(source_ + ": field '" + path + "': " + what);
  }

  double number(const Json& j, const std::string& path) const {
    if (!j.is_number()) bad(path, "expected a number, got " + j.dump());
    const double v = j.get<double>();
    if (!std::isfinite(v)) bad(path, "not finite");
    return v;
  }

  /// An integer in [min, max] (range-checked before any conversion: 4294967298 does not wrap).
  int integer(const Json& j, const std::string& path, int min, int max) const {
    long long value = 0;
    std::string problem;
    if (!jsonInteger(j, min, max, value, problem)) bad(path, problem);
    return static_cast<int>(value);
  }

  std::string string(const Json& j, const std::string& path) const {
    if (!j.is_string()) bad(path, "expected a string, got " + j.dump());
    return j.get<std::string>();
  }

  const Json& object(const Json& j, const std::string& path) const {
    if (!j.is_object()) bad(path, "expected an object, got " + j.dump());
    return j;
  }

  /// Index of `name` in `names`, else an error listing the valid names.
  int index(const std::vector<std::string>& names, const std::string& name,
            const std::string& path, const char* kind) const {
    for (std::size_t i = 0; i < names.size(); ++i)
      if (names[i] == name) return static_cast<int>(i);
    std::string list;
    for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
    bad(path, "unknown " + std::string(kind) + " '" + name + "' (expected one of: " + list + ")");
  }

  /// {"name": value, ...} into v (entries not named keep their value).
  void namedValues(const Json& j, const std::string& path, const std::vector<std::string>& names,
                   const char* kind, Eigen::VectorXd& v) const {
    object(j, path);
    for (const auto& [key, value] : j.items()) {
      const int i = index(names, key, path + "." + key, kind);
      v(i) = number(value, path + "." + key);
    }
  }

  /// {"name": [lower, upper], ...}; null means no bound on that side.
  void namedBounds(const Json& j, const std::string& path, const std::vector<std::string>& names,
                   const char* kind, Eigen::VectorXd& lower, Eigen::VectorXd& upper) const {
    object(j, path);
    for (const auto& [key, value] : j.items()) {
      const std::string p = path + "." + key;
      const int i = index(names, key, p, kind);
      if (!value.is_array() || value.size() != 2) bad(p, "expected [lower, upper], got " + value.dump());
      lower(i) = value[0].is_null() ? -kInf : number(value[0], p + "[0]");
      upper(i) = value[1].is_null() ? kInf : number(value[1], p + "[1]");
      if (lower(i) > upper(i)) bad(p, "lower bound " + str(lower(i)) + " > upper bound " + str(upper(i)));
    }
  }

  void freeList(const Json& j, const std::string& path, const std::vector<std::string>& names,
                std::vector<bool>& fixed) const {
    if (!j.is_array()) bad(path, "expected a list of state names, got " + j.dump());
    for (std::size_t k = 0; k < j.size(); ++k) {
      const std::string p = path + "[" + std::to_string(k) + "]";
      fixed[index(names, string(j[k], p), p, "state")] = false;
    }
  }

  /// A diagonal weight {"name": w ≥ 0} or a full matrix [[...], ...].
  void weight(const Json& j, const std::string& path, const std::vector<std::string>& names,
              const char* kind, Eigen::MatrixXd& W) const {
    const int size = static_cast<int>(names.size());
    if (j.is_array()) {
      if (static_cast<int>(j.size()) != size) {
        bad(path, "expected " + std::to_string(size) + " rows, got " + std::to_string(j.size()));
      }
      for (int r = 0; r < size; ++r) {
        const std::string pr = path + "[" + std::to_string(r) + "]";
        if (!j[r].is_array() || static_cast<int>(j[r].size()) != size) {
          bad(pr, "expected a row of " + std::to_string(size) + " numbers");
        }
        for (int c = 0; c < size; ++c) W(r, c) = number(j[r][c], pr + "[" + std::to_string(c) + "]");
      }
      return;
    }
    object(j, path);
    W.setZero();
    for (const auto& [key, value] : j.items()) {
      const std::string p = path + "." + key;
      const int i = index(names, key, p, kind);
      W(i, i) = number(value, p);
      if (W(i, i) < 0.0) bad(p, str(W(i, i)) + " must be >= 0");
    }
  }

  void checkKeys(const Json& j, const std::string& path, const std::set<std::string>& allowed) const {
    for (const auto& [key, value] : j.items()) {
      if (!allowed.count(key)) {
        std::string list;
        for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
        bad(path.empty() ? key : path + "." + key, "unknown field (expected one of: " + list + ")");
      }
    }
  }

  std::string resolve(const std::string& path) const {
    const std::filesystem::path p(path);
    if (p.is_absolute() || baseDir_.empty()) return path;
    return (std::filesystem::path(baseDir_) / p).string();
  }

  OptimalControlProblem parse(const std::string& text) const {
    Json root;
    try {
      root = Json::parse(text);
    } catch (const Json::exception& e) {
      // parse_error, and out_of_range.406 for a number that overflows a double (1e999); the
      // library's "[json.exception.KIND.ID] " prefix names nothing the user wrote.
      std::string what = e.what();
      if (const auto end = what.find("] "); what.rfind("[json.exception.", 0) == 0 && end != std::string::npos) {
        what.erase(0, end + 2);
      }
      fail(source_ + ": invalid JSON: " + what);
    }
    if (!root.is_object()) fail(source_ + ": expected a JSON object at the top level");
    checkKeys(root, "", {"description", "scene", "method", "knots", "horizon", "initial_state",
                         "final_state", "free_initial", "free_final", "state_bounds",
                         "input_bounds", "constraint_force_bounds", "cost", "initial_guess", "hessian", "dynamics"});
    if (!root.contains("scene")) bad("scene", "missing (the path of a scene file)");
    const std::string scenePath = resolve(string(root["scene"], "scene"));
    Scene scene = loadScene(scenePath);
    OptimalControlProblem problem(std::make_shared<const Model>(std::move(scene.model)));
    const std::vector<std::string> states = problem.stateNames();
    const std::vector<std::string>& inputs = problem.model->inputNames();

    if (root.contains("method")) {
      const std::string method = string(root["method"], "method");
      if (method == "hermite_simpson") {
        problem.method = CollocationMethod::kHermiteSimpson;
      } else if (method == "trapezoidal") {
        problem.method = CollocationMethod::kTrapezoidal;
      } else if (method == "radau") {
        problem.method = CollocationMethod::kRadau;
      } else {
        bad("method", "'" + method + "' (expected \"hermite_simpson\", \"trapezoidal\" or \"radau\")");
      }
    }
    // An enumerated key: one of its names, else an error naming the file, the key and the choices.
    const auto enumKey = [&](const char* key, auto& field) {
      if (!root.contains(key)) return;
      const std::string name = string(root[key], key);
      try {
        field = parseEnum<std::decay_t<decltype(field)>>(name, key);
      } catch (const std::invalid_argument& e) {
        fail(source_ + ": " + e.what());
      }
    };
    enumKey("hessian", problem.hessian);
    enumKey("dynamics", problem.dynamics);
    if (root.contains("knots")) {
      problem.knots = integer(root["knots"], "knots", 2, kMaxKnots);
    }
    if (!root.contains("horizon")) bad("horizon", "missing (seconds, or {\"min\", \"max\", \"guess\"})");
    const Json& h = root["horizon"];
    if (h.is_number()) {
      const double T = number(h, "horizon");
      if (!(T > 0.0)) bad("horizon", str(T) + " must be > 0");
      problem.setFixedHorizon(T);
    } else {
      object(h, "horizon");
      checkKeys(h, "horizon", {"min", "max", "guess"});
      if (!h.contains("min") || !h.contains("max")) bad("horizon", "needs \"min\" and \"max\"");
      problem.minHorizon = number(h["min"], "horizon.min");
      problem.maxHorizon = number(h["max"], "horizon.max");
      if (!(problem.minHorizon > 0.0)) bad("horizon.min", str(problem.minHorizon) + " must be > 0");
      if (!(problem.maxHorizon >= problem.minHorizon)) {
        bad("horizon.max", str(problem.maxHorizon) + " must be >= horizon.min");
      }
      problem.horizon = h.contains("guess") ? number(h["guess"], "horizon.guess")
                                            : 0.5 * (problem.minHorizon + problem.maxHorizon);
      if (problem.horizon < problem.minHorizon || problem.horizon > problem.maxHorizon) {
        bad("horizon.guess", str(problem.horizon) + " must lie in [min, max]");
      }
    }
    if (root.contains("initial_state")) {
      namedValues(root["initial_state"], "initial_state", states, "state", problem.initialState);
    }
    if (root.contains("final_state")) {
      namedValues(root["final_state"], "final_state", states, "state", problem.finalState);
    }
    if (root.contains("free_initial")) freeList(root["free_initial"], "free_initial", states, problem.initialFixed);
    if (root.contains("free_final")) freeList(root["free_final"], "free_final", states, problem.finalFixed);
    if (root.contains("state_bounds")) {
      namedBounds(root["state_bounds"], "state_bounds", states, "state", problem.stateLower,
                  problem.stateUpper);
    }
    if (root.contains("input_bounds")) {
      namedBounds(root["input_bounds"], "input_bounds", inputs, "input", problem.inputLower,
                  problem.inputUpper);
    }
    if (root.contains("constraint_force_bounds")) {
      // Keyed by the constraint's row ("0", "1", … in the scene's order; scene constraints have
      // no names of their own).
      std::vector<std::string> rows;
      for (int r = 0; r < problem.model->nc(); ++r) rows.push_back(std::to_string(r));
      namedBounds(root["constraint_force_bounds"], "constraint_force_bounds", rows,
                  "constraint row", problem.forceLower, problem.forceUpper);
    }
    problem.goalState = problem.finalState;
    if (root.contains("cost")) {
      const Json& c = object(root["cost"], "cost");
      checkKeys(c, "cost", {"R", "Q", "Qf", "goal", "time_weight"});
      if (c.contains("R")) weight(c["R"], "cost.R", inputs, "input", problem.R);
      if (c.contains("Q")) weight(c["Q"], "cost.Q", states, "state", problem.Q);
      if (c.contains("Qf")) weight(c["Qf"], "cost.Qf", states, "state", problem.Qf);
      if (c.contains("goal")) namedValues(c["goal"], "cost.goal", states, "state", problem.goalState);
      if (c.contains("time_weight")) {
        problem.timeWeight = number(c["time_weight"], "cost.time_weight");
        if (problem.timeWeight < 0.0) bad("cost.time_weight", str(problem.timeWeight) + " must be >= 0");
      }
    }
    if (root.contains("initial_guess")) {
      const std::string guess = resolve(string(root["initial_guess"], "initial_guess"));
      try {
        problem.initialGuess = Trajectory::readCsvFile(guess);
        problem.initialGuess->checkCompatible(*problem.model);
      } catch (const std::exception& e) {
        bad("initial_guess", e.what());
      }
    }
    try {
      problem.validate();
    } catch (const ProblemError& e) {
      fail(source_ + ": " + e.what());
    }
    return problem;
  }

 private:
  std::string source_, baseDir_;
};

}  // namespace

OptimalControlProblem parseProblem(const std::string& jsonText, const std::string& source,
                                   const std::string& baseDir) {
  return FileParser(source, baseDir).parse(jsonText);
}

OptimalControlProblem loadProblem(const std::string& path) {
  std::string text;
  try {
    text = readTextFile(path, std::size_t{64} << 20, "problem file");  // names a directory as such
  } catch (const FileError& e) {
    fail(e.what());
  }
  const std::filesystem::path p(path);
  return parseProblem(text, path, p.parent_path().string());
}

}  // namespace trellis
