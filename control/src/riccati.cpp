// riccati.cpp — solveRiccati: the backward integration loop (steps stored for dense output,
// gain nodes, failure statuses, the factored→plain switch, the S ⪰ 0 check). The right-hand
// sides and their derivatives are in riccati_system.*, the integrator in ode_driver.*.
#include "trellis/control/riccati.hpp"

#include "trellis/analysis/detail/dense_kernels.hpp"
#include "trellis/analysis/detail/ode_driver.hpp"
#include "riccati_packing.hpp"
#include "riccati_system.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <vector>

namespace trellis {

namespace {

void checkProblem(double t0, double T, int nx, int nu, const LinearizationCallback& linearization,
                  const LqrWeights& weights) {
  if (!(t0 < T) || !std::isfinite(t0) || !std::isfinite(T)) {
    std::ostringstream m;
    m << "solveRiccati: need finite t0 < T, got t0 = " << t0 << ", T = " << T;
    throw std::invalid_argument(m.str());
  }
  if (nx <= 0 || nu < 0) {
    throw std::invalid_argument("solveRiccati: need nx > 0 and nu >= 0, got nx = " +
                                std::to_string(nx) + ", nu = " + std::to_string(nu));
  }
  if (!linearization) throw std::invalid_argument("solveRiccati: empty linearization callback");
  checkWeightMatrix(weights.Qf, "Qf", nx, false);
  for (double t : {t0, 0.5 * (t0 + T), T}) {
    Eigen::MatrixXd Q = weights.Q, R = weights.R;
    if (weights.Qfun) {
      Q.setZero(nx, nx);
      weights.Qfun(t, Q);
    }
    if (weights.Rfun) {
      R.setZero(nu, nu);
      weights.Rfun(t, R);
    }
    checkWeightMatrix(Q, weights.Qfun ? "Q(t)" : "Q", nx, false);
    checkWeightMatrix(R, weights.Rfun ? "R(t)" : "R", nu, true);
    if (!weights.Qfun && !weights.Rfun) break;
  }
}

// Linear solver and method. Measured on bench/riccati_bench (planar chain, 2 s, rtol 1e-6):
// see RiccatiLinearSolver::kAuto in the header for the rule and bench/README.md for the numbers.
// Above nx = 10 the plain form uses the direct Lyapunov solve (kLyapunov, 2026-12-01, 40 states,
// callgrind): 0.52e9 instructions per solve against 0.64e9 for GMRES with the same Lyapunov
// preconditioner (and 1.13e9 for that GMRES before the compiled N_Vector kernels), error of S
// 1.6e-6 against 1.2e-6 at rtol 1e-6: one O(nx³) solve per Newton iteration and no Jacobian
// products or Gram–Schmidt on N = nx(nx+1)/2 unknowns.
// Why Newton at all (measured 2026-12, 40 states): on the benchmark's blended chain, which is
// barely stiff, BDF with fixed-point iterations was cheaper than the GMRES solve of the time, but
// on the damped 20-link chain held hanging (`trellis gains`, Q = 10, R = 1) the equation is stiff:
// fixed point runs out of 100000 steps and Adams needs 5225 steps where BDF–Newton needs 814.
// The factored form keeps GMRES: its Newton matrix is not a Lyapunov operator.
detail::OdeOptions integratorOptions(const RiccatiOptions& options, int nx, bool factored,
                                     bool& usesLyapunov) {
  const bool bdf = options.method != RiccatiMethod::kAdams;
  RiccatiLinearSolver ls = options.linearSolver;
  if (ls == RiccatiLinearSolver::kAuto) {
    ls = nx <= 10 ? RiccatiLinearSolver::kDense
                  : (factored ? RiccatiLinearSolver::kKrylov : RiccatiLinearSolver::kLyapunov);
  }
  const detail::OdeLinearSolver solver =
      !bdf ? detail::OdeLinearSolver::FixedPoint
      : ls == RiccatiLinearSolver::kLyapunov ? detail::OdeLinearSolver::SystemSolve
      : ls == RiccatiLinearSolver::kKrylov   ? detail::OdeLinearSolver::Gmres
                                             : detail::OdeLinearSolver::Dense;
  detail::OdeOptions o = detail::makeOdeOptions(
      "Riccati equation (in reversed time tau = T - t)",
      bdf ? detail::OdeMethod::Bdf : detail::OdeMethod::Adams, solver, options.rtol, options.atol,
      options.maxSteps, options.maxStep);
  o.initialStep = options.initialStep;
  o.exactJacobian = options.exactJacobian;
  o.maxOrder = options.maxOrder;
  usesLyapunov = (o.linearSolver == detail::OdeLinearSolver::Gmres && options.krylovPreconditioner) ||
                 o.linearSolver == detail::OdeLinearSolver::SystemSolve;
  return o;
}

}  // namespace

RiccatiSolution solveRiccati(double t0, double T, int nx, int nu,
                             const LinearizationCallback& linearization, const LqrWeights& weights,
                             const RiccatiOptions& options) {
  options.validate();
  checkProblem(t0, T, nx, nu, linearization, weights);

  RiccatiSolution sol;
  sol.nx_ = nx;
  sol.nu_ = nu;
  sol.t0_ = t0;
  sol.tf_ = T;

  const Eigen::Index N = detail::packedSize(nx);
  const double tauEnd = T - t0;
  bool factored = options.method == RiccatiMethod::kFactored;
  detail::RiccatiSystem system(nx, nu, T, linearization, weights);
  system.factored = factored;
  bool usesLyapunov = false;
  const detail::OdeOptions odeOptions = integratorOptions(options, nx, factored, usesLyapunov);
  system.preconditioned = usesLyapunov;
  // As the linear solver the Lyapunov solve must be exact (no identity shortcut on mildly stiff
  // steps: an inexact Newton matrix costs Newton iterations and convergence failures).
  system.exactSolve = odeOptions.linearSolver == detail::OdeLinearSolver::SystemSolve;

  Eigen::VectorXd y0(N);
  if (factored) {
    // U(T) = chol(Qf + shift·I), upper triangular.
    Eigen::MatrixXd Qf = 0.5 * (weights.Qf + weights.Qf.transpose());
    Qf.diagonal().array() += options.factoredQfShift;
    Eigen::LLT<Eigen::MatrixXd> llt(Qf);
    const Eigen::MatrixXd U0 = llt.matrixU();
    if (llt.info() != Eigen::Success || !(U0.diagonal().array() > 0.0).all()) {
      const double lmin = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(
                              weights.Qf, Eigen::EigenvaluesOnly).eigenvalues()(0);
      std::ostringstream m;
      m << "solveRiccati: RiccatiMethod::kFactored needs Qf + factoredQfShift*I positive definite"
        << " (Qf's smallest eigenvalue is " << lmin << ", factoredQfShift = "
        << options.factoredQfShift << "); set RiccatiOptions.factoredQfShift > 0 to regularize";
      throw std::invalid_argument(m.str());
    }
    detail::packUpper(U0, nx, y0.data());
  } else {
    detail::packUpper(weights.Qf, nx, y0.data());
  }
  auto normOf = [&](const double* yk) {
    return factored ? detail::factorNorm(yk, nx) : detail::maxAbs(yk, N);
  };

  // The factored solve may switch to the plain form: a second driver then takes over (its
  // system offers the exact Jacobian the factored form lacks).
  auto driver = std::make_unique<detail::OdeDriver>(system, N, odeOptions);
  driver->start(0.0, y0);
  detail::OdeStats finishedStats;

  // S at a stored step (scratch reused), for the eigenvalue tracking and the S ⪰ 0 check.
  Eigen::MatrixXd Sk(nx, nx), Uk = Eigen::MatrixXd::Zero(nx, nx), Sshift(nx, nx);
  Eigen::VectorXd cholWork(nx);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(nx);
  sol.minEigenvalue = std::numeric_limits<double>::infinity();
  sol.maxEigenvalue = -std::numeric_limits<double>::infinity();
  const double psdEps = options.psdSlack * nx * options.rtol;
  double worstRatio = 0.0, worstTime = T;
  bool indefinite = false;
  auto inspect = [&](const double* yk, double t) {
    const bool check = options.checkPositiveSemidefinite && !factored;
    if (!options.trackEigenvalues && !check) return;
    if (factored) {
      detail::unpackUpper(yk, nx, Uk);
      Sk.noalias() = Uk.transpose() * Uk;
    } else {
      detail::unpackSymmetric(yk, nx, Sk);
    }
    bool haveEig = false;
    if (options.trackEigenvalues) {
      eig.compute(Sk, Eigen::EigenvaluesOnly);
      haveEig = true;
      sol.minEigenvalue = std::min(sol.minEigenvalue, eig.eigenvalues()(0));
      sol.maxEigenvalue = std::max(sol.maxEigenvalue, eig.eigenvalues()(nx - 1));
    }
    if (!check) return;
    // λmin ≥ −ε·λmax passes when S + ε·max_i S_ii·I has a Cholesky factor (max_i S_ii ≤ λmax);
    // only a failure needs the eigenvalues to decide and to say by how much.
    const double scale = Sk.diagonal().maxCoeff();
    Sshift = Sk;
    Sshift.diagonal().array() += psdEps * std::max(scale, 0.0);
    if (detail::choleskyUpper(Sshift.data(), nx, nx, cholWork.data())) return;
    if (!haveEig) eig.compute(Sk, Eigen::EigenvaluesOnly);
    const double lmin = eig.eigenvalues()(0), lmax = eig.eigenvalues()(nx - 1);
    const double ratio = lmax > 0.0 ? lmin / lmax : -std::numeric_limits<double>::infinity();
    if (lmin < -psdEps * std::max(lmax, 0.0) && (!indefinite || ratio < worstRatio)) {
      indefinite = true;
      worstRatio = ratio;
      worstTime = t;
    }
  };
  // Every stored step polynomial, counting the leading ones that hold the factor U.
  auto store = [&](double tauEnd, Eigen::MatrixXd D) {
    sol.steps_.append(tauEnd, std::move(D));
    if (factored) ++sol.factoredSteps_;
  };
  store(0.0, y0);  // τ = 0: S = Qf (a constant "polynomial")
  inspect(y0.data(), T);

  // G = R⁻¹Bᵀ at a node, so that K(t) needs neither the model nor the callbacks later. The
  // step end's coefficients are usually still cached from the step's last Newton iteration.
  auto storeGain = [&](double t) {
    if (!system.coefficientsAt(t)) return false;
    sol.gainTimes_.push_back(t);
    sol.gainNodes_.push_back(system.gain());
    return true;
  };
  auto gainFailure = [&](double t) {
    sol.status.code = RiccatiCode::kCallbackFailure;
    sol.status.t = t;
    sol.status.message = "Riccati solve stopped: " + system.failMessage;
  };
  if (!storeGain(T)) {
    gainFailure(T);
    sol.status.message = "Riccati solve: " + system.failMessage;
    return sol;
  }

  double tau = 0.0;
  double lastNorm = normOf(y0.data());
  long taken = 0;
  while (tau < tauEnd) {
    // The step budget is over the whole horizon (both drivers of a switched solve).
    if (++taken > options.maxSteps) {
      sol.status.code = RiccatiCode::kIntegratorFailure;
      sol.status.t = T - tau;
      sol.failureNorm = lastNorm;
      std::ostringstream m;
      m << "Riccati solve stopped at t = " << sol.status.t << " (max |S_ij| = " << lastNorm
        << "): more than maxSteps = " << options.maxSteps << " steps (too much work)";
      sol.status.message = m.str();
      break;
    }
    const detail::OdeStatus st = driver->step(tauEnd);
    if (!st.ok()) {
      // A failed callback names its own time (a trial point inside the step that failed);
      // otherwise the integrator's current time, the last point it reached.
      sol.status.t = system.failed ? system.failTime : T - st.t;
      sol.failureNorm = lastNorm;
      sol.status.code = system.failed ? system.failStatus : RiccatiCode::kIntegratorFailure;
      std::ostringstream m;
      m << "Riccati solve stopped at t = " << sol.status.t << " (max |S_ij| = " << lastNorm
        << " at the last accepted step): ";
      if (system.failed) m << system.failMessage << "; ";
      m << st.message;
      sol.status.message = m.str();
      break;
    }
    tau = st.t;
    const int q = driver->lastOrder();
    Eigen::MatrixXd D(N, q + 1);
    for (int k = 0; k <= q; ++k) {
      if (!driver->interpolate(tau, k, D.col(k))) {
        D.conservativeResize(N, k);
        break;
      }
    }
    const double* y = driver->state().data();
    const double norm = normOf(y);
    if (!std::isfinite(norm) || !D.allFinite()) {
      sol.status.code = RiccatiCode::kNonFinite;
      sol.status.t = T - tau;
      sol.failureNorm = lastNorm;
      std::ostringstream m;
      m << "S became non-finite at t = " << sol.status.t << " (max |S_ij| = " << lastNorm
        << " at the previous step)";
      sol.status.message = m.str();
      break;
    }
    const double tauPrev = sol.steps_.back();
    // Step end first: its coefficients are cached from the step's last Newton iteration.
    if (!storeGain(T - tau) || !storeGain(T - 0.5 * (tauPrev + tau))) {
      gainFailure(T - tau);
      sol.failureNorm = lastNorm;
      sol.gainTimes_.resize(2 * sol.steps_.size() - 1);
      sol.gainNodes_.resize(2 * sol.steps_.size() - 1);
      break;
    }
    // Keep the nodes in descending t (reversed at the end): midpoint before the step end.
    std::iter_swap(sol.gainTimes_.end() - 1, sol.gainTimes_.end() - 2);
    std::iter_swap(sol.gainNodes_.end() - 1, sol.gainNodes_.end() - 2);
    store(tau, std::move(D));
    inspect(y, T - tau);
    if (norm > options.maxNorm) {
      sol.status.code = RiccatiCode::kBlowUp;
      sol.status.t = T - tau;
      sol.failureNorm = norm;
      std::ostringstream m;
      m << "S blew up at t = " << sol.status.t << ": max |S_ij| = " << norm
        << " > maxNorm = " << options.maxNorm;
      sol.status.message = m.str();
      break;
    }
    lastNorm = norm;
    if (tau >= tauEnd) break;
    // Factored form near a singular S: U⁻¹ amplifies the integration error of U's small diagonal
    // entries, the problem turns stiff in U although S itself is smooth (thousands of steps, or
    // too much work). Past cond(S) = (max U_ii / min U_ii)² > factoredSwitchCondition the rest of
    // the horizon is integrated in the plain form on S = UᵀU (see the header).
    if (factored && options.factoredSwitchCondition > 0.0) {
      detail::unpackUpper(y, nx, Uk);
      const Eigen::ArrayXd d = Uk.diagonal().array().abs();
      const double ratio = d.minCoeff() / d.maxCoeff();
      if (!(ratio * ratio * options.factoredSwitchCondition > 1.0)) {
        Sk.noalias() = Uk.transpose() * Uk;
        detail::packUpper(Sk, nx, y0.data());
        factored = false;
        system.factored = false;
        sol.switchedToPlainAt = T - tau;
        const detail::OdeStats s = driver->stats();
        finishedStats.steps += s.steps;
        finishedStats.rhsEvaluations += s.rhsEvaluations + s.linearRhsEvaluations;
        finishedStats.jacobianEvaluations += s.jacobianEvaluations;
        finishedStats.linearIterations += s.linearIterations;
        finishedStats.preconditionerSolves += s.preconditionerSolves;
        finishedStats.nonlinearIterations += s.nonlinearIterations;
        finishedStats.linearSolverSetups += s.linearSolverSetups;
        finishedStats.errorTestFailures += s.errorTestFailures;
        finishedStats.nonlinearFailures += s.nonlinearFailures;
        driver = std::make_unique<detail::OdeDriver>(system, N, odeOptions);
        driver->start(tau, y0);
        lastNorm = normOf(y0.data());
      }
    }
  }
  const detail::OdeStats s = driver->stats();
  sol.steps = finishedStats.steps + s.steps;
  sol.rhsEvaluations = finishedStats.rhsEvaluations + s.rhsEvaluations + s.linearRhsEvaluations;
  sol.jacobianEvaluations = finishedStats.jacobianEvaluations + s.jacobianEvaluations;
  sol.linearIterations = finishedStats.linearIterations + s.linearIterations;
  sol.preconditionerSolves = finishedStats.preconditionerSolves + s.preconditionerSolves;
  sol.newtonIterations = finishedStats.nonlinearIterations + s.nonlinearIterations;
  sol.linearSolverSetups = finishedStats.linearSolverSetups + s.linearSolverSetups;
  sol.errorTestFailures = finishedStats.errorTestFailures + s.errorTestFailures;
  sol.convergenceFailures = finishedStats.nonlinearFailures + s.nonlinearFailures;
  sol.schurFactorizations = system.schurFactorizations();
  sol.linearizations = system.linearizations();
  if (!options.trackEigenvalues) sol.minEigenvalue = sol.maxEigenvalue = 0.0;
  if (sol.ok() && indefinite) {
    sol.status.code = RiccatiCode::kIndefinite;
    sol.status.t = worstTime;
    sol.indefiniteRatio = worstRatio;
    std::ostringstream m;
    m << "S is indefinite at t = " << worstTime << ": smallest/largest eigenvalue = "
      << worstRatio << " < -" << psdEps << " (the slack psdSlack*nx*rtol = " << options.psdSlack
      << "*" << nx << "*" << options.rtol
      << "); the tolerances are too loose for this problem or Q(t) is indefinite";
    sol.status.message = m.str();
  }
  std::reverse(sol.gainTimes_.begin(), sol.gainTimes_.end());
  std::reverse(sol.gainNodes_.begin(), sol.gainNodes_.end());
  if ((sol.status.code == RiccatiCode::kBlowUp || sol.status.code == RiccatiCode::kNonFinite) &&
      options.maxOrder == 0 && options.method != RiccatiMethod::kAdams) {
    // Growth past maxNorm at BDF order up to 5 may be the integrator's (see RiccatiOptions::
    // maxOrder): redone at order ≤ 2, where it is not. If that solve fails too, the failure is
    // S's own and the first solve's report stands (its figures are the more accurate ones).
    RiccatiOptions low = options;
    low.maxOrder = 2;
    RiccatiSolution retry = solveRiccati(t0, T, nx, nu, linearization, weights, low);
    if (retry.ok()) {
      retry.lowOrderRetry = true;
      retry.firstAttempt = sol.status.describe();
      return retry;
    }
    sol.status.message += "; confirmed at BDF order <= 2: " + retry.status.message;
  }
  return sol;
}

}  // namespace trellis
