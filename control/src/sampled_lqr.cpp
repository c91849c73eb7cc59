// sampled_lqr.cpp — exact discretization of a time-varying linearization over sample intervals
// (variational equation + cost quadrature, integrated by OdeDriver) and the discrete Riccati recursion with the
// cross term. See sampled_lqr.hpp for the math.
#include "trellis/control/sampled_lqr.hpp"

#include "trellis/analysis/detail/ode_driver.hpp"
#include "trellis/core/detail/report_json.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis {

void SampledDiscretizationOptions::validate() const {
  auto bad = [](const char* field, double v) {
    std::ostringstream m;
    m << "SampledDiscretizationOptions." << field << " = " << v << " is invalid (must be > 0)";
    throw std::invalid_argument(m.str());
  };
  if (!(rtol > 0.0) || !std::isfinite(rtol)) bad("rtol", rtol);
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol);
  if (maxSteps <= 0) bad("maxSteps", static_cast<double>(maxSteps));
}

Eigen::VectorXd sampleTimes(double t0, double T, double rate) {
  if (!(rate > 0.0) || !std::isfinite(rate)) {
    throw std::invalid_argument("sampleTimes: the rate must be finite and > 0, got " + std::to_string(rate));
  }
  if (!(t0 < T) || !std::isfinite(t0) || !std::isfinite(T)) {
    throw std::invalid_argument("sampleTimes: need finite t0 < T");
  }
  const double h = 1.0 / rate;
  std::vector<double> t;
  for (long k = 0;; ++k) {
    const double tk = t0 + static_cast<double>(k) * h;  // k·h from t0: no accumulated round-off
    if (tk >= T - 1e-9 * h) break;
    t.push_back(tk);
  }
  t.push_back(T);
  return Eigen::Map<Eigen::VectorXd>(t.data(), static_cast<Eigen::Index>(t.size()));
}

namespace {

/// The variational equation Y = [Φ Γ] (nx × (nx+m), column-major) and the cost quadrature
/// W = ∫ [Φ Γ]ᵀ Q [Φ Γ] + blkdiag(0, R) ((nx+m)² entries), for OdeDriver.
class Discretizer final : public detail::LinearOdeSystem {
 public:
  int nx, nu, cols;
  const LinearizationCallback& lin;
  const LqrWeights& w;
  Eigen::MatrixXd A, B, Q, R, QY, LUmat;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu;
  double cachedT = std::numeric_limits<double>::quiet_NaN();
  bool cacheValid = false;
  double luGamma = std::numeric_limits<double>::quiet_NaN();
  double precT = std::numeric_limits<double>::quiet_NaN();
  Eigen::MatrixXd Aprec;
  long linearizations = 0;
  bool failed = false;
  double failTime = 0.0;
  std::string failMessage;

  Discretizer(int nx_, int nu_, const LinearizationCallback& l, const LqrWeights& w_)
      : nx(nx_), nu(nu_), cols(nx_ + nu_), lin(l), w(w_), A(nx_, nx_), B(nx_, nu_), Q(nx_, nx_),
        R(nu_, nu_), QY(nx_, nx_ + nu_), LUmat(nx_, nx_), lu(nx_), Aprec(nx_, nx_) {
    if (!w.Qfun) Q = w.Q;
    if (!w.Rfun) R = w.R;
  }

  void fail(double t, const std::string& m) {
    if (!failed) {
      failed = true;
      failTime = t;
      failMessage = m;
    }
  }

  /// A, B (and Q, R if callbacks) at t, cached on t.
  bool evaluate(double t) {
    if (cacheValid && t == cachedT) return true;
    cacheValid = false;
    // A user's callback may throw: caught here, at the integrator's C boundary (the library's
    // own callbacks return their failure as the status).
    try {
      const ReferenceStatus st = lin(t, A, B);
      ++linearizations;
      if (!st.ok()) {
        fail(t, st.message);
        return false;
      }
      if (A.rows() != nx || A.cols() != nx || B.rows() != nx || B.cols() != nu) {
        std::ostringstream m;
        m << "linearization callback returned A " << A.rows() << "x" << A.cols() << ", B " << B.rows()
          << "x" << B.cols() << " at t = " << t << " (expected " << nx << "x" << nx << ", " << nx
          << "x" << nu << ")";
        fail(t, m.str());
        return false;
      }
      if (w.Qfun) w.Qfun(t, Q);
      if (w.Rfun) w.Rfun(t, R);
      if (Q.rows() != nx || Q.cols() != nx || R.rows() != nu || R.cols() != nu) {
        fail(t, "Q(t)/R(t) callback returned a wrong size at t = " + std::to_string(t));
        return false;
      }
    } catch (const std::exception& e) {
      fail(t, std::string("callback threw at t = ") + std::to_string(t) + ": " + e.what());
      return false;
    }
    if (!A.allFinite() || !B.allFinite() || !Q.allFinite() || !R.allFinite()) {
      fail(t, "A, B, Q or R has a non-finite entry at t = " + std::to_string(t));
      return false;
    }
    cachedT = t;
    cacheValid = true;
    return true;
  }

  // Ẏ = A Y + [0 B]: a linear ODE (detail::LinearOdeSystem), J V = A V (one A per column).
  bool prepareAt(double t) override { return evaluate(t); }
  void applyJacobian(detail::ConstVectorMap v, detail::VectorMap Jv) override {
    Eigen::Map<Eigen::MatrixXd>(Jv.data(), nx, cols).noalias() =
        A * Eigen::Map<const Eigen::MatrixXd>(v.data(), nx, cols);
  }
  void addForcing(detail::VectorMap ydot) override {
    Eigen::Map<Eigen::MatrixXd>(ydot.data(), nx, cols).rightCols(nu) += B;
  }

  // Ẇ = Yᵀ Q Y + blkdiag(0, R).
  int quadrature(double t, detail::ConstVectorMap y, detail::VectorMap qdot) override {
    if (!evaluate(t)) return -1;
    Eigen::Map<const Eigen::MatrixXd> Y(y.data(), nx, cols);
    Eigen::Map<Eigen::MatrixXd> Wd(qdot.data(), cols, cols);
    QY.noalias() = Q * Y;
    Wd.noalias() = Y.transpose() * QY;
    Wd.bottomRightCorner(nu, nu) += R;
    return 0;
  }

  // Exact preconditioner: the Newton matrix is blkdiag(I − γA), solved column by column with one
  // LU of I − γA (refactored when γ or the set-up time changes).
  bool hasPreconditioner() const override { return true; }
  int preconditionerSetup(double t, detail::ConstVectorMap, detail::ConstVectorMap, bool jacOk,
                          bool* jacUpdated, double gamma) override {
    if (!jacOk || !(t == precT)) {
      if (!evaluate(t)) return -1;
      Aprec = A;
      precT = t;
      *jacUpdated = true;
    } else {
      *jacUpdated = false;
    }
    factor(gamma);
    return 0;
  }
  void factor(double gamma) {
    LUmat = -gamma * Aprec;
    LUmat.diagonal().array() += 1.0;
    lu.compute(LUmat);
    luGamma = gamma;
  }
  int preconditionerSolve(double, detail::ConstVectorMap, detail::ConstVectorMap,
                          detail::ConstVectorMap r, detail::VectorMap z, double gamma) override {
    if (gamma != luGamma) factor(gamma);
    Eigen::Map<const Eigen::MatrixXd> Rm(r.data(), nx, cols);
    Eigen::Map<Eigen::MatrixXd> Z(z.data(), nx, cols);
    Z = lu.solve(Rm);
    return Z.allFinite() ? 0 : 1;
  }
};

}  // namespace

std::string SampledDiscretization::describe() const {
  return status.describe() + " (" + std::to_string(intervals.size()) + " intervals, " +
         std::to_string(steps) + " steps, " + std::to_string(linearizations) + " linearizations)";
}

std::string SampledDiscretization::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["intervals"] = intervals.size();
  j["steps"] = steps;
  j["rhs_evaluations"] = rhsEvaluations;
  j["linearizations"] = linearizations;
  return j.dump();
}

std::string SampledRiccatiRecursion::describe() const {
  return status.describe() + " (" + std::to_string(K.size()) + " steps)";
}

std::string SampledRiccatiRecursion::json() const {
  detail::ReportJson j = detail::statusJson(status);
  j["steps"] = K.size();
  return j.dump();
}

SampledDiscretization discretizeSampledData(const Eigen::VectorXd& times, int nx, int nu,
                                            const LinearizationCallback& linearization,
                                            const LqrWeights& weights,
                                            const SampledDiscretizationOptions& options) {
  options.validate();
  if (nx <= 0 || nu <= 0) {
    throw std::invalid_argument("discretizeSampledData: need nx > 0 and m > 0, got nx = " +
                                std::to_string(nx) + ", m = " + std::to_string(nu));
  }
  if (times.size() < 2) throw std::invalid_argument("discretizeSampledData: need at least 2 times");
  for (Eigen::Index k = 0; k < times.size(); ++k) {
    if (!std::isfinite(times(k)) || (k > 0 && !(times(k) > times(k - 1)))) {
      throw std::invalid_argument("discretizeSampledData: times must be finite and increase strictly (entry " +
                                  std::to_string(k) + ")");
    }
  }
  if (!linearization) throw std::invalid_argument("discretizeSampledData: empty linearization callback");
  if (!weights.Qfun) checkWeightMatrix(weights.Q, "Q", nx, false);
  if (!weights.Rfun) checkWeightMatrix(weights.R, "R", nu, true);

  SampledDiscretization out;
  Discretizer s(nx, nu, linearization, weights);
  const int cols = nx + nu;

  const Eigen::Index N = static_cast<Eigen::Index>(nx) * cols;
  const Eigen::Index NQ = static_cast<Eigen::Index>(cols) * cols;
  Eigen::VectorXd y0 = Eigen::VectorXd::Zero(N);  // Y(a) = [I 0]
  Eigen::Map<Eigen::MatrixXd>(y0.data(), nx, cols).leftCols(nx).setIdentity();
  Eigen::VectorXd wq(NQ);

  detail::OdeOptions o = detail::makeOdeOptions(
      "sampled-data discretization", detail::OdeMethod::Bdf, detail::OdeLinearSolver::Gmres,
      options.rtol, options.atol, options.maxSteps);
  o.quadratureSize = static_cast<int>(NQ);
  o.quadratureErrorControl = true;
  o.quadratureRtol = options.rtol;
  o.quadratureAtol = options.atol;
  detail::OdeDriver driver(s, N, o);

  // Scale of the cost entries per unit time, for the quadrature's absolute tolerance.
  double costScale = 1.0;
  if (!weights.Qfun) costScale = std::max(costScale, weights.Q.cwiseAbs().maxCoeff());
  if (!weights.Rfun) costScale = std::max(costScale, weights.R.cwiseAbs().maxCoeff());

  out.intervals.reserve(static_cast<std::size_t>(times.size() - 1));
  for (Eigen::Index k = 0; k + 1 < times.size(); ++k) {
    const double a = times(k), b = times(k + 1);
    // Every interval starts from Y = [I 0], W = 0 (a restart: Φ, Γ are per interval).
    driver.start(a, y0);
    driver.setQuadratureTolerances(options.rtol, options.atol * (b - a) * costScale);
    const detail::OdeStatus st = driver.advanceTo(b);
    if (!st.ok()) {
      const double at = s.failed ? s.failTime : st.t;
      std::ostringstream m;
      m << "sampled-data discretization stopped in interval " << k << " [" << a << ", " << b
        << "] at t = " << at << ": ";
      if (s.failed) m << s.failMessage << "; ";
      m << st.message;
      out.status.set(s.failed ? SampledCode::kCallbackFailure : SampledCode::kIntegratorFailure,
                     m.str(), at, static_cast<long>(k));
      break;
    }
    driver.quadrature(wq);
    Eigen::Map<const Eigen::MatrixXd> Y(driver.state().data(), nx, cols);
    Eigen::Map<const Eigen::MatrixXd> W(wq.data(), cols, cols);
    SampledInterval iv;
    iv.t0 = a;
    iv.t1 = b;
    iv.Phi = Y.leftCols(nx);
    iv.Gamma = Y.rightCols(nu);
    const Eigen::MatrixXd Ws = 0.5 * (W + W.transpose());
    iv.Q = Ws.topLeftCorner(nx, nx);
    iv.N = Ws.topRightCorner(nx, nu);
    iv.R = Ws.bottomRightCorner(nu, nu);
    if (!iv.Phi.allFinite() || !iv.Gamma.allFinite() || !Ws.allFinite()) {
      out.status.set(SampledCode::kNonFinite,
                     "sampled-data discretization: non-finite Phi, Gamma or cost in interval " +
                         std::to_string(k) + " ending at t = " + std::to_string(b),
                     b, static_cast<long>(k));
      break;
    }
    out.intervals.push_back(std::move(iv));
  }
  const detail::OdeStats stats = driver.stats();
  out.steps = stats.steps;
  out.rhsEvaluations = stats.rhsEvaluations;
  out.linearizations = s.linearizations;
  return out;
}

SampledRiccatiRecursion solveSampledRiccatiRecursion(const std::vector<SampledInterval>& intervals,
                                                     const Eigen::MatrixXd& Qf) {
  SampledRiccatiRecursion rec;
  const std::size_t N = intervals.size();
  if (N == 0) throw std::invalid_argument("solveSampledRiccatiRecursion: no intervals");
  const Eigen::Index nx = intervals[0].Phi.rows(), nu = intervals[0].Gamma.cols();
  checkWeightMatrix(Qf, "Qf", nx, false);
  rec.S.assign(N + 1, Eigen::MatrixXd());
  rec.K.assign(N, Eigen::MatrixXd());
  rec.S[N] = 0.5 * (Qf + Qf.transpose());
  Eigen::MatrixXd SPhi(nx, nx), SGamma(nx, nu), G(nu, nu), H(nu, nx);
  Eigen::LLT<Eigen::MatrixXd> llt(nu);
  for (std::size_t k = N; k-- > 0;) {
    const SampledInterval& iv = intervals[k];
    if (iv.Phi.rows() != nx || iv.Phi.cols() != nx || iv.Gamma.rows() != nx || iv.Gamma.cols() != nu ||
        iv.Q.rows() != nx || iv.Q.cols() != nx || iv.N.rows() != nx || iv.N.cols() != nu ||
        iv.R.rows() != nu || iv.R.cols() != nu) {
      throw std::invalid_argument("solveSampledRiccatiRecursion: interval " + std::to_string(k) +
                                  " has inconsistent sizes");
    }
    const Eigen::MatrixXd& S1 = rec.S[k + 1];
    SPhi.noalias() = S1 * iv.Phi;
    SGamma.noalias() = S1 * iv.Gamma;
    G = iv.R;
    G.noalias() += iv.Gamma.transpose() * SGamma;
    H = iv.N.transpose();
    H.noalias() += iv.Gamma.transpose() * SPhi;
    llt.compute(0.5 * (G + G.transpose()));
    if (llt.info() != Eigen::Success) {
      std::ostringstream m;
      m << "sampled Riccati recursion: R_k + Gamma_k^T S_{k+1} Gamma_k is not positive definite at step " << k
        << " (t = " << iv.t0 << ")";
      rec.status.set(SampledCode::kNotPositiveDefinite, m.str(), iv.t0, static_cast<long>(k));
      return rec;
    }
    rec.K[k] = llt.solve(H);
    Eigen::MatrixXd Sk = iv.Q;
    Sk.noalias() += iv.Phi.transpose() * SPhi;
    Sk.noalias() -= H.transpose() * rec.K[k];
    rec.S[k] = 0.5 * (Sk + Sk.transpose());
    if (!rec.S[k].allFinite() || !rec.K[k].allFinite()) {
      std::ostringstream m;
      m << "sampled Riccati recursion: S or K became non-finite at step " << k << " (t = " << iv.t0 << ")";
      rec.status.set(SampledCode::kNonFinite, m.str(), iv.t0, static_cast<long>(k));
      return rec;
    }
  }
  return rec;
}

}  // namespace trellis
