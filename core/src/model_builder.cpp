// Validation, frame-tree folding and mass lumping (see model_builder.hpp).
#include "trellis/core/model_builder.hpp"
#include "trellis/core/names.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace trellis {
namespace {

std::string fmt(double x) {
  std::ostringstream s;
  s.precision(10);
  s << x;
  return s.str();
}

Eigen::Matrix3d axisRotation(int axis, double angle) {
  return Eigen::AngleAxisd(angle, Eigen::Vector3d::Unit(axis)).toRotationMatrix();
}

bool isTranslation(TransformType t) {
  return t == TransformType::kTx || t == TransformType::kTy || t == TransformType::kTz;
}
int axisOf(TransformType t) {
  switch (t) {
    case TransformType::kTx: case TransformType::kRx: return 0;
    case TransformType::kTy: case TransformType::kRy: return 1;
    default: return 2;
  }
}

bool isAxisType(TransformType t) { return t == TransformType::kRotAxis || t == TransformType::kTransAxis; }

Transform axisTransform(TransformType type, const Eigen::Vector3d& axis, const Eigen::Matrix4d& origin) {
  Transform t;
  t.type = type;
  t.axis = axis;
  t.matrix = origin;
  return t;
}

/// A rotation Ra with Ra e_z = a (a unit). Built from basis vectors so that a = ±e_i gives an
/// exact signed permutation: x = the basis vector least aligned with a, made orthogonal to a.
Eigen::Matrix3d axisFrame(const Eigen::Vector3d& a) {
  int k = 0;
  a.cwiseAbs().minCoeff(&k);
  const Eigen::Vector3d x = (Eigen::Vector3d::Unit(k) - a[k] * a).normalized();
  Eigen::Matrix3d R;
  R << x, a.cross(x), a;
  return R;
}

/// The index i if a is exactly e_i (then the joint is a plain rx…tz), else -1.
int basisIndex(const Eigen::Vector3d& a) {
  for (int i = 0; i < 3; ++i)
    if (a == Eigen::Vector3d::Unit(i)) return i;
  return -1;
}

std::string showVector(const Eigen::Vector3d& v) {
  return "[" + fmt(v.x()) + ", " + fmt(v.y()) + ", " + fmt(v.z()) + "]";
}

/// Throws unless m is a rigid homogeneous transform (last row [0 0 0 1], R orthonormal, det +1).
void checkRigid(const Eigen::Matrix4d& m, const std::string& element, const char* field) {
  if (!m.allFinite()) throw ModelError(element + ": field '" + field + "': entries must be finite");
  const Eigen::RowVector4d lastRow(0, 0, 0, 1);
  if ((m.row(3) - lastRow).cwiseAbs().maxCoeff() > 1e-9)
    throw ModelError(element + ": field '" + field + "': last row must be [0, 0, 0, 1], got [" +
                     fmt(m(3, 0)) + ", " + fmt(m(3, 1)) + ", " + fmt(m(3, 2)) + ", " + fmt(m(3, 3)) + "]");
  const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
  const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (err > 1e-9 || R.determinant() < 0)
    throw ModelError(element + ": field '" + field + "': rotation part is not orthonormal and right-handed "
                     "(max |RᵀR − I| = " + fmt(err) + ", det = " + fmt(R.determinant()) + ")");
}

Transform primitive(TransformType type, double value) {
  Transform t;
  t.type = type;
  t.value = value;
  return t;
}
Transform primitive(TransformType type, std::string config) {
  Transform t;
  t.type = type;
  t.config = std::move(config);
  return t;
}

/// The top-level tree (block) that contains joint j, as [first, end); the world is no block.
std::pair<int, int> blockOf(const Model& model, int j) {
  if (j == kWorld) return {model.nq(), 0};  // empty: neutral for min/max
  while (model.joints()[j].parent != kWorld) j = model.joints()[j].parent;
  return {j, model.joints()[j].subtreeEnd};
}

/// The structure the algorithms walk (model.hpp: ModelTopology), from the folded joints and the
/// elements. Loops only (no recursion): O(n + path points + nc³) for the row groups.
ModelTopology describeTopology(const Model& model) {
  const int n = model.nq(), nc = model.nc(), m = model.nu();
  ModelTopology t;
  t.parent.resize(n);
  t.runStart.resize(n);
  t.treeRoot.resize(n);
  for (int i = 0; i < n; ++i) {
    const int p = model.joints()[i].parent;
    t.parent[i] = p;
    t.runStart[i] = (p != kWorld && p == i - 1) ? t.runStart[i - 1] : i;
    t.treeRoot[i] = p == kWorld ? i : t.treeRoot[p];  // p < i: pre-order
    if (p == kWorld) t.blockStart.push_back(i);
  }
  t.blockStart.push_back(n);
  t.tendonFirst.assign(1, 0);
  t.tendonSegmentStart.assign(1, 0);
  for (const Tendon& td : model.tendons()) {
    int lo = n, hi = -1;
    for (size_t k = 0; k < td.path.size(); ++k) {
      const int j = td.path[k].joint;
      if (j != kWorld) {
        lo = std::min(lo, j);
        hi = std::max(hi, j);
      }
      if (k + 1 < td.path.size() && j != td.path[k + 1].joint)
        t.tendonSegmentPoint.push_back(static_cast<int>(t.tendonPointJoint.size()));
      t.tendonPointJoint.push_back(j);
    }
    t.tendonJointLo.push_back(lo);
    t.tendonJointHi.push_back(hi);
    t.tendonFirst.push_back(t.tendonFirst.back() + static_cast<int>(td.path.size()));
    t.tendonSegmentStart.push_back(static_cast<int>(t.tendonSegmentPoint.size()));
  }
  // Row r of A (and column r of M⁻¹Aᵀ) lives on the blocks of the constraint's two bodies.
  t.rowLo.assign(nc, 0);
  t.rowHi.assign(nc, 0);
  for (int r = 0; r < nc; ++r) {
    const Constraint& c = model.constraints()[r];
    const auto [a0, a1] = blockOf(model, c.a.joint);
    const auto [b0, b1] = blockOf(model, c.b.joint);
    t.rowLo[r] = std::min(a0, b0);
    t.rowHi[r] = std::max(a1, b1);
    if (t.rowHi[r] <= t.rowLo[r]) t.rowLo[r] = t.rowHi[r] = 0;  // touches no coordinate
  }
  // Groups of consecutive rows: a boundary s is kept when no row before it shares a coordinate
  // with a row after it; A M⁻¹ Aᵀ is then block diagonal over the groups.
  t.rowGroupStart.assign(1, 0);
  for (int s = 1; s < nc; ++s) {
    bool split = true;
    for (int r = 0; r < s && split; ++r)
      for (int q = s; q < nc && split; ++q)
        split = std::min(t.rowHi[r], t.rowHi[q]) <= std::max(t.rowLo[r], t.rowLo[q]);
    if (split) t.rowGroupStart.push_back(s);
  }
  if (nc > 0) t.rowGroupStart.push_back(nc);
  // Inputs that are generalized forces on one coordinate: their column of B is a column of M⁻¹.
  t.unitInputConfig.assign(m, -2);
  t.unitInputGain.assign(m, 0.0);
  for (const ConfigForce& cf : model.configForces()) {
    int& c = t.unitInputConfig[cf.input];
    c = (c == -2 || c == cf.config) ? cf.config : -1;
    t.unitInputGain[cf.input] += 1.0;
  }
  for (const BodyWrench& bw : model.bodyWrenches())
    for (int k : bw.input)
      if (k >= 0 && bw.joint != kWorld) t.unitInputConfig[k] = -1;
  for (const Tendon& td : model.tendons()) t.unitInputConfig[td.input] = -1;
  for (int& c : t.unitInputConfig)
    if (c == -2) c = -1;
  return t;
}

}  // namespace

Transform Transform::tx(double v) { return primitive(TransformType::kTx, v); }
Transform Transform::ty(double v) { return primitive(TransformType::kTy, v); }
Transform Transform::tz(double v) { return primitive(TransformType::kTz, v); }
Transform Transform::rx(double v) { return primitive(TransformType::kRx, v); }
Transform Transform::ry(double v) { return primitive(TransformType::kRy, v); }
Transform Transform::rz(double v) { return primitive(TransformType::kRz, v); }
Transform Transform::tx(std::string c) { return primitive(TransformType::kTx, std::move(c)); }
Transform Transform::ty(std::string c) { return primitive(TransformType::kTy, std::move(c)); }
Transform Transform::tz(std::string c) { return primitive(TransformType::kTz, std::move(c)); }
Transform Transform::rx(std::string c) { return primitive(TransformType::kRx, std::move(c)); }
Transform Transform::ry(std::string c) { return primitive(TransformType::kRy, std::move(c)); }
Transform Transform::rz(std::string c) { return primitive(TransformType::kRz, std::move(c)); }
Transform Transform::rotAxis(const Eigen::Vector3d& a, std::string c, const Eigen::Matrix4d& g) {
  Transform t = axisTransform(TransformType::kRotAxis, a, g);
  t.config = std::move(c);
  return t;
}
Transform Transform::rotAxis(const Eigen::Vector3d& a, double v, const Eigen::Matrix4d& g) {
  Transform t = axisTransform(TransformType::kRotAxis, a, g);
  t.value = v;
  return t;
}
Transform Transform::transAxis(const Eigen::Vector3d& a, std::string c, const Eigen::Matrix4d& g) {
  Transform t = axisTransform(TransformType::kTransAxis, a, g);
  t.config = std::move(c);
  return t;
}
Transform Transform::transAxis(const Eigen::Vector3d& a, double v, const Eigen::Matrix4d& g) {
  Transform t = axisTransform(TransformType::kTransAxis, a, g);
  t.value = v;
  return t;
}

Eigen::Matrix4d poseFromXyzRpy(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy) {
  Eigen::Matrix4d g = Eigen::Matrix4d::Identity();
  // Products of the three rotation matrices (not of quaternions): a zero angle is an exact
  // identity factor, so an origin with one angle is exactly that elementary rotation.
  g.topLeftCorner<3, 3>() = axisRotation(2, rpy.z()) * axisRotation(1, rpy.y()) * axisRotation(0, rpy.x());
  g.topRightCorner<3, 1>() = xyz;
  return g;
}

Transform Transform::constSE3(const Eigen::Matrix4d& m) {
  Transform t;
  t.type = TransformType::kConstSE3;
  t.matrix = m;
  return t;
}

Eigen::Isometry3d Transform::evaluate(double q) const {
  Eigen::Isometry3d g = Eigen::Isometry3d::Identity();
  if (type == TransformType::kConstSE3) {
    g.linear() = matrix.topLeftCorner<3, 3>();
    g.translation() = matrix.topRightCorner<3, 1>();
    return g;
  }
  const double x = isDriven() ? q : value;
  if (isAxisType(type)) {
    g.linear() = matrix.topLeftCorner<3, 3>();
    g.translation() = matrix.topRightCorner<3, 1>();
    if (type == TransformType::kRotAxis) {
      g.linear() = g.linear() * Eigen::AngleAxisd(x, axis).toRotationMatrix();
    } else {
      g.translation() += g.linear() * (x * axis);
    }
    return g;
  }
  if (isTranslation(type)) {
    g.translation()[axisOf(type)] = x;
  } else {
    g.linear() = axisRotation(axisOf(type), x);
  }
  return g;
}

double modelLengthScale(const Model& model) {
  double L = 0.0;
  for (const Joint& j : model.joints()) L = std::max(L, j.p0.norm());
  for (const FramePlacement& f : model.frames()) L = std::max(L, f.p.norm());
  for (const Constraint& c : model.constraints()) {
    L = std::max({L, c.a.local.norm(), c.b.local.norm(), std::abs(c.distance)});
  }
  for (const LinearSpring& s : model.linearSprings()) {
    L = std::max({L, s.a.local.norm(), s.b.local.norm(), std::abs(s.x0)});
  }
  return L > 0.0 && std::isfinite(L) ? L : 1.0;
}

Eigen::VectorXd coordinateScales(const Model& model) {
  const double L = modelLengthScale(model);
  Eigen::VectorXd s(model.nq());
  for (int j = 0; j < model.nq(); ++j) s(j) = model.joints()[static_cast<std::size_t>(j)].revolute ? 1.0 : L;
  return s;
}

int Model::frameIndex(std::string_view name) const {
  for (int i = 0; i < nframes(); ++i)
    if (frames_[i].name == name) return i;
  throw std::out_of_range("unknown frame '" + std::string(name) + "'");
}
int Model::configIndex(std::string_view name) const {
  for (int i = 0; i < nq(); ++i)
    if (configNames_[i] == name) return i;
  throw std::out_of_range("unknown configuration variable '" + std::string(name) + "'");
}
int Model::inputIndex(std::string_view name) const {
  for (int i = 0; i < nu(); ++i)
    if (inputNames_[i] == name) return i;
  throw std::out_of_range("unknown input '" + std::string(name) + "'");
}

// ------------------------------------------------------------------------------------------------

int ModelBuilder::frameId(const std::string& name, const std::string& element,
                          const std::string& field) const {
  if (name == "world") return kWorld;
  auto it = frameIds_.find(name);
  if (it == frameIds_.end())
    throw ModelError(element + ": field '" + field + "': unknown frame '" + name + "'");
  return it->second;
}

int ModelBuilder::inputId(const std::string& input) {
  for (int i = 0; i < static_cast<int>(inputNames_.size()); ++i)
    if (inputNames_[i] == input) return i;
  if (const std::string problem = nameProblem(input); !problem.empty()) throw ModelError("input: " + problem);
  inputNames_.push_back(input);
  return static_cast<int>(inputNames_.size()) - 1;
}

const std::string& ModelBuilder::addFrame(const std::string& name, const std::string& parent,
                                          const Transform& transform, std::optional<Mass> mass) {
  const std::string element = "frame '" + name + "'";
  if (name.empty()) throw ModelError("frame with parent '" + parent + "': field 'name': empty name");
  if (name == "world") throw ModelError("frame 'world': field 'name': 'world' is reserved");
  if (const std::string problem = nameProblem(name); !problem.empty())
    throw ModelError("frame '" + printableName(name) + "': field 'name': " + problem);
  if (frameIds_.count(name)) throw ModelError(element + ": field 'name': duplicate frame name '" + name + "'");
  const int parentId = frameId(parent, element, "parent");
  if (transform.isDriven()) {
    if (transform.type == TransformType::kConstSE3)
      throw ModelError(element + ": field 'config': a const_se3 transform cannot carry a configuration");
    if (const std::string problem = nameProblem(transform.config); !problem.empty())
      throw ModelError(element + ": field 'config': " + problem);
    auto it = configFrames_.find(transform.config);
    if (it != configFrames_.end())
      throw ModelError(element + ": field 'config': configuration '" + transform.config +
                       "' is already used by frame '" + frames_[it->second].name + "'");
  } else if (transform.type == TransformType::kConstSE3) {
    checkRigid(transform.matrix, element, "matrix");
  } else if (!std::isfinite(transform.value)) {
    throw ModelError(element + ": field 'value': " + fmt(transform.value) + " is not finite");
  }
  Transform checked = transform;
  if (isAxisType(transform.type)) {
    checkRigid(transform.matrix, element, "origin");
    const double norm = transform.axis.norm();
    if (!transform.axis.allFinite() || std::abs(norm - 1.0) > 1e-9)
      throw ModelError(element + ": field 'axis': " + showVector(transform.axis) +
                       " must be a unit vector (norm " + fmt(norm) + ")");
    checked.axis = transform.axis / norm;
  }
  if (mass) {
    if (!std::isfinite(mass->m) || mass->m < 0)
      throw ModelError(element + ": field 'mass.m': " + fmt(mass->m) + " must be >= 0");
    const Eigen::Matrix3d& I = mass->inertia;
    if (!I.allFinite()) throw ModelError(element + ": field 'mass.inertia': entries must be finite");
    const double scale = std::max(1.0, I.cwiseAbs().maxCoeff());
    if ((I - I.transpose()).cwiseAbs().maxCoeff() > 1e-12 * scale)
      throw ModelError(element + ": field 'mass.inertia': tensor is not symmetric");
    const double minEig = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(I, Eigen::EigenvaluesOnly).eigenvalues()[0];
    if (minEig < -1e-12 * scale)
      throw ModelError(element + ": field 'mass.inertia': tensor is not positive semidefinite "
                       "(smallest eigenvalue " + fmt(minEig) + ")");
  }
  const int id = static_cast<int>(frames_.size());
  frames_.push_back({name, parentId, std::move(checked), mass});
  frameIds_[name] = id;
  if (transform.isDriven()) configFrames_[transform.config] = id;
  return frames_.back().name;
}

void ModelBuilder::addGravity(const Eigen::Vector3d& g) {
  if (!g.allFinite()) throw ModelError("gravity: field 'g': entries must be finite");
  gravity_ += g;
}

namespace {
void requireFinite(double x, const std::string& element, const char* field) {
  if (!std::isfinite(x)) throw ModelError(element + ": field '" + field + "': " + fmt(x) + " is not finite");
}
}  // namespace

void ModelBuilder::addLinearSpring(const std::string& f1, const std::string& f2, double k, double x0) {
  const std::string element = "linear_spring(" + f1 + ", " + f2 + ")";
  requireFinite(k, element, "k");
  requireFinite(x0, element, "x0");
  if (x0 < 0) throw ModelError(element + ": field 'x0': " + fmt(x0) + " must be >= 0");
  springs_.push_back({frameId(f1, element, "frame1"), frameId(f2, element, "frame2"), k, x0});
}

void ModelBuilder::addConfigSpring(const std::string& config, double k, double q0) {
  const std::string element = "config_spring(" + config + ")";
  requireFinite(k, element, "k");
  requireFinite(q0, element, "q0");
  configSprings_.push_back({config, k, q0, element});
}

void ModelBuilder::addConfigForce(const std::string& config, const std::string& input) {
  const std::string element = "config_force(" + config + ")";
  if (input.empty()) throw ModelError(element + ": field 'input': empty input name");
  configForces_.push_back({config, inputId(input), element});
}

void ModelBuilder::addDamping(double dflt, const std::map<std::string, double>& coefficients) {
  const std::string element = "damping";
  requireFinite(dflt, element, "default");
  for (const auto& [name, c] : coefficients) requireFinite(c, element, ("coefficients." + name).c_str());
  dampings_.push_back({dflt, coefficients, element});
}

void ModelBuilder::addBodyWrench(const std::string& frame, const std::array<WrenchEntry, 6>& wrench) {
  const std::string element = "body_wrench(" + frame + ")";
  WrenchSpec w{frameId(frame, element, "frame"), {}, {-1, -1, -1, -1, -1, -1}};
  for (int i = 0; i < 6; ++i) {
    if (const double* x = std::get_if<double>(&wrench[i])) {
      requireFinite(*x, element, ("wrench[" + std::to_string(i) + "]").c_str());
      w.constant[i] = *x;
    } else {
      const std::string& in = std::get<std::string>(wrench[i]);
      if (in.empty()) throw ModelError(element + ": field 'wrench[" + std::to_string(i) + "]': empty input name");
      w.input[i] = inputId(in);
    }
  }
  wrenches_.push_back(w);
}

void ModelBuilder::addTendon(const std::vector<std::string>& path, const std::string& input) {
  const std::string element = "tendon(" + input + ")";
  if (path.size() < 2)
    throw ModelError(element + ": field 'path': needs at least 2 frames, got " + std::to_string(path.size()));
  if (input.empty()) throw ModelError(element + ": field 'input': empty input name");
  TendonSpec t;
  for (size_t i = 0; i < path.size(); ++i) t.path.push_back(frameId(path[i], element, "path[" + std::to_string(i) + "]"));
  t.input = inputId(input);
  tendons_.push_back(std::move(t));
}

void ModelBuilder::addDistanceConstraint(const std::string& f1, const std::string& f2, double d) {
  const std::string element = "constraints[" + std::to_string(constraints_.size()) + "] (distance " + f1 + "–" + f2 + ")";
  requireFinite(d, element, "distance");
  // d = 0: the gradient of h = |p1 - p2|^2 vanishes wherever h = 0 (a degenerate row).
  if (!(d > 0)) throw ModelError(element + ": field 'distance': " + fmt(d) + " must be > 0 (at 0 the gradient vanishes where the constraint holds)");
  constraints_.push_back({ConstraintType::kDistance, frameId(f1, element, "frame1"), frameId(f2, element, "frame2"),
                          d, 0, Eigen::Vector3d::Zero(), element});
}

void ModelBuilder::addPointConstraint(const std::string& f1, const std::string& f2, int axis) {
  const std::string element = "constraints[" + std::to_string(constraints_.size()) + "] (point " + f1 + "–" + f2 + ")";
  if (axis < 0 || axis > 2) throw ModelError(element + ": field 'axis': " + std::to_string(axis) + " must be x, y or z");
  constraints_.push_back({ConstraintType::kPoint, frameId(f1, element, "frame1"), frameId(f2, element, "frame2"),
                          0.0, axis, Eigen::Vector3d::Zero(), element});
}

void ModelBuilder::addPointOnPlaneConstraint(const std::string& plane, const Eigen::Vector3d& normal,
                                             const std::string& point) {
  const std::string element = "constraints[" + std::to_string(constraints_.size()) + "] (point_on_plane " + plane + "–" + point + ")";
  if (!normal.allFinite() || normal.norm() == 0.0)
    throw ModelError(element + ": field 'normal': must be a finite nonzero 3-vector");
  constraints_.push_back({ConstraintType::kPointOnPlane, frameId(plane, element, "plane_frame"),
                          frameId(point, element, "point_frame"), 0.0, 0, normal, element});
}

void ModelBuilder::addKnifeEdgeConstraint(const std::string& frame, const Eigen::Vector3d& axis) {
  const std::string element = "constraints[" + std::to_string(constraints_.size()) + "] (knife_edge " + frame + ")";
  if (!axis.allFinite() || axis.norm() == 0.0)
    throw ModelError(element + ": field 'axis': must be a finite nonzero 3-vector");
  constraints_.push_back({ConstraintType::kKnifeEdge, frameId(frame, element, "frame"), kWorld, 0.0, 0,
                          axis, element});
}

void ModelBuilder::addCoordinateCoupling(const std::string& follower, const std::string& leader, double multiplier,
                                         double offset) {
  const std::string element = "constraints[" + std::to_string(constraints_.size()) + "] (coordinate_coupling " +
                              follower + "–" + leader + ")";
  requireFinite(multiplier, element, "multiplier");
  requireFinite(offset, element, "offset");
  if (multiplier == 0.0)
    throw ModelError(element + ": field 'multiplier': 0 would fix the coordinate (q = offset), not couple it");
  if (follower == leader) throw ModelError(element + ": field 'leader': '" + leader + "' is the follower itself");
  ConstraintSpec c{ConstraintType::kCoordinateCoupling, kWorld, kWorld, 0.0, 0, Eigen::Vector3d::Zero(), element};
  c.follower = follower;
  c.leader = leader;
  c.multiplier = multiplier;
  c.offset = offset;
  constraints_.push_back(std::move(c));
}

Model ModelBuilder::finalize() const& { return ModelBuilder(*this).finalize(); }

Model ModelBuilder::finalize() && {
  Model model;
  model.name_ = name_;
  const int nf = static_cast<int>(frames_.size());
  // The limits of scene files (scene.cpp), here for models built in C++: checked before any
  // n×n matrix exists, so that a Data for the model cannot ask for gigabytes.
  if (frames_.size() > static_cast<std::size_t>(kMaxFrames))
    throw ModelError("model" + (name_.empty() ? std::string() : " '" + name_ + "'") + " has " +
                     std::to_string(frames_.size()) + " frames, more than the limit of " + std::to_string(kMaxFrames));
  std::size_t driven = 0;
  for (const FrameSpec& f : frames_) driven += f.transform.isDriven() ? 1 : 0;
  if (driven > static_cast<std::size_t>(kMaxConfigs))
    throw ModelError("model" + (name_.empty() ? std::string() : " '" + name_ + "'") + " has " + std::to_string(driven) +
                     " configuration variables, more than the limit of " + std::to_string(kMaxConfigs) +
                     " (the dense matrices of the linearization take about 200 n^2 bytes: " +
                     fmt(200.0 * static_cast<double>(driven) * static_cast<double>(driven) / 1e9) +
                     " GB at n = " + std::to_string(driven) + ")");

  // Pre-order of the frame tree, children in the order they were added.
  std::vector<std::vector<int>> children(nf);
  std::vector<int> roots;
  for (int i = 0; i < nf; ++i) (frames_[i].parent == kWorld ? roots : children[frames_[i].parent]).push_back(i);
  // Iterative (an explicit stack, children pushed in reverse so the first is visited first): a
  // recursion per frame would overflow the call stack on a chain of kMaxFrames frames.
  std::vector<int> order;
  order.reserve(nf);
  std::vector<int> stack(roots.rbegin(), roots.rend());
  while (!stack.empty()) {
    const int f = stack.back();
    stack.pop_back();
    order.push_back(f);
    stack.insert(stack.end(), children[f].rbegin(), children[f].rend());
  }

  // Fold constant transforms: every frame becomes (joint body, constant placement in it).
  std::vector<int> newIndex(nf);
  std::vector<FramePlacement> placed(nf);  // by builder index
  for (int f : order) {
    const FrameSpec& spec = frames_[f];
    FramePlacement parent;  // world: joint kWorld, identity
    if (spec.parent != kWorld) parent = placed[spec.parent];
    FramePlacement p;
    p.name = spec.name;
    p.parentFrame = spec.parent;
    if (spec.transform.isDriven()) {
      const Transform& t = spec.transform;
      Joint j;
      j.config = t.config;
      j.frame = spec.name;
      j.parent = parent.joint;
      j.R0 = parent.R;
      j.p0 = parent.p;
      if (isAxisType(t.type)) {
        // g_local = G · exp(q [a]) = (G · Ra) · exp(q [e_z]) · Raᵀ: the joint body is turned by
        // G·Ra (z along a) and the frame sits on it at the constant rotation Raᵀ.
        j.revolute = t.type == TransformType::kRotAxis;
        j.R0 = parent.R * t.matrix.topLeftCorner<3, 3>();
        j.p0 = parent.p + parent.R * t.matrix.topRightCorner<3, 1>();
        if (const int i = basisIndex(t.axis); i >= 0) {
          j.axis = i;
        } else {
          const Eigen::Matrix3d Ra = axisFrame(t.axis);
          j.axis = 2;
          j.R0 = j.R0 * Ra;
          p.R = Ra.transpose();
        }
      } else {
        j.revolute = !isTranslation(t.type);
        j.axis = axisOf(t.type);
      }
      j.depth = (j.parent == kWorld ? 0 : model.joints_[j.parent].depth) + 1;
      model.joints_.push_back(j);
      model.configNames_.push_back(j.config);
      p.joint = static_cast<int>(model.joints_.size()) - 1;
    } else {
      const Eigen::Isometry3d g = spec.transform.evaluate(0.0);
      p.joint = parent.joint;
      p.R = parent.R * g.linear();
      p.p = parent.p + parent.R * g.translation();
    }
    newIndex[f] = static_cast<int>(model.frames_.size());
    placed[f] = p;
    model.frames_.push_back(p);
  }
  for (auto& fp : model.frames_)
    if (fp.parentFrame != kWorld) fp.parentFrame = newIndex[fp.parentFrame];

  const int n = model.nq();
  for (int j = 0; j < n; ++j) model.joints_[j].subtreeEnd = j + 1;
  for (int j = n - 1; j >= 0; --j) {
    const int p = model.joints_[j].parent;
    if (p != kWorld) model.joints_[p].subtreeEnd = std::max(model.joints_[p].subtreeEnd, model.joints_[j].subtreeEnd);
  }

  // Lump masses: inertia about the joint origin, I_o = R I_c Rᵀ + m ([c]ᵀ[c]).
  for (int f = 0; f < nf; ++f) {
    const auto& mass = frames_[f].mass;
    const FramePlacement& p = placed[f];
    if (!mass || p.joint == kWorld) continue;
    Joint& j = model.joints_[p.joint];
    const Eigen::Vector3d& c = p.p;
    j.mass += mass->m;
    j.firstMoment += mass->m * c;
    j.inertiaAtOrigin += p.R * mass->inertia * p.R.transpose() +
                         mass->m * (c.squaredNorm() * Eigen::Matrix3d::Identity() - c * c.transpose());
  }

  auto point = [&](int f) {
    BodyPoint bp;
    if (f == kWorld) return bp;
    bp.joint = placed[f].joint;
    bp.local = placed[f].p;
    return bp;
  };
  auto config = [&](const std::string& name, const std::string& element, const char* field) {
    for (int i = 0; i < n; ++i)
      if (model.configNames_[i] == name) return i;
    throw ModelError(element + ": field '" + field + "': unknown configuration '" + name + "'");
  };

  model.gravity_ = gravity_;
  model.inputNames_ = inputNames_;
  checkColumnNames(model.configNames_, model.inputNames_);  // names.hpp: CSV columns that read back
  for (const auto& s : springs_) model.linearSprings_.push_back({point(s.f1), point(s.f2), s.k, s.x0});
  for (const auto& s : configSprings_) model.configSprings_.push_back({config(s.config, s.element, "config"), s.k, s.q0});
  for (const auto& s : configForces_) model.configForces_.push_back({config(s.config, s.element, "config"), s.input});
  model.damping_ = Eigen::VectorXd::Zero(n);
  for (const auto& d : dampings_) {
    Eigen::VectorXd c = Eigen::VectorXd::Constant(n, d.dflt);
    for (const auto& [name, value] : d.coeffs) c[config(name, d.element, ("coefficients." + name).c_str())] = value;
    model.damping_ += c;
  }
  for (const auto& w : wrenches_) {
    BodyWrench bw;
    if (w.frame != kWorld) {
      bw.joint = placed[w.frame].joint;
      bw.R = placed[w.frame].R;
      bw.p = placed[w.frame].p;
    }
    bw.constant = w.constant;
    bw.input = w.input;
    model.bodyWrenches_.push_back(bw);
  }
  for (const auto& t : tendons_) {
    Tendon td;
    for (int f : t.path) td.path.push_back(point(f));
    td.input = t.input;
    model.tendons_.push_back(std::move(td));
  }
  for (const auto& c : constraints_) {
    Constraint k;
    k.type = c.type;
    k.name = c.name;
    k.a = point(c.f1);
    k.b = point(c.f2);
    k.distance = c.distance;
    k.axis = c.axis;
    if (c.type == ConstraintType::kPointOnPlane || c.type == ConstraintType::kKnifeEdge)
      k.direction = (c.f1 == kWorld ? Eigen::Matrix3d::Identity() : placed[c.f1].R) * c.direction;
    if (c.type == ConstraintType::kCoordinateCoupling) {
      // The coordinates' joints stand for the two "bodies" (topology: the row's blocks).
      const int j = config(c.follower, c.name, "follower"), i = config(c.leader, c.name, "leader");
      k.a = BodyPoint{};
      k.b = BodyPoint{};
      k.a.joint = j;
      k.b.joint = i;
      k.coupling = {c.multiplier, c.offset, model.joints_[j].parent, model.joints_[i].parent,
                    model.joints_[j].revolute, model.joints_[i].revolute};
    }
    if (k.holonomic()) ++model.nholonomic_;
    model.constraints_.push_back(k);
  }
  model.topology_ = describeTopology(model);
  return model;
}

}  // namespace trellis
