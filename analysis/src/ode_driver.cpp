// ode_driver.cpp — OdeDriver: the CVODES calls of trellis::control, written once.
#include "trellis/analysis/detail/ode_driver.hpp"

#include "nvector_kernels.hpp"
#include "radau_stepper.hpp"
#include "sundials_raii.hpp"

#include <cvodes/cvodes.h>
#include <cvodes/cvodes_ls.h>
#include <nvector/nvector_serial.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunlinsol/sunlinsol_spgmr.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>
#include <sunnonlinsol/sunnonlinsol_newton.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace trellis::detail {

OdeOptions makeOdeOptions(const char* what, OdeMethod method, OdeLinearSolver linearSolver,
                          double rtol, double atol, long maxSteps, double maxStep) {
  OdeOptions o;
  o.what = what;
  o.method = method;
  o.linearSolver = linearSolver;
  o.rtol = rtol;
  o.atol = atol;
  o.maxSteps = maxSteps;
  o.maxStep = maxStep;
  return o;
}


namespace {

ConstVectorMap view(N_Vector v) {
  return ConstVectorMap(N_VGetArrayPointer(v), N_VGetLength(v));
}
VectorMap viewMutable(N_Vector v) { return VectorMap(N_VGetArrayPointer(v), N_VGetLength(v)); }

// OdeLinearSolver::SystemSolve: a SUNLinearSolver whose solve is one application of the system's
// preconditioner, P⁻¹ = (I − γJ)⁻¹ exactly. It declares itself ITERATIVE, matrix-free, so that
// CVODES's linear-solver interface keeps its Jacobian-age heuristics (the set-up is called after
// a convergence failure, every 20 steps or on a γ change > 30 %, with jok telling the system
// whether it may keep J) and passes the current γ to every solve. (A MATRIX_EMBEDDED solver would
// not do: CVODES 6 never calls the set-up of one, and every refresh decision would have to be
// rebuilt here.) It reports zero iterations: linearIterations stays 0.
struct SystemSolveContent {
  void* pData = nullptr;
  SUNPSetupFn pset = nullptr;
  SUNPSolveFn psolve = nullptr;
  sunindextype lastFlag = 0;
};

SystemSolveContent& content(SUNLinearSolver S) { return *static_cast<SystemSolveContent*>(S->content); }

SUNLinearSolver_Type systemSolveType(SUNLinearSolver) { return SUNLINEARSOLVER_ITERATIVE; }
SUNLinearSolver_ID systemSolveId(SUNLinearSolver) { return SUNLINEARSOLVER_CUSTOM; }
int systemSolveSetATimes(SUNLinearSolver, void*, SUNATimesFn) { return SUNLS_SUCCESS; }
int systemSolveSetPreconditioner(SUNLinearSolver S, void* pData, SUNPSetupFn pset,
                                 SUNPSolveFn psolve) {
  content(S).pData = pData;
  content(S).pset = pset;
  content(S).psolve = psolve;
  return SUNLS_SUCCESS;
}
// Scaling is irrelevant to an exact solve; offering the operation spares CVODES the weight-mean
// computation it does for iterative solvers without it.
int systemSolveSetScaling(SUNLinearSolver, N_Vector, N_Vector) { return SUNLS_SUCCESS; }
int systemSolveInitialize(SUNLinearSolver S) {
  return content(S).psolve ? SUNLS_SUCCESS : SUNLS_ILL_INPUT;
}
int systemSolveSetup(SUNLinearSolver S, SUNMatrix) {
  SystemSolveContent& c = content(S);
  const int r = c.pset ? c.pset(c.pData) : 0;
  c.lastFlag = r;
  return r == 0 ? SUNLS_SUCCESS : (r > 0 ? SUNLS_PSET_FAIL_REC : SUNLS_PSET_FAIL_UNREC);
}
int systemSolveSolve(SUNLinearSolver S, SUNMatrix, N_Vector x, N_Vector b, realtype tol) {
  SystemSolveContent& c = content(S);
  const int r = c.psolve(c.pData, b, x, tol, SUN_PREC_LEFT);
  c.lastFlag = r;
  return r == 0 ? SUNLS_SUCCESS : (r > 0 ? SUNLS_PSOLVE_FAIL_REC : SUNLS_PSOLVE_FAIL_UNREC);
}
int systemSolveIters(SUNLinearSolver) { return 0; }
realtype systemSolveResNorm(SUNLinearSolver) { return 0.0; }
sunindextype systemSolveLastFlag(SUNLinearSolver S) { return content(S).lastFlag; }
int systemSolveFree(SUNLinearSolver S) {
  if (!S) return SUNLS_SUCCESS;
  delete static_cast<SystemSolveContent*>(S->content);
  S->content = nullptr;
  SUNLinSolFreeEmpty(S);
  return SUNLS_SUCCESS;
}

SUNLinearSolver newSystemSolve(SUNContext ctx) {
  SUNLinearSolver S = SUNLinSolNewEmpty(ctx);
  if (!S) return nullptr;
  S->content = new SystemSolveContent();
  S->ops->gettype = systemSolveType;
  S->ops->getid = systemSolveId;
  S->ops->setatimes = systemSolveSetATimes;
  S->ops->setpreconditioner = systemSolveSetPreconditioner;
  S->ops->setscalingvectors = systemSolveSetScaling;
  S->ops->initialize = systemSolveInitialize;
  S->ops->setup = systemSolveSetup;
  S->ops->solve = systemSolveSolve;
  S->ops->numiters = systemSolveIters;
  S->ops->resnorm = systemSolveResNorm;
  S->ops->lastflag = systemSolveLastFlag;
  S->ops->free = systemSolveFree;
  return S;
}

}  // namespace

struct OdeDriver::Impl {
  CvodeSession cv;
  Vector quad;
  Vector atol;
  std::string cvodeMessage;  // the last error CVODES reported through the handler

  // --- C callbacks: user data is the OdeSystem (via the driver) ---------------------------
  static int rhs(double t, N_Vector y, N_Vector ydot, void* user) {
    auto& s = *static_cast<OdeSystem*>(user);
    return s.rhs(t, view(y), viewMutable(ydot));
  }
  static int jac(double t, N_Vector y, N_Vector fy, SUNMatrix J, void* user, N_Vector, N_Vector,
                 N_Vector) {
    auto& s = *static_cast<OdeSystem*>(user);
    const auto n = static_cast<Eigen::Index>(SUNDenseMatrix_Rows(J));
    return s.jacobian(t, view(y), view(fy), MatrixMap(SUNDenseMatrix_Data(J), n, n));
  }
  static int jtSetup(double t, N_Vector y, N_Vector fy, void* user) {
    return static_cast<OdeSystem*>(user)->jacTimesSetup(t, view(y), view(fy));
  }
  static int jtimes(N_Vector v, N_Vector Jv, double t, N_Vector y, N_Vector fy, void* user,
                    N_Vector) {
    return static_cast<OdeSystem*>(user)->jacTimes(t, view(y), view(fy), view(v), viewMutable(Jv));
  }
  static int precSetup(double t, N_Vector y, N_Vector fy, sunbooleantype jok,
                       sunbooleantype* jcur, double gamma, void* user) {
    bool updated = false;
    const int r = static_cast<OdeSystem*>(user)->preconditionerSetup(t, view(y), view(fy),
                                                                     jok == SUNTRUE, &updated, gamma);
    *jcur = updated ? SUNTRUE : SUNFALSE;
    return r;
  }
  static int precSolve(double t, N_Vector y, N_Vector fy, N_Vector r, N_Vector z, double gamma,
                       double, int, void* user) {
    return static_cast<OdeSystem*>(user)->preconditionerSolve(t, view(y), view(fy), view(r),
                                                              viewMutable(z), gamma);
  }
  static int quadRhs(double t, N_Vector y, N_Vector qdot, void* user) {
    return static_cast<OdeSystem*>(user)->quadrature(t, view(y), viewMutable(qdot));
  }
  static int rootFn(double t, N_Vector y, double* g, void* user) {
    return static_cast<OdeSystem*>(user)->roots(t, view(y), g);
  }
  static void errorHandler(int code, const char* module, const char* function, char* msg,
                           void* data) {
    if (code < 0) {
      auto& self = *static_cast<Impl*>(data);
      self.cvodeMessage = std::string(module) + "::" + function + ": " + msg;
    }
  }
};

namespace {

void check(int flag, const char* call, const std::string& what) {
  if (flag < 0) {
    throw std::runtime_error(what + ": " + call + " failed with flag " + std::to_string(flag));
  }
}

}  // namespace

bool OdeStatus::callbackFailed() const {
  return outcome == OdeOutcome::Failed &&
         (flag == CV_RHSFUNC_FAIL || flag == CV_FIRST_RHSFUNC_ERR || flag == CV_REPTD_RHSFUNC_ERR ||
          flag == CV_UNREC_RHSFUNC_ERR || flag == CV_CONV_FAILURE || flag == CV_LSETUP_FAIL ||
          flag == CV_LSOLVE_FAIL || flag == CV_NLS_FAIL);
}

bool OdeStatus::tooMuchWork() const {
  return outcome == OdeOutcome::Failed && flag == CV_TOO_MUCH_WORK;
}

OdeDriver::OdeDriver(OdeSystem& system, Eigen::Index n, OdeOptions options)
    : system_(system), n_(n), options_(std::move(options)), impl_(std::make_unique<Impl>()) {
  const std::string& what = options_.what;
  if (n <= 0) throw std::invalid_argument(what + ": the state has no components");
  if (!(options_.rtol > 0.0) || !(options_.atol >= 0.0) || !std::isfinite(options_.rtol) ||
      !std::isfinite(options_.atol)) {
    throw std::invalid_argument(what + ": tolerances must be finite with rtol > 0, atol >= 0");
  }
  if (options_.atolVector.size() != 0 && options_.atolVector.size() != n) {
    throw std::invalid_argument(what + ": atolVector has " +
                                std::to_string(options_.atolVector.size()) +
                                " components, the state " + std::to_string(n));
  }
  if (options_.maxSteps <= 0) throw std::invalid_argument(what + ": maxSteps must be > 0");
  if (options_.quadratureSize < 0 || options_.rootCount < 0) {
    throw std::invalid_argument(what + ": negative quadrature or root count");
  }
  if (options_.method == OdeMethod::Radau) {
    radau_ = std::make_unique<RadauStepper>(system_, n, options_);
    return;
  }

  auto& cv = impl_->cv;
  cv.context.reset(createContext());
  SUNContext ctx = cv.context.get();
  const auto N = static_cast<sunindextype>(n);
  cv.y.reset(N_VNew_Serial(N, ctx));
  cv.dky.reset(N_VNew_Serial(N, ctx));
  if (!cv.y || !cv.dky) throw std::runtime_error(what + ": N_VNew_Serial failed");
  useKernels(cv.y.get());  // before CVodeInit: its work vectors are clones of y
  useKernels(cv.dky.get());
  N_VConst(0.0, cv.y.get());
  if (options_.quadratureSize > 0) {
    impl_->quad.reset(N_VNew_Serial(options_.quadratureSize, ctx));
    if (!impl_->quad) throw std::runtime_error(what + ": N_VNew_Serial failed");
    useKernels(impl_->quad.get());
    N_VConst(0.0, impl_->quad.get());
  }
  if (options_.atolVector.size() == n) {
    impl_->atol.reset(N_VNew_Serial(N, ctx));
    if (!impl_->atol) throw std::runtime_error(what + ": N_VNew_Serial failed");
    useKernels(impl_->atol.get());
    viewMutable(impl_->atol.get()) = options_.atolVector;
  }

  cv.cvode.reset(CVodeCreate(options_.method == OdeMethod::Bdf ? CV_BDF : CV_ADAMS, ctx));
  void* mem = cv.cvode.get();
  if (!mem) throw std::runtime_error(what + ": CVodeCreate failed");
  check(CVodeSetErrHandlerFn(mem, &Impl::errorHandler, impl_.get()), "CVodeSetErrHandlerFn", what);
  // CVodeInit needs a y0 to size its internals; start() re-initializes with the real one.
  check(CVodeInit(mem, &Impl::rhs, 0.0, cv.y.get()), "CVodeInit", what);
  if (impl_->atol) {
    check(CVodeSVtolerances(mem, options_.rtol, impl_->atol.get()), "CVodeSVtolerances", what);
  } else {
    check(CVodeSStolerances(mem, options_.rtol, options_.atol), "CVodeSStolerances", what);
  }
  check(CVodeSetUserData(mem, &system_), "CVodeSetUserData", what);
  check(CVodeSetMaxNumSteps(mem, options_.maxSteps), "CVodeSetMaxNumSteps", what);
  if (options_.maxStep > 0.0) check(CVodeSetMaxStep(mem, options_.maxStep), "CVodeSetMaxStep", what);
  if (options_.initialStep > 0.0) {
    check(CVodeSetInitStep(mem, options_.initialStep), "CVodeSetInitStep", what);
  }
  if (options_.maxOrder > 0) check(CVodeSetMaxOrd(mem, options_.maxOrder), "CVodeSetMaxOrd", what);

  switch (options_.linearSolver) {
    case OdeLinearSolver::Dense: {
      cv.jacobian.reset(SUNDenseMatrix(N, N, ctx));
      if (!cv.jacobian) throw std::runtime_error(what + ": SUNDenseMatrix failed");
      cv.linearSolver.reset(SUNLinSol_Dense(cv.y.get(), cv.jacobian.get(), ctx));
      if (!cv.linearSolver) throw std::runtime_error(what + ": SUNLinSol_Dense failed");
      check(CVodeSetLinearSolver(mem, cv.linearSolver.get(), cv.jacobian.get()),
            "CVodeSetLinearSolver", what);
      if (options_.exactJacobian && system_.hasJacobian()) {
        check(CVodeSetJacFn(mem, &Impl::jac), "CVodeSetJacFn", what);
      }
      break;
    }
    case OdeLinearSolver::Gmres: {
      const bool prec = system_.hasPreconditioner();
      cv.linearSolver.reset(
          SUNLinSol_SPGMR(cv.y.get(), prec ? SUN_PREC_LEFT : SUN_PREC_NONE, 0, ctx));
      if (!cv.linearSolver) throw std::runtime_error(what + ": SUNLinSol_SPGMR failed");
      check(CVodeSetLinearSolver(mem, cv.linearSolver.get(), nullptr), "CVodeSetLinearSolver", what);
      if (options_.exactJacobian && system_.hasJacTimes()) {
        check(CVodeSetJacTimes(mem, &Impl::jtSetup, &Impl::jtimes), "CVodeSetJacTimes", what);
      }
      if (prec) {
        check(CVodeSetPreconditioner(mem, &Impl::precSetup, &Impl::precSolve),
              "CVodeSetPreconditioner", what);
      }
      break;
    }
    case OdeLinearSolver::SystemSolve: {
      if (!system_.hasPreconditioner()) {
        throw std::invalid_argument(what + ": OdeLinearSolver::SystemSolve needs the system's exact "
                                           "solve (preconditionerSetup/preconditionerSolve)");
      }
      cv.linearSolver.reset(newSystemSolve(ctx));
      if (!cv.linearSolver) throw std::runtime_error(what + ": SUNLinSolNewEmpty failed");
      check(CVodeSetLinearSolver(mem, cv.linearSolver.get(), nullptr), "CVodeSetLinearSolver", what);
      check(CVodeSetPreconditioner(mem, &Impl::precSetup, &Impl::precSolve),
            "CVodeSetPreconditioner", what);
      break;
    }
    case OdeLinearSolver::FixedPoint: {
      cv.nonlinearSolver.reset(SUNNonlinSol_FixedPoint(cv.y.get(), 0, ctx));
      if (!cv.nonlinearSolver) throw std::runtime_error(what + ": SUNNonlinSol_FixedPoint failed");
      check(CVodeSetNonlinearSolver(mem, cv.nonlinearSolver.get()), "CVodeSetNonlinearSolver", what);
      break;
    }
  }

  if (options_.quadratureSize > 0) {
    check(CVodeQuadInit(mem, &Impl::quadRhs, impl_->quad.get()), "CVodeQuadInit", what);
    if (options_.quadratureErrorControl) {
      check(CVodeQuadSStolerances(mem, options_.quadratureRtol, options_.quadratureAtol),
            "CVodeQuadSStolerances", what);
      check(CVodeSetQuadErrCon(mem, SUNTRUE), "CVodeSetQuadErrCon", what);
    }
  }
  if (options_.rootCount > 0) {
    check(CVodeRootInit(mem, options_.rootCount, &Impl::rootFn), "CVodeRootInit", what);
  }
}

OdeDriver::~OdeDriver() = default;

void OdeDriver::start(double t0, const Eigen::Ref<const Eigen::VectorXd>& y0,
                      const Eigen::Ref<const Eigen::VectorXd>& q0) {
  const std::string& what = options_.what;
  if (y0.size() != n_) {
    throw std::invalid_argument(what + ": start state has " + std::to_string(y0.size()) +
                                " components, expected " + std::to_string(n_));
  }
  if (!std::isfinite(t0) || !y0.allFinite()) {
    throw std::invalid_argument(what + ": start time or state is not finite (t = " +
                                std::to_string(t0) + ")");
  }
  if (radau_) {
    if (started_) ++finished_.restarts;
    radau_->start(t0, y0);
    t_ = t0;
    started_ = true;
    system_.failure.clear();
    return;
  }
  auto& cv = impl_->cv;
  void* mem = cv.cvode.get();
  if (started_) {
    collectCounters(finished_);  // CVodeReInit zeroes CVODES's counters
    ++finished_.restarts;
  }
  viewMutable(cv.y.get()) = y0;
  check(CVodeReInit(mem, t0, cv.y.get()), "CVodeReInit", what);
  if (options_.quadratureSize > 0) {
    if (q0.size() == 0) {
      N_VConst(0.0, impl_->quad.get());
    } else if (q0.size() == options_.quadratureSize) {
      viewMutable(impl_->quad.get()) = q0;
    } else {
      throw std::invalid_argument(what + ": start quadrature has the wrong size");
    }
    check(CVodeQuadReInit(mem, impl_->quad.get()), "CVodeQuadReInit", what);
  }
  check(CVodeSetMaxNumSteps(mem, options_.maxSteps), "CVodeSetMaxNumSteps", what);
  t_ = t0;
  started_ = true;
  stepsAtStart_ = 0;
  impl_->cvodeMessage.clear();
  system_.failure.clear();
}

ConstVectorMap OdeDriver::state() const {
  if (radau_) return ConstVectorMap(radau_->state().data(), n_);
  return view(impl_->cv.y.get());
}

OdeStatus OdeDriver::radauFailed() {
  OdeStatus st;
  st.outcome = OdeOutcome::Failed;
  st.flag = radau_->flag;
  st.t = radau_->time();
  std::ostringstream m;
  m.precision(10);
  char* name = CVodeGetReturnFlagName(st.flag);
  m << options_.what << ": Radau step failed";
  if (name) m << " (" << name << ")";
  m << " at t = " << st.t << ", |y|inf = " << state().cwiseAbs().maxCoeff() << ": " << radau_->reason;
  if (!system_.failure.empty()) m << ": " << system_.failure;
  std::free(name);
  st.message = m.str();
  return st;
}

OdeStatus OdeDriver::failed(int flag, const char* call) {
  OdeStatus st;
  st.outcome = OdeOutcome::Failed;
  st.flag = flag;
  double tcur = t_;
  CVodeGetCurrentTime(impl_->cv.cvode.get(), &tcur);
  st.t = tcur;
  std::ostringstream m;
  m.precision(10);
  char* name = flag < 0 ? CVodeGetReturnFlagName(flag) : nullptr;
  m << options_.what << ": " << call << " failed";
  if (name) m << " (" << name << ")";
  m << " at t = " << tcur << ", |y|inf = " << state().cwiseAbs().maxCoeff();
  if (!system_.failure.empty()) m << ": " << system_.failure;
  if (!impl_->cvodeMessage.empty()) m << " [" << impl_->cvodeMessage << "]";
  std::free(name);  // CVodeGetReturnFlagName returns malloc'ed memory
  st.message = m.str();
  return st;
}

OdeStatus OdeDriver::advanceTo(double tout) {
  if (!started_) throw std::logic_error(options_.what + ": advanceTo before start");
  if (radau_) {
    if (!(tout >= t_)) {
      radau_->flag = CV_ILL_INPUT;
      radau_->reason = "the target time " + std::to_string(tout) + " is behind the current time";
      return radauFailed();
    }
    while (t_ < tout) {
      if (!radau_->step(tout)) return radauFailed();
      t_ = radau_->time();
    }
    OdeStatus st;
    st.t = t_;
    return st;
  }
  void* mem = impl_->cv.cvode.get();
  OdeStatus st;
  if (tout == t_) {
    st.t = t_;
    return st;
  }
  long used = 0;
  CVodeGetNumSteps(mem, &used);
  const long remaining = options_.maxSteps - used;
  if (remaining <= 0) return failed(CV_TOO_MUCH_WORK, "step budget");
  CVodeSetMaxNumSteps(mem, remaining);
  const int s = CVodeSetStopTime(mem, tout);
  if (s < 0) return failed(s, "CVodeSetStopTime");
  double tret = t_;
  const int flag = CVode(mem, tout, impl_->cv.y.get(), &tret, CV_NORMAL);
  if (flag < 0) return failed(flag, "CVode");
  t_ = tret;
  st.t = tret;
  st.flag = flag;
  if (flag == CV_ROOT_RETURN) st.outcome = OdeOutcome::Root;
  return st;
}

OdeStatus OdeDriver::step(double tstop) {
  if (!started_) throw std::logic_error(options_.what + ": step before start");
  if (radau_) {
    if (!radau_->step(tstop)) return radauFailed();
    t_ = radau_->time();
    OdeStatus st;
    st.t = t_;
    return st;
  }
  void* mem = impl_->cv.cvode.get();
  long used = 0;
  CVodeGetNumSteps(mem, &used);
  if (used >= options_.maxSteps) return failed(CV_TOO_MUCH_WORK, "step budget");
  const int s = CVodeSetStopTime(mem, tstop);
  if (s < 0) return failed(s, "CVodeSetStopTime");
  double tret = t_;
  const int flag = CVode(mem, tstop, impl_->cv.y.get(), &tret, CV_ONE_STEP);
  if (flag < 0) return failed(flag, "CVode");
  OdeStatus st;
  t_ = tret;
  st.t = tret;
  st.flag = flag;
  if (flag == CV_ROOT_RETURN) st.outcome = OdeOutcome::Root;
  return st;
}

bool OdeDriver::interpolate(double t, int k, Eigen::Ref<Eigen::VectorXd> out) {
  if (radau_) return radau_->interpolate(t, k, out);
  auto& cv = impl_->cv;
  if (out.size() != n_) return false;
  if (CVodeGetDky(cv.cvode.get(), t, k, cv.dky.get()) < 0) return false;
  out = view(cv.dky.get());
  return true;
}

void OdeDriver::quadrature(Eigen::Ref<Eigen::VectorXd> out) {
  if (options_.quadratureSize == 0 || radau_) throw std::logic_error(options_.what + ": no quadratures");
  double tq = 0.0;
  check(CVodeGetQuad(impl_->cv.cvode.get(), &tq, impl_->quad.get()), "CVodeGetQuad", options_.what);
  out = view(impl_->quad.get());
}

void OdeDriver::rootDirections(int* directions) {
  if (radau_) throw std::logic_error(options_.what + ": no root functions");
  check(CVodeGetRootInfo(impl_->cv.cvode.get(), directions), "CVodeGetRootInfo", options_.what);
}

void OdeDriver::setMaxStep(double h) {
  if (radau_) {
    radau_->setMaxStep(h);
    return;
  }
  check(CVodeSetMaxStep(impl_->cv.cvode.get(), h), "CVodeSetMaxStep", options_.what);
}

void OdeDriver::setQuadratureTolerances(double rtol, double atol) {
  if (options_.quadratureSize == 0 || !options_.quadratureErrorControl || radau_) {
    throw std::logic_error(options_.what + ": quadrature tolerances without quadrature error control");
  }
  if (!(rtol > 0.0) || !(atol >= 0.0) || !std::isfinite(rtol) || !std::isfinite(atol)) {
    throw std::invalid_argument(options_.what + ": quadrature tolerances must be finite with rtol > 0, atol >= 0");
  }
  check(CVodeQuadSStolerances(impl_->cv.cvode.get(), rtol, atol), "CVodeQuadSStolerances",
        options_.what);
  options_.quadratureRtol = rtol;
  options_.quadratureAtol = atol;
}

int OdeDriver::lastOrder() const {
  if (radau_) return radau_->stepsSinceStart() > 0 ? 3 : 0;  // the dense output's degree
  int q = 0;
  if (CVodeGetLastOrder(impl_->cv.cvode.get(), &q) < 0) return 0;
  return q;
}

void OdeDriver::collectCounters(OdeStats& into) const {
  void* mem = impl_->cv.cvode.get();
  long v = 0;
  if (CVodeGetNumSteps(mem, &v) >= 0) into.steps += v;
  if (CVodeGetNumRhsEvals(mem, &v) >= 0) into.rhsEvaluations += v;
  if (CVodeGetNumErrTestFails(mem, &v) >= 0) into.errorTestFailures += v;
  if (CVodeGetNumNonlinSolvConvFails(mem, &v) >= 0) into.nonlinearFailures += v;
  if (CVodeGetNumNonlinSolvIters(mem, &v) >= 0) into.nonlinearIterations += v;
  if (options_.linearSolver != OdeLinearSolver::FixedPoint) {
    if (CVodeGetNumLinRhsEvals(mem, &v) >= 0) into.linearRhsEvaluations += v;
    if (CVodeGetNumJacEvals(mem, &v) >= 0) into.jacobianEvaluations += v;
    if (CVodeGetNumLinSolvSetups(mem, &v) >= 0) into.linearSolverSetups += v;
    if (options_.linearSolver == OdeLinearSolver::Gmres ||
        options_.linearSolver == OdeLinearSolver::SystemSolve) {
      if (CVodeGetNumLinIters(mem, &v) >= 0) into.linearIterations += v;
      if (CVodeGetNumPrecEvals(mem, &v) >= 0) into.preconditionerSetups += v;
      if (CVodeGetNumPrecSolves(mem, &v) >= 0) into.preconditionerSolves += v;
    }
  }
}

OdeStats OdeDriver::stats() const {
  OdeStats s = finished_;
  if (radau_) {
    radau_->addStats(s);
    return s;
  }
  if (started_) collectCounters(s);
  int q = 0;
  double h = 0.0;
  void* mem = impl_->cv.cvode.get();
  if (CVodeGetLastOrder(mem, &q) >= 0) s.lastOrder = q;
  if (CVodeGetLastStep(mem, &h) >= 0) s.lastStep = h;
  return s;
}

}  // namespace trellis::detail
