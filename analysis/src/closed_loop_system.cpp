// closed_loop_system.cpp — the closed loop's right-hand side, input law with saturation, and the
// exact Jacobian A − B S K (see closed_loop_system.hpp).
#include "closed_loop_system.hpp"

#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <limits>
#include <sstream>

namespace trellis::detail {

std::string formatVector(const Eigen::VectorXd& v) {
  std::ostringstream m;
  m.precision(10);
  m << "[";
  for (Eigen::Index i = 0; i < v.size(); ++i) m << (i ? ", " : "") << v(i);
  m << "]";
  return m.str();
}

std::string formatTime(double t) {
  std::ostringstream m;
  m.precision(12);
  m << t;
  return m.str();
}

ClosedLoopSystem::ClosedLoopSystem(const Model& model, const InputLaw& law,
                                   const SimulationOptions& options)
    : model_(model),
      law_(law),
      n_(model.nq()),
      m_(model.nu()),
      sampled_(options.sampleRate > 0.0),
      bounded_(options.inputLower.size() > 0 || options.inputUpper.size() > 0),
      // ∂u/∂x is known unless a continuous user policy decides u.
      jacobianKnown_(options.exactJacobian && (sampled_ || law.kind != InputLaw::Kind::kPolicy)),
      // Not with BDF's difference-quotient Jacobian: CVODES scales its increments to |y| and
      // atol, which near the reference are far below the rounding of x = x_ref + y (measured on
      // the hand: 5314 Jacobians and 13461 steps instead of 56 and 2758).
      deviation_(law.kind != InputLaw::Kind::kPolicy && law.reference != nullptr &&
                 (jacobianKnown_ || options.method == IntegrationMethod::kAdams)),
      data_(model),
      x_(2 * n_),
      q_(n_),
      dq_(n_),
      u_(Eigen::VectorXd::Zero(m_)),
      held_(Eigen::VectorXd::Zero(m_)),
      lower_(Eigen::VectorXd::Constant(m_, -std::numeric_limits<double>::infinity())),
      upper_(Eigen::VectorXd::Constant(m_, std::numeric_limits<double>::infinity())),
      xr_(2 * n_),
      ur_(m_),
      xrdot_(2 * n_),
      dx_(2 * n_),
      xc_(2 * n_),
      uc_(m_),
      active_(Eigen::VectorXd::Ones(m_)),
      K_(m_, 2 * n_),
      SK_(m_, 2 * n_),
      jac_(2 * n_, 2 * n_),
      newton_(n_, n_),
      lu_(n_),
      rhsB_(n_),
      solB_(n_) {
  if (options.inputLower.size() == m_) lower_ = options.inputLower;
  if (options.inputUpper.size() == m_) upper_ = options.inputUpper;
  failState.resize(2 * n_);
}

void ClosedLoopSystem::fail(SimulationCode s, double t, const Eigen::VectorXd& state,
                            std::string message) {
  // Keeps the LAST failure: after a recoverable failure CVODES retries with ever smaller steps,
  // so the last failing point is the closest to where the integration stuck.
  failed = true;
  failStatus = s;
  failTime = t;
  failState = state;
  failMessage = std::move(message);
  failure = failMessage;
}

void ClosedLoopSystem::resetCallState() {
  failed = false;
  aborted_ = false;
  failuresThisCall_ = 0;
}

int ClosedLoopSystem::failureReturn() {
  if (failStatus == SimulationCode::kPolicyFailure ||
      ++failuresThisCall_ >= kMaxRecoverableFailures) {
    aborted_ = true;
  }
  return aborted_ ? -1 : 1;
}

void ClosedLoopSystem::toState(double t, const Eigen::Ref<const Eigen::VectorXd>& y,
                               Eigen::VectorXd& x) {
  if (!deviation_) {
    x = y;
    return;
  }
  law_.reference->evaluate(t, xc_, uc_);
  x = xc_ + y;
}

void ClosedLoopSystem::toIntegrator(double t, const Eigen::VectorXd& x, Eigen::VectorXd& y) {
  if (!deviation_) {
    y = x;
    return;
  }
  law_.reference->evaluate(t, xc_, uc_);
  y = x - xc_;
}

bool ClosedLoopSystem::stateFrom(double t, ConstVectorMap y) {
  if (!deviation_) {
    x_ = y;
    return true;
  }
  try {
    law_.reference->evaluate(t, xr_, ur_, xrdot_);
  } catch (const std::exception& e) {
    x_ = y;
    fail(SimulationCode::kPolicyFailure, t, x_, std::string("the reference threw: ") + e.what());
    return false;
  }
  x_ = xr_ + y;
  return true;
}

bool ClosedLoopSystem::input(double t, const Eigen::VectorXd& x, Eigen::VectorXd& out,
                             bool referenceFresh) {
  try {
    if (law_.kind != InputLaw::Kind::kPolicy && !referenceFresh) {
      law_.reference->evaluate(t, xr_, ur_);
    }
    switch (law_.kind) {
      case InputLaw::Kind::kPolicy:
        (*law_.policy)(t, x, out);
        break;
      case InputLaw::Kind::kOpenLoop:
        out = ur_;
        break;
      case InputLaw::Kind::kFeedback:
        law_.gains->evaluate(t, K_);
        dx_ = x - xr_;
        // Sampled gains with a held feed-forward: ū_k of the sample interval instead of
        // u_ref(t_k) (gain_schedule.hpp: the input that carries the reference over the hold).
        if (sampled_ && law_.gains->hasFeedforward()) {
          law_.gains->evaluateFeedforward(t, out);
        } else {
          out = ur_;
        }
        out.noalias() -= K_ * dx_;
        break;
    }
  } catch (const std::exception& e) {
    fail(SimulationCode::kPolicyFailure, t, x, std::string("the policy threw: ") + e.what());
    return false;
  } catch (...) {
    fail(SimulationCode::kPolicyFailure, t, x, "the policy threw an unknown exception");
    return false;
  }
  if (out.size() != m_) {
    fail(SimulationCode::kPolicyFailure, t, x,
         "the policy returned u of size " + std::to_string(out.size()) + ", expected " +
             std::to_string(m_));
    return false;
  }
  if (!out.allFinite()) {
    fail(SimulationCode::kNonFinite, t, x,
         "the policy returned a non-finite input u = " + formatVector(out));
    return false;
  }
  active_.setOnes();
  if (bounded_) {
    for (int i = 0; i < m_; ++i) {
      if (out(i) < lower_(i)) {
        out(i) = lower_(i);
        active_(i) = 0.0;
      } else if (out(i) > upper_(i)) {
        out(i) = upper_(i);
        active_(i) = 0.0;
      }
    }
  }
  return true;
}

bool ClosedLoopSystem::control(double t, const Eigen::VectorXd& x, Eigen::VectorXd& out,
                               bool& clipped) {
  if (!input(t, x, out)) return false;
  clipped = (active_.array() == 0.0).any();
  return true;
}

int ClosedLoopSystem::rhs(double t, ConstVectorMap y, VectorMap ydot) {
  lastValid_ = false;
  if (aborted_) return -1;
  if (!stateFrom(t, y)) return failureReturn();
  if (!x_.allFinite()) {
    fail(SimulationCode::kNonFinite, t, x_, "the state became non-finite");
    return failureReturn();
  }
  if (sampled_) {
    u_ = held_;
  } else if (!input(t, x_, u_, deviation_)) {
    return failureReturn();
  }
  q_ = x_.head(n_);
  dq_ = x_.tail(n_);
  computeDynamics(model_, data_, q_, dq_, u_);
  const DynamicsStatus& st = data_.status;
  if (!st.ok()) {
    fail(st.code == DynamicsStatus::Code::kNonFinite ? SimulationCode::kNonFinite
                                                     : SimulationCode::kDynamicsFailure,
         t, x_, "computeDynamics failed: " + st.message);
    return failureReturn();
  }
  ydot.head(n_) = dq_;
  ydot.tail(n_) = data_.qdd;
  if (deviation_) ydot -= xrdot_;
  lastValid_ = true;
  lastT_ = t;
  return 0;
}

int ClosedLoopSystem::jacobian(double t, ConstVectorMap y, ConstVectorMap /*fy*/, MatrixMap J) {
  lastValid_ = false;  // data_ and x_, u_ now hold the linearization's point
  if (aborted_) return -1;
  if (!stateFrom(t, y)) return failureReturn();
  const bool feedback = !sampled_ && law_.kind == InputLaw::Kind::kFeedback;
  if (sampled_) {
    u_ = held_;
  } else if (!input(t, x_, u_, deviation_)) {  // also K_ and active_ at t
    return failureReturn();
  }
  q_ = x_.head(n_);
  dq_ = x_.tail(n_);
  const DynamicsStatus st = computeLinearization(model_, data_, q_, dq_, u_);
  if (!st.ok()) {
    fail(st.code == DynamicsStatus::Code::kNonFinite ? SimulationCode::kNonFinite
                                                     : SimulationCode::kDynamicsFailure,
         t, x_, "computeLinearization failed: " + st.message);
    return failureReturn();
  }
  J = data_.A;
  if (feedback) {
    // ∂u/∂x = −S K: a clipped input's row drops out.
    SK_ = active_.asDiagonal() * K_;
    J.noalias() -= data_.B * SK_;
  }
  return 0;
}

void ClosedLoopSystem::factorNewton(double gamma) {
  const auto Aq = jac_.bottomLeftCorner(n_, n_);
  const auto Av = jac_.bottomRightCorner(n_, n_);
  newton_.noalias() = (-gamma * gamma) * Aq;
  newton_.noalias() -= gamma * Av;
  newton_.diagonal().array() += 1.0;
  lu_.compute(newton_);
  gammaLu_ = gamma;
}

int ClosedLoopSystem::preconditionerSetup(double t, ConstVectorMap y, ConstVectorMap fy, bool jacOk,
                                          bool* jacUpdated, double gamma) {
  *jacUpdated = false;
  if (!jacOk || !haveJac_) {
    haveJac_ = false;
    const int r = jacobian(t, y, fy, MatrixMap(jac_.data(), jac_.rows(), jac_.cols()));
    if (r != 0) return r;
    haveJac_ = true;
    ++structuredJacobians_;
    *jacUpdated = true;
  }
  factorNewton(gamma);
  return 0;
}

int ClosedLoopSystem::preconditionerSolve(double, ConstVectorMap, ConstVectorMap, ConstVectorMap r, VectorMap z,
                                          double gamma) {
  if (!haveJac_) return -1;
  if (gamma != gammaLu_) factorNewton(gamma);
  const auto r1 = r.head(n_);
  rhsB_ = r.tail(n_);
  rhsB_.noalias() += gamma * (jac_.bottomLeftCorner(n_, n_) * r1);
  solB_ = lu_.solve(rhsB_);
  z.head(n_) = r1 + gamma * solB_;
  z.tail(n_) = solB_;
  return 0;
}

}  // namespace trellis::detail
