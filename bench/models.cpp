// bench/models.cpp — builders for the benchmark systems (see models.hpp).
#include "models.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/kinematics.hpp"
#include "trellis/core/model_builder.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <Eigen/QR>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace trellis::bench {
namespace {

/// Inertia about the centre of a slender rod of mass m, length l and radius r whose long axis is
/// body y, turned by a fixed small rotation so that every entry of the tensor is non-zero.
Eigen::Matrix3d rodInertia(double m, double l, double r, bool tilted) {
  const double transverse = m * (l * l / 12.0 + r * r / 4.0);
  const double axial = 0.5 * m * r * r;
  const Eigen::Matrix3d principal = Eigen::Vector3d(transverse, axial, transverse).asDiagonal();
  if (!tilted) return principal;
  const Eigen::Matrix3d R =
      (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitZ()))
          .toRotationMatrix();
  Eigen::Matrix3d I = R * principal * R.transpose();
  return 0.5 * (I + I.transpose());  // exactly symmetric for the builder's check
}

/// prefix + i. (Spelled out because GCC 12 at -O3 warns falsely (-Wrestrict) on
/// "literal" + std::to_string(i).)
std::string indexed(const char* prefix, int i) {
  std::string s(prefix);
  s += std::to_string(i);
  return s;
}

Eigen::Matrix4d se3(const Eigen::Matrix3d& R, const Eigen::Vector3d& p) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = R;
  T.topRightCorner<3, 1>() = p;
  return T;
}

constexpr double kChainLength = 0.5;  // m per link
constexpr double kChainMass = 1.0;    // kg per link
constexpr double kChainRadius = 0.02;

/// Planar chain: frame j<i> (rz joint) then l<i> = ty(−l) carrying the link mass, so the masses
/// hang at the link ends as in trep's N-link pendulum. Returns the tip frame.
std::string addPlanarChain(ModelBuilder& b, int n) {
  std::string parent = "world";
  for (int i = 0; i < n; ++i) {
    const std::string joint = indexed("j", i);
    const std::string link = indexed("l", i);
    const std::string q = indexed("q", i);
    b.addFrame(joint, parent, Transform::rz(q));
    b.addFrame(link, joint, Transform::ty(-kChainLength),
               Mass{kChainMass, rodInertia(kChainMass, kChainLength, kChainRadius, false)});
    b.addConfigForce(q, indexed("u", i));
    parent = link;
  }
  b.addGravity({0.0, -9.81, 0.0});
  return parent;
}

/// Spatial chain: joints rotate about x, y, z in turn; full (tilted) inertia tensors.
std::string addSpatialChain(ModelBuilder& b, int n) {
  std::string parent = "world";
  for (int i = 0; i < n; ++i) {
    const std::string joint = indexed("j", i);
    const std::string link = indexed("l", i);
    const std::string q = indexed("q", i);
    switch (i % 3) {
      case 0: b.addFrame(joint, parent, Transform::rx(q)); break;
      case 1: b.addFrame(joint, parent, Transform::ry(q)); break;
      default: b.addFrame(joint, parent, Transform::rz(q)); break;
    }
    b.addFrame(link, joint, Transform::ty(-kChainLength),
               Mass{kChainMass, rodInertia(kChainMass, kChainLength, kChainRadius, true)});
    b.addConfigForce(q, indexed("u", i));
    parent = link;
  }
  b.addGravity({0.0, 0.0, -9.81});
  return parent;
}

struct FingerSpec {
  const char* name;
  Eigen::Vector3d base;          // knuckle position in the palm frame
  double yaw, roll;              // base orientation (thumb only is strongly turned)
  std::array<double, 3> length;  // proximal, middle, distal phalanx
  std::array<double, 3> mass;
};

/// A palm fixed to the world (palm plane x-y, fingers along +y) with five fingers. Each finger:
/// a constant base placement, an abduction joint (rz), then three flexion joints (rx) separated by
/// the phalanges; each phalanx carries its mass at its middle, and a knuckle mass sits on the
/// abduction body. Returns the index fingertip frame.
std::string addHand(ModelBuilder& b) {
  const std::array<FingerSpec, 5> fingers{{
      {"thumb", {-0.040, 0.010, -0.010}, 0.9, -0.7, {0.045, 0.035, 0.030}, {0.040, 0.025, 0.015}},
      {"index", {-0.025, 0.090, 0.000}, 0.05, 0.0, {0.045, 0.027, 0.020}, {0.030, 0.015, 0.010}},
      {"middle", {-0.005, 0.095, 0.000}, 0.0, 0.0, {0.050, 0.030, 0.022}, {0.035, 0.018, 0.011}},
      {"ring", {0.015, 0.090, 0.000}, -0.05, 0.0, {0.046, 0.028, 0.021}, {0.030, 0.016, 0.010}},
      {"little", {0.033, 0.080, 0.000}, -0.12, 0.0, {0.035, 0.022, 0.018}, {0.020, 0.010, 0.008}},
  }};
  constexpr double kRadius = 0.008;
  constexpr double kKnuckleMass = 0.005;
  b.addFrame("palm", "world", Transform::tz(0.0));
  std::string indexTip;
  for (const FingerSpec& f : fingers) {
    const std::string n = f.name;
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(f.yaw, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(f.roll, Eigen::Vector3d::UnitY()))
                                  .toRotationMatrix();
    b.addFrame(n + "_base", "palm", Transform::constSE3(se3(R, f.base)));
    const std::string abd = n + "_abd";
    b.addFrame(abd, n + "_base", Transform::rz(abd),
               Mass{kKnuckleMass, rodInertia(kKnuckleMass, 0.01, kRadius, false)});
    b.addConfigForce(abd, "u_" + abd);
    std::string parent = abd;
    const std::array<const char*, 3> flex{"mcp", "pip", "dip"};
    for (int k = 0; k < 3; ++k) {
      const std::string joint = n + "_" + flex[k];
      const double l = f.length[k];
      b.addFrame(joint, parent, Transform::rx(joint));
      b.addFrame(joint + "_com", joint, Transform::ty(0.5 * l),
                 Mass{f.mass[k], rodInertia(f.mass[k], l, kRadius, false)});
      b.addFrame(joint + "_end", joint, Transform::ty(l));
      b.addConfigForce(joint, "u_" + joint);
      parent = joint + "_end";
    }
    if (n == "index") indexTip = parent;
  }
  b.addGravity({0.0, 0.0, -9.81});
  return indexTip;
}

double uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

}  // namespace

const char* kindName(ModelKind kind) {
  switch (kind) {
    case ModelKind::kPlanarChain: return "planar";
    case ModelKind::kSpatialChain: return "spatial";
    case ModelKind::kHandTree: return "hand";
  }
  return "?";
}

BenchModel makeBenchModel(const ModelSpec& spec, std::uint32_t seed) {
  if (spec.kind != ModelKind::kHandTree && spec.links < 1) {
    throw std::invalid_argument("makeBenchModel: links must be >= 1, got " +
                                std::to_string(spec.links));
  }
  ModelBuilder b(std::string(kindName(spec.kind)) + "_" + std::to_string(spec.links));
  std::string tip;
  switch (spec.kind) {
    case ModelKind::kPlanarChain: tip = addPlanarChain(b, spec.links); break;
    case ModelKind::kSpatialChain: tip = addSpatialChain(b, spec.links); break;
    case ModelKind::kHandTree: tip = addHand(b); break;
  }

  // The free model fixes the configuration order; the constrained one only adds a world frame
  // and constraint rows, so the same q, q̇, u vectors fit both.
  Model free = b.finalize();
  std::mt19937 rng(seed);
  const int n = free.nq();
  Eigen::VectorXd q(n), dq(n), u(free.nu());
  for (int i = 0; i < n; ++i) {
    const std::string& name = free.configNames()[i];
    if (spec.kind != ModelKind::kHandTree) {
      q[i] = uniform(rng, -1.0, 1.0);
    } else if (name.size() > 4 && name.compare(name.size() - 4, 4, "_abd") == 0) {
      q[i] = uniform(rng, -0.3, 0.3);
    } else {
      q[i] = uniform(rng, -0.2, 1.2);
    }
  }
  for (int i = 0; i < n; ++i) dq[i] = uniform(rng, -1.0, 1.0);
  // Hand joints move grams over centimetres: torques of a few mN·m give accelerations of the
  // same order as gravity's on the distal phalanges (hundreds to a thousand rad/s²).
  const double inputScale = spec.kind == ModelKind::kHandTree ? 1e-3 : 1.0;
  for (int i = 0; i < u.size(); ++i) u[i] = inputScale * uniform(rng, -1.0, 1.0);

  if (!spec.constrained) {
    return BenchModel{std::move(free), q, dq, u, kindName(spec.kind)};
  }

  Data freeData(free);
  computeKinematics(free, freeData, q, dq);
  const Eigen::Vector3d anchor = freeData.framePose[free.frameIndex(tip)].translation();
  b.addFrame("anchor", "world", Transform::constSE3(se3(Eigen::Matrix3d::Identity(), anchor)));
  if (spec.kind == ModelKind::kHandTree) {
    for (int axis = 0; axis < 3; ++axis) b.addPointConstraint(tip, "anchor", axis);
  } else if (spec.tip != TipRows::kOne) {
    for (int axis = 0; axis < constraintRows(spec); ++axis) b.addPointConstraint(tip, "anchor", axis);
  } else if (spec.kind == ModelKind::kSpatialChain) {
    // Not x: a 2-link x-y chain swings its tip in the y-z plane only, which would make the
    // x row identically zero.
    b.addPointConstraint(tip, "anchor", 2);
  } else {
    b.addPointConstraint(tip, "anchor", 0);
  }
  Model model = std::move(b).finalize();
  if (model.nq() != n || model.configNames() != free.configNames()) {
    throw std::runtime_error("makeBenchModel: adding the constraint changed the configuration");
  }

  // q̇ ← q̇ − Aᵀ (A Aᵀ)⁺ A q̇: the nearest velocity with A q̇ = 0 (a pseudo-inverse: the planar
  // chain's redundant z row is zero).
  Data data(model);
  computeKinematics(model, data, q, dq);
  computeConstraints(model, data, q, dq);
  const Eigen::MatrixXd& A = data.constraintJacobian;
  const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(A.transpose());
  Eigen::VectorXd t = cod.householderQ().adjoint() * dq;  // range(Aᵀ) is Q's first rank columns
  t.tail(n - cod.rank()).setZero();
  dq -= cod.householderQ() * t;
  const double hErr = data.constraintValue.cwiseAbs().maxCoeff();
  const double vErr = (A * dq).cwiseAbs().maxCoeff();
  if (!(hErr < 1e-12) || !(vErr < 1e-10)) {
    throw std::runtime_error("makeBenchModel: inconsistent constrained state for " +
                             model.name() + ": |h| = " + std::to_string(hErr) +
                             ", |A dq| = " + std::to_string(vErr));
  }
  return BenchModel{std::move(model), q, dq, u, kindName(spec.kind)};
}

int constraintRows(const ModelSpec& spec) {
  if (!spec.constrained) return 0;
  if (spec.kind == ModelKind::kHandTree) return 3;
  switch (spec.tip) {
    case TipRows::kOne: return 1;
    case TipRows::kPinned: return spec.kind == ModelKind::kSpatialChain ? 3 : 2;
    case TipRows::kRedundant: return 3;
  }
  return 1;
}

bool parseProfileModel(const char* kind, const char* links, const char* constrained, ModelSpec& spec) {
  const std::string k = kind;
  if (k == "planar") {
    spec.kind = ModelKind::kPlanarChain;
  } else if (k == "spatial") {
    spec.kind = ModelKind::kSpatialChain;
  } else if (k == "hand" || k == "scene") {
    spec.kind = ModelKind::kHandTree;
  } else {
    std::fprintf(stderr, "unknown model '%s' (planar, spatial, hand, scene)\n", kind);
    return false;
  }
  spec.links = k == "scene" ? 0 : std::atoi(links);
  const int c = std::atoi(constrained);
  if (c < 0 || c > 3 || (c == 3 && spec.kind != ModelKind::kPlanarChain)) {
    std::fprintf(stderr, "constrained must be 0, 1, 2 or 3 (3: planar only), got '%s'\n", constrained);
    return false;
  }
  spec.constrained = c != 0;
  spec.tip = c == 3 ? TipRows::kRedundant : c == 2 ? TipRows::kPinned : TipRows::kOne;
  return true;
}

}  // namespace trellis::bench
