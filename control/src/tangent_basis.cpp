// tangent_basis.cpp — the held tangent basis (plain data: Hermite interpolation of the corrected
// nodes, then the polar factor) and ReducedLinearization, its model-bound evaluation for solvers.
#include "trellis/core/reference.hpp"
#include "trellis/control/manifold_lqr.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace trellis {

void TangentTransportOptions::validate() const {
  auto bad = [](const char* field, double v, const char* rule) {
    std::ostringstream m;
    m << "TangentTransportOptions." << field << " = " << v << " must be " << rule;
    throw std::invalid_argument(m.str());
  };
  if (!(rtol > 0.0) || !std::isfinite(rtol)) bad("rtol", rtol, "> 0 and finite");
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol, "> 0 and finite");
  if (maxSteps <= 0) bad("maxSteps", static_cast<double>(maxSteps), "> 0");
  if (substeps < 1) bad("substeps", substeps, "≥ 1");
}

const Trajectory& TangentBasisTrajectory::reference() const {
  if (!trajectory_) throw std::out_of_range("TangentBasisTrajectory: empty (not transported)");
  return *trajectory_;
}

std::string TangentBasisTrajectory::describe() const {
  if (!ok()) return status_.describe();
  std::ostringstream m;
  m << "ok: T(t) " << nx_ << "x" << d_ << " on [" << t0_ << ", " << tf_ << "], " << steps_
    << " steps, largest correction " << maxCorrection_;
  return m.str();
}

std::string TangentBasisTrajectory::json() const {
  detail::ReportJson j = detail::statusJson(status_);
  j["dimension"] = d_;
  j["nx"] = nx_;
  j["start_time"] = detail::toJson(t0_);
  j["end_time"] = detail::toJson(tf_);
  j["valid_until"] = hasBasis() ? detail::toJson(validUntil_) : detail::ReportJson(nullptr);
  j["steps"] = steps_;
  j["difference_quotient_evaluations"] = linearRhsEvaluations_;
  j["max_correction"] = detail::toJson(maxCorrection_);
  return j.dump();
}

void TangentBasisTrajectory::checkRange(double t, const char* what) const {
  if (nx_ == 0) throw std::out_of_range("TangentBasisTrajectory: empty (not transported)");
  if (!hasBasis()) {
    throw std::out_of_range(std::string("TangentBasisTrajectory::") + what +
                            ": no basis anywhere (" + status_.describe() + ")");
  }
  const double slack = 1e-12 * std::max({1.0, std::abs(t0_), std::abs(tf_)});
  if (!(t >= t0_ - slack && t <= validUntil_ + slack)) {
    std::ostringstream m;
    m << "TangentBasisTrajectory::" << what << ": t = " << t << " is outside [" << t0_ << ", "
      << validUntil_ << "]";
    throw std::out_of_range(m.str());
  }
}

// Cubic Hermite on the node interval [t_i, t_{i+1}] ∋ t with values T_i and slopes Ṫ_i.
void TangentBasisTrajectory::interpolate(double t, Eigen::MatrixXd& T) const {
  T.resize(nx_, d_);
  if (identity_) {
    T.setIdentity();
    return;
  }
  t = std::clamp(t, t0_, validUntil_);
  const auto it = std::upper_bound(nodeTimes_.begin(), nodeTimes_.end(), t);
  std::size_t i = it == nodeTimes_.begin() ? 0 : static_cast<std::size_t>(it - nodeTimes_.begin()) - 1;
  if (i + 1 >= nodeTimes_.size()) {
    T = nodeT_[i];  // t is the last node
    return;
  }
  const double h = nodeTimes_[i + 1] - nodeTimes_[i], s = (t - nodeTimes_[i]) / h;
  const double s2 = s * s, s3 = s2 * s;
  const double h00 = 2 * s3 - 3 * s2 + 1, h10 = (s3 - 2 * s2 + s) * h, h01 = -2 * s3 + 3 * s2,
               h11 = (s3 - s2) * h;
  T = h00 * nodeT_[i] + h10 * nodeDT_[i] + h01 * nodeT_[i + 1] + h11 * nodeDT_[i + 1];
}

void TangentBasisTrajectory::basis(double t, Eigen::MatrixXd& out) const {
  checkRange(t, "basis");
  interpolate(t, out);
  if (identity_) return;
  // Polar factor T (TᵀT)^{-1/2}: TᵀT = I + O(h⁴), so the eigenvalues are ≈ 1.
  const Eigen::MatrixXd G = out.transpose() * out;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(G);
  const Eigen::VectorXd ev = es.eigenvalues();
  if (!(ev(0) > 0.25)) {
    std::ostringstream m;
    m << "TangentBasisTrajectory::basis: the interpolated basis at t = " << t
      << " is far from orthonormal (smallest eigenvalue of TᵀT " << ev(0) << ")";
    throw std::runtime_error(m.str());
  }
  out = out * (es.eigenvectors() * ev.cwiseSqrt().cwiseInverse().asDiagonal() *
               es.eigenvectors().transpose());
}

Eigen::MatrixXd TangentBasisTrajectory::basis(double t) const {
  Eigen::MatrixXd T;
  basis(t, T);
  return T;
}

Eigen::MatrixXd TangentBasisTrajectory::transportedBasis(double t) const {
  checkRange(t, "transportedBasis");
  Eigen::MatrixXd T(nx_, d_);
  if (identity_) {
    T.setIdentity();
    return T;
  }
  t = std::clamp(t, t0_, validUntil_);
  Eigen::Map<Eigen::VectorXd> y(T.data(), T.size());
  stored_.evaluate(t, y);  // the step polynomial covering t (CVODES's dense output)
  return T;
}

void TangentBasisTrajectory::reducedLinearization(const Model& model, double t, Eigen::MatrixXd& T,
                                                  Eigen::MatrixXd& Ar, Eigen::MatrixXd& Br) const {
  ReducedLinearization lin(model, *this);
  const ReferenceStatus st = lin.evaluate(t);
  if (!st.ok()) throw std::runtime_error(st.message);
  T = lin.T();
  Ar = lin.Ar();
  Br = lin.Br();
}

// ---- ReducedLinearization ----------------------------------------------------------------------

namespace {

/// C¹ cubic Hermite at t ∈ [x_i, x_{i+1}] of values F with three-point slopes
/// m_i = (h_i δ_{i−1} + h_{i−1} δ_i)/(h_{i−1} + h_i) (one-sided three-point at the ends).
void hermiteThreePoint(const std::vector<double>& x, const std::vector<Eigen::MatrixXd>& F,
                       double t, Eigen::MatrixXd& out, Eigen::MatrixXd& m0, Eigen::MatrixXd& m1) {
  const std::size_t n = x.size();
  if (n == 1) {
    out = F[0];
    return;
  }
  auto it = std::upper_bound(x.begin(), x.end(), t);
  std::size_t i = it == x.begin() ? 0 : static_cast<std::size_t>(it - x.begin()) - 1;
  if (i + 1 >= n) i = n - 2;
  auto slope = [&](std::size_t k, Eigen::MatrixXd& m) {
    if (n == 2) {
      m = (F[1] - F[0]) / (x[1] - x[0]);
    } else if (k == 0) {
      const double h0 = x[1] - x[0], h1 = x[2] - x[1];
      m = ((2 * h0 + h1) / (h0 * (h0 + h1))) * (F[1] - F[0]) - (h0 / (h1 * (h0 + h1))) * (F[2] - F[1]);
    } else if (k == n - 1) {
      const double h0 = x[k - 1] - x[k - 2], h1 = x[k] - x[k - 1];
      m = ((2 * h1 + h0) / (h1 * (h0 + h1))) * (F[k] - F[k - 1]) - (h1 / (h0 * (h0 + h1))) * (F[k - 1] - F[k - 2]);
    } else {
      const double hm = x[k] - x[k - 1], hp = x[k + 1] - x[k];
      m = (hp / (hm * (hm + hp))) * (F[k] - F[k - 1]) + (hm / (hp * (hm + hp))) * (F[k + 1] - F[k]);
    }
  };
  slope(i, m0);
  slope(i + 1, m1);
  const double h = x[i + 1] - x[i], s = std::clamp((t - x[i]) / h, 0.0, 1.0);
  const double s2 = s * s, s3 = s2 * s;
  out = (2 * s3 - 3 * s2 + 1) * F[i] + ((s3 - 2 * s2 + s) * h) * m0 + (-2 * s3 + 3 * s2) * F[i + 1] +
        ((s3 - s2) * h) * m1;
}

}  // namespace

struct ReducedLinearization::Work {
  ReferenceEvaluator point;  // checks the reference against the model once
  Eigen::MatrixXd Th, C, AT, m0, m1;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd;
  Work(const Model& m, const Trajectory& tr) : point(m, tr) {}
};

ReducedLinearization::ReducedLinearization(const Model& model, TangentBasisTrajectory basis)
    : model_(model), basis_(std::move(basis)) {
  work_ = std::make_unique<Work>(model_, basis_.reference());
}

ReducedLinearization::~ReducedLinearization() = default;

const Eigen::MatrixXd& ReducedLinearization::A() const { return work_->point.A(); }

// T = polar(P T_h) with P = Tc Tcᵀ (Tc the core's basis at x(t)): P T_h = Tc (Tcᵀ T_h), and for
// Tcᵀ T_h = U Σ Vᵀ the polar factor is Tc U Vᵀ (Tc has orthonormal columns).
ReferenceStatus ReducedLinearization::evaluate(double t) {
  if (cached_ && cachedTime_ == t) return {};
  cached_ = false;
  Work& w = *work_;
  const TangentBasisTrajectory& b = basis_;
  b.checkRange(t, "reduced linearization");  // before the dynamics
  const bool constrained = !b.identity_;
  if (constrained && b.nodeLinearization_) {  // kNodes: no dynamics evaluation
    b.basis(t, T_);
    hermiteThreePoint(b.nodeTimes_, b.nodeAr_, t, Ar_, w.m0, w.m1);
    hermiteThreePoint(b.nodeTimes_, b.nodeBr_, t, Br_, w.m0, w.m1);
    cached_ = true;
    cachedTime_ = t;
    return {};
  }
  const ReferenceStatus st = constrained ? w.point.linearizeWithTangentBasis(t, b.d_)
                                         : w.point.linearize(t);
  ++evaluations_;  // dynamics evaluations (the node path above takes none)
  if (!st.ok()) return st;
  if (!constrained) {
    T_.setIdentity(b.nx_, b.nx_);
    Ar_ = w.point.A();
    Br_ = w.point.B();
  } else {
    const Eigen::Index d = b.d_;
    b.interpolate(t, w.Th);
    const Eigen::MatrixXd& Tc = w.point.tangentBasis();
    w.C.noalias() = Tc.transpose() * w.Th;
    w.svd.compute(w.C, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const double smin = w.svd.singularValues()(d - 1);
    if (!(smin > 1e-3)) {
      std::ostringstream m;
      m << "at t = " << t
        << " the transported basis has drifted off the tangent space (smallest singular value of "
           "its projection "
        << smin << ")";
      ReferenceStatus drift;
      drift.set(ReferenceCode::kBasisDrift, m.str(), t);
      return drift;
    }
    T_.noalias() = Tc * (w.svd.matrixU() * w.svd.matrixV().transpose());
    w.AT.noalias() = w.point.A() * T_;
    Ar_.noalias() = T_.transpose() * w.AT;
    Br_.noalias() = T_.transpose() * w.point.B();
  }
  cached_ = true;
  cachedTime_ = t;
  return {};
}

}  // namespace trellis
