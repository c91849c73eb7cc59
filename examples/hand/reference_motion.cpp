// reference_motion.cpp — designed motion on the hand's constraint manifold and its tensions.
#include "reference_motion.hpp"

#include <trellis/core/dynamics.hpp>
#include <trellis/core/linearization.hpp>
#include <trellis/core/projection.hpp>

#include <Eigen/QR>
#include <Eigen/LU>
#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace trellis::hand {

NnlsResult solveNonNegativeLeastSquares(const Eigen::MatrixXd& C, const Eigen::VectorXd& d,
                                        int maxIterations, double tolerance) {
  const Eigen::Index rows = C.rows(), k = C.cols();
  if (d.size() != rows) {
    throw std::invalid_argument("solveNonNegativeLeastSquares: C has " + std::to_string(rows) +
                                " rows but d has " + std::to_string(d.size()));
  }
  if (!C.allFinite() || !d.allFinite()) {
    throw std::invalid_argument("solveNonNegativeLeastSquares: C or d has a non-finite entry");
  }
  if (maxIterations <= 0) maxIterations = static_cast<int>(3 * std::max<Eigen::Index>(k, 1));
  NnlsResult r;
  r.x = Eigen::VectorXd::Zero(k);
  // isFree[j]: j is in the passive set P (unconstrained), otherwise held at its bound x_j = 0.
  std::vector<bool> isFree(static_cast<std::size_t>(k), false);
  // Tolerance on the multipliers w = Cᵀ(d − Cx): rounding of Cᵀ d is ~eps ‖C‖ ‖d‖ per entry.
  const double tol = tolerance > 0.0 ? tolerance
                                     : 10.0 * std::numeric_limits<double>::epsilon() *
                                           static_cast<double>(k) * C.norm() * std::max(1.0, d.norm());
  Eigen::VectorXd w = C.transpose() * (d - C * r.x);
  Eigen::VectorXd z(k);
  while (r.iterations < maxIterations) {
    // Lawson–Hanson step 1: the bound variable with the largest positive multiplier is freed.
    Eigen::Index t = -1;
    double best = tol;
    for (Eigen::Index j = 0; j < k; ++j) {
      if (!isFree[j] && w(j) > best) best = w(j), t = j;
    }
    if (t < 0) {
      r.converged = true;
      break;
    }
    ++r.iterations;
    isFree[t] = true;
    for (int inner = 0; inner <= 3 * k; ++inner) {
      // Least squares on the free columns; the bound ones stay at 0.
      std::vector<Eigen::Index> cols;
      for (Eigen::Index j = 0; j < k; ++j)
        if (isFree[j]) cols.push_back(j);
      Eigen::MatrixXd Cp(rows, static_cast<Eigen::Index>(cols.size()));
      for (std::size_t c = 0; c < cols.size(); ++c) Cp.col(static_cast<Eigen::Index>(c)) = C.col(cols[c]);
      const Eigen::VectorXd zp = Cp.colPivHouseholderQr().solve(d);
      z.setZero();
      for (std::size_t c = 0; c < cols.size(); ++c) z(cols[c]) = zp(static_cast<Eigen::Index>(c));
      bool feasible = true;
      for (Eigen::Index j : cols) feasible = feasible && z(j) > 0.0;
      if (feasible) {
        r.x = z;
        break;
      }
      // Step 3: move from x towards z until the first free variable reaches its bound, and bind
      // every free variable that is (numerically) at zero.
      double alpha = 1.0;
      for (Eigen::Index j : cols) {
        if (z(j) <= 0.0) alpha = std::min(alpha, r.x(j) / (r.x(j) - z(j)));
      }
      r.x += alpha * (z - r.x);
      for (Eigen::Index j : cols) {
        if (r.x(j) <= 1e-15 * std::max(1.0, r.x.cwiseAbs().maxCoeff())) {
          r.x(j) = 0.0;
          isFree[j] = false;
        }
      }
    }
    w = C.transpose() * (d - C * r.x);
  }
  r.residualNorm = (C * r.x - d).norm();
  return r;
}

TensionDistribution distributeTensions(const Model& model, Data& data, const Eigen::VectorXd& q,
                                       const Eigen::VectorXd& dq, const Eigen::VectorXd& qdd,
                                       const TensionDistributionOptions& options) {
  const int n = model.nq(), m = model.nu(), nc = model.nc();
  if (qdd.size() != n) {
    throw std::invalid_argument("distributeTensions: qdd has " + std::to_string(qdd.size()) +
                                " entries, the model " + std::to_string(n));
  }
  TensionDistribution out;
  out.tension = Eigen::VectorXd::Zero(m);
  out.lambda = Eigen::VectorXd::Zero(nc);
  // M, b(q, q̇) with u = 0 (all forces but the tendons), A, from one dynamics evaluation.
  const DynamicsStatus st = computeDynamics(model, data, q, dq, Eigen::VectorXd::Zero(m));
  if (!st.ok()) {
    out.message = "dynamics failed: " + st.message;
    return out;
  }
  const Eigen::VectorXd rhs = data.M * qdd + data.bias;  // r = M q̈ + b
  const Eigen::MatrixXd At = data.constraintJacobian.transpose();  // n×nc
  computeInputMatrix(model, data, q);
  const Eigen::MatrixXd& B = data.inputMatrix;  // n×m

  // Orthonormal null-space basis N of A: the last n − rank columns of the full Q of Aᵀ's QR.
  Eigen::MatrixXd N;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qrAt(At);
  if (nc > 0) {
    const Eigen::Index rank = qrAt.rank();
    const Eigen::MatrixXd Q = qrAt.householderQ() * Eigen::MatrixXd::Identity(n, n);
    N = Q.rightCols(n - rank);
  } else {
    N = Eigen::MatrixXd::Identity(n, n);
  }
  const Eigen::MatrixXd C = N.transpose() * B;  // p×m, the tangential equations C u = d
  const Eigen::VectorXd d = N.transpose() * rhs;
  const double mu = options.barrier, rest = options.restingTension;
  const Eigen::Index p = C.rows();
  const double eps = std::numeric_limits<double>::epsilon();
  // min f(u) = ½‖u − u_rest‖² − μ Σ ln u  s.t.  C u = d  (∇f = u − u_rest − μ/u, ∇²f = H =
  // diag(1 + μ/u²)). Newton's step from u with C u = c toward C u = e solves
  //   [H Cᵀ; C 0] [Δu; ν] = −[∇f; c − e]   by the Schur complement S = C H⁻¹ Cᵀ (p×p, SPD when C
  // has full row rank): S ν = (c − e) − C H⁻¹ ∇f,  Δu = −H⁻¹ (∇f + Cᵀ ν).
  // Globalization by homotopy in the right-hand side: along e(s) = (1 − s) C u₀ + s d (u₀ = u_rest,
  // feasible for s = 0) every e(s) has the strictly positive solution (1 − s) u₀ + s u* whenever
  // some u* ≥ 0 meets C u* = d, so the path stays inside u > 0; each increase of s is taken by one
  // full Newton step that must keep u > 0 (else s advances by less), then feasible Newton
  // iterations with backtracking on f — convergent for this strictly convex barrier function.
  Eigen::VectorXd u = Eigen::VectorXd::Constant(m, rest > 0.0 ? rest : 1.0);
  Eigen::VectorXd grad(m), Hinv(m), du(m), nu(p), trial(m);
  Eigen::MatrixXd CHinv(p, m);
  Eigen::LDLT<Eigen::MatrixXd> schur(p);
  auto objective = [&](const Eigen::VectorXd& v) {
    return 0.5 * (v.array() - rest).matrix().squaredNorm() - mu * v.array().log().sum();
  };
  // Newton step at u for the residual r = C u − e; false when S is singular or the step not finite.
  auto newtonStep = [&](const Eigen::VectorXd& r) {
    grad = (u.array() - rest - mu / u.array()).matrix();
    Hinv = (1.0 + mu / u.array().square()).inverse().matrix();
    CHinv = C * Hinv.asDiagonal();
    schur.compute(CHinv * C.transpose());
    if (schur.info() != Eigen::Success) return false;
    nu = schur.solve(r - CHinv * grad);
    du = -Hinv.cwiseProduct(grad + C.transpose() * nu);
    return du.allFinite() && nu.allFinite();
  };
  // The largest step α ≤ 1 along du that keeps u ≥ (1 − fraction) u (fraction to the boundary).
  auto stepToBoundary = [&](double fraction) {
    double alpha = 1.0;
    for (int i = 0; i < m; ++i)
      if (du(i) < 0.0) alpha = std::min(alpha, -fraction * u(i) / du(i));
    return alpha;
  };
  // Size of the terms of the dual residual ∇f + Cᵀν (its rounding level is eps times this).
  auto dualTermScale = [&] { return (u.array().abs() + std::abs(rest) + mu / u.array()).maxCoeff(); };
  const Eigen::VectorXd cStart = C * u;
  double s = 0.0, ds = 1.0;
  bool converged = false, failed = false;
  out.iterations = 0;
  while (!failed && out.iterations < options.maxIterations) {
    // Advance the homotopy: the Newton step toward e(s + ds), damped to stay inside u > 0. By
    // linearity a fraction α of it lands exactly on e(s + α ds), so every step makes progress.
    if (s < 1.0) {
      const double sNext = std::min(1.0, s + ds);
      ++out.iterations;
      if (!newtonStep(C * u - ((1.0 - sNext) * cStart + sNext * d))) {
        failed = true;
        break;
      }
      const double alpha = stepToBoundary(0.9);
      u += alpha * du;
      s = alpha == 1.0 ? sNext : s + alpha * (sNext - s);
      ds = alpha == 1.0 ? 2.0 * ds : std::max(alpha * ds, 1e-3);
    }
    // Centering: feasible Newton for e(s) with backtracking on f, to δ² ≤ 0.01 on the way (close
    // enough to the path for the next full step) and to rounding level at s = 1.
    const Eigen::VectorXd target = (1.0 - s) * cStart + s * d;
    int smallSteps = 0;
    while (out.iterations < options.maxIterations) {
      ++out.iterations;
      if (!newtonStep(C * u - target)) {
        failed = true;
        break;
      }
      const double decrement = du.dot(du.cwiseQuotient(Hinv));
      const double scale = dualTermScale();
      if (s < 1.0 && decrement <= 1e-2) break;
      if (decrement <= 16.0 * eps * eps * scale * scale) break;  // dual residual at rounding level
      double alpha = stepToBoundary(0.99);
      if (alpha == 1.0 && decrement < 1e-8) {
        // Quadratic-convergence region (δ ≪ 1 for a self-concordant f): the full step, without a
        // line search whose decrease δ²/4 would be below the rounding of f itself.
        trial = u + du;
        if (++smallSteps > 8) break;  // rounding floor reached
      } else {
        const double f0 = objective(u);
        while (alpha > 1e-12) {
          trial = u + alpha * du;
          if (objective(trial) <= f0 - 0.25 * alpha * decrement) break;
          alpha *= 0.5;
        }
        if (!(alpha > 1e-12)) break;  // no decrease left
      }
      u = trial;
    }
    if (s >= 1.0) {
      converged = true;
      break;
    }
  }
  // Verify, independently of how the loop ended: at the final u the Newton system's best ν leaves
  // the dual residual ∇f + Cᵀν = −H Δu, and the primal residual C u − d; both at the rounding
  // level of their own terms.
  const Eigen::VectorXd rp = C * u - d;
  double primal = rp.cwiseAbs().maxCoeff(), dual = std::numeric_limits<double>::infinity();
  if (newtonStep(rp)) dual = du.cwiseQuotient(Hinv).cwiseAbs().maxCoeff();
  const double primalScale = (C.size() ? C.cwiseAbs().rowwise().sum().maxCoeff() : 0.0) * u.cwiseAbs().maxCoeff() +
                             d.cwiseAbs().maxCoeff();
  const double dualScale = dualTermScale();
  converged = converged && !failed && primal <= 1e3 * eps * primalScale && dual <= 1e3 * eps * dualScale &&
              u.minCoeff() > 0.0;
  out.tension = u;
  if (!converged) {
    std::ostringstream msg;
    msg << "interior-point tension distribution did not converge in " << out.iterations
        << " Newton iterations (homotopy at s = " << s << " of 1, tangential residual " << primal
        << " against " << primalScale << ", dual residual " << dual << " against " << dualScale
        << ", smallest tension " << u.minCoeff() << " N)";
    // Is there any u ≥ 0 with C u = d at all? Non-negative least squares says how close one gets.
    const NnlsResult nnls = solveNonNegativeLeastSquares(C, d);
    msg << "; the best non-negative tensions leave a tangential residual " << nnls.residualNorm
        << " against ‖d‖ = " << d.norm();
    out.message = msg.str();
  }
  const Eigen::VectorXd normal = rhs - B * out.tension;
  if (nc > 0) out.lambda = qrAt.solve(normal);
  const Eigen::VectorXd residual = B * out.tension + At * out.lambda - rhs;
  out.residual = residual.cwiseAbs().maxCoeff();
  const double scale = std::max({rhs.cwiseAbs().maxCoeff(),
                                 B.cwiseAbs().maxCoeff() * out.tension.cwiseAbs().maxCoeff(), 1e-300});
  out.relativeResidual = out.residual / scale;
  out.converged = out.message.empty();
  return out;
}

namespace {

/// h(q) = 0 by Newton over the coordinates not in `drivers` (core projectState with the drivers
/// fixed: the free coordinates are as many as the constraint rows, so its closest-point step is
/// the Newton step). q is updated in place; returns the final ‖h(q)‖∞.
double projectWithDriversFixed(const Model& model, Data& data, Eigen::VectorXd& q,
                              const std::vector<int>& drivers) {
  ProjectionOptions options;
  options.fixed = drivers;
  options.velocities = false;
  options.tolerance = 1e-14;
  options.stepTolerance = std::numeric_limits<double>::infinity();  // feasibility only
  const ProjectionResult projected = projectState(model, data, q, Eigen::VectorXd::Zero(model.nq()), options);
  q = projected.q;
  return projected.positionResidual;
}

}  // namespace

namespace {

std::string knotLabel(int k, double t) {
  std::ostringstream s;
  s << "knot " << k << " (t = " << t << " s)";
  return s.str();
}

}  // namespace

ReferenceMotion makeReferenceMotion(const Model& model, const Eigen::VectorXd& q0,
                                    const ReferenceMotionOptions& options) {
  const int n = model.nq(), m = model.nu(), nc = model.nc(), N = options.knots;
  if (q0.size() != n) {
    throw std::invalid_argument("makeReferenceMotion: q0 has " + std::to_string(q0.size()) +
                                " entries, the model " + std::to_string(n));
  }
  if (N < 2 || !(options.duration > 0.0)) {
    throw std::invalid_argument("makeReferenceMotion: need knots >= 2 and duration > 0, got knots " +
                                std::to_string(N) + ", duration " + std::to_string(options.duration));
  }
  if (options.drivers.size() != options.amplitudes.size()) {
    throw std::invalid_argument("makeReferenceMotion: " + std::to_string(options.drivers.size()) +
                                " drivers but " + std::to_string(options.amplitudes.size()) +
                                " amplitudes");
  }
  if (!(options.rateStep > 0.0) || !std::isfinite(options.rateStep)) {
    throw std::invalid_argument("makeReferenceMotion: rateStep must be > 0 and finite, got " +
                                std::to_string(options.rateStep));
  }
  std::vector<int> drivers;
  for (const std::string& name : options.drivers) {
    try {
      drivers.push_back(model.configIndex(name));
    } catch (const std::out_of_range&) {
      throw std::invalid_argument("makeReferenceMotion: unknown driver coordinate '" + name + "'");
    }
  }
  std::vector<int> others;
  for (int i = 0; i < n; ++i)
    if (std::find(drivers.begin(), drivers.end(), i) == drivers.end()) others.push_back(i);
  const int p = static_cast<int>(drivers.size());

  Data data(model);
  ReferenceMotion out;
  Eigen::VectorXd times(N);
  Eigen::MatrixXd states(2 * n, N), inputs(m, N), derivatives(2 * n, N);
  out.accelerations.resize(n, N);
  out.lambda.resize(nc, N);
  out.constraintResidual.resize(N);
  out.velocityResidual.resize(N);
  out.accelerationResidual.resize(N);
  out.dynamicsResidual.resize(N);
  out.forwardDynamicsError.resize(N);
  out.inputRates.resize(m, N);
  out.rateCorrection.resize(N);
  out.rateDifferenceEstimate.resize(N);
  out.rateResidual.resize(N);
  out.ok = true;
  auto fail = [&](const std::string& what) {
    if (out.ok) out.message = what;
    out.ok = false;
  };

  Eigen::VectorXd qStart = q0;
  projectWithDriversFixed(model, data, qStart, drivers);
  const double T = options.duration, w = 2.0 * std::numbers::pi / T;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);

  // The design at time t: drivers a_i (1 − cos ωt)/2 about their start values, the others by
  // Newton from q (the caller's guess, updated in place), q̇ and q̈ on the manifold, the tensions.
  struct Design {
    Eigen::VectorXd dq, qdd;
    TensionDistribution tensions;
    double constraintResidual = 0.0, velocityResidual = 0.0, accelerationResidual = 0.0;
    std::string failure;  // empty when the design is valid
  };
  auto design = [&](double t, Eigen::VectorXd& q) {
    Design d;
    d.dq.resize(n);
    d.qdd.resize(n);
    Eigen::VectorXd dqd(p), ddqd(p);
    for (int i = 0; i < p; ++i) {
      const double a = options.amplitudes[static_cast<std::size_t>(i)];
      q(drivers[i]) = qStart(drivers[i]) + 0.5 * a * (1.0 - std::cos(w * t));
      dqd(i) = 0.5 * a * w * std::sin(w * t);
      ddqd(i) = 0.5 * a * w * w * std::cos(w * t);
    }
    d.constraintResidual = projectWithDriversFixed(model, data, q, drivers);
    computeConstraints(model, data, q, zero);
    Eigen::MatrixXd Ao(nc, static_cast<Eigen::Index>(others.size())), Ad(nc, p);
    for (std::size_t c = 0; c < others.size(); ++c)
      Ao.col(static_cast<Eigen::Index>(c)) = data.constraintJacobian.col(others[c]);
    for (int i = 0; i < p; ++i) Ad.col(i) = data.constraintJacobian.col(drivers[i]);
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qrAo(Ao);
    if (qrAo.rank() < static_cast<Eigen::Index>(others.size())) {
      d.failure = "∂h/∂q_others is singular (the drivers do not parameterize the manifold here)";
    }
    const Eigen::VectorXd dqo = qrAo.solve(-Ad * dqd);
    for (int i = 0; i < p; ++i) d.dq(drivers[i]) = dqd(i);
    for (std::size_t c = 0; c < others.size(); ++c) d.dq(others[c]) = dqo(static_cast<Eigen::Index>(c));
    computeConstraints(model, data, q, d.dq);  // Ȧ q̇ at the final q̇
    const Eigen::VectorXd ddqo = qrAo.solve(-Ad * ddqd - data.constraintDrift);
    for (int i = 0; i < p; ++i) d.qdd(drivers[i]) = ddqd(i);
    for (std::size_t c = 0; c < others.size(); ++c) d.qdd(others[c]) = ddqo(static_cast<Eigen::Index>(c));
    d.velocityResidual = nc ? (data.constraintJacobian * d.dq).cwiseAbs().maxCoeff() : 0.0;
    d.accelerationResidual =
        nc ? (data.constraintJacobian * d.qdd + data.constraintDrift).cwiseAbs().maxCoeff() : 0.0;
    if (d.failure.empty() && !(d.constraintResidual < 1e-10)) {
      d.failure = "Newton on h(q) = 0 stopped at ‖h‖∞ = " + std::to_string(d.constraintResidual);
    }
    d.tensions = distributeTensions(model, data, q, d.dq, d.qdd, options.tensions);
    if (d.failure.empty() && !d.tensions.converged) d.failure = "tension distribution: " + d.tensions.message;
    return d;
  };

  // u̇_fd by the central quotient with step h from the designs at t ± h (Newton starts at q).
  auto rateQuotient = [&](double t, const Eigen::VectorXd& q, double h, std::string& failure) {
    Eigen::VectorXd qm = q, qp = q;
    const Design minus = design(t - h, qm), plus = design(t + h, qp);
    if (!minus.failure.empty()) failure = "the design at t - " + std::to_string(h) + ": " + minus.failure;
    if (!plus.failure.empty()) failure = "the design at t + " + std::to_string(h) + ": " + plus.failure;
    const Eigen::VectorXd rate = (plus.tensions.tension - minus.tensions.tension) / (2.0 * h);
    return rate;
  };

  Eigen::VectorXd q = qStart;
  for (int k = 0; k < N; ++k) {
    const double t = T * k / (N - 1);
    times(k) = t;
    // q from the previous knot is the Newton start: the path is continuous.
    const Design d = design(t, q);
    if (!d.failure.empty()) fail(knotLabel(k, t) + ": " + d.failure);
    out.constraintResidual(k) = d.constraintResidual;
    out.velocityResidual(k) = d.velocityResidual;
    out.accelerationResidual(k) = d.accelerationResidual;
    const TensionDistribution& td = d.tensions;
    out.dynamicsResidual(k) = td.relativeResidual;
    const DynamicsStatus st = computeDynamics(model, data, q, d.dq, td.tension);
    if (!st.ok()) fail(knotLabel(k, t) + ": forward dynamics: " + st.message);
    out.forwardDynamicsError(k) = (data.qdd - d.qdd).cwiseAbs().maxCoeff();

    // The tensions' rate (header comment): the quotient, then the exact correction.
    std::string rateFailure;
    const Eigen::VectorXd rateFd = rateQuotient(t, q, options.rateStep, rateFailure);
    const Eigen::VectorXd rateFd2 = rateQuotient(t, q, 2.0 * options.rateStep, rateFailure);
    if (!rateFailure.empty()) fail(knotLabel(k, t) + ": input rate: " + rateFailure);
    out.rateDifferenceEstimate(k) = (rateFd - rateFd2).cwiseAbs().maxCoeff();
    const DynamicsStatus lin = computeLinearization(model, data, q, d.dq, td.tension);
    if (!lin.ok()) fail(knotLabel(k, t) + ": linearization: " + lin.message);
    Eigen::VectorXd xdot(2 * n);
    xdot << d.dq, d.qdd;
    // Every tension is > 0 (interior point), so every tendon may take part in the correction.
    Eigen::MatrixXd S(p, m);
    Eigen::VectorXd g(p);
    for (int r = 0; r < p; ++r) {
      const int row = n + drivers[r];
      const double a = options.amplitudes[static_cast<std::size_t>(r)];
      const double jerk = -0.5 * a * w * w * w * std::sin(w * t);  // q⃛ of driver r
      g(r) = jerk - data.A.row(row).dot(xdot);
      S.row(r) = data.B.row(row);
    }
    const Eigen::VectorXd rate = rateFd + S.completeOrthogonalDecomposition().solve(g - S * rateFd);
    out.rateCorrection(k) = (rate - rateFd).cwiseAbs().maxCoeff();
    Eigen::VectorXd residual = -g;
    for (int r = 0; r < p; ++r) residual(r) += data.B.row(n + drivers[r]).dot(rate);
    out.rateResidual(k) = residual.cwiseAbs().maxCoeff() / std::max(g.cwiseAbs().maxCoeff(), 1e-300);

    states.col(k) << q, d.dq;
    inputs.col(k) = td.tension;
    derivatives.col(k) << d.dq, d.qdd;
    out.inputRates.col(k) = rate;
    out.accelerations.col(k) = d.qdd;
    out.lambda.col(k) = td.lambda;
  }
  out.trajectory = Trajectory(model.configNames(), model.inputNames(), times, states, inputs);
  out.trajectory.setStateDerivatives(derivatives);
  if (options.inputRates) out.trajectory.setInputDerivatives(out.inputRates);
  return out;
}

}  // namespace trellis::hand
