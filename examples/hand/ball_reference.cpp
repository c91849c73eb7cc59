// examples/hand/ball_reference.cpp — the inverse-dynamics reference of ball_reference.hpp.
#include "ball_reference.hpp"

#include <trellis/core/data.hpp>
#include <trellis/core/dynamics.hpp>
#include <trellis/core/linearization.hpp>
#include <trellis/core/projection.hpp>

#include <Eigen/Dense>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>
#include <stdexcept>

namespace trellis::hand {

void InverseReferenceOptions::validate() const {
  const auto bad = [](const std::string& what) { throw std::invalid_argument("InverseReferenceOptions: " + what); };
  if (knots < 2 || knots > 100000) bad("knots = " + std::to_string(knots) + " must be in [2, 100000]");
  if (facets < 3 || facets > 64) bad("facets = " + std::to_string(facets) + " must be in [3, 64]");
  if (!(frictionUse > 0.0 && frictionUse <= 1.0)) bad("frictionUse = " + std::to_string(frictionUse) + " must be in (0, 1]");
  if (!(normalMargin >= 0.0 && std::isfinite(normalMargin))) bad("normalMargin = " + std::to_string(normalMargin) + " must be >= 0");
  if (!(barrier > 0.0 && std::isfinite(barrier))) bad("barrier = " + std::to_string(barrier) + " must be > 0");
  if (!(edgeWeight > 0.0 && std::isfinite(edgeWeight))) bad("edgeWeight = " + std::to_string(edgeWeight) + " must be > 0");
  if (!(rateStep >= 0.0 && rateStep < 1.0)) bad("rateStep = " + std::to_string(rateStep) + " must be in [0, 1)");
  if (!(tensionFloor >= 0.0 && std::isfinite(tensionFloor))) bad("tensionFloor = " + std::to_string(tensionFloor) + " must be >= 0");
  if (maxIterations < 1) bad("maxIterations = " + std::to_string(maxIterations) + " must be >= 1");
}

namespace {

/// The interpolating quintic spline of the knots' positions, C⁴ at the interior knots, with the
/// first and second derivatives given at both ends: per segment j of length h_j, in s ∈ [0, 1],
/// p_j(s) = Σ_i c_ji sⁱ. 6S unknowns: 2S values, 4(S − 1) continuity rows, 4 end rows (a banded
/// system, solved sparse). C⁴ and not the C² quintic Hermite through (q, q̇, q̈): the distribution
/// depends on q̈, so its tensions are as smooth as q̈ — a jump of q⃛ at a knot is a kink of u(t)
/// that one rate per knot cannot follow (measured: 1e-2 of the state's range at the kinks).
class QuinticSpline {
 public:
  QuinticSpline(const Eigen::VectorXd& times, const Eigen::MatrixXd& values, const Eigen::VectorXd& v0,
                const Eigen::VectorXd& a0, const Eigen::VectorXd& v1, const Eigen::VectorXd& a1)
      : times_(times) {
    const int N = static_cast<int>(times.size()), S = N - 1, p = static_cast<int>(values.rows());
    h_ = times.tail(S) - times.head(S);
    std::vector<Eigen::Triplet<double>> t;
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(6 * S, p);
    int row = 0;
    // d^r/dt^r of segment j at s, coefficient of c_ji.
    const auto coeff = [&](int j, int i, int r, double s) {
      if (i < r) return 0.0;
      double f = 1.0;
      for (int k = 0; k < r; ++k) f *= (i - k);
      return f * std::pow(s, i - r) / std::pow(h_(j), r);
    };
    const auto put = [&](int j, int r, double s, double sign) {
      for (int i = 0; i < 6; ++i) {
        const double c = coeff(j, i, r, s);
        if (c != 0.0) t.emplace_back(row, 6 * j + i, sign * c);
      }
    };
    for (int j = 0; j < S; ++j) {
      put(j, 0, 0.0, 1.0);
      rhs.row(row++) = values.col(j).transpose();
      put(j, 0, 1.0, 1.0);
      rhs.row(row++) = values.col(j + 1).transpose();
    }
    for (int j = 1; j < S; ++j)
      for (int r = 1; r <= 4; ++r) {
        put(j - 1, r, 1.0, 1.0);
        put(j, r, 0.0, -1.0);
        ++row;
      }
    put(0, 1, 0.0, 1.0);
    rhs.row(row++) = v0.transpose();
    put(0, 2, 0.0, 1.0);
    rhs.row(row++) = a0.transpose();
    put(S - 1, 1, 1.0, 1.0);
    rhs.row(row++) = v1.transpose();
    put(S - 1, 2, 1.0, 1.0);
    rhs.row(row++) = a1.transpose();
    Eigen::SparseMatrix<double> K(6 * S, 6 * S);
    K.setFromTriplets(t.begin(), t.end());
    Eigen::SparseLU<Eigen::SparseMatrix<double>> lu;
    lu.compute(K);
    if (lu.info() != Eigen::Success) throw std::runtime_error("the motion's quintic spline is singular");
    c_ = lu.solve(rhs);  // 6S × p
  }
  /// Value, first and second time derivatives at t (the end segments extrapolate outside).
  void eval(double t, Eigen::VectorXd& p, Eigen::VectorXd& v, Eigen::VectorXd& a) const {
    const int N = static_cast<int>(times_.size());
    int j = static_cast<int>(std::upper_bound(times_.data(), times_.data() + N, t) - times_.data()) - 1;
    j = std::clamp(j, 0, N - 2);
    const double s = (t - times_(j)) / h_(j), h = h_(j);
    const auto c = [&](int i) { return c_.row(6 * j + i).transpose(); };
    p = c(0) + s * (c(1) + s * (c(2) + s * (c(3) + s * (c(4) + s * c(5)))));
    v = (c(1) + s * (2.0 * c(2) + s * (3.0 * c(3) + s * (4.0 * c(4) + s * 5.0 * c(5))))) / h;
    a = (2.0 * c(2) + s * (6.0 * c(3) + s * (12.0 * c(4) + s * 20.0 * c(5)))) / (h * h);
  }

 private:
  Eigen::VectorXd times_, h_;
  Eigen::MatrixXd c_;
};

/// One state of the design at time t: the drivers from the spline, the rest from the constraints.
struct DesignPoint {
  Eigen::VectorXd q, dq, qdd;
  double constraintResidual = 0.0;
  std::string failure;
};

class Design {
 public:
  Design(const Model& model, const Trajectory& motion, const std::vector<int>& drivers,
         const std::vector<int>& dependent)
      : model_(model), drivers_(drivers), dependent_(dependent), data_(model) {
    const int n = model.nq(), N = motion.size();
    Eigen::VectorXd a0, a1;
    for (const int k : {0, N - 1}) {
      const Eigen::VectorXd x = motion.states().col(k);
      if (!computeDynamics(model, data_, x.head(n), x.tail(n), motion.inputs().col(k)).ok())
        throw std::runtime_error("the motion's dynamics fail at knot " + std::to_string(k));
      (k == 0 ? a0 : a1) = data_.qdd;
    }
    const Eigen::MatrixXd q = motion.states().topRows(n);
    spline_ = std::make_unique<QuinticSpline>(motion.times(), q, motion.states().col(0).tail(n), a0,
                                              motion.states().col(N - 1).tail(n), a1);
  }

  DesignPoint at(double t) {
    const int n = model_.nq();
    DesignPoint d;
    Eigen::VectorXd p, v, a;
    spline_->eval(t, p, v, a);
    // h(q) = 0 with the drivers fixed, from the spline's own point.
    ProjectionOptions po;
    po.fixed = drivers_;
    po.velocities = false;
    po.tolerance = 1e-14;
    po.stepTolerance = std::numeric_limits<double>::infinity();
    const ProjectionResult pr = projectState(model_, data_, p, Eigen::VectorXd::Zero(n), po);
    d.q = pr.q;
    d.constraintResidual = pr.positionResidual;
    if (!(pr.positionResidual <= 1e-10)) {
      d.failure = "the constraints cannot be met with the drivers fixed (|h| = " + std::to_string(pr.positionResidual) + " m)";
      return d;
    }
    // q̇, q̈ of the dependent coordinates from A q̇ = 0 and A q̈ + Ȧ q̇ = 0.
    d.dq = v;
    d.qdd = a;
    ImplicitDynamics id(model_);
    const Eigen::VectorXd u0 = Eigen::VectorXd::Zero(model_.nu()), l0 = Eigen::VectorXd::Zero(model_.nc());
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
    if (!computeImplicitDynamics(model_, data_, d.q, zero, zero, u0, l0, id).ok()) {
      d.failure = "the dynamics fail";
      return d;
    }
    const Eigen::MatrixXd A = data_.constraintJacobian;
    Eigen::MatrixXd AD(A.rows(), dependent_.size()), AI(A.rows(), drivers_.size());
    for (size_t j = 0; j < dependent_.size(); ++j) AD.col(j) = A.col(dependent_[j]);
    for (size_t j = 0; j < drivers_.size(); ++j) AI.col(j) = A.col(drivers_[j]);
    const Eigen::PartialPivLU<Eigen::MatrixXd> lu(AD);
    Eigen::VectorXd vI(drivers_.size()), aI(drivers_.size());
    for (size_t j = 0; j < drivers_.size(); ++j) {
      vI(j) = v(drivers_[j]);
      aI(j) = a(drivers_[j]);
    }
    const Eigen::VectorXd vD = -lu.solve(AI * vI);
    for (size_t j = 0; j < dependent_.size(); ++j) d.dq(dependent_[j]) = vD(j);
    // c₀ = A q̈ + Ȧ q̇ at q̈ = 0 (the residual is affine in q̈).
    if (!computeImplicitDynamics(model_, data_, d.q, d.dq, zero, u0, l0, id).ok()) {
      d.failure = "the dynamics fail";
      return d;
    }
    const Eigen::VectorXd aD = -lu.solve(AI * aI + id.c);
    for (size_t j = 0; j < dependent_.size(); ++j) d.qdd(dependent_[j]) = aD(j);
    return d;
  }

 private:
  const Model& model_;
  std::vector<int> drivers_, dependent_;
  Data data_;
  std::unique_ptr<QuinticSpline> spline_;
};

/// The barrier distribution of the file comment at one design point. z = [u; α] is the start and
/// the result; returns "" or what failed.
class Distribution {
 public:
  Distribution(const Model& model, const BallLimits& limits, const InverseReferenceOptions& o)
      : model_(model), limits_(limits), o_(o), data_(model), id_(model) {
    const int nc = model.nc(), contacts = nc / 3, F = o.facets;
    const double mu = o.frictionUse * limits.friction;
    E_ = Eigen::MatrixXd::Zero(nc, contacts * F);
    lambda0_ = Eigen::VectorXd::Zero(nc);
    for (int d = 0; d < contacts; ++d) {
      lambda0_(3 * d) = limits.normalMin + o.normalMargin;
      for (int k = 0; k < F; ++k) {
        const double phi = (2.0 * k + 1.0) * std::numbers::pi / F;
        E_(3 * d, d * F + k) = 1.0;
        E_(3 * d + 1, d * F + k) = mu * std::cos(phi);
        E_(3 * d + 2, d * F + k) = mu * std::sin(phi);
      }
    }
  }
  int size() const { return model_.nu() + static_cast<int>(E_.cols()); }
  Eigen::VectorXd lambda(const Eigen::VectorXd& z) const { return lambda0_ + E_ * z.tail(E_.cols()); }

  /// Solves at p; on return z is the solution, residual the equations' relative residual.
  std::string solve(const DesignPoint& p, Eigen::VectorXd& z, double& relativeResidual, int& iterations) {
    const int n = model_.nq(), m = model_.nu(), nz = size();
    const Eigen::VectorXd u0 = Eigen::VectorXd::Zero(m), l0 = Eigen::VectorXd::Zero(model_.nc());
    // r(u, λ) = r₀ + R_u u + R_λ λ: r₀ at u = λ = 0; the columns from the model's matrices, their
    // signs checked against the residual's own evaluation below.
    if (!computeImplicitDynamics(model_, data_, p.q, p.dq, p.qdd, u0, l0, id_).ok()) return "the dynamics fail";
    const Eigen::VectorXd r0 = id_.r;
    const Eigen::MatrixXd Ru = -data_.inputMatrix;
    const Eigen::MatrixXd Rl = -data_.constraintJacobian.transpose();
    const Eigen::VectorXd scaleTerms = (data_.M * p.qdd).cwiseAbs().cwiseMax(r0.cwiseAbs());
    Eigen::MatrixXd G(n, nz);
    G << Ru, Rl * E_;
    const Eigen::VectorXd d = -(r0 + Rl * lambda0_);
    const double beta = o_.barrier, eps = o_.edgeWeight;
    const Eigen::VectorXd& umax = limits_.uMax;
    // Interior start.
    const double lo = o_.tensionFloor;
    for (int i = 0; i < m; ++i) z(i) = std::clamp(z(i), lo + 1e-3 * (umax(i) - lo), umax(i) - 1e-3 * (umax(i) - lo));
    for (int j = m; j < nz; ++j) z(j) = std::max(z(j), 1e-3);
    Eigen::VectorXd nu = Eigen::VectorXd::Zero(n), g(nz), H(nz);
    const auto gradient = [&](const Eigen::VectorXd& zz, Eigen::VectorXd& gg, Eigen::VectorXd& hh) {
      for (int i = 0; i < m; ++i) {
        const double a = zz(i) - lo, b = umax(i) - zz(i);
        gg(i) = a - o_.restingTension - beta / a + beta / b;
        hh(i) = 1.0 + beta / (a * a) + beta / (b * b);
      }
      for (int j = m; j < nz; ++j) {
        gg(j) = eps * zz(j) - beta / zz(j);
        hh(j) = eps + beta / (zz(j) * zz(j));
      }
    };
    const auto kktNorm = [&](const Eigen::VectorXd& zz, const Eigen::VectorXd& vv) {
      Eigen::VectorXd gg(nz), hh(nz);
      gradient(zz, gg, hh);
      return std::sqrt((gg + G.transpose() * vv).squaredNorm() + (G * zz - d).squaredNorm());
    };
    const double gScale = std::max(1.0, G.cwiseAbs().maxCoeff());
    for (int it = 0; it < o_.maxIterations; ++it) {
      gradient(z, g, H);
      const Eigen::VectorXd rp = d - G * z;
      const Eigen::VectorXd rd = g + G.transpose() * nu;
      const double norm = std::sqrt(rd.squaredNorm() + rp.squaredNorm());
      // Converged: the equations at rounding level of their terms, the barrier's stationarity
      // to 1e-10 of its scale.
      if (rp.cwiseAbs().maxCoeff() <= 1e-12 * gScale * std::max(1.0, scaleTerms.maxCoeff()) &&
          rd.cwiseAbs().maxCoeff() <= 1e-9 * std::max(1.0, g.cwiseAbs().maxCoeff())) {
        iterations += it;
        Eigen::VectorXd u = z.head(m), lam = lambda(z);
        if (!computeImplicitDynamics(model_, data_, p.q, p.dq, p.qdd, u, lam, id_).ok()) return "the dynamics fail at the solution";
        const double terms = std::max({(data_.M * p.qdd).cwiseAbs().maxCoeff(), r0.cwiseAbs().maxCoeff(),
                                       (data_.inputMatrix * u).cwiseAbs().maxCoeff(),
                                       (data_.constraintJacobian.transpose() * lam).cwiseAbs().maxCoeff(), 1e-300});
        relativeResidual = id_.r.cwiseAbs().maxCoeff() / terms;
        if (!(relativeResidual <= 1e-10))
          return "the distribution's equations are not met (relative residual " + std::to_string(relativeResidual) + ")";
        return "";
      }
      // Newton: H Δz + Gᵀ Δν = −rd, G Δz = rp, by the Schur complement S = G H⁻¹ Gᵀ.
      const Eigen::VectorXd Hinv = H.cwiseInverse();
      const Eigen::MatrixXd S = G * Hinv.asDiagonal() * G.transpose();
      const Eigen::LDLT<Eigen::MatrixXd> ldlt(S);
      if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 1e-14 * ldlt.vectorD().maxCoeff())) {
        // G = [R_u, R_λ E] without full row rank: some generalized force neither the tendons nor
        // the contacts can produce (two pads leave the ball's spin about their common axis free).
        const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(G);
        return "the tendons and the contact forces span " + std::to_string(qr.rank()) + " of the " + std::to_string(n) +
               " generalized forces: the motion cannot be made by them in every direction";
      }
      const Eigen::VectorXd dnu = ldlt.solve(-rp - G * Hinv.cwiseProduct(rd));
      const Eigen::VectorXd dz = -Hinv.cwiseProduct(rd + G.transpose() * dnu);
      double alpha = 1.0;
      for (int i = 0; i < m; ++i) {
        if (dz(i) < 0.0) alpha = std::min(alpha, -0.99 * (z(i) - lo) / dz(i));
        if (dz(i) > 0.0) alpha = std::min(alpha, 0.99 * (umax(i) - z(i)) / dz(i));
      }
      for (int j = m; j < nz; ++j)
        if (dz(j) < 0.0) alpha = std::min(alpha, -0.99 * z(j) / dz(j));
      // Backtracking on the KKT residual (infeasible-start Newton).
      Eigen::VectorXd zn, nn;
      for (int ls = 0; ls < 40; ++ls) {
        zn = z + alpha * dz;
        nn = nu + alpha * dnu;
        if (kktNorm(zn, nn) <= (1.0 - 0.01 * alpha) * norm) break;
        alpha *= 0.5;
      }
      z = zn;
      nu = nn;
    }
    iterations += o_.maxIterations;
    return "no convergence in " + std::to_string(o_.maxIterations) + " Newton iterations (no interior point meets the "
           "equations: the contacts or the tensions cannot make this motion)";
  }

 private:
  const Model& model_;
  const BallLimits& limits_;
  const InverseReferenceOptions& o_;
  Data data_;
  ImplicitDynamics id_;
  Eigen::MatrixXd E_;
  Eigen::VectorXd lambda0_;
};

std::string where(int k, double t) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "knot %d (t = %.4g s)", k, t);
  return buf;
}

}  // namespace

InverseReference inverseDynamicsReference(const Model& model, const BallLimits& limits, const Trajectory& motion,
                                          const InverseReferenceOptions& options) {
  options.validate();
  motion.checkCompatible(model);
  if (motion.size() < 2) throw std::invalid_argument("inverseDynamicsReference: the motion has " + std::to_string(motion.size()) + " knots (needs >= 2)");
  if (model.nc() % 3 != 0 || limits.uMax.size() != model.nu())
    throw std::invalid_argument("inverseDynamicsReference: the scene's contacts (nc = " + std::to_string(model.nc()) +
                                ") or the limits' u_max do not match the model");
  const int n = model.nq(), m = model.nu(), nc = model.nc(), N = options.knots;
  InverseReference out;

  // Drivers: the complement of the pivots of A(q₀)'s column-pivoted QR.
  Data data(model);
  {
    const Eigen::VectorXd x0 = motion.states().col(0);
    if (!computeDynamics(model, data, x0.head(n), x0.tail(n), motion.inputs().col(0)).ok()) {
      out.message = "the dynamics fail at the motion's first knot";
      return out;
    }
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(data.constraintJacobian);
  if (qr.rank() != nc) {
    out.message = "the constraint Jacobian has rank " + std::to_string(qr.rank()) + " < " + std::to_string(nc);
    return out;
  }
  std::vector<int> dependent, drivers;
  std::vector<bool> isDependent(n, false);
  for (int j = 0; j < nc; ++j) isDependent[qr.colsPermutation().indices()(j)] = true;
  for (int j = 0; j < n; ++j) (isDependent[j] ? dependent : drivers).push_back(j);
  for (const int j : drivers) out.drivers.push_back(model.configNames()[j]);

  Design design(model, motion, drivers, dependent);
  Distribution dist(model, limits, options);
  const double t0 = motion.startTime(), T = motion.endTime() - t0;
  Eigen::VectorXd times(N);
  for (int k = 0; k < N; ++k) times(k) = t0 + T * k / (N - 1);
  times(N - 1) = motion.endTime();
  Eigen::MatrixXd states(2 * n, N), inputs(m, N), rates(m, N);
  out.lambda.resize(nc, N);
  Eigen::VectorXd z(dist.size());
  z.head(m) = motion.inputs().col(0);
  z.tail(dist.size() - m).setConstant(0.1);
  out.minNormal = 1e300;
  out.minTensionMargin = 1e300;
  out.minTension = 1e300;
  const auto distribute = [&](double t, Eigen::VectorXd& zz, int k, DesignPoint* keep) -> std::string {
    const DesignPoint p = design.at(t);
    if (!p.failure.empty()) return where(k, t) + ": " + p.failure;
    out.maxConstraintResidual = std::max(out.maxConstraintResidual, p.constraintResidual);
    double rel = 0.0;
    const std::string e = dist.solve(p, zz, rel, out.iterations);
    if (!e.empty()) return where(k, t) + ": " + e;
    out.maxRelativeResidual = std::max(out.maxRelativeResidual, rel);
    if (keep) *keep = p;
    return "";
  };
  for (int k = 0; k < N; ++k) {
    DesignPoint p;
    std::string e = distribute(times(k), z, k, &p);
    if (!e.empty()) {
      out.message = e;
      return out;
    }
    states.col(k) << p.q, p.dq;
    inputs.col(k) = z.head(m);
    out.lambda.col(k) = dist.lambda(z);
    const ContactMargins c = contactMargins(out.lambda.col(k), limits);
    out.minNormal = std::min(out.minNormal, c.minNormal);
    out.worstFrictionRatio = std::max(out.worstFrictionRatio, c.worstFrictionRatio);
    out.minTensionMargin = std::min(out.minTensionMargin, std::min(z.head(m).minCoeff(), (limits.uMax - z.head(m)).minCoeff()));
    out.minTension = std::min(out.minTension, z.head(m).minCoeff());
    if (options.rateStep > 0.0) {
      Eigen::VectorXd zp = z, zm = z;
      const double dt = options.rateStep;
      if (!(e = distribute(times(k) + dt, zp, k, nullptr)).empty() || !(e = distribute(times(k) - dt, zm, k, nullptr)).empty()) {
        out.message = "tension rate at " + e;
        return out;
      }
      rates.col(k) = (zp.head(m) - zm.head(m)) / (2.0 * dt);
    }
  }
  out.trajectory = Trajectory(model.configNames(), model.inputNames(), times, states, inputs);
  if (options.rateStep > 0.0) out.trajectory.setInputDerivatives(rates);
  out.ok = out.maxRelativeResidual <= 1e-10 && out.maxConstraintResidual <= 1e-10 &&
           out.minNormal >= limits.normalMin && out.worstFrictionRatio <= 1.0 && out.minTensionMargin > 0.0;
  if (!out.ok) out.message = "a limit is not kept at the knots (see the figures)";
  return out;
}

}  // namespace trellis::hand

