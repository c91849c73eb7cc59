// examples/hand/grasp.cpp — the free-ball grasp search (grasp.hpp).
#include "grasp.hpp"
#include "reference_motion.hpp"

#include <Eigen/Dense>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace trellis::hand {

namespace {

constexpr double kLength = 0.02;  // ℓ [m]: angular rows (N m) are divided by it to read as forces

nlohmann::json* findFrame(nlohmann::json& frames, const std::string& name) {
  for (auto& f : frames) {
    if (f.value("name", "") == name) return &f;
    if (f.contains("children"))
      if (nlohmann::json* g = findFrame(f["children"], name)) return g;
  }
  return nullptr;
}

void setTranslation(nlohmann::json& frame, const Eigen::Vector3d& t) {
  for (int i = 0; i < 3; ++i) frame["matrix"][i][3] = t(i);
}

/// Inward normal n, t1 = unit(z × r) (a positive turn about the palm normal), t2 = n × t1 — the
/// contact frame of make_hand_scene.py's contact_directions, for the point r from the centre.
Eigen::Matrix3d contactFrame(const Eigen::Vector3d& r) {
  const Eigen::Vector3d n = -r.normalized();
  const Eigen::Vector3d t1 = Eigen::Vector3d::UnitZ().cross(r).normalized();
  Eigen::Matrix3d f;
  f << n, t1, n.cross(t1);
  return f;
}

/// One digit: its coordinates (driver second, as the scene orders them) and its pad frame.
struct Digit {
  std::string name;
  int coords[4];
  int tip;
};

/// Nelder–Mead simplex minimization of f from x0 with initial steps `step` (per variable).
Eigen::VectorXd nelderMead(const std::function<double(const Eigen::VectorXd&)>& f, const Eigen::VectorXd& x0,
                           const Eigen::VectorXd& step, int maxEvaluations, double target, int& evaluations) {
  const int n = static_cast<int>(x0.size());
  std::vector<Eigen::VectorXd> x(n + 1, x0);
  std::vector<double> fx(n + 1);
  for (int i = 0; i < n; ++i) x[i + 1](i) += step(i);
  for (int i = 0; i <= n; ++i) fx[i] = f(x[i]);
  evaluations += n + 1;
  std::vector<int> order(n + 1);
  for (int used = n + 1; used < maxEvaluations;) {
    for (int i = 0; i <= n; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](int a, int b) { return fx[a] < fx[b]; });
    const int best = order[0], worst = order[n], second = order[n - 1];
    if (fx[best] <= target) break;
    double spread = 0.0;
    for (int i = 1; i <= n; ++i) spread = std::max(spread, ((x[order[i]] - x[best]).cwiseQuotient(step)).cwiseAbs().maxCoeff());
    if (spread < 1e-7) break;
    Eigen::VectorXd centroid = Eigen::VectorXd::Zero(n);
    for (int i = 0; i < n; ++i) centroid += x[order[i]] / n;
    const auto at = [&](double t) { return Eigen::VectorXd(centroid + t * (x[worst] - centroid)); };
    const Eigen::VectorXd xr = at(-1.0);
    const double fr = f(xr);
    ++used;
    if (fr < fx[best]) {
      const Eigen::VectorXd xe = at(-2.0);
      const double fe = f(xe);
      ++used;
      if (fe < fr) x[worst] = xe, fx[worst] = fe;
      else x[worst] = xr, fx[worst] = fr;
    } else if (fr < fx[second]) {
      x[worst] = xr, fx[worst] = fr;
    } else {
      const Eigen::VectorXd xc = fr < fx[worst] ? at(-0.5) : at(0.5);
      const double fc = f(xc);
      ++used;
      if (fc < std::min(fr, fx[worst])) {
        x[worst] = xc, fx[worst] = fc;
      } else {  // shrink towards the best
        for (int i = 1; i <= n; ++i) {
          x[order[i]] = x[best] + 0.5 * (x[order[i]] - x[best]);
          fx[order[i]] = f(x[order[i]]);
        }
        used += n;
      }
    }
    evaluations = used;
  }
  const int best = static_cast<int>(std::min_element(fx.begin(), fx.end()) - fx.begin());
  return x[best];
}

}  // namespace

std::string placeBall(const std::string& sceneJson, const std::vector<std::string>& digits,
                      const Eigen::Vector3d& centre, const std::vector<Eigen::Vector3d>& contacts,
                      const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& u) {
  nlohmann::json j = nlohmann::json::parse(sceneJson);
  nlohmann::json* base = findFrame(j["frames"], "ball_grasp_centre");
  if (!base) throw std::runtime_error("placeBall: the scene has no frame 'ball_grasp_centre' (not a free-ball scene)");
  setTranslation(*base, centre);
  for (std::size_t d = 0; d < digits.size(); ++d) {
    const std::string frame = "ball_contact_" + digits[d];
    nlohmann::json* c = findFrame(j["frames"], frame);
    if (!c) throw std::runtime_error("placeBall: the scene has no frame '" + frame + "'");
    setTranslation(*c, contacts[d]);
    const Eigen::Matrix3d axes = contactFrame(contacts[d]);
    int k = 0;
    for (auto& row : j["constraints"])
      if (row.value("plane_frame", "") == frame) {
        if (k > 2) throw std::runtime_error("placeBall: more than 3 rows on " + frame);
        row["normal"] = {axes(0, k), axes(1, k), axes(2, k)};
        ++k;
      }
    if (k != 3) throw std::runtime_error("placeBall: " + std::to_string(k) + " rows on " + frame + " (3 expected)");
  }
  if (q.size() == model.nq())
    for (int i = 0; i < model.nq(); ++i) j["state"]["q"][model.configNames()[i]] = q(i);
  if (u.size() == model.nu())
    for (int i = 0; i < model.nu(); ++i) j["state"]["u"][model.inputNames()[i]] = u(i);
  return j.dump();
}

PyramidHold pyramidHold(const Model& model, const Eigen::VectorXd& q, double fMin,
                        double muPrime, int facets, double tensionWeight) {
  const int n = model.nq(), m = model.nu(), nd = model.nc() / 3, F = facets;
  PyramidHold h;
  Data data(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  if (!computeDynamics(model, data, q, zero, Eigen::VectorXd::Zero(m)).ok()) return h;
  computeMassMatrix(model, data, q);
  computeConstraints(model, data, q, zero);
  computeInputMatrix(model, data, q);
  const Eigen::MatrixXd& A = data.constraintJacobian;
  const Eigen::VectorXd Q0 = data.M * data.qdd - A.transpose() * data.lambda;
  Eigen::VectorXd w = Eigen::VectorXd::Ones(n);
  for (int i = 0; i < n; ++i)
    if (model.joints()[i].revolute) w(i) = 1.0 / kLength;
  // λ = λ_min + E α: E's column (d, k) is n + μ'(cos θ_k t1 + sin θ_k t2) in contact coordinates.
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(model.nc(), nd * F);
  Eigen::VectorXd lambdaMin = Eigen::VectorXd::Zero(model.nc());
  for (int d = 0; d < nd; ++d) {
    lambdaMin(3 * d) = fMin;
    for (int k = 0; k < F; ++k) {
      const double th = 2.0 * std::numbers::pi * k / F;
      E(3 * d, d * F + k) = 1.0;
      E(3 * d + 1, d * F + k) = muPrime * std::cos(th);
      E(3 * d + 2, d * F + k) = muPrime * std::sin(th);
    }
  }
  const int cols = m + nd * F, rows = n + (tensionWeight > 0.0 ? m : 0);
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(rows, cols);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(rows);
  C.topLeftCorner(n, m) = w.asDiagonal() * data.inputMatrix;
  C.topRightCorner(n, nd * F) = w.asDiagonal() * (A.transpose() * E);
  rhs.head(n) = -(w.asDiagonal() * (Q0 + A.transpose() * lambdaMin));
  const double load = (w.asDiagonal() * Q0).norm();
  // The weight on ‖u‖ in the load's units: √w·load per newton of tension.
  if (tensionWeight > 0.0) C.bottomLeftCorner(m, m).diagonal().setConstant(std::sqrt(tensionWeight) * load);
  const NnlsResult x = solveNonNegativeLeastSquares(C, rhs);
  h.tension = x.x.head(m);
  h.lambda = lambdaMin + E * x.x.tail(nd * F);
  h.residual = (C.topRows(n) * x.x - rhs.head(n)) / std::max(load, 1e-300);
  h.relativeResidual = h.residual.norm();
  h.ok = x.x.allFinite();
  return h;
}

FreeBallGrasp findFreeBallGrasp(const std::string& sceneJson, const BallLimits& limits,
                                const GraspSearchOptions& options) {
  const Scene tmpl = parseScene(sceneJson, "<free-ball scene>");
  const Model& fk = tmpl.model;  // kinematics of the pads (the contact rows play no part there)
  const int n = fk.nq(), m = fk.nu(), nd = static_cast<int>(limits.digits.size()), F = options.facets;
  const double r = options.ballRadius;
  std::vector<Digit> digits;
  for (const std::string& d : limits.digits) {
    Digit g;
    g.name = d;
    const bool thumb = d == "thumb";
    const char* parts[4] = {thumb ? "cmc_abd" : "mcp_abd", thumb ? "cmc_flex" : "mcp_flex", thumb ? "mcp" : "pip",
                            thumb ? "ip" : "dip"};
    for (int k = 0; k < 4; ++k) g.coords[k] = fk.configIndex(d + "_" + parts[k]);
    g.tip = fk.frameIndex(d + "_tip");
    digits.push_back(g);
  }
  Data fkData(fk);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  // The start: the stored grasp's ball centre (ball_grasp_centre + the stored ball offset).
  Eigen::Vector3d c0;
  {
    nlohmann::json j = nlohmann::json::parse(sceneJson);
    nlohmann::json* base = findFrame(j["frames"], "ball_grasp_centre");
    if (!base) throw std::runtime_error("findFreeBallGrasp: the scene has no frame 'ball_grasp_centre'");
    for (int i = 0; i < 3; ++i) c0(i) = (*base)["matrix"][i][3].get<double>();
  }
  for (int i = 0; i < 3; ++i) c0(i) += tmpl.q(fk.configIndex(std::string("ball_") + "xyz"[i]));

  // The posture of parameters p = [c − c0; drivers]: each digit's other three coordinates by
  // Newton's method on e = [|p − c| − r; x̂ᵀ(c − p); ŷᵀ(c − p)] from the stored grasp (difference
  // Jacobian: it only sets the rate; the residual is exact). False when a digit cannot.
  const auto padResidual = [&](const Digit& g, const Eigen::VectorXd& q, const Eigen::Vector3d& c) {
    computeKinematics(fk, fkData, q, zero);
    const Eigen::Isometry3d& pose = fkData.framePose[g.tip];
    const Eigen::Vector3d v = c - pose.translation();
    return Eigen::Vector4d(v.norm() - r, pose.linear().col(0).dot(v), pose.linear().col(1).dot(v),
                           pose.linear().col(2).dot(v));
  };
  const auto posture = [&](const Eigen::VectorXd& p, Eigen::VectorXd& q, std::vector<Eigen::Vector3d>& contacts,
                           double& tilt) {
    tilt = 0.0;
    const Eigen::Vector3d c = c0 + p.head<3>();
    q = tmpl.q;
    for (const char* b : {"ball_x", "ball_y", "ball_z", "ball_yaw", "ball_pitch", "ball_roll"}) q(fk.configIndex(b)) = 0.0;
    contacts.assign(nd, Eigen::Vector3d::Zero());
    for (int d = 0; d < nd; ++d) {
      const Digit& g = digits[d];
      q(g.coords[1]) = p(3 + d);
      const int free[3] = {g.coords[0], g.coords[2], g.coords[3]};
      // Gauss–Newton: the distance row exactly (minimum-norm), the two alignment rows in least
      // squares within its null space — the pad on the sphere, its normal as close to the
      // centre as the digit allows (a finger's pad normal stays in its flexion plane).
      bool converged = false;
      for (int it = 0; it < 60 && !converged; ++it) {
        const Eigen::Vector3d e = padResidual(g, q, c).head<3>();
        Eigen::Matrix3d J;
        for (int k = 0; k < 3; ++k) {
          const double h = 1e-7, keep = q(free[k]);
          q(free[k]) = keep + h;
          const Eigen::Vector3d plus = padResidual(g, q, c).head<3>();
          q(free[k]) = keep - h;
          const Eigen::Vector3d minus = padResidual(g, q, c).head<3>();
          q(free[k]) = keep;
          J.col(k) = (plus - minus) / (2.0 * h);
        }
        const Eigen::RowVector3d Jd = J.row(0);
        const double jj = Jd.squaredNorm();
        if (!(jj > 0.0)) return false;
        const Eigen::Vector3d base = -Jd.transpose() * e(0) / jj;
        const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - Jd.transpose() * Jd / jj;
        const Eigen::Matrix<double, 2, 3> Ja = J.bottomRows<2>() * P;
        const Eigen::Vector2d ra = -(e.tail<2>() + J.bottomRows<2>() * base);
        Eigen::Vector3d step = base + P * Ja.completeOrthogonalDecomposition().solve(ra);
        if (!step.allFinite()) return false;
        step *= std::min(1.0, 0.2 / std::max(step.cwiseAbs().maxCoeff(), 1e-300));
        for (int k = 0; k < 3; ++k) q(free[k]) += step(k);
        converged = std::abs(e(0)) < 1e-14 && step.cwiseAbs().maxCoeff() < 1e-10;
      }
      const Eigen::Vector4d e = padResidual(g, q, c);
      if (!(std::abs(e(0)) < 1e-12)) return false;
      if (!(e(3) < 0.0)) return false;  // the pad faces away from the centre
      tilt = std::max(tilt, std::atan2(e.segment<2>(1).norm(), -e(3)));
      contacts[d] = fkData.framePose[g.tip].translation() - c;
    }
    return true;
  };

  // The hold's margins at a posture: the NNLS of the file comment. Returns the relative residual
  // (+ penalties), and the tensions in `u` when asked.
  struct Hold {
    double objective = 1e3;
    Eigen::VectorXd q, u;
    std::vector<Eigen::Vector3d> contacts;
  };
  const auto hold = [&](const Eigen::VectorXd& p, double fMin, double muPrime, double tensionWeight) {
    Hold h;
    double tilt = 0.0;
    if (!posture(p, h.q, h.contacts, tilt)) return h;
    double penalty = std::max(0.0, tilt - options.maxTilt);
    for (int i = 0; i < n; ++i) penalty += std::max({0.0, limits.qLower(i) - h.q(i), h.q(i) - limits.qUpper(i)});
    const Scene s = parseScene(placeBall(sceneJson, limits.digits, c0 + p.head<3>(), h.contacts, fk), "<candidate>");
    const PyramidHold ph = pyramidHold(s.model, h.q, fMin, muPrime, F, tensionWeight);
    if (!ph.ok) return h;
    h.u = ph.tension;
    for (int k = 0; k < m; ++k) penalty += std::max(0.0, h.u(k) - limits.uMax(k)) / limits.uMax(k);
    const double residual = ph.relativeResidual;
    h.objective = residual + penalty;
    return h;
  };

  FreeBallGrasp out;
  Eigen::VectorXd p(3 + nd), step(3 + nd);
  p.head<3>().setZero();
  step.head<3>().setConstant(0.004);
  for (int d = 0; d < nd; ++d) {
    p(3 + d) = tmpl.q(digits[d].coords[1]);
    step(3 + d) = 0.08;
  }
  const double facetMu = limits.friction * std::cos(std::numbers::pi / F);
  bool reached = false;
  for (const auto& [fMin, muFactor] : options.targets) {
    const double muPrime = muFactor * facetMu;
    const auto objective = [&](const Eigen::VectorXd& x) { return hold(x, fMin, muPrime, 0.0).objective; };
    p = nelderMead(objective, p, step, options.maxEvaluations, 1e-12, out.evaluations);
    if (hold(p, fMin, muPrime, 0.0).objective <= 1e-12) {
      out.targetNormal = fMin;
      out.targetFriction = muPrime;
      reached = true;
      break;
    }
  }
  if (!reached) {
    // Say where the best posture falls short: the least balanced coordinate of its hold.
    Eigen::VectorXd qd;
    std::vector<Eigen::Vector3d> cts;
    double tilt = 0.0;
    std::string where = "its posture cannot be built";
    if (posture(p, qd, cts, tilt)) {
      const Scene sc = parseScene(placeBall(sceneJson, limits.digits, c0 + p.head<3>(), cts, fk), "<candidate>");
      const PyramidHold ph = pyramidHold(sc.model, qd, options.targets.back().first,
                                         options.targets.back().second * facetMu, F);
      Eigen::Index worst = 0;
      ph.residual.cwiseAbs().maxCoeff(&worst);
      where = "relative residual " + std::to_string(ph.relativeResidual) + ", largest on " +
              fk.configNames()[worst] + " (" + std::to_string(ph.residual(worst)) + "), pad tilt " +
              std::to_string(tilt) + " rad";
      out.q = qd;
      out.u = ph.tension;
      out.lambda = ph.lambda;
    }
    out.message = "no posture holds the ball with the weakest target (f_min " +
                  std::to_string(options.targets.back().first) + " N) within " +
                  std::to_string(out.evaluations) + " evaluations: best " + where;
    return out;
  }
  // Small tensions among the holds of this posture, then the polish.
  const Hold best = hold(p, out.targetNormal, out.targetFriction, options.tensionWeight);
  out.centre = c0 + p.head<3>();
  out.contacts = best.contacts;
  out.u = best.u.cwiseMax(0.0);
  const Scene s = parseScene(placeBall(sceneJson, limits.digits, out.centre, out.contacts, fk), "<grasp>");
  Data data(s.model);
  const EquilibriumResult eq = findEquilibrium(s.model, data, best.q, out.u);
  // The ball is a uniform sphere: its orientation changes nothing, so the polished ball pose is
  // folded into the placement (centre = where the polish moved it, contact points = the pads
  // relative to it in palm axes, ball coordinates 0) — the stored grasp then has h(q) = 0 exactly
  // at ball coordinates 0, and the hold is checked again on that model.
  out.q = eq.q;
  computeKinematics(s.model, data, out.q, zero);
  out.centre = data.framePose[s.model.frameIndex("ball")].translation();
  for (int d = 0; d < nd; ++d) out.contacts[d] = data.framePose[digits[d].tip].translation() - out.centre;
  for (const char* b : {"ball_x", "ball_y", "ball_z", "ball_yaw", "ball_pitch", "ball_roll"}) out.q(fk.configIndex(b)) = 0.0;
  const Scene placed = parseScene(placeBall(sceneJson, limits.digits, out.centre, out.contacts, fk), "<grasp>");
  Data pd(placed.model);
  if (!computeDynamics(placed.model, pd, out.q, zero, out.u).ok()) {
    out.message = "the dynamics failed at the polished grasp: " + pd.status.message;
    return out;
  }
  out.lambda = pd.lambda;
  out.accelerationResidual = pd.qdd.cwiseAbs().maxCoeff();
  out.margins = contactMargins(out.lambda, limits);
  computeKinematics(placed.model, pd, out.q, zero);
  for (const Digit& g : digits) {
    const Eigen::Isometry3d& pose = pd.framePose[g.tip];
    const Eigen::Vector3d v = (out.centre - pose.translation()).normalized();
    out.alignment = std::max(out.alignment, std::acos(std::clamp(-pose.linear().col(2).dot(v), -1.0, 1.0)));
  }
  double rangeExcess = 0.0;
  for (int i = 0; i < n; ++i) rangeExcess = std::max({rangeExcess, limits.qLower(i) - out.q(i), out.q(i) - limits.qUpper(i)});
  const double tensionExcess = (out.u - limits.uMax).maxCoeff();
  const double facetRatio = out.margins.worstFrictionRatio / std::cos(std::numbers::pi / F);
  if (!eq.ok()) out.message = "the equilibrium polish did not converge: " + eq.describe();
  else if (out.margins.minNormal < limits.normalMin)
    out.message = limits.digits[out.margins.minNormalContact] + " presses by " + std::to_string(out.margins.minNormal) + " N only";
  else if (facetRatio > 1.0)
    out.message = limits.digits[out.margins.worstFrictionContact] + " leaves the pyramid (ratio " + std::to_string(facetRatio) + ")";
  else if (rangeExcess > 0.0) out.message = "a joint leaves its range by " + std::to_string(rangeExcess) + " rad";
  else if (tensionExcess > 0.0) out.message = "a tension exceeds its maximum by " + std::to_string(tensionExcess) + " N";
  out.ok = out.message.empty();
  return out;
}

}  // namespace trellis::hand
