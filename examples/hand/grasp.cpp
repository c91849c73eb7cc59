// examples/hand/grasp.cpp — the free-ball grasp search (grasp.hpp).
#include "grasp.hpp"
#include "reference_motion.hpp"

#include <Eigen/Dense>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <sstream>
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

namespace {

/// The hold's linear system at a posture (grasp.hpp): columns [u; α], rows the nq weighted
/// coordinates, right-hand side −W (Q₀ + Aᵀλ_min); λ = λ_min + E α.
struct HoldSystem {
  Eigen::MatrixXd C, E;
  Eigen::VectorXd rhs, lambdaMin;
  double load = 0.0;  ///< ‖W Q₀‖
  bool ok = false;
};

HoldSystem holdSystem(const Model& model, const Eigen::VectorXd& q, double fMin, double muPrime, int facets) {
  const int n = model.nq(), m = model.nu(), nd = model.nc() / 3, F = facets;
  HoldSystem s;
  Data data(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  if (!computeDynamics(model, data, q, zero, Eigen::VectorXd::Zero(m)).ok()) return s;
  computeMassMatrix(model, data, q);
  computeConstraints(model, data, q, zero);
  computeInputMatrix(model, data, q);
  const Eigen::MatrixXd& A = data.constraintJacobian;
  const Eigen::VectorXd Q0 = data.M * data.qdd - A.transpose() * data.lambda;
  Eigen::VectorXd w = Eigen::VectorXd::Ones(n);
  for (int i = 0; i < n; ++i)
    if (model.joints()[i].revolute) w(i) = 1.0 / kLength;
  // λ = λ_min + E α: E's column (d, k) is n + μ'(cos θ_k t1 + sin θ_k t2) in contact coordinates.
  s.E = Eigen::MatrixXd::Zero(model.nc(), nd * F);
  s.lambdaMin = Eigen::VectorXd::Zero(model.nc());
  for (int d = 0; d < nd; ++d) {
    s.lambdaMin(3 * d) = fMin;
    for (int k = 0; k < F; ++k) {
      const double th = 2.0 * std::numbers::pi * k / F;
      s.E(3 * d, d * F + k) = 1.0;
      s.E(3 * d + 1, d * F + k) = muPrime * std::cos(th);
      s.E(3 * d + 2, d * F + k) = muPrime * std::sin(th);
    }
  }
  s.C.resize(n, m + nd * F);
  s.C.leftCols(m) = w.asDiagonal() * data.inputMatrix;
  s.C.rightCols(nd * F) = w.asDiagonal() * (A.transpose() * s.E);
  s.rhs = -(w.asDiagonal() * (Q0 + A.transpose() * s.lambdaMin));
  s.load = (w.asDiagonal() * Q0).norm();
  s.ok = s.C.allFinite() && s.rhs.allFinite();
  return s;
}

}  // namespace

PyramidHold pyramidHold(const Model& model, const Eigen::VectorXd& q, double fMin,
                        double muPrime, int facets, double tensionWeight) {
  const int n = model.nq(), m = model.nu(), nd = model.nc() / 3, F = facets;
  PyramidHold h;
  const HoldSystem s = holdSystem(model, q, fMin, muPrime, facets);
  if (!s.ok) return h;
  const int cols = m + nd * F, rows = n + (tensionWeight > 0.0 ? m : 0);
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(rows, cols);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(rows);
  C.topRows(n) = s.C;
  rhs.head(n) = s.rhs;
  // The weight on ‖u‖ in the load's units: √w·load per newton of tension.
  if (tensionWeight > 0.0) C.bottomLeftCorner(m, m).diagonal().setConstant(std::sqrt(tensionWeight) * s.load);
  const NnlsResult x = solveNonNegativeLeastSquares(C, rhs);
  h.tension = x.x.head(m);
  h.lambda = s.lambdaMin + s.E * x.x.tail(nd * F);
  h.residual = (C.topRows(n) * x.x - rhs.head(n)) / std::max(s.load, 1e-300);
  h.relativeResidual = h.residual.norm();
  h.ok = x.x.allFinite();
  return h;
}

HoldDiagnosis diagnoseHold(const Model& model, const Eigen::VectorXd& q, const std::vector<std::string>& digits,
                           double fMin, double muPrime, int facets) {
  HoldDiagnosis out;
  out.whole = pyramidHold(model, q, fMin, muPrime, facets);
  const HoldSystem s = holdSystem(model, q, fMin, muPrime, facets);
  if (!s.ok || !out.whole.ok) return out;
  const auto& names = model.configNames();
  // The same NNLS on a subset of the rows: the other rows' balance is not asked for, so a
  // residual there is that subset's own shortfall (columns of other digits vanish on a digit's rows).
  const auto subset = [&](const std::vector<int>& rows, std::string& worst) {
    Eigen::MatrixXd C(rows.size(), s.C.cols());
    Eigen::VectorXd d(rows.size());
    for (std::size_t i = 0; i < rows.size(); ++i) C.row(i) = s.C.row(rows[i]), d(i) = s.rhs(rows[i]);
    const NnlsResult x = solveNonNegativeLeastSquares(C, d);
    const Eigen::VectorXd r = (C * x.x - d) / std::max(s.load, 1e-300);
    Eigen::Index k = 0;
    r.cwiseAbs().maxCoeff(&k);
    worst = names[rows[k]] + " (" + std::to_string(r(k)) + ")";
    return r.norm();
  };
  std::vector<int> ball;
  for (int i = 0; i < model.nq(); ++i)
    if (names[i].rfind("ball_", 0) == 0) ball.push_back(i);
  out.ballResidual = subset(ball, out.ballWorst);
  for (const std::string& dg : digits) {
    std::vector<int> rows;
    for (int i = 0; i < model.nq(); ++i)
      if (names[i].rfind(dg + "_", 0) == 0) rows.push_back(i);
    std::string worst;
    out.digitResidual.push_back(subset(rows, worst));
    out.digitWorst.push_back(worst);
  }
  return out;
}

GraspCheck checkGrasp(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& u,
                      const BallLimits& limits, int facets, double accelerationTolerance) {
  GraspCheck c;
  const int n = model.nq();
  if (q.size() != n || u.size() != model.nu())
    throw std::invalid_argument("checkGrasp: q has " + std::to_string(q.size()) + " entries (" + std::to_string(n) +
                                " expected), u " + std::to_string(u.size()) + " (" + std::to_string(model.nu()) + ")");
  Data data(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  if (!computeDynamics(model, data, q, zero, Eigen::VectorXd::Zero(model.nu())).ok()) {
    c.message = "the dynamics failed at rest: " + data.status.message;
    return c;
  }
  computeMassMatrix(model, data, q);
  Eigen::VectorXd w = Eigen::VectorXd::Ones(n);
  for (int i = 0; i < n; ++i)
    if (model.joints()[i].revolute) w(i) = 1.0 / kLength;
  const double load = (w.asDiagonal() * (data.M * data.qdd - data.constraintJacobian.transpose() * data.lambda)).norm();
  if (!computeDynamics(model, data, q, zero, u).ok()) {
    c.message = "the dynamics failed under the tensions: " + data.status.message;
    return c;
  }
  computeMassMatrix(model, data, q);
  computeConstraints(model, data, q, zero);
  c.constraintResidual = data.constraintValue.cwiseAbs().maxCoeff();
  c.accelerationResidual = data.qdd.cwiseAbs().maxCoeff();
  c.relativeAcceleration = (w.asDiagonal() * (data.M * data.qdd)).norm() / std::max(load, 1e-300);
  c.margins = contactMargins(data.lambda, limits);
  const int nd = static_cast<int>(limits.digits.size());
  const double facetMu = limits.friction * std::cos(std::numbers::pi / facets);
  int worstFacet = 0;
  c.facetRatio = -std::numeric_limits<double>::infinity();
  for (int d = 0; d < nd; ++d)
    for (int k = 0; k < facets; ++k) {
      const double th = 2.0 * std::numbers::pi * k / facets;
      const double use = (std::cos(th) * data.lambda(3 * d + 1) + std::sin(th) * data.lambda(3 * d + 2)) /
                         (facetMu * std::max(data.lambda(3 * d), 1e-300));
      if (use > c.facetRatio) c.facetRatio = use, worstFacet = d;
    }
  c.rangeExcess = -std::numeric_limits<double>::infinity();
  int worstJoint = 0;
  for (int i = 0; i < n; ++i) {
    const double e = std::max(limits.qLower(i) - q(i), q(i) - limits.qUpper(i));
    if (e > c.rangeExcess) c.rangeExcess = e, worstJoint = i;
  }
  Eigen::Index worstTendon = 0;
  c.tensionExcess = (u - limits.uMax).cwiseMax(-u).maxCoeff(&worstTendon);
  const auto num = [](double v) { return std::to_string(v); };
  if (!(c.constraintResidual <= 1e-10)) c.message = "the pads leave their contact points by " + num(c.constraintResidual) + " m";
  else if (!(c.relativeAcceleration <= accelerationTolerance))
    c.message = "not at rest: the residual force is " + num(c.relativeAcceleration) + " of the rest load (|qdd| " +
                num(c.accelerationResidual) + ")";
  else if (!(c.margins.minNormal >= limits.normalMin))
    c.message = limits.digits[c.margins.minNormalContact] + " presses by " + num(c.margins.minNormal) + " N only (margin " +
                num(limits.normalMin) + " N)";
  else if (!(c.facetRatio <= 1.0))
    c.message = limits.digits[worstFacet] + " leaves the friction pyramid (facet ratio " + num(c.facetRatio) + ")";
  else if (!(c.rangeExcess <= 0.0))
    c.message = model.configNames()[worstJoint] + " = " + num(q(worstJoint)) + " leaves its range by " + num(c.rangeExcess) + " rad";
  else if (!(c.tensionExcess <= 0.0))
    c.message = "tension " + model.inputNames()[worstTendon] + " = " + num(u(worstTendon)) + " N leaves [0, " +
                num(limits.uMax(worstTendon)) + "]";
  c.ok = c.message.empty();
  return c;
}

std::string foldBallPose(const std::string& sceneJson, const Model& model, const std::vector<std::string>& digits,
                         Eigen::VectorXd& q, Eigen::Vector3d& centre, std::vector<Eigen::Vector3d>& contacts) {
  Data data(model);
  computeKinematics(model, data, q, Eigen::VectorXd::Zero(model.nq()));
  centre = data.framePose[model.frameIndex("ball")].translation();
  contacts.assign(digits.size(), Eigen::Vector3d::Zero());
  for (std::size_t d = 0; d < digits.size(); ++d)
    contacts[d] = data.framePose[model.frameIndex(digits[d] + "_tip")].translation() - centre;
  for (const char* b : {"ball_x", "ball_y", "ball_z", "ball_yaw", "ball_pitch", "ball_roll"}) q(model.configIndex(b)) = 0.0;
  return placeBall(sceneJson, digits, centre, contacts, model);
}

std::string placeThumbBase(const std::string& sceneJson, const Eigen::Isometry3d& base) {
  nlohmann::json j = nlohmann::json::parse(sceneJson);
  nlohmann::json* f = findFrame(j["frames"], "thumb_cmc_site");
  if (!f) throw std::runtime_error("placeThumbBase: the scene has no frame 'thumb_cmc_site'");
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 4; ++k) (*f)["matrix"][i][k] = base.matrix()(i, k);
  return j.dump();
}

FreeBallGrasp findFreeBallGrasp(const std::string& sceneJson, const BallLimits& limits,
                                const GraspSearchOptions& options) {
  const Scene tmpl = parseScene(sceneJson, "<free-ball scene>");
  const int n = tmpl.model.nq(), m = tmpl.model.nu(), nd = static_cast<int>(limits.digits.size()), F = options.facets;
  const double r = options.ballRadius;
  std::vector<Digit> digits;
  bool hasThumb = false;
  for (const std::string& d : limits.digits) {
    Digit g;
    g.name = d;
    const bool thumb = d == "thumb";
    hasThumb = hasThumb || thumb;
    const char* parts[4] = {thumb ? "cmc_abd" : "mcp_abd", thumb ? "cmc_flex" : "mcp_flex", thumb ? "mcp" : "pip",
                            thumb ? "ip" : "dip"};
    for (int k = 0; k < 4; ++k) g.coords[k] = tmpl.model.configIndex(d + "_" + parts[k]);
    g.tip = tmpl.model.frameIndex(d + "_tip");
    digits.push_back(g);
  }
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  // The start: the stored grasp's ball centre (ball_grasp_centre + the stored ball offset) and
  // thumb base (thumb_cmc_site).
  Eigen::Vector3d c0;
  Eigen::Isometry3d thumb0 = Eigen::Isometry3d::Identity();
  {
    nlohmann::json j = nlohmann::json::parse(sceneJson);
    nlohmann::json* base = findFrame(j["frames"], "ball_grasp_centre");
    if (!base) throw std::runtime_error("findFreeBallGrasp: the scene has no frame 'ball_grasp_centre'");
    for (int i = 0; i < 3; ++i) c0(i) = (*base)["matrix"][i][3].get<double>();
    if (hasThumb) {
      nlohmann::json* t = findFrame(j["frames"], "thumb_cmc_site");
      if (!t) throw std::runtime_error("findFreeBallGrasp: the scene has no frame 'thumb_cmc_site'");
      for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 4; ++k) thumb0.matrix()(i, k) = (*t)["matrix"][i][k].get<double>();
    }
  }
  for (int i = 0; i < 3; ++i) c0(i) += tmpl.q(tmpl.model.configIndex(std::string("ball_") + "xyz"[i]));
  const bool moveThumb = hasThumb && options.thumbBaseRotation > 0.0;
  const int np = 3 + 2 * nd + (moveThumb ? 6 : 0);

  // Parameters p = [c − c0; drivers; ω; δ]: the thumb base R0·exp([ω]×) (ω in base axes) at the
  // CMC site t0 + δ (palm axes), when the thumb base is searched.
  const auto thumbBase = [&](const Eigen::VectorXd& p) {  // p = [c − c0; drivers; φ; ω; δ]
    Eigen::Isometry3d b = thumb0;
    if (!moveThumb) return b;
    const Eigen::Vector3d w = p.segment<3>(3 + 2 * nd);
    if (w.norm() > 0.0) b.linear() = thumb0.linear() * Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    b.translation() = thumb0.translation() + p.segment<3>(6 + 2 * nd);
    return b;
  };

  // The posture at parameters p on the hand `fk`: each digit's other three coordinates by
  // Newton's method on e = [|p − c| − r; x̂ᵀ(c − p); ŷᵀ(c − p)] from the stored grasp (difference
  // Jacobian: it only sets the rate; the residual is exact). Returns the distance left from the
  // sphere, summed over the digits (0: every pad is on it).
  const auto padResidual = [&](const Model& fk, Data& fkData, const Digit& g, const Eigen::VectorXd& q,
                               const Eigen::Vector3d& c) {
    computeKinematics(fk, fkData, q, zero);
    const Eigen::Isometry3d& pose = fkData.framePose[g.tip];
    const Eigen::Vector3d v = c - pose.translation();
    return Eigen::Vector4d(v.norm() - r, pose.linear().col(0).dot(v), pose.linear().col(1).dot(v),
                           pose.linear().col(2).dot(v));
  };
  const auto posture = [&](const Model& fk, const Eigen::VectorXd& p, Eigen::VectorXd& q,
                           std::vector<Eigen::Vector3d>& contacts, double& tilt) {
    Data fkData(fk);
    tilt = 0.0;
    double miss = 0.0;
    const Eigen::Vector3d c = c0 + p.head<3>();
    q = tmpl.q;
    for (const char* b : {"ball_x", "ball_y", "ball_z", "ball_yaw", "ball_pitch", "ball_roll"}) q(fk.configIndex(b)) = 0.0;
    contacts.assign(nd, Eigen::Vector3d::Zero());
    for (int d = 0; d < nd; ++d) {
      const Digit& g = digits[d];
      q(g.coords[1]) = p(3 + d);
      const int free[3] = {g.coords[0], g.coords[2], g.coords[3]};
      // The pad's normal tilted by φ_d about the phalanx's lateral axis ŷ (the contact on the
      // rounded pad proximal (φ > 0) or distal of its centre): −ẑ' with ẑ' = (sin φ, 0, cos φ).
      const Eigen::Vector3d padAxis(std::sin(p(3 + nd + d)), 0.0, std::cos(p(3 + nd + d)));
      // Gauss–Newton: the distance row exactly (minimum-norm), the two alignment rows in least
      // squares within its null space — the pad on the sphere, its normal as close to the
      // centre as the digit allows (a finger's pad normal stays in its flexion plane).
      // Gauss–Newton: the distance row exactly (minimum-norm), the alignment in least squares
      // within its null space — the pad on the sphere, its normal −ẑ as close to the direction v̂
      // to the centre as the digit allows. The alignment residual is ẑ + v̂ (zero only when the
      // pad faces the centre; the rows x̂ᵀv, ŷᵀv would vanish also with the pad facing away, where
      // the little finger's side-on start of the fixed-ball grasp used to end).
      const auto rows = [&](const Eigen::VectorXd& qq) {
        computeKinematics(fk, fkData, qq, zero);
        const Eigen::Isometry3d& pose = fkData.framePose[g.tip];
        const Eigen::Vector3d v = c - pose.translation();
        Eigen::Vector4d e;
        e << v.norm() - r, pose.linear() * padAxis + v / v.norm();
        return e;
      };
      bool converged = false;
      for (int it = 0; it < 80 && !converged; ++it) {
        const Eigen::Vector4d e = rows(q);
        Eigen::Matrix<double, 4, 3> J;
        for (int k = 0; k < 3; ++k) {
          const double h = 1e-7, keep = q(free[k]);
          q(free[k]) = keep + h;
          const Eigen::Vector4d plus = rows(q);
          q(free[k]) = keep - h;
          const Eigen::Vector4d minus = rows(q);
          q(free[k]) = keep;
          J.col(k) = (plus - minus) / (2.0 * h);
        }
        const Eigen::RowVector3d Jd = J.row(0);
        const double jj = Jd.squaredNorm();
        if (!(jj > 0.0)) break;
        const Eigen::Vector3d base = -Jd.transpose() * e(0) / jj;
        const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - Jd.transpose() * Jd / jj;
        const Eigen::Matrix3d Ja = J.bottomRows<3>() * P;
        const Eigen::Vector3d ra = -(e.tail<3>() + J.bottomRows<3>() * base);
        Eigen::Vector3d step = base + P * Ja.completeOrthogonalDecomposition().solve(ra);
        if (!step.allFinite()) break;
        step *= std::min(1.0, 0.2 / std::max(step.cwiseAbs().maxCoeff(), 1e-300));
        for (int k = 0; k < 3; ++k) q(free[k]) += step(k);
        converged = std::abs(e(0)) < 1e-14 && step.cwiseAbs().maxCoeff() < 1e-10;
      }
      const Eigen::Vector4d e = padResidual(fk, fkData, g, q, c);
      if (!e.allFinite()) return std::numeric_limits<double>::infinity();
      if (std::abs(e(0)) >= 1e-12) miss += std::abs(e(0));
      // The pad must face the centre: a pad facing away counts as a miss of its distance.
      if (!(e(3) < 0.0)) miss += e(3);
      tilt = std::max(tilt, std::atan2(e.segment<2>(1).norm(), -e(3)));
      contacts[d] = fkData.framePose[g.tip].translation() - c;
    }
    return miss;
  };

  // The hold's margins at a posture: the NNLS of the file comment. Returns the relative residual
  // (+ penalties), and the tensions in `u` when asked.
  struct Hold {
    double objective = 1e3;
    Eigen::VectorXd q, u;
    std::vector<Eigen::Vector3d> contacts;
    std::string text;  ///< the candidate scene (thumb base and ball placed)
    std::string penalties;  ///< which bounds the posture exceeds, and by how much
  };
  const auto hold = [&](const Eigen::VectorXd& p, double fMin, double muPrime, double tensionWeight) {
    Hold h;
    double tilt = 0.0;
    double penalty = 0.0;
    std::string withThumb = sceneJson;
    if (moveThumb) {
      withThumb = placeThumbBase(sceneJson, thumbBase(p));
      penalty += std::max(0.0, p.segment<3>(3 + 2 * nd).norm() - options.thumbBaseRotation);
      penalty += std::max(0.0, p.segment<3>(6 + 2 * nd).cwiseAbs().maxCoeff() - options.thumbBaseShift) / kLength;
      if (penalty > 0.0) h.penalties += " thumb base beyond its bounds;";
    }
    const Scene fkScene = parseScene(withThumb, "<candidate>");
    const double miss = posture(fkScene.model, p, h.q, h.contacts, tilt);
    if (!(miss == 0.0)) {
      // Graded, so the simplex can walk towards postures whose pads reach the sphere.
      h.objective = 10.0 + std::min(miss / r, 1e2) + penalty;
      return h;
    }
    penalty += std::max(0.0, tilt - options.maxTilt);
    if (tilt > options.maxTilt) h.penalties += " pad tilt " + std::to_string(tilt) + " rad;";
    for (int i = 0; i < n; ++i) {
      const double e = std::max({0.0, limits.qLower(i) - h.q(i), h.q(i) - limits.qUpper(i)});
      penalty += e;
      if (e > 0.0) h.penalties += " " + fkScene.model.configNames()[i] + " out of range by " + std::to_string(e) + ";";
    }
    h.text = placeBall(withThumb, limits.digits, c0 + p.head<3>(), h.contacts, fkScene.model);
    const Scene s = parseScene(h.text, "<candidate>");
    const PyramidHold ph = pyramidHold(s.model, h.q, fMin, muPrime, F, tensionWeight);
    if (!ph.ok) return h;
    h.u = ph.tension;
    for (int k = 0; k < m; ++k) {
      const double e = std::max(0.0, h.u(k) - limits.uMax(k)) / limits.uMax(k);
      penalty += e;
      if (e > 0.0) h.penalties += " " + s.model.inputNames()[k] + " over its maximum by " + std::to_string(e) + ";";
    }
    h.objective = ph.relativeResidual + penalty;
    return h;
  };

  FreeBallGrasp out;
  Eigen::VectorXd p = Eigen::VectorXd::Zero(np), step(np);
  const bool given = options.start.size() == np;
  if (options.start.size() != 0 && !given)
    throw std::invalid_argument("findFreeBallGrasp: options.start has " + std::to_string(options.start.size()) +
                                " entries, " + std::to_string(np) + " expected");
  step.head<3>().setConstant(0.004);
  for (int d = 0; d < nd; ++d) {
    p(3 + d) = tmpl.q(digits[d].coords[1]);
    step(3 + d) = 0.08;
    step(3 + nd + d) = 0.1;
  }
  if (given) p = options.start;
  if (moveThumb) {
    step.segment<3>(3 + 2 * nd).setConstant(0.1);
    step.segment<3>(6 + 2 * nd).setConstant(0.003);
  }
  const double facetMu = limits.friction * std::cos(std::numbers::pi / F);
  // Continuation over the targets: the first must be reached (else no grasp); each further one is
  // tried from the last posture that holds, and the strongest reached is kept.
  Eigen::VectorXd reachedAt;
  for (const auto& [fMin, muFactor] : options.targets) {
    const double muPrime = muFactor * facetMu;
    const auto objective = [&](const Eigen::VectorXd& x) { return hold(x, fMin, muPrime, 0.0).objective; };
    const int budget = reachedAt.size() == 0 ? options.maxEvaluations : options.strengthenEvaluations;
    // Nelder–Mead restarted from its best point with the first steps while the budget lasts: a
    // collapsed simplex is a local stop of this non-smooth objective, not a certificate.
    Eigen::VectorXd x = p;
    for (int spent = 0, round = 0; spent < budget && round <= options.restarts; ++round) {
      int used = 0;
      x = nelderMead(objective, x, step, budget - spent, options.holdTolerance, used);
      spent += used;
      out.evaluations += used;
      if (objective(x) <= options.holdTolerance) break;
    }
    if (hold(x, fMin, muPrime, 0.0).objective <= options.holdTolerance) {
      out.targetNormal = fMin;
      out.targetFriction = muPrime;
      reachedAt = p = x;
    } else {
      if (reachedAt.size() == 0) p = x;
      break;
    }
  }
  if (reachedAt.size() == 0) {
    // Say where the best posture falls short: the least balanced coordinate of its hold.
    const Hold best = hold(p, options.targets.front().first, options.targets.front().second * facetMu, 0.0);
    std::string where = "its posture cannot be built (objective " + std::to_string(best.objective) + ")";
    if (!best.text.empty()) {
      const Scene sc = parseScene(best.text, "<candidate>");
      const PyramidHold ph = pyramidHold(sc.model, best.q, options.targets.front().first,
                                         options.targets.front().second * facetMu, F);
      Eigen::Index worst = 0;
      ph.residual.cwiseAbs().maxCoeff(&worst);
      where = "relative residual " + std::to_string(ph.relativeResidual) + ", largest on " +
              sc.model.configNames()[worst] + " (" + std::to_string(ph.residual(worst)) + ")";
      // By parts (diagnoseHold): which of the ball and the digits cannot be balanced on its own.
      const HoldDiagnosis dg = diagnoseHold(sc.model, best.q, limits.digits, options.targets.front().first,
                                            options.targets.front().second * facetMu, F);
      where += "; bounds exceeded:" + (best.penalties.empty() ? std::string(" none") : best.penalties);
      where += "; alone: ball " + std::to_string(dg.ballResidual);
      for (int d = 0; d < nd; ++d) where += ", " + limits.digits[d] + " " + std::to_string(dg.digitResidual[d]);
      out.q = best.q;
      out.u = ph.tension;
      out.lambda = ph.lambda;
      out.scene = best.text;
      out.thumbBase = thumbBase(p);
      if (moveThumb) out.thumbTurn = p.segment<3>(3 + 2 * nd), out.thumbShift = p.segment<3>(6 + 2 * nd);
      out.centre = c0 + p.head<3>();
      out.contacts = best.contacts;
    }
    out.parameters = p;
    out.message = "no posture holds the ball with the first target (f_min " +
                  std::to_string(options.targets.front().first) + " N) within " +
                  std::to_string(out.evaluations) + " evaluations: best " + where;
    return out;
  }
  // Small tensions among the holds of this posture, then the polish.
  const Hold best = hold(p, out.targetNormal, out.targetFriction, options.tensionWeight);
  out.parameters = p;
  out.thumbBase = thumbBase(p);
  if (moveThumb) out.thumbTurn = p.segment<3>(3 + 2 * nd), out.thumbShift = p.segment<3>(6 + 2 * nd);
  const std::string withThumb = moveThumb ? placeThumbBase(sceneJson, out.thumbBase) : sceneJson;
  out.centre = c0 + p.head<3>();
  out.contacts = best.contacts;
  out.u = best.u.cwiseMax(0.0);
  const Scene s = parseScene(best.text, "<grasp>");
  Data data(s.model);
  const EquilibriumResult eq = findEquilibrium(s.model, data, best.q, out.u);
  // The ball is a uniform sphere: its orientation changes nothing, so the polished ball pose is
  // folded into the placement (centre = where the polish moved it, contact points = the pads
  // relative to it in palm axes, ball coordinates 0) — the stored grasp then has h(q) = 0 exactly
  // at ball coordinates 0, and the hold is checked again on that model.
  out.q = eq.q;
  out.scene = foldBallPose(withThumb, s.model, limits.digits, out.q, out.centre, out.contacts);
  const Scene placed = parseScene(out.scene, "<grasp>");
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
  const GraspCheck check = checkGrasp(placed.model, out.q, out.u, limits, F);
  out.relativeAcceleration = check.relativeAcceleration;
  if (!eq.ok()) out.message = "the equilibrium polish did not converge: " + eq.describe();
  else out.message = check.message;
  out.ok = out.message.empty();
  return out;
}

GraspProgram makeGraspProgram(const std::string& sceneJson, const Eigen::VectorXd& q0, const Eigen::VectorXd& u0,
                              const BallLimits& limits, const GraspNlpOptions& options) {
  const Scene full = parseScene(sceneJson, "<free-ball scene>");
  const Model& fm = full.model;
  const int n = fm.nq(), m = fm.nu(), nd = static_cast<int>(limits.digits.size());
  if (q0.size() != n || u0.size() != m || fm.nc() != 3 * nd)
    throw std::invalid_argument("solveGraspNlp: q0 has " + std::to_string(q0.size()) + " entries (" + std::to_string(n) +
                                "), u0 " + std::to_string(u0.size()) + " (" + std::to_string(m) + "), constraints " +
                                std::to_string(fm.nc()) + " (3 per digit: " + std::to_string(3 * nd) + ")");
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  // The hand alone: no contact rows, a wrench input (f_x, f_y, f_z in tip axes) at each pad.
  nlohmann::json hj = nlohmann::json::parse(sceneJson);
  hj["constraints"] = nlohmann::json::array();
  hj.erase("state");
  for (const std::string& d : limits.digits)
    hj["forces"].push_back({{"type", "body_wrench"},
                            {"frame", d + "_tip"},
                            {"wrench", {"pad_" + d + "_x", "pad_" + d + "_y", "pad_" + d + "_z", 0.0, 0.0, 0.0}}});
  const auto handScene = std::make_shared<const Scene>(parseScene(hj.dump(), "<hand alone>"));
  const Model& hm = handScene->model;
  std::vector<int> hand, ballTranslation, inputOf(m), padInput(3 * nd);  // indices into the hand model
  for (int i = 0; i < n; ++i) {
    const std::string& name = fm.configNames()[i];
    if (hm.configIndex(name) != i) throw std::runtime_error("solveGraspNlp: the hand model orders '" + name + "' differently");
    if (name.rfind("ball_", 0) != 0) hand.push_back(i);
  }
  for (const char* b : {"ball_x", "ball_y", "ball_z"}) ballTranslation.push_back(fm.configIndex(b));
  for (int k = 0; k < m; ++k) inputOf[k] = hm.inputIndex(fm.inputNames()[k]);
  for (int d = 0; d < nd; ++d)
    for (int a = 0; a < 3; ++a) padInput[3 * d + a] = hm.inputIndex("pad_" + limits.digits[d] + "_" + "xyz"[a]);
  const int nh = static_cast<int>(hand.size()), mh = hm.nu();
  std::vector<int> tips;
  for (const std::string& d : limits.digits) {
    tips.push_back(fm.frameIndex(d + "_tip"));
    if (hm.frameIndex(d + "_tip") != tips.back()) throw std::runtime_error("solveGraspNlp: the hand model orders the frames differently");
  }
  const int ballFrame = fm.frameIndex("ball");
  const double muPrime = limits.friction * std::cos(std::numbers::pi / options.facets);
  const double r = options.ballRadius, cosTilt = std::cos(options.maxTilt);

  // Scales and constants at the start: ‖W Q₀‖ (checkGrasp's rest load), S = W M_hh(q₀) / ‖W Q₀‖,
  // the ball's weight m_b g (the free body's q̈ without contacts is g), its centre c₀ and the pad
  // forces of the start's λ (contact frames as placeBall writes them, ball at zero orientation).
  Data fd(fm), hd(hm);
  if (!computeDynamics(fm, fd, q0, zero, Eigen::VectorXd::Zero(m)).ok())
    throw std::runtime_error("solveGraspNlp: the dynamics failed at the start: " + fd.status.message);
  computeMassMatrix(fm, fd, q0);
  Eigen::VectorXd w = Eigen::VectorXd::Ones(n);
  for (int i = 0; i < n; ++i)
    if (fm.joints()[i].revolute) w(i) = 1.0 / kLength;
  const double load = (w.asDiagonal() * (fd.M * fd.qdd - fd.constraintJacobian.transpose() * fd.lambda)).norm();
  Eigen::VectorXd uh0 = Eigen::VectorXd::Zero(mh);
  if (!computeDynamics(hm, hd, q0, zero, uh0).ok())
    throw std::runtime_error("solveGraspNlp: the hand's dynamics failed at the start: " + hd.status.message);
  computeMassMatrix(hm, hd, q0);
  Eigen::MatrixXd S(nh, nh);
  for (int a = 0; a < nh; ++a)
    for (int b = 0; b < nh; ++b) S(a, b) = w(hand[a]) * hd.M(hand[a], hand[b]) / load;
  Eigen::Vector3d weight;
  for (int a = 0; a < 3; ++a) weight(a) = hd.M(ballTranslation[a], ballTranslation[a]) * hd.qdd(ballTranslation[a]);
  computeKinematics(fm, fd, q0, zero);
  const Eigen::Vector3d c0 = fd.framePose[ballFrame].translation();
  if (!computeDynamics(fm, fd, q0, zero, u0).ok())
    throw std::runtime_error("solveGraspNlp: the dynamics failed at the start under u0: " + fd.status.message);
  Eigen::VectorXd f0(3 * nd);
  double s0 = std::numeric_limits<double>::infinity();
  computeKinematics(fm, fd, q0, zero);
  for (int d = 0; d < nd; ++d) {
    const Eigen::Isometry3d& tp = fd.framePose[tips[d]];
    const Eigen::Vector3d F = contactFrame(tp.translation() - c0) * fd.lambda.segment<3>(3 * d);
    f0.segment<3>(3 * d) = -tp.linear().transpose() * F;
    s0 = std::min(s0, fd.lambda(3 * d));
  }

  // x = [q_h; c; u; f; s]; rows [hand rest (nh); ball force (3); ball moment (3); sphere (nd);
  // per digit normal, cone, facing (3 nd)].
  const int ic = nh, iu = nh + 3, iF = iu + m, is = iF + 3 * nd, nx = is + 1;
  const int rRest = 0, rForce = nh, rMoment = nh + 3, rSphere = nh + 6, rDigit = nh + 6 + nd, rows = rDigit + 3 * nd;
  const double inf = std::numeric_limits<double>::infinity();
  NlpProblem p;
  p.lower = Eigen::VectorXd::Constant(nx, -inf);
  p.upper = Eigen::VectorXd::Constant(nx, inf);
  for (int a = 0; a < nh; ++a) p.lower(a) = limits.qLower(hand[a]), p.upper(a) = limits.qUpper(hand[a]);
  // Tensions inside [reserve, u_max − reserve]: feedback about the hold moves every tendon both ways.
  p.lower.segment(iu, m).setConstant(options.tensionReserve);
  p.upper.segment(iu, m) = limits.uMax.array() - options.tensionReserve;
  p.upper(is) = options.marginCap;
  p.constraintLower = Eigen::VectorXd::Zero(rows);
  p.constraintUpper = Eigen::VectorXd::Zero(rows);
  for (int d = 0; d < nd; ++d) {
    p.constraintUpper.segment(rDigit + 3 * d, 3).setConstant(inf);
    p.constraintLower(rDigit + 3 * d + 2) = cosTilt;
  }
  p.objective = [uMax = limits.uMax, weightU = options.tensionWeight, iu, m, is](const Eigen::VectorXd& x, double& f, Eigen::VectorXd& g) {
    const Eigen::ArrayXd ur = x.segment(iu, m).array() / uMax.array();
    f = -x(is) + weightU * ur.square().sum();
    g.setZero();
    g.segment(iu, m) = (2.0 * weightU * ur / uMax.array()).matrix();
    g(is) = -1.0;
    return true;
  };
  const auto fullQ = [=](const Eigen::VectorXd& x) {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(n);
    for (int a = 0; a < nh; ++a) q(hand[a]) = x(a);
    return q;
  };
  // The workspace of the constraint callback (the program may outlive this function: tests).
  struct Work {
    Data lin;
    std::vector<Eigen::Matrix<double, 6, Eigen::Dynamic>> Jb;
  };
  const auto work = std::make_shared<Work>(Work{Data(hm), std::vector<Eigen::Matrix<double, 6, Eigen::Dynamic>>(
                                                              nd, Eigen::Matrix<double, 6, Eigen::Dynamic>(6, nh))});
  p.constraints = [=](const Eigen::VectorXd& x, Eigen::VectorXd& g, Eigen::MatrixXd& J) {
    const Model& hm = handScene->model;
    Data& lin = work->lin;
    auto& Jb = work->Jb;
    const Eigen::VectorXd q = fullQ(x);
    const Eigen::Vector3d c = x.segment<3>(ic);
    const double s = x(is);
    Eigen::VectorXd uh = Eigen::VectorXd::Zero(mh);
    for (int k = 0; k < m; ++k) uh(inputOf[k]) = x(iu + k);
    for (int k = 0; k < 3 * nd; ++k) uh(padInput[k]) = x(iF + k);
    if (!computeLinearization(hm, lin, q, zero, uh).ok()) return false;
    J.setZero();
    g.setZero();
    for (int a = 0; a < nh; ++a) {
      for (int b = 0; b < nh; ++b) {
        const double S_ab = S(a, b);
        g(rRest + a) += S_ab * lin.qdd(hand[b]);
        for (int k = 0; k < nh; ++k) J(rRest + a, k) += S_ab * lin.dqdd_dq(hand[b], hand[k]);
        for (int k = 0; k < m; ++k) J(rRest + a, iu + k) += S_ab * lin.dqdd_du(hand[b], inputOf[k]);
        for (int k = 0; k < 3 * nd; ++k) J(rRest + a, iF + k) += S_ab * lin.dqdd_du(hand[b], padInput[k]);
      }
    }
    // Body Jacobians of the tips: [v_b; ω_b] at q̇ = e_i (tip axes).
    Eigen::VectorXd e = Eigen::VectorXd::Zero(n);
    for (int a = 0; a < nh; ++a) {
      e.setZero();
      e(hand[a]) = 1.0;
      computeKinematics(hm, lin, q, e);
      for (int d = 0; d < nd; ++d) Jb[d].col(a) = lin.frameVelocity[tips[d]];
    }
    computeKinematics(hm, lin, q, zero);
    g.segment<3>(rForce) = weight;
    for (int d = 0; d < nd; ++d) {
      const Eigen::Isometry3d& tp = lin.framePose[tips[d]];
      const Eigen::Matrix3d& R = tp.linear();
      const Eigen::Vector3d fb = x.segment<3>(iF + 3 * d), F = -R * fb, pd = tp.translation(), rd = pd - c;
      Eigen::MatrixXd Jp = R * Jb[d].topRows(3), dF(3, nh), dv(3, nh);  // ∂p/∂q_h, ∂F/∂q_h, ∂v/∂q_h
      for (int a = 0; a < nh; ++a) {
        const Eigen::Vector3d om = Jb[d].col(a).tail<3>();
        dF.col(a) = -R * om.cross(fb);
        dv.col(a) = -R * om.cross(Eigen::Vector3d::UnitZ());
      }
      const Eigen::Matrix3d dFdf = -R;
      const auto cross = [](const Eigen::Vector3d& v) {
        Eigen::Matrix3d X;
        X << 0, -v(2), v(1), v(2), 0, -v(0), -v(1), v(0), 0;
        return X;
      };
      // Ball force and moment.
      g.segment<3>(rForce) += F;
      J.block(rForce, 0, 3, nh) += dF;
      J.block(rForce, iF + 3 * d, 3, 3) += dFdf;
      g.segment<3>(rMoment) += rd.cross(F) / kLength;
      J.block(rMoment, 0, 3, nh) += (-cross(F) * Jp + cross(rd) * dF) / kLength;
      J.block(rMoment, ic, 3, 3) += cross(F) / kLength;
      J.block(rMoment, iF + 3 * d, 3, 3) += cross(rd) * dFdf / kLength;
      // On the sphere.
      const double dist = rd.norm();
      g(rSphere + d) = (rd.squaredNorm() - r * r) / (2.0 * r);
      J.block(rSphere + d, 0, 1, nh) = rd.transpose() * Jp / r;
      J.block(rSphere + d, ic, 1, 3) = -rd.transpose() / r;
      // Normal force, cone, facing.
      const Eigen::Vector3d nh3 = -rd / dist;
      const Eigen::Matrix3d P = (Eigen::Matrix3d::Identity() - nh3 * nh3.transpose()) / dist;
      const Eigen::MatrixXd dn_dq = -P * Jp;  // n = (c − p)/|c − p|
      const Eigen::Matrix3d dn_dc = P;
      const double ln = nh3.dot(F);
      Eigen::RowVectorXd dln = Eigen::RowVectorXd::Zero(nx);
      dln.head(nh) = F.transpose() * dn_dq + nh3.transpose() * dF;
      dln.segment<3>(ic) = F.transpose() * dn_dc;
      dln.segment<3>(iF + 3 * d) = nh3.transpose() * dFdf;
      const int r0 = rDigit + 3 * d;
      g(r0) = ln - s;
      J.row(r0) = dln;
      J(r0, is) = -1.0;
      const double a = ln - s;
      g(r0 + 1) = muPrime * muPrime * a * a - F.squaredNorm() + ln * ln;
      Eigen::RowVectorXd dFF = Eigen::RowVectorXd::Zero(nx);  // ∂|F|²
      dFF.head(nh) = 2.0 * F.transpose() * dF;
      dFF.segment<3>(iF + 3 * d) = 2.0 * F.transpose() * dFdf;
      J.row(r0 + 1) = 2.0 * (muPrime * muPrime * a + ln) * dln - dFF;
      J(r0 + 1, is) = -2.0 * muPrime * muPrime * a;
      const Eigen::Vector3d v = -R.col(2);
      g(r0 + 2) = v.dot(nh3);
      J.block(r0 + 2, 0, 1, nh) = nh3.transpose() * dv + v.transpose() * dn_dq;
      J.block(r0 + 2, ic, 1, 3) = v.transpose() * dn_dc;
    }
    return true;
  };
  p.start.resize(nx);
  for (int a = 0; a < nh; ++a) p.start(a) = q0(hand[a]);
  p.start.segment<3>(ic) = c0;
  p.start.segment(iu, m) = u0;
  p.start.segment(iF, 3 * nd) = f0;
  p.start(is) = std::min(s0, options.marginCap);

  GraspProgram prog;
  prog.problem = std::move(p);
  prog.hand = hand;
  prog.centre = ic, prog.tensions = iu, prog.forces = iF, prog.margin = is;
  prog.rest = rRest, prog.ballForce = rForce, prog.ballMoment = rMoment, prog.sphere = rSphere, prog.digitRows = rDigit;
  prog.state = std::make_shared<std::pair<std::shared_ptr<const Scene>, std::shared_ptr<Work>>>(handScene, work);
  return prog;
}

GraspNlpResult solveGraspNlp(const std::string& sceneJson, const Eigen::VectorXd& q0, const Eigen::VectorXd& u0,
                             const BallLimits& limits, const GraspNlpOptions& options) {
  const GraspProgram prog = makeGraspProgram(sceneJson, q0, u0, limits, options);
  const NlpProblem& p = prog.problem;
  const Scene full = parseScene(sceneJson, "<free-ball scene>");
  const Model& fm = full.model;
  const int n = fm.nq(), m = fm.nu(), nd = static_cast<int>(limits.digits.size()), nh = static_cast<int>(prog.hand.size());
  const std::vector<int>& hand = prog.hand;
  const int ic = prog.centre, iu = prog.tensions, iF = prog.forces, is = prog.margin, nx = is + 1;
  const int rRest = prog.rest, rForce = prog.ballForce, rMoment = prog.ballMoment, rSphere = prog.sphere,
            rDigit = prog.digitRows;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  const auto fullQ = [&](const Eigen::VectorXd& x) {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(n);
    for (int a = 0; a < nh; ++a) q(hand[a]) = x(a);
    return q;
  };
  GraspNlpResult out;
  out.nlp = solveNlp(p, options.ipopt);
  // The second solve: from the first's result, with the bounds and equalities exact (no
  // relaxation; Ipopt's default start push), so that they hold to constr_viol_tol.
  if (out.nlp.x.allFinite()) {
    NlpOptions exact = options.ipopt;
    exact.boundRelaxFactor = 0.0;
    out.relaxedViolation = out.nlp.constraintViolation;
    out.firstIterations = out.nlp.iterations;
    NlpProblem again = p;
    again.start = out.nlp.x.cwiseMax(p.lower).cwiseMin(p.upper);
    NlpResult second = solveNlp(again, exact);
    second.iterations += out.nlp.iterations;
    second.evaluations += out.nlp.evaluations;
    second.solveTime += out.nlp.solveTime;
    // The exact solve can wander from a relaxed point that already met the rows to ~1e-8
    // (measured after the tendon-geometry change: 2.6e-8 relaxed, 7e-4 at the exact solve's
    // iteration limit): keep the point with the smaller violation; the polish below makes it exact.
    if (second.x.allFinite() && !(second.constraintViolation > out.nlp.constraintViolation)) {
      out.nlp = std::move(second);
    } else {
      out.nlp.iterations = second.iterations;
      out.nlp.evaluations = second.evaluations;
      out.nlp.solveTime = second.solveTime;
      out.keptRelaxed = true;
    }
  }
  const Eigen::VectorXd& x = out.nlp.x;
  out.q = fullQ(x);
  out.u = x.segment(iu, m).cwiseMax(0.0).cwiseMin(limits.uMax);
  out.margin = x(is);
  out.centre = x.segment<3>(ic);
  Data lin(fm);
  computeKinematics(fm, lin, out.q, zero);
  for (int d = 0; d < nd; ++d) {
    out.contacts.push_back(lin.framePose[fm.frameIndex(limits.digits[d] + "_tip")].translation() - out.centre);
    if (out.nlp.g.allFinite())
      out.alignment = std::max(out.alignment, std::acos(std::clamp(out.nlp.g(rDigit + 3 * d + 2), -1.0, 1.0)));
  }
  // The free-ball scene placed at the result: the pads on the sphere to the program's tolerance;
  // the contact points are the pads, so h(q) = 0 there exactly, and the core's λ are the f's.
  out.scene = placeBall(sceneJson, limits.digits, out.centre, out.contacts, fm);
  {
    // The polish: at the program's tensions, findEquilibrium moves q until q̈ = 0 to its tolerance
    // (the rows hold only to Ipopt's tolerance, ~1e-8 scaled); the ball's pose is folded into the
    // placement as the search does (ball coordinates 0, h(q) = 0 exactly), and the check decides.
    const Scene unpolished = parseScene(out.scene, "<grasp>");
    Data data(unpolished.model);
    out.q = out.q.cwiseMax(limits.qLower).cwiseMin(limits.qUpper);  // the relaxed bounds' 1e-8
    const EquilibriumResult eq = findEquilibrium(unpolished.model, data, out.q, out.u);
    if (eq.ok()) {
      // The polish knows no ranges: a coordinate resting on its range end may step ~1e-8 rad past
      // it; clamped back, the force it leaves is ~1e-9 of the load (the check's tolerance 1e-8),
      // and the fold below puts the contact points at the pads again (h = 0 exactly).
      out.q = eq.q.cwiseMax(limits.qLower).cwiseMin(limits.qUpper);
      out.scene = foldBallPose(out.scene, unpolished.model, limits.digits, out.q, out.centre, out.contacts);
      // Then the tensions at that q: q̈ is affine in u, so the smallest change of the tensions
      // that are not at 0 N with (∂q̈/∂u) Δu = −q̈ makes q̈ = 0 again (a change of ~1e-8 N).
      const Scene folded = parseScene(out.scene, "<grasp>");
      Data fd(folded.model);
      if (computeLinearization(folded.model, fd, out.q, zero, out.u).ok()) {
        std::vector<int> free;
        for (int k = 0; k < out.u.size(); ++k)
          if (out.u(k) > 1e-6 && out.u(k) < limits.uMax(k) - 1e-6) free.push_back(k);
        Eigen::MatrixXd G(fd.qdd.size(), static_cast<Eigen::Index>(free.size()));
        for (std::size_t k = 0; k < free.size(); ++k) G.col(static_cast<Eigen::Index>(k)) = fd.dqdd_du.col(free[k]);
        const Eigen::VectorXd du = G.completeOrthogonalDecomposition().solve(-fd.qdd);
        for (std::size_t k = 0; k < free.size(); ++k) out.u(free[k]) += du(static_cast<Eigen::Index>(k));
        out.u = out.u.cwiseMax(0.0).cwiseMin(limits.uMax);
      }
    }
    out.polished = eq.ok();
  }
  const Scene placed = parseScene(out.scene, "<grasp>");
  Data pd(placed.model);
  if (computeDynamics(placed.model, pd, out.q, zero, out.u).ok()) out.lambda = pd.lambda;
  out.check = checkGrasp(placed.model, out.q, out.u, limits, options.facets);
  // ok is the hold, checked: Ipopt's status speaks of the margin's optimality, not of the hold.
  out.ok = out.check.ok;

  // The report: each group's worst violation, and the bounds that limit s most (their multipliers).
  std::ostringstream rep;
  const auto worstOf = [&](int first, int count, int stride, const std::string& what, bool perDigit) {
    double worst = 0.0;
    int at = -1;
    for (int k = 0; k < count; ++k) {
      const int i = first + k * stride;
      const double v = std::max(p.constraintLower(i) - out.nlp.g(i), out.nlp.g(i) - p.constraintUpper(i));
      if (v > worst) worst = v, at = k;
    }
    if (at >= 0)
      rep << what << " violated by " << worst << " ("
          << (perDigit ? limits.digits[at] : (stride == 1 && first == rRest ? fm.configNames()[hand[at]] : std::to_string(at)))
          << "); ";
  };
  if (out.nlp.g.allFinite()) {
    worstOf(rRest, nh, 1, "hand rest [rel]", false);
    worstOf(rForce, 3, 1, "ball force [N]", false);
    worstOf(rMoment, 3, 1, "ball moment / l [N]", false);
    worstOf(rSphere, nd, 1, "pad on sphere [m]", true);
    worstOf(rDigit, nd, 3, "normal force >= s [N]", true);
    worstOf(rDigit + 1, nd, 3, "friction cone [N^2]", true);
    worstOf(rDigit + 2, nd, 3, "pad facing [cos]", true);
  }
  rep << "s = " << out.margin << " N; bounds limiting s (multiplier, value):";
  std::vector<std::pair<double, int>> active;
  for (int i = 0; i < nx - 1; ++i) {
    const double z = std::max(out.nlp.lowerBoundMultipliers(i), out.nlp.upperBoundMultipliers(i));
    if (z > 1e-6 && (i < nh || (i >= iu && i < iF))) active.emplace_back(z, i);
  }
  std::sort(active.rbegin(), active.rend());
  for (std::size_t k = 0; k < active.size() && k < 8; ++k) {
    const int i = active[k].second;
    const bool upper = out.nlp.upperBoundMultipliers(i) > out.nlp.lowerBoundMultipliers(i);
    rep << " " << (i < nh ? fm.configNames()[hand[i]] : fm.inputNames()[i - iu]) << (upper ? " at upper " : " at lower ")
        << (upper ? p.upper(i) : p.lower(i)) << " (" << active[k].first << ")";
  }
  out.report = rep.str();
  return out;
}

}  // namespace trellis::hand
