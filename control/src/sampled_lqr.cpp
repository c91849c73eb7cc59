// sampled_lqr.cpp — exact discretization of a time-varying linearization over sample intervals
// (variational equation + cost quadrature with CVODES) and the discrete Riccati recursion with the
// cross term. See sampled_lqr.hpp for the math.
#include "trellis/control/sampled_lqr.hpp"

#include "sundials_raii.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <cvodes/cvodes_ls.h>
#include <sunlinsol/sunlinsol_spgmr.h>

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

/// CVODES user data: Y = [Φ Γ] (nx × (nx+m), column-major in the N_Vector), quadrature
/// W = [Φ Γ]ᵀ Q [Φ Γ] + blkdiag(0, R) ((nx+m)² entries).
struct Discretizer {
  int nx, nu, cols;
  const LinearizationCallback& lin;
  const LqrWeights& w;
  Eigen::MatrixXd A, B, Q, R, QY, W, LUmat;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu;
  double cachedT = std::numeric_limits<double>::quiet_NaN();
  bool cacheValid = false;
  double luGamma = std::numeric_limits<double>::quiet_NaN();
  double precT = std::numeric_limits<double>::quiet_NaN();
  Eigen::MatrixXd Aprec;
  long linearizations = 0;
  bool failed = false;
  double failTime = 0.0;
  std::string failMessage, cvodeMessage;

  Discretizer(int nx_, int nu_, const LinearizationCallback& l, const LqrWeights& w_)
      : nx(nx_), nu(nu_), cols(nx_ + nu_), lin(l), w(w_), A(nx_, nx_), B(nx_, nu_), Q(nx_, nx_),
        R(nu_, nu_), QY(nx_, nx_ + nu_), W(nx_ + nu_, nx_ + nu_), LUmat(nx_, nx_), lu(nx_),
        Aprec(nx_, nx_) {
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
    try {
      lin(t, A, B);
      ++linearizations;
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

  // Ẏ = A Y + [0 B].
  static int rhs(double t, N_Vector yv, N_Vector ydotv, void* user) {
    auto& s = *static_cast<Discretizer*>(user);
    if (!s.evaluate(t)) return -1;
    Eigen::Map<const Eigen::MatrixXd> Y(N_VGetArrayPointer(yv), s.nx, s.cols);
    Eigen::Map<Eigen::MatrixXd> Yd(N_VGetArrayPointer(ydotv), s.nx, s.cols);
    Yd.noalias() = s.A * Y;
    Yd.rightCols(s.nu) += s.B;
    return 0;
  }

  // Ẇ = Yᵀ Q Y + blkdiag(0, R).
  static int quad(double t, N_Vector yv, N_Vector qdot, void* user) {
    auto& s = *static_cast<Discretizer*>(user);
    if (!s.evaluate(t)) return -1;
    Eigen::Map<const Eigen::MatrixXd> Y(N_VGetArrayPointer(yv), s.nx, s.cols);
    Eigen::Map<Eigen::MatrixXd> Wd(N_VGetArrayPointer(qdot), s.cols, s.cols);
    s.QY.noalias() = s.Q * Y;
    Wd.noalias() = Y.transpose() * s.QY;
    Wd.bottomRightCorner(s.nu, s.nu) += s.R;
    return 0;
  }

  // Jacobian-vector product: J V = A V (block diagonal, one A per column).
  static int jtSetup(double t, N_Vector, N_Vector, void* user) {
    auto& s = *static_cast<Discretizer*>(user);
    return s.evaluate(t) ? 0 : -1;
  }
  static int jtimes(N_Vector v, N_Vector Jv, double t, N_Vector, N_Vector, void* user, N_Vector) {
    auto& s = *static_cast<Discretizer*>(user);
    if (!s.evaluate(t)) return -1;
    Eigen::Map<const Eigen::MatrixXd> V(N_VGetArrayPointer(v), s.nx, s.cols);
    Eigen::Map<Eigen::MatrixXd> out(N_VGetArrayPointer(Jv), s.nx, s.cols);
    out.noalias() = s.A * V;
    return 0;
  }

  // Exact preconditioner: the Newton matrix is blkdiag(I − γA), solved column by column with one
  // LU of I − γA (refactored when γ or the set-up time changes).
  static int precSetup(double t, N_Vector, N_Vector, int jok, int* jcur, double gamma, void* user) {
    auto& s = *static_cast<Discretizer*>(user);
    if (!jok || !(t == s.precT)) {
      if (!s.evaluate(t)) return -1;
      s.Aprec = s.A;
      s.precT = t;
      *jcur = 1;
    } else {
      *jcur = 0;
    }
    s.factor(gamma);
    return 0;
  }
  void factor(double gamma) {
    LUmat = -gamma * Aprec;
    LUmat.diagonal().array() += 1.0;
    lu.compute(LUmat);
    luGamma = gamma;
  }
  static int precSolve(double, N_Vector, N_Vector, N_Vector rv, N_Vector zv, double gamma, double,
                       int, void* user) {
    auto& s = *static_cast<Discretizer*>(user);
    if (gamma != s.luGamma) s.factor(gamma);
    Eigen::Map<const Eigen::MatrixXd> Rm(N_VGetArrayPointer(rv), s.nx, s.cols);
    Eigen::Map<Eigen::MatrixXd> Z(N_VGetArrayPointer(zv), s.nx, s.cols);
    Z = s.lu.solve(Rm);
    return Z.allFinite() ? 0 : 1;
  }

  static void errorHandler(int code, const char* module, const char* function, char* msg, void* user) {
    auto& s = *static_cast<Discretizer*>(user);
    if (code < 0) s.cvodeMessage = std::string(module) + "::" + function + ": " + msg;
  }
};

}  // namespace

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
  const sunindextype N = static_cast<sunindextype>(nx) * cols;
  const sunindextype NQ = static_cast<sunindextype>(cols) * cols;

  detail::CvodeSession cv;
  cv.context.reset(detail::createContext());
  SUNContext ctx = cv.context.get();
  cv.y.reset(N_VNew_Serial(N, ctx));
  detail::Vector yQ(N_VNew_Serial(NQ, ctx));
  if (!cv.y || !yQ) throw std::runtime_error("discretizeSampledData: N_VNew_Serial failed");
  Eigen::Map<Eigen::MatrixXd> Y(N_VGetArrayPointer(cv.y.get()), nx, cols);
  Eigen::Map<Eigen::MatrixXd> W(N_VGetArrayPointer(yQ.get()), cols, cols);
  auto resetState = [&] {
    Y.setZero();
    Y.leftCols(nx).setIdentity();
    W.setZero();
  };
  resetState();

  cv.cvode.reset(CVodeCreate(CV_BDF, ctx));
  void* mem = cv.cvode.get();
  if (!mem) throw std::runtime_error("discretizeSampledData: CVodeCreate failed");
  auto check = [&](int flag, const char* call) {
    if (flag < 0) {
      throw std::runtime_error(std::string("discretizeSampledData: ") + call + " failed with flag " +
                               std::to_string(flag) + ": " + s.cvodeMessage);
    }
  };
  check(CVodeSetErrHandlerFn(mem, &Discretizer::errorHandler, &s), "CVodeSetErrHandlerFn");
  check(CVodeInit(mem, &Discretizer::rhs, times(0), cv.y.get()), "CVodeInit");
  check(CVodeSStolerances(mem, options.rtol, options.atol), "CVodeSStolerances");
  check(CVodeSetUserData(mem, &s), "CVodeSetUserData");
  check(CVodeSetMaxNumSteps(mem, options.maxSteps), "CVodeSetMaxNumSteps");
  cv.linearSolver.reset(SUNLinSol_SPGMR(cv.y.get(), SUN_PREC_LEFT, 0, ctx));
  if (!cv.linearSolver) throw std::runtime_error("discretizeSampledData: SPGMR solver");
  check(CVodeSetLinearSolver(mem, cv.linearSolver.get(), nullptr), "CVodeSetLinearSolver");
  check(CVodeSetJacTimes(mem, &Discretizer::jtSetup, &Discretizer::jtimes), "CVodeSetJacTimes");
  check(CVodeSetPreconditioner(mem, &Discretizer::precSetup, &Discretizer::precSolve),
        "CVodeSetPreconditioner");
  check(CVodeQuadInit(mem, &Discretizer::quad, yQ.get()), "CVodeQuadInit");
  check(CVodeSetQuadErrCon(mem, SUNTRUE), "CVodeSetQuadErrCon");

  // Scale of the cost entries per unit time, for the quadrature's absolute tolerance.
  double costScale = 1.0;
  if (!weights.Qfun) costScale = std::max(costScale, weights.Q.cwiseAbs().maxCoeff());
  if (!weights.Rfun) costScale = std::max(costScale, weights.R.cwiseAbs().maxCoeff());

  out.intervals.reserve(static_cast<std::size_t>(times.size() - 1));
  for (Eigen::Index k = 0; k + 1 < times.size(); ++k) {
    const double a = times(k), b = times(k + 1);
    resetState();
    if (k > 0) {
      check(CVodeReInit(mem, a, cv.y.get()), "CVodeReInit");
      check(CVodeQuadReInit(mem, yQ.get()), "CVodeQuadReInit");
    }
    check(CVodeQuadSStolerances(mem, options.rtol, options.atol * (b - a) * costScale),
          "CVodeQuadSStolerances");
    check(CVodeSetStopTime(mem, b), "CVodeSetStopTime");
    double t = a;
    const int flag = CVode(mem, b, cv.y.get(), &t, CV_NORMAL);
    long v = 0;
    if (CVodeGetNumSteps(mem, &v) >= 0) out.steps += v;
    if (CVodeGetNumRhsEvals(mem, &v) >= 0) out.rhsEvaluations += v;
    if (flag < 0) {
      out.ok = false;
      double tcur = t;
      CVodeGetCurrentTime(mem, &tcur);
      out.failureTime = s.failed ? s.failTime : tcur;
      char* name = CVodeGetReturnFlagName(flag);
      std::ostringstream m;
      m << "sampled-data discretization stopped in interval " << k << " [" << a << ", " << b
        << "] at t = " << out.failureTime << ": ";
      if (s.failed) m << s.failMessage << "; ";
      m << "CVODES " << (name ? name : "error") << " (" << flag << ")";
      if (!s.cvodeMessage.empty()) m << ": " << s.cvodeMessage;
      std::free(name);
      out.message = m.str();
      break;
    }
    double tq = t;
    check(CVodeGetQuad(mem, &tq, yQ.get()), "CVodeGetQuad");
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
      out.ok = false;
      out.failureTime = b;
      out.message = "sampled-data discretization: non-finite Phi, Gamma or cost in interval " +
                    std::to_string(k) + " ending at t = " + std::to_string(b);
      break;
    }
    out.intervals.push_back(std::move(iv));
  }
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
      rec.ok = false;
      std::ostringstream m;
      m << "sampled Riccati recursion: R_k + Gamma_k^T S_{k+1} Gamma_k is not positive definite at step " << k
        << " (t = " << iv.t0 << ")";
      rec.message = m.str();
      return rec;
    }
    rec.K[k] = llt.solve(H);
    Eigen::MatrixXd Sk = iv.Q;
    Sk.noalias() += iv.Phi.transpose() * SPhi;
    Sk.noalias() -= H.transpose() * rec.K[k];
    rec.S[k] = 0.5 * (Sk + Sk.transpose());
    if (!rec.S[k].allFinite() || !rec.K[k].allFinite()) {
      rec.ok = false;
      std::ostringstream m;
      m << "sampled Riccati recursion: S or K became non-finite at step " << k << " (t = " << iv.t0 << ")";
      rec.message = m.str();
      return rec;
    }
  }
  return rec;
}

}  // namespace trellis
