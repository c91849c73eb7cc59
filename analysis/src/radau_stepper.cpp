// radau_stepper.cpp — OdeMethod::Radau, the three-stage Radau IIA stepper (radau_stepper.hpp).
#include "radau_stepper.hpp"

#include "trellis/analysis/detail/radau_tableau.hpp"

#include <cvodes/cvodes.h>  // the failure flags OdeStatus reads

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis::detail {

namespace {

using Complex = std::complex<double>;
constexpr double kEps = std::numeric_limits<double>::epsilon();
constexpr double kSafe = 0.9;       // step-size safety factor
constexpr double kGrowMax = 8.0;    // h_new / h at most
constexpr double kShrinkMax = 5.0;  // h / h_new at most
constexpr double kKeepJacobian = 1e-3;  // Newton contraction below which J is kept (file comment)

std::string number(double v) {
  std::ostringstream m;
  m.precision(10);
  m << v;
  return m.str();
}

}  // namespace

RadauStepper::RadauStepper(OdeSystem& system, Eigen::Index n, const OdeOptions& options)
    : system_(system),
      n_(n),
      secondOrder_(system.secondOrder() && n % 2 == 0),
      maxSteps_(options.maxSteps),
      maxStep_(options.maxStep),
      initialStep_(options.initialStep) {
  const std::string& what = options.what;
  if (!system.hasJacobian() || !options.exactJacobian) {
    throw std::invalid_argument(what + ": the Radau method needs the system's exact Jacobian");
  }
  if (options.quadratureSize > 0 || options.rootCount > 0) {
    throw std::invalid_argument(what + ": the Radau method has no quadratures or root functions");
  }
  // Its error norm weighs each component by atol + rtol|y|: a zero weight at y_i = 0 is a division
  // by zero, not a purely relative test.
  if (options.atolVector.size() == n ? !(options.atolVector.array() > 0.0).all() : !(options.atol > 0.0)) {
    throw std::invalid_argument(what + ": the Radau method needs atol > 0 (every component)");
  }
  // RADAU5's transformation (file comment).
  rtol_ = 0.1 * std::pow(options.rtol, 2.0 / 3.0);
  const double ratio = rtol_ / options.rtol;
  // One absolute tolerance per component, the scalar's copied when no vector is given.
  atol_ = options.atolVector.size() == n ? Eigen::VectorXd(options.atolVector * ratio)
                                         : Eigen::VectorXd::Constant(n, options.atol * ratio);
  newtonTolerance_ = options.newtonTolerance > 0.0 ? options.newtonTolerance
                                                  : std::max(10.0 * kEps / rtol_, std::min(0.03, std::sqrt(rtol_)));
  y_ = Eigen::VectorXd::Zero(n_);
  f0_.resize(n_);
  y1_.resize(n_);
  scale_.resize(n_);
  errScale_.resize(n_);
  tmpN_.resize(n_);
  err_.resize(n_);
  rhsErr_.resize(n_);
  yOld_.resize(n_);
  Z_ = Eigen::MatrixXd::Zero(n_, 3);
  F_.resize(n_, 3);
  dZ_.resize(n_, 3);
  poly_ = Eigen::MatrixXd::Zero(n_, 3);
  W0_.resize(n_);
  G0_.resize(n_);
  dW0_.resize(n_);
  W1_.resize(n_);
  G1_.resize(n_);
  dW1_.resize(n_);
  J_ = Eigen::MatrixXd::Zero(n_, n_);
  realSolve_.resize(n_, secondOrder_, 1);
  complexSolve_.resize(n_, secondOrder_, 1);
  zr_.resize(n_);
  zi_.resize(n_);
}

void RadauStepper::start(double t0, const Eigen::Ref<const Eigen::VectorXd>& y0) {
  // Newton may still start from the last step's polynomial when the run goes on from its end.
  extrapolate_ = haveStep_ && t0 == t_;
  t_ = t0;
  y_ = y0;
  f0Valid_ = false;
  haveStep_ = false;
  afterStart_ = true;
  lastRejected_ = false;
  predictive_ = false;
  jacobianCurrent_ = false;  // kept (haveJacobian_) until Newton asks for a fresh one
  // The right-hand side jumped: its transient allows what the last start's first step's estimate
  // asked for, not the long step carried from the end (rejected a few times per restart).
  if (firstStep_ > 0.0) h_ = firstStep_;
  stepsSinceStart_ = 0;
  flag = 0;
  reason.clear();
}

bool RadauStepper::evaluate(double t, const Eigen::VectorXd& y, Eigen::Ref<Eigen::VectorXd> f, bool& recoverable) {
  ++rhs_;
  const int r = system_.rhs(t, ConstVectorMap(y.data(), n_), VectorMap(f.data(), n_));
  if (r == 0 && f.allFinite()) return true;
  recoverable = r >= 0;  // a non-finite f: a smaller step may avoid it
  return false;
}

bool RadauStepper::refreshJacobian() {
  ++jacobians_;
  const int r = system_.jacobian(t_, ConstVectorMap(y_.data(), n_), ConstVectorMap(f0_.data(), n_),
                                 MatrixMap(J_.data(), n_, n_));
  if (r != 0 || !J_.allFinite()) {
    flag = CV_LSETUP_FAIL;
    reason = r != 0 ? "the Jacobian failed" : "the Jacobian is not finite";
    return false;
  }
  haveJacobian_ = jacobianCurrent_ = true;
  needJacobian_ = false;
  haveFactors_ = false;
  return true;
}

void RadauStepper::factor(double h) {
  const RadauTableau& tab = RadauTableau::get();
  sigma0_ = 1.0 / (tab.gamma0 * h);
  sigma1_ = 1.0 / (tab.mu * h);
  // σI − J = σ (I − κJ) with κ = 1/σ (shifted_solve.hpp; halved for a second-order J).
  realSolve_.factor(J_, tab.gamma0 * h, secondOrder_);
  complexSolve_.factor(J_, tab.mu * h, secondOrder_);
  factoredH_ = h;
  haveFactors_ = true;
  ++factorizations_;
}

// (σ0 I − J) z = r is (I − κ0 J) z = κ0 r.
void RadauStepper::solveReal(const Eigen::VectorXd& r, Eigen::VectorXd& z) {
  z = r / sigma0_;
  realSolve_.solve(z);
}

void RadauStepper::solveComplex(const Eigen::VectorXcd& r, Eigen::VectorXcd& z) {
  const Complex kappa = 1.0 / sigma1_;
  for (Eigen::Index i = 0; i < n_; ++i) {
    const Complex v = kappa * r[i];
    zr_[i] = v.real();
    zi_[i] = v.imag();
  }
  complexSolve_.solve(zr_, zi_);
  for (Eigen::Index i = 0; i < n_; ++i) z[i] = Complex(zr_[i], zi_[i]);
}

double RadauStepper::rms(const Eigen::Ref<const Eigen::MatrixXd>& v, const Eigen::VectorXd& scale) const {
  double sum = 0.0;
  for (Eigen::Index j = 0; j < v.cols(); ++j) sum += (v.col(j).array() / scale.array()).square().sum();
  return std::sqrt(sum / static_cast<double>(v.size()));
}

double RadauStepper::initialStep(double tstop) {
  const double span = tstop - t_;
  if (initialStep_ > 0.0) return std::min(initialStep_, span);
  // Hairer, Nørsett & Wanner's estimate for the estimate's order 3: h ~ (0.01/|y''|)^{1/4},
  // |y''| from one explicit Euler step of h0 = 0.01 |y|/|f|.
  errScale_ = atol_.array() + rtol_ * y_.cwiseAbs().array();
  const double d0 = rms(y_, errScale_), d1 = rms(f0_, errScale_);
  double h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
  h0 = std::min(h0, span);
  tmpN_ = y_ + h0 * f0_;
  bool recoverable = false;
  if (!evaluate(t_ + h0, tmpN_, err_, recoverable)) return 0.01 * h0;
  err_ -= f0_;
  const double d2 = rms(err_, errScale_) / h0;
  const double dm = std::max(d1, d2);
  const double h1 = dm <= 1e-15 ? std::max(1e-6, 1e-3 * h0) : std::pow(0.01 / dm, 0.25);
  return std::min({100.0 * h0, h1, span});
}

RadauStepper::Attempt RadauStepper::attempt(double h, bool landing, double tstop) {
  const RadauTableau& tab = RadauTableau::get();
  if (!haveJacobian_ || (needJacobian_ && !jacobianCurrent_)) {
    if (!refreshJacobian()) return Attempt::kFailed;
  }
  if (!haveFactors_ || h != factoredH_) factor(h);
  scale_ = atol_.array() + rtol_ * y_.cwiseAbs().array();

  // Newton's start: the last step's collocation polynomial extrapolated (across a start() only
  // from the last step's end: the state is continuous there, the right-hand side's jump is what
  // Newton corrects).
  if (extrapolate_) {
    const double c1 = tab.c[0], c2 = tab.c[1];
    const double p1b = (1.0 - c1), p1c = (1.0 - c1) * (1.0 - c2);
    for (int i = 0; i < 3; ++i) {
      const double th = 1.0 + tab.c[i] * h / hOld_;
      Z_.col(i) = (th - 1.0) * poly_.col(0) + (th * (th - c1) - p1b) * poly_.col(1) +
                  (th * (th - c1) * (th - c2) - p1c) * poly_.col(2);
    }
  } else {
    Z_.setZero();
  }
  W0_ = tab.Tinv(0, 0).real() * Z_.col(0) + tab.Tinv(0, 1).real() * Z_.col(1) + tab.Tinv(0, 2).real() * Z_.col(2);
  W1_ = tab.Tinv(1, 0) * Z_.col(0).cast<Complex>() + tab.Tinv(1, 1) * Z_.col(1).cast<Complex>() +
        tab.Tinv(1, 2) * Z_.col(2).cast<Complex>();

  // Simplified Newton (file comment).
  faccon_ = std::pow(std::max(faccon_, kEps), 0.8);
  double dynoOld = 0.0, thqOld = 0.0;
  bool converged = false;
  newtonFactor_ = 0.5;
  rhsFailed_ = false;
  for (int it = 0; it < kMaxNewton; ++it) {
    for (int i = 0; i < 3; ++i) {
      tmpN_ = y_ + Z_.col(i);
      bool recoverable = false;
      if (!evaluate(t_ + tab.c[i] * h, tmpN_, F_.col(i), recoverable)) {
        if (!recoverable) {
          flag = CV_RHSFUNC_FAIL;
          reason = "the right-hand side failed unrecoverably at t = " + number(t_ + tab.c[i] * h);
          return Attempt::kFailed;
        }
        rhsFailed_ = true;
        return Attempt::kNewtonFailed;
      }
    }
    ++newtonIts_;
    G0_ = tab.Tinv(0, 0).real() * F_.col(0) + tab.Tinv(0, 1).real() * F_.col(1) + tab.Tinv(0, 2).real() * F_.col(2);
    G0_ -= sigma0_ * W0_;
    G1_ = tab.Tinv(1, 0) * F_.col(0).cast<Complex>() + tab.Tinv(1, 1) * F_.col(1).cast<Complex>() +
          tab.Tinv(1, 2) * F_.col(2).cast<Complex>();
    G1_ -= sigma1_ * W1_;
    solveReal(G0_, dW0_);
    solveComplex(G1_, dW1_);
    for (int i = 0; i < 3; ++i) {
      dZ_.col(i) = tab.T(i, 0).real() * dW0_ + 2.0 * (tab.T(i, 1) * dW1_).real();
    }
    const double dyno = rms(dZ_, scale_);
    if (!std::isfinite(dyno)) return Attempt::kNewtonFailed;
    if (it >= 1) {
      const double thq = dyno / dynoOld;
      theta_ = it == 1 ? thq : std::sqrt(thq * thqOld);
      thqOld = thq;
      if (theta_ >= 0.99) return Attempt::kNewtonFailed;
      faccon_ = theta_ / (1.0 - theta_);
      const double dyth = faccon_ * dyno * std::pow(theta_, kMaxNewton - 1 - it) / newtonTolerance_;
      if (dyth >= 1.0) {
        // Not converging within the remaining iterations: a step the contraction would allow.
        const double qnewt = std::max(1e-4, std::min(20.0, dyth));
        newtonFactor_ = 0.8 * std::pow(qnewt, -1.0 / (4.0 + kMaxNewton - 1 - it));
        return Attempt::kNewtonFailed;
      }
    }
    dynoOld = std::max(dyno, kEps);
    W0_ += dW0_;
    W1_ += dW1_;
    Z_ += dZ_;
    newtonIterations_ = it + 1;
    if (faccon_ * dyno <= newtonTolerance_) {
      converged = true;
      break;
    }
  }
  if (!converged) return Attempt::kNewtonFailed;

  // The embedded estimate: err = (σ0 I − J)⁻¹ (f(t_n, y_n) + Σ d_i Z_i / h).
  y1_ = y_ + Z_.col(2);
  rhsErr_ = (tab.d[0] / h) * Z_.col(0) + (tab.d[1] / h) * Z_.col(1) + (tab.d[2] / h) * Z_.col(2);
  tmpN_ = f0_ + rhsErr_;
  solveReal(tmpN_, err_);
  errScale_ = atol_.array() + rtol_ * y_.cwiseAbs().cwiseMax(y1_.cwiseAbs()).array();
  double errn = std::max(rms(err_, errScale_), 1e-10);
  if (errn >= 1.0 && (afterStart_ || lastRejected_)) {
    tmpN_ = y_ + err_;
    bool recoverable = false;
    if (evaluate(t_, tmpN_, F_.col(0), recoverable)) {
      tmpN_ = F_.col(0) + rhsErr_;
      solveReal(tmpN_, err_);
      errn = std::max(rms(err_, errScale_), 1e-10);
    }
  }
  if (!std::isfinite(errn)) errn = 1e10;

  const double fac = std::min(kSafe, kSafe * (1 + 2 * kMaxNewton) / (newtonIterations_ + 2 * kMaxNewton));
  double quot = std::clamp(std::pow(errn, 0.25) / fac, 1.0 / kGrowMax, kShrinkMax);
  if (errn >= 1.0) {
    ++errorFailures_;
    lastRejected_ = true;
    h_ = h / quot;
    if (!jacobianCurrent_) needJacobian_ = true;  // J is an earlier point's: refresh it first
    return Attempt::kRejected;
  }
  // Accepted.
  if (predictive_) {
    // Gustafsson's predictive controller, h_new = s h (h/h_acc) (err_acc/err)^{1/4} (1/err)^{1/4},
    // taken alone (RADAU5 takes the smaller of it and the standard step): it follows the trend
    // of the error per h⁴, which after a restart falls step by step as the fast transient dies
    // (hand loop: the standard step grew ~1.3× per step at err ≈ 0.2, this one ~1.5× at err
    // 0.3–0.7 with no rejection; 12 → 9 steps per 5 ms sample).
    quot = std::clamp((hAccepted_ / h) * std::pow(errn * errn / errAccepted_, 0.25) / kSafe, 1.0 / kGrowMax, kShrinkMax);
  }
  predictive_ = true;
  hAccepted_ = h;
  errAccepted_ = std::max(1e-2, errn);
  if (afterStart_) firstStep_ = h / quot;  // what this first step's estimate asks for
  double hnew = h / quot;
  if (lastRejected_) hnew = std::min(hnew, h);
  // The dense output: Newton's divided differences of 0, Z_1, Z_2, Z_3 at 0, c_1, c_2, 1.
  {
    const double c1 = tab.c[0], c2 = tab.c[1];
    poly_.col(0) = Z_.col(0) / c1;                                   // [0, c1]
    dZ_.col(1) = (Z_.col(1) - Z_.col(0)) / (c2 - c1);                // [c1, c2]
    dZ_.col(2) = (Z_.col(2) - Z_.col(1)) / (1.0 - c2);               // [c2, 1]
    poly_.col(1) = (dZ_.col(1) - poly_.col(0)) / c2;                 // [0, c1, c2]
    dZ_.col(2) = (dZ_.col(2) - dZ_.col(1)) / (1.0 - c1);             // [c1, c2, 1]
    poly_.col(2) = dZ_.col(2) - poly_.col(1);                        // [0, c1, c2, 1]
  }
  yOld_ = y_;
  tOld_ = t_;
  hOld_ = h;
  t_ = landing ? tstop : t_ + h;
  y_ = y1_;
  bool recoverable = false;
  f0Valid_ = evaluate(t_, y_, f0_, recoverable);
  ++steps_;
  ++stepsSinceStart_;
  haveStep_ = extrapolate_ = true;
  afterStart_ = false;
  lastRejected_ = false;
  jacobianCurrent_ = false;
  needJacobian_ = theta_ > kKeepJacobian;
  // Keep h (and the factorizations) when the change would be small.
  if (!needJacobian_ && hnew >= h && hnew <= 1.2 * h) hnew = h;
  h_ = hnew;
  return Attempt::kAccepted;
}

bool RadauStepper::step(double tstop) {
  flag = 0;
  reason.clear();
  if (stepsSinceStart_ >= maxSteps_) {
    flag = CV_TOO_MUCH_WORK;
    reason = "more than maxSteps = " + std::to_string(maxSteps_) + " steps";
    return false;
  }
  if (!(tstop > t_)) {
    flag = CV_ILL_INPUT;
    reason = "the stop time " + number(tstop) + " is not after t";
    return false;
  }
  if (!f0Valid_) {
    bool recoverable = false;
    if (!evaluate(t_, y_, f0_, recoverable)) {
      flag = CV_FIRST_RHSFUNC_ERR;
      reason = "the right-hand side failed at the start point";
      return false;
    }
    f0Valid_ = true;
  }
  if (!(h_ > 0.0)) h_ = initialStep(tstop);
  int rhsRetries = 0;
  for (;;) {
    double h = h_;
    if (maxStep_ > 0.0) h = std::min(h, maxStep_);
    const double proposal = h;
    bool landing = false;
    if (t_ + 1.05 * h >= tstop) {
      h = tstop - t_;
      landing = true;
    }
    const double hmin = 16.0 * kEps * std::max(std::abs(t_), std::abs(tstop));
    if (!(h > hmin)) {
      flag = newtonFailures_ > 0 && lastWasNewton_ ? CV_CONV_FAILURE : CV_ERR_FAILURE;
      reason = "the step size " + number(h) + " fell below the resolution of t = " + number(t_) +
               (flag == CV_CONV_FAILURE ? " after Newton failures" : " after error-test failures");
      return false;
    }
    switch (attempt(h, landing, tstop)) {
      case Attempt::kAccepted:
        // A step shortened to land on tstop keeps the proposal it was cut from.
        if (landing && h_ >= h) h_ = std::max(h_, proposal);
        return true;
      case Attempt::kRejected:
        lastWasNewton_ = false;
        break;
      case Attempt::kNewtonFailed:
        ++newtonFailures_;
        lastWasNewton_ = true;
        if (rhsFailed_ && ++rhsRetries > kMaxRhsRetries) {
          flag = CV_REPTD_RHSFUNC_ERR;
          reason = "the right-hand side failed " + std::to_string(rhsRetries) + " times in a row";
          return false;
        }
        h_ = h * newtonFactor_;
        lastRejected_ = true;
        if (!jacobianCurrent_) needJacobian_ = true;
        break;
      case Attempt::kFailed:
        return false;
    }
  }
}

bool RadauStepper::interpolate(double t, int k, Eigen::Ref<Eigen::VectorXd> out) const {
  if (out.size() != n_ || k < 0 || k > 3) return false;
  if (!haveStep_) {
    if (k != 0 || t != t_) return false;
    out = y_;
    return true;
  }
  const double slack = 4.0 * kEps * std::max(std::abs(tOld_), std::abs(t_));
  if (t < tOld_ - slack || t > t_ + slack) return false;
  const RadauTableau& tab = RadauTableau::get();
  const double c1 = tab.c[0], c2 = tab.c[1];
  const double th = (t - tOld_) / hOld_;
  switch (k) {
    case 0:
      out = yOld_ + th * poly_.col(0) + (th * (th - c1)) * poly_.col(1) + (th * (th - c1) * (th - c2)) * poly_.col(2);
      break;
    case 1:
      out = (poly_.col(0) + (2.0 * th - c1) * poly_.col(1) + (3.0 * th * th - 2.0 * (c1 + c2) * th + c1 * c2) * poly_.col(2)) / hOld_;
      break;
    case 2:
      out = (2.0 * poly_.col(1) + (6.0 * th - 2.0 * (c1 + c2)) * poly_.col(2)) / (hOld_ * hOld_);
      break;
    default:
      out = (6.0 / (hOld_ * hOld_ * hOld_)) * poly_.col(2);
      break;
  }
  return true;
}

void RadauStepper::addStats(OdeStats& into) const {
  into.steps += steps_;
  into.rhsEvaluations += rhs_;
  into.jacobianEvaluations += jacobians_;
  into.nonlinearIterations += newtonIts_;
  into.linearSolverSetups += factorizations_;
  into.errorTestFailures += errorFailures_;
  into.nonlinearFailures += newtonFailures_;
  into.lastOrder = 3;  // the dense output's degree
  into.lastStep = hOld_;
}

}  // namespace trellis::detail
