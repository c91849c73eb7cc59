// manifold_lqr.cpp — tangent-basis transport, the reduced Riccati solve, and the reduced
// reachability Gramian (declared in controllability.hpp; it shares the forward CVODES driver and
// the transported basis defined here). SUNDIALS stays in this file.
#include "trellis/control/manifold_lqr.hpp"

#include "sundials_raii.hpp"
#include "trellis/control/controllability.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/core/data.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/model.hpp"

#include <cvodes/cvodes_ls.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>

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

namespace {

/// Outcome of integrateForward: the stored steps (t, Nordsieck derivatives) and, on failure, the
/// time and the message.
struct ForwardResult {
  struct Step {
    double t;
    Eigen::MatrixXd D;  // N × (q+1)
  };
  std::vector<Step> steps;
  Eigen::VectorXd yEnd;
  std::string message;  // empty when the integration reached t1
  double failureTime = 0.0;
  long internalSteps = 0;
};

/// The CVODES callbacks of a Problem with
///   bool rhs(double t, const double* y, double* ydot);
///   bool jacobian(double t, const double* y, double* J);   // N×N column-major
///   double failTime; std::string failMessage;               // set when rhs/jacobian return false
/// Nothing throws through CVODES: the problem catches and returns false.
template <class Problem>
struct ForwardCallbacks {
  Problem* problem;
  std::string cvodeMessage;

  static int rhs(double t, N_Vector y, N_Vector ydot, void* user) {
    auto& c = *static_cast<ForwardCallbacks*>(user);
    return c.problem->rhs(t, N_VGetArrayPointer(y), N_VGetArrayPointer(ydot)) ? 0 : -1;
  }
  static int jac(double t, N_Vector y, N_Vector, SUNMatrix J, void* user, N_Vector, N_Vector,
                 N_Vector) {
    auto& c = *static_cast<ForwardCallbacks*>(user);
    return c.problem->jacobian(t, N_VGetArrayPointer(y), SM_DATA_D(J)) ? 0 : -1;
  }
  static void errorHandler(int code, const char* module, const char* function, char* msg,
                           void* user) {
    auto& c = *static_cast<ForwardCallbacks*>(user);
    if (code < 0) c.cvodeMessage = std::string(module) + "::" + function + ": " + msg;
  }
};

/// Integrates ẏ = f(t, y) from t0 to t1 > t0 with CVODES BDF (dense Newton, exact Jacobian),
/// keeping the Nordsieck data of every step when keepSteps (dense output, as in riccati.cpp).
/// Set-up errors throw; numerical failure is returned in the result.
template <class Problem>
ForwardResult integrateForward(Problem& problem, Eigen::Index N, const Eigen::VectorXd& y0,
                               double t0, double t1, double rtol, double atol, long maxSteps,
                               bool keepSteps, const char* what) {
  ForwardCallbacks<Problem> cb{&problem, {}};
  ForwardResult out;
  detail::CvodeSession cv;
  cv.context.reset(detail::createContext());
  SUNContext ctx = cv.context.get();
  cv.y.reset(N_VNew_Serial(static_cast<sunindextype>(N), ctx));
  cv.dky.reset(N_VNew_Serial(static_cast<sunindextype>(N), ctx));
  if (!cv.y || !cv.dky) throw std::runtime_error(std::string(what) + ": N_VNew_Serial failed");
  double* y = N_VGetArrayPointer(cv.y.get());
  Eigen::Map<Eigen::VectorXd>(y, N) = y0;
  cv.cvode.reset(CVodeCreate(CV_BDF, ctx));
  void* mem = cv.cvode.get();
  if (!mem) throw std::runtime_error(std::string(what) + ": CVodeCreate failed");
  auto check = [&](int flag, const char* call) {
    if (flag < 0) {
      throw std::runtime_error(std::string(what) + ": " + call + " failed with flag " +
                               std::to_string(flag) + ": " + cb.cvodeMessage);
    }
  };
  check(CVodeSetErrHandlerFn(mem, &ForwardCallbacks<Problem>::errorHandler, &cb),
        "CVodeSetErrHandlerFn");
  check(CVodeInit(mem, &ForwardCallbacks<Problem>::rhs, t0, cv.y.get()), "CVodeInit");
  check(CVodeSStolerances(mem, rtol, atol), "CVodeSStolerances");
  check(CVodeSetUserData(mem, &cb), "CVodeSetUserData");
  check(CVodeSetMaxNumSteps(mem, maxSteps), "CVodeSetMaxNumSteps");
  check(CVodeSetStopTime(mem, t1), "CVodeSetStopTime");
  cv.jacobian.reset(SUNDenseMatrix(static_cast<sunindextype>(N), static_cast<sunindextype>(N), ctx));
  cv.linearSolver.reset(SUNLinSol_Dense(cv.y.get(), cv.jacobian.get(), ctx));
  if (!cv.jacobian || !cv.linearSolver) {
    throw std::runtime_error(std::string(what) + ": dense solver");
  }
  check(CVodeSetLinearSolver(mem, cv.linearSolver.get(), cv.jacobian.get()),
        "CVodeSetLinearSolver");
  check(CVodeSetJacFn(mem, &ForwardCallbacks<Problem>::jac), "CVodeSetJacFn");

  if (keepSteps) out.steps.push_back({t0, Eigen::Map<Eigen::VectorXd>(y, N)});
  double t = t0;
  long taken = 0;
  while (t < t1) {
    if (++taken > maxSteps) {  // CV_ONE_STEP applies maxSteps per call: the budget is ours
      out.failureTime = t;
      std::ostringstream m;
      m << what << " stopped at t = " << t << ": more than maxSteps = " << maxSteps
        << " steps (too much work)";
      out.message = m.str();
      break;
    }
    const int flag = CVode(mem, t1, cv.y.get(), &t, CV_ONE_STEP);
    if (flag < 0) {
      double tcur = t;
      CVodeGetCurrentTime(mem, &tcur);
      const bool callback = !problem.failMessage.empty();
      out.failureTime = callback ? problem.failTime : tcur;
      char* name = CVodeGetReturnFlagName(flag);
      std::ostringstream m;
      m << what << " stopped at t = " << out.failureTime << ": ";
      if (callback) m << problem.failMessage << "; ";
      m << "CVODES " << (name ? name : "error") << " (" << flag << ")";
      if (!cb.cvodeMessage.empty()) m << ": " << cb.cvodeMessage;
      std::free(name);
      out.message = m.str();
      break;
    }
    if (!Eigen::Map<const Eigen::VectorXd>(y, N).allFinite()) {
      out.failureTime = t;
      out.message = std::string(what) + " became non-finite at t = " + std::to_string(t);
      break;
    }
    if (keepSteps) {
      int q = 0;
      CVodeGetLastOrder(mem, &q);
      ForwardResult::Step st{t, Eigen::MatrixXd(N, q + 1)};
      for (int k = 0; k <= q; ++k) {
        if (CVodeGetDky(mem, t, k, cv.dky.get()) < 0) {
          st.D.conservativeResize(N, k);
          break;
        }
        st.D.col(k) = Eigen::Map<Eigen::VectorXd>(N_VGetArrayPointer(cv.dky.get()), N);
      }
      out.steps.push_back(std::move(st));
    }
    if (flag == CV_TSTOP_RETURN) break;
  }
  out.yEnd = Eigen::Map<Eigen::VectorXd>(y, N);
  long v = 0;
  if (CVodeGetNumSteps(mem, &v) >= 0) out.internalSteps = v;
  return out;
}

/// Exact linearization A(t), B(t) at the reference's x(t), u(t), in a caller-owned workspace.
struct ReferenceLinearization {
  const Model& model;
  const Trajectory& trajectory;
  Data data;
  Eigen::VectorXd x, u, q, dq;

  ReferenceLinearization(const Model& m, const Trajectory& tr) : model(m), trajectory(tr), data(m) {}

  /// Throws std::runtime_error naming t when the dynamics fail.
  void evaluate(double t) {
    trajectory.evaluate(t, x, u);
    const int n = trajectory.nq();
    q = x.head(n);
    dq = x.tail(n);
    const DynamicsStatus s = computeLinearization(model, data, q, dq, u);
    if (!s.ok()) {
      std::ostringstream m;
      m << "linearization failed at t = " << t << ": " << s.message;
      throw std::runtime_error(m.str());
    }
  }
};

/// Ṫ = (I − P(t)) A(t) T on vec(T) (column-major, 2n·d unknowns), P(t) = T_c T_cᵀ the orthogonal
/// projector onto the tangent space at x_ref(t) (T_c: the core's basis there; P does not depend on
/// which basis). For T tangent, (I − P)AT = ṖT (see the header), so the solution is the parallel
/// transport; and the equation is LINEAR in T, with the constant-in-T Jacobian
///   E ↦ (I − P) A E   (block diagonal: d copies of W = (I − P)A).
/// Why P(t) rather than TTᵀ: with TTᵀ, Ṫ = AT − T(TᵀAT) has the exact solution but a
/// non-orthonormal perturbation δT = T S (S symmetric) grows like −S·TᵀAT, i.e. with the NEGATED
/// tangent dynamics: on a stiff scene (the hand: damped modes at −1e4 s⁻¹) that is an unstable
/// mode at +1e4 s⁻¹ and CVODES grinds to a halt. With P(t) a tangent perturbation obeys
/// δṪ = (I − P)A δT ∈ normal space (bounded), and a normal one follows the neutral constraint-drift
/// dynamics: no stiffness is created.
struct TransportProblem {
  ReferenceLinearization lin;
  Eigen::Index nx, d;
  Eigen::MatrixXd W;  // (I − P) A at preparedTime
  bool prepared = false;
  double preparedTime = 0.0;
  double failTime = 0.0;
  std::string failMessage;

  TransportProblem(const Model& m, const Trajectory& tr, Eigen::Index d_)
      : lin(m, tr), nx(tr.nx()), d(d_), W(nx, nx) {}

  bool fail(double t, const std::string& message) {
    if (failMessage.empty()) {
      failTime = t;
      failMessage = message;
    }
    return false;
  }

  bool prepare(double t) {
    // CVODES asks for the Jacobian at the time of a right-hand side it just evaluated, and W
    // depends on t only (the equation is linear in T): evaluate the core once per t.
    if (prepared && t == preparedTime) return true;
    prepared = false;
    try {
      lin.evaluate(t);
    } catch (const std::exception& e) {
      return fail(t, e.what());
    }
    const int dc = computeConstraintTangentBasis(lin.model, lin.data);
    if (dc != d) {
      std::ostringstream m;
      m << "the tangent space changed dimension from " << d << " to " << dc << " at t = " << t
        << " (the constraints changed rank)";
      return fail(t, m.str());
    }
    const Eigen::MatrixXd& Tc = lin.data.tangentBasis;
    W = lin.data.A;
    W.noalias() -= Tc * (Tc.transpose() * lin.data.A);
    prepared = true;
    preparedTime = t;
    return true;
  }

  bool rhs(double t, const double* y, double* ydot) {
    if (!prepare(t)) return false;
    Eigen::Map<const Eigen::MatrixXd> T(y, nx, d);
    Eigen::Map<Eigen::MatrixXd> F(ydot, nx, d);
    F.noalias() = W * T;
    return true;
  }

  bool jacobian(double t, const double*, double* J) {
    if (!prepare(t)) return false;
    const Eigen::Index N = nx * d;
    Eigen::Map<Eigen::MatrixXd>(J, N, N).setZero();
    for (Eigen::Index j = 0; j < d; ++j)
      Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>(J + (j * nx) * N + j * nx, nx, nx,
                                                            Eigen::OuterStride<>(N)) = W;
    return true;
  }
};

}  // namespace

// ---- TangentBasisTrajectory --------------------------------------------------------------------

struct TangentBasisTrajectory::Workspace {
  ReferenceLinearization lin;
  Eigen::MatrixXd Ttilde, C, AT;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd;
  // Cache of the last reducedLinearization (the Riccati solver asks for A, B then Q at one t).
  bool cached = false;
  double cachedTime = 0.0;
  Eigen::MatrixXd T, Ar, Br;
  Workspace(const Model& m, const Trajectory& tr) : lin(m, tr) {}
};

TangentBasisTrajectory::TangentBasisTrajectory() = default;
TangentBasisTrajectory::~TangentBasisTrajectory() = default;
TangentBasisTrajectory::TangentBasisTrajectory(TangentBasisTrajectory&&) noexcept = default;
TangentBasisTrajectory& TangentBasisTrajectory::operator=(TangentBasisTrajectory&&) noexcept =
    default;

TangentBasisTrajectory::TangentBasisTrajectory(const TangentBasisTrajectory& o)
    : model_(o.model_), trajectory_(o.trajectory_), nx_(o.nx_), d_(o.d_), t0_(o.t0_), tf_(o.tf_),
      identity_(o.identity_), stored_(o.stored_), message_(o.message_), steps_(o.steps_),
      maxCorrection_(o.maxCorrection_) {}  // the workspace is not shared: a copy makes its own

TangentBasisTrajectory& TangentBasisTrajectory::operator=(const TangentBasisTrajectory& o) {
  if (this != &o) {
    TangentBasisTrajectory copy(o);
    *this = std::move(copy);
  }
  return *this;
}

double TangentBasisTrajectory::validUntil() const {
  if (identity_) return tf_;
  return stored_.empty() ? t0_ : stored_.back().t;
}

void TangentBasisTrajectory::evaluateStored(double t, Eigen::MatrixXd& Ttilde) const {
  if (!trajectory_) throw std::out_of_range("TangentBasisTrajectory: empty (not transported)");
  const double until = validUntil();
  const double slack = 1e-12 * std::max({1.0, std::abs(t0_), std::abs(tf_)});
  if (!(t >= t0_ - slack && t <= until + slack)) {
    std::ostringstream m;
    m << "TangentBasisTrajectory: t = " << t << " is outside [" << t0_ << ", " << until << "]";
    throw std::out_of_range(m.str());
  }
  t = std::clamp(t, t0_, until);
  Ttilde.resize(nx_, d_);
  if (identity_) {
    Ttilde.setIdentity();
    return;
  }
  // First stored step with t_k ≥ t; its polynomial covers [t_{k−1}, t_k].
  const auto it = std::lower_bound(stored_.begin(), stored_.end(), t,
                                   [](const Step& s, double v) { return s.t < v; });
  const Step& st = *it;
  const double dt = t - st.t;
  const Eigen::Index q = st.D.cols() - 1;
  Eigen::Map<Eigen::VectorXd> y(Ttilde.data(), Ttilde.size());
  y = st.D.col(q);
  for (Eigen::Index k = q; k-- > 0;) y = st.D.col(k) + (dt / static_cast<double>(k + 1)) * y;
}

// T = polar(P T̃) with P = Tc Tcᵀ (Tc the core's basis at x(t)): P T̃ = Tc (Tcᵀ T̃), and for
// Tcᵀ T̃ = U Σ Vᵀ the polar factor is Tc U Vᵀ (Tc has orthonormal columns).
void TangentBasisTrajectory::correct(double t, const Eigen::MatrixXd& Ttilde,
                                     Eigen::MatrixXd& T) const {
  Workspace& w = *work_;
  computeConstraintTangentBasis(*model_, w.lin.data);
  const Eigen::MatrixXd& Tc = w.lin.data.tangentBasis;
  if (Tc.cols() != d_) {
    std::ostringstream m;
    m << "TangentBasisTrajectory: the tangent space at t = " << t << " has dimension "
      << Tc.cols() << ", the transported basis " << d_
      << " (the constraints change rank along the trajectory)";
    throw std::runtime_error(m.str());
  }
  w.C.noalias() = Tc.transpose() * Ttilde;
  w.svd.compute(w.C, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const double smin = w.svd.singularValues()(d_ - 1);
  if (!(smin > 1e-3)) {
    std::ostringstream m;
    m << "TangentBasisTrajectory: at t = " << t
      << " the transported basis has drifted off the tangent space (smallest singular value of "
         "its projection "
      << smin << ")";
    throw std::runtime_error(m.str());
  }
  T.noalias() = Tc * (w.svd.matrixU() * w.svd.matrixV().transpose());
  maxCorrection_ = std::max(maxCorrection_, (T - Ttilde).norm());
}

void TangentBasisTrajectory::reducedLinearization(double t, Eigen::MatrixXd& T,
                                                  Eigen::MatrixXd& Ar, Eigen::MatrixXd& Br) const {
  if (!trajectory_) throw std::out_of_range("TangentBasisTrajectory: empty (not transported)");
  if (!work_) work_ = std::make_unique<Workspace>(*model_, *trajectory_);
  Workspace& w = *work_;
  if (!(w.cached && w.cachedTime == t)) {
    w.cached = false;
    evaluateStored(t, w.Ttilde);  // range check before the dynamics
    w.lin.evaluate(t);
    if (identity_) {
      w.T = w.Ttilde;
      w.Ar = w.lin.data.A;
      w.Br = w.lin.data.B;
    } else {
      correct(t, w.Ttilde, w.T);
      w.AT.noalias() = w.lin.data.A * w.T;
      w.Ar.noalias() = w.T.transpose() * w.AT;
      w.Br.noalias() = w.T.transpose() * w.lin.data.B;
    }
    w.cached = true;
    w.cachedTime = t;
  }
  T = w.T;
  Ar = w.Ar;
  Br = w.Br;
}

Eigen::MatrixXd TangentBasisTrajectory::basis(double t) const {
  Eigen::MatrixXd T, Ar, Br;
  reducedLinearization(t, T, Ar, Br);
  return T;
}

Eigen::MatrixXd TangentBasisTrajectory::transportedBasis(double t) const {
  Eigen::MatrixXd T;
  evaluateStored(t, T);
  return T;
}

TangentBasisTrajectory transportTangentBasis(const Model& model, const Trajectory& reference,
                                             const TangentTransportOptions& options) {
  options.validate();
  reference.checkCompatible(model);
  if (!reference.hasStateDerivatives()) {
    throw std::logic_error(
        "transportTangentBasis: the trajectory has no state derivatives (call "
        "computeStateDerivatives)");
  }
  if (reference.size() < 2) {
    throw std::invalid_argument("transportTangentBasis: the trajectory needs at least 2 knots, got " +
                                std::to_string(reference.size()));
  }
  TangentBasisTrajectory out;
  out.model_ = &model;
  out.trajectory_ = std::make_shared<const Trajectory>(reference);
  out.nx_ = reference.nx();
  out.t0_ = reference.startTime();
  out.tf_ = reference.endTime();

  if (model.nc() == 0) {  // T = I: Ṫ = (I − I) A I = 0
    out.identity_ = true;
    out.d_ = out.nx_;
    return out;
  }

  // T(t0): the core's basis at x(t0).
  ReferenceLinearization start(model, *out.trajectory_);
  start.evaluate(out.t0_);  // throws (bad start) std::runtime_error naming t0
  const int d = computeConstraintTangentBasis(model, start.data);
  if (d == 0) {
    throw std::invalid_argument(
        "transportTangentBasis: the constraint manifold has no tangent directions at t0 = " +
        std::to_string(out.t0_));
  }
  out.d_ = d;
  const Eigen::Index N = static_cast<Eigen::Index>(out.nx_) * d;
  const Eigen::VectorXd y0 = Eigen::Map<const Eigen::VectorXd>(start.data.tangentBasis.data(), N);

  if (options.method == TangentTransport::kProjected) {
    // Steps stored as {t_{k+1}, T_k}: evaluateStored returns T_k on (t_k, t_{k+1}], and the query
    // correction polar(P(t) T_k) gives T_{k+1} at t_{k+1} (see the header).
    const Eigen::VectorXd& times = reference.times();
    Eigen::MatrixXd T = start.data.tangentBasis, Ttilde, C;
    out.stored_.reserve(static_cast<std::size_t>(times.size() - 1) * options.substeps + 1);
    out.stored_.push_back({out.t0_, Eigen::Map<const Eigen::VectorXd>(T.data(), N)});
    Eigen::JacobiSVD<Eigen::MatrixXd> svd;
    for (Eigen::Index k = 0; k + 1 < times.size() && out.message_.empty(); ++k) {
      for (int s = 1; s <= options.substeps; ++s) {
        const double t = times(k) + (times(k + 1) - times(k)) * s / options.substeps;
        out.stored_.push_back({t, Eigen::Map<const Eigen::VectorXd>(T.data(), N)});
        try {
          start.evaluate(t);
        } catch (const std::exception& e) {
          out.message_ = std::string("tangent basis transport: ") + e.what();
          out.stored_.pop_back();
          break;
        }
        const int dc = computeConstraintTangentBasis(model, start.data);
        const Eigen::MatrixXd& Tc = start.data.tangentBasis;
        C.noalias() = Tc.transpose() * T;
        if (dc != d) {
          out.message_ = "tangent basis transport: the tangent space changed dimension from " +
                         std::to_string(d) + " to " + std::to_string(dc) + " at t = " + std::to_string(t);
          out.stored_.pop_back();
          break;
        }
        svd.compute(C, Eigen::ComputeThinU | Eigen::ComputeThinV);
        if (!(svd.singularValues()(d - 1) > 1e-3)) {
          out.message_ = "tangent basis transport: the tangent space turned by more than the step "
                         "can follow at t = " + std::to_string(t) + " (use more substeps)";
          out.stored_.pop_back();
          break;
        }
        T = Tc * (svd.matrixU() * svd.matrixV().transpose());
        ++out.steps_;
      }
    }
  } else {
  TransportProblem problem(model, *out.trajectory_, d);
  ForwardResult r = integrateForward(problem, N, y0, out.t0_, out.tf_, options.rtol, options.atol,
                                     options.maxSteps, true, "tangent basis transport");
  out.stored_.reserve(r.steps.size());
  for (auto& s : r.steps) out.stored_.push_back({s.t, std::move(s.D)});
  out.message_ = r.message;
  out.steps_ = r.internalSteps;
  }

  // Seed maxCorrection with the knots inside the transported range.
  for (int k = 0; k < reference.size(); ++k) {
    const double tk = reference.times()(k);
    if (tk > out.validUntil()) break;
    try {
      out.basis(tk);
    } catch (const std::exception& e) {
      if (out.message_.empty()) {
        out.message_ = std::string("tangent basis transport: at knot ") + std::to_string(k + 1) +
                       ": " + e.what();
      }
      break;
    }
  }
  return out;
}

// ---- Manifold Riccati --------------------------------------------------------------------------

const std::string& ManifoldRiccatiSolution::message() const {
  if (!basis.ok()) return basis.message();
  return reduced.message;
}

Eigen::MatrixXd ManifoldRiccatiSolution::K(double t) const {
  return reduced.K(t) * basis.basis(t).transpose();
}

Eigen::MatrixXd ManifoldRiccatiSolution::S(double t) const {
  const Eigen::MatrixXd T = basis.basis(t);
  Eigen::MatrixXd S = T * reduced.S(t) * T.transpose();
  return 0.5 * (S + S.transpose());
}

ManifoldRiccatiSolution solveManifoldRiccati(const Model& model, const Trajectory& reference,
                                             const LqrWeights& weights,
                                             const RiccatiOptions& options,
                                             const TangentTransportOptions& transport) {
  options.validate();
  const int nx = reference.nx(), nu = reference.nu();
  checkWeightMatrix(weights.Qf, "Qf", nx, false);
  if (!weights.Qfun) checkWeightMatrix(weights.Q, "Q", nx, false);
  if (!weights.Rfun) checkWeightMatrix(weights.R, "R", nu, true);

  ManifoldRiccatiSolution sol;
  sol.basis = transportTangentBasis(model, reference, transport);
  if (!sol.basis.ok()) return sol;

  // One basis object serves the linearization and the Q callbacks (its cache gives one dynamics
  // evaluation per t); it is owned by the callbacks, which live on in sol.reduced.
  struct Shared {
    TangentBasisTrajectory basis;
    Eigen::MatrixXd T, Ar, Br, Q, QT;
  };
  auto sh = std::make_shared<Shared>();
  sh->basis = sol.basis;
  const int d = sol.basis.dimension();

  LinearizationCallback lin = [sh](double t, Eigen::MatrixXd& A, Eigen::MatrixXd& B) {
    sh->basis.reducedLinearization(t, sh->T, sh->Ar, sh->Br);
    A = sh->Ar;
    B = sh->Br;
  };
  LqrWeights reducedWeights;
  reducedWeights.R = weights.R;
  reducedWeights.Rfun = weights.Rfun;
  const Eigen::MatrixXd Qconst = weights.Q;
  const WeightCallback Qfull = weights.Qfun;
  reducedWeights.Qfun = [sh, Qconst, Qfull, nx](double t, Eigen::MatrixXd& Qr) {
    sh->basis.reducedLinearization(t, sh->T, sh->Ar, sh->Br);
    if (Qfull) {
      sh->Q.setZero(nx, nx);
      Qfull(t, sh->Q);
      if (sh->Q.rows() != nx || sh->Q.cols() != nx) {
        throw std::runtime_error("Q(t) callback returned " + std::to_string(sh->Q.rows()) + "x" +
                                 std::to_string(sh->Q.cols()) + ", expected " +
                                 std::to_string(nx) + "x" + std::to_string(nx));
      }
      sh->QT.noalias() = sh->Q * sh->T;
    } else {
      sh->QT.noalias() = Qconst * sh->T;
    }
    Qr.noalias() = sh->T.transpose() * sh->QT;
    for (Eigen::Index j = 0; j < Qr.cols(); ++j) {  // exactly symmetric: upper triangle mirrored
      for (Eigen::Index i = j + 1; i < Qr.rows(); ++i) Qr(i, j) = Qr(j, i);
    }
  };
  Eigen::MatrixXd Tf;
  try {
    Tf = sh->basis.basis(reference.endTime());
  } catch (const std::exception& e) {
    // The dynamics failed at tf: report it as a failed solve (nothing else can run).
    sol.reduced.status = RiccatiStatus::kCallbackFailure;
    sol.reduced.failureTime = reference.endTime();
    sol.reduced.message = std::string("manifold Riccati: basis at tf failed: ") + e.what();
    return sol;
  }
  reducedWeights.Qf = Tf.transpose() * weights.Qf * Tf;
  reducedWeights.Qf = 0.5 * (reducedWeights.Qf + reducedWeights.Qf.transpose()).eval();

  sol.reduced = solveRiccati(reference.startTime(), reference.endTime(), d, nu, lin,
                             reducedWeights, options);
  sol.basis = sh->basis;  // carries the corrections seen during the solve
  return sol;
}

// ---- Reachability Gramian (controllability.hpp) ------------------------------------------------

namespace {

/// Ẇ = Ar W + W Arᵀ + Br Brᵀ on the packed upper triangle of W (column by column), with the
/// exact Jacobian E ↦ Ar E + E Arᵀ.
struct GramianProblem {
  const TangentBasisTrajectory& basis;
  Eigen::Index d;
  Eigen::MatrixXd T, Ar, Br, W, F, G;
  double failTime = 0.0;
  std::string failMessage;

  GramianProblem(const TangentBasisTrajectory& b, Eigen::Index d_)
      : basis(b), d(d_), W(d_, d_), F(d_, d_), G(d_, d_) {}

  bool prepare(double t) {
    try {
      basis.reducedLinearization(t, T, Ar, Br);
    } catch (const std::exception& e) {
      if (failMessage.empty()) {
        failTime = t;
        failMessage = e.what();
      }
      return false;
    }
    return true;
  }

  static void unpack(const double* y, Eigen::Index n, Eigen::MatrixXd& S) {
    for (Eigen::Index j = 0; j < n; ++j) {
      const double* col = y + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) S(i, j) = S(j, i) = col[i];
    }
  }
  static void pack(const Eigen::MatrixXd& S, Eigen::Index n, double* y) {
    for (Eigen::Index j = 0; j < n; ++j) {
      double* col = y + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = S(i, j);
    }
  }

  bool rhs(double t, const double* y, double* ydot) {
    if (!prepare(t)) return false;
    unpack(y, d, W);
    F.noalias() = Ar * W;
    G.noalias() = Br * Br.transpose();
    for (Eigen::Index j = 0; j < d; ++j) {  // (ArW + (ArW)ᵀ + BrBrᵀ)_ij, i ≤ j
      double* col = ydot + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = F(i, j) + F(j, i) + G(i, j);
    }
    return true;
  }

  // Direction of the packed unknown w_ij (i ≤ j): E = e_i e_jᵀ + e_j e_iᵀ (i < j) or e_i e_iᵀ.
  // With a_k = Ar e_k: Ar E + E Arᵀ = a_i e_jᵀ + e_j a_iᵀ (+ a_j e_iᵀ + e_i a_jᵀ when i < j).
  bool jacobian(double t, const double*, double* J) {
    if (!prepare(t)) return false;
    const Eigen::Index N = d * (d + 1) / 2;
    for (Eigen::Index j = 0; j < d; ++j) {
      for (Eigen::Index i = 0; i <= j; ++i) {
        F.setZero();
        F.col(j) += Ar.col(i);
        F.row(j) += Ar.col(i).transpose();
        if (i != j) {
          F.col(i) += Ar.col(j);
          F.row(i) += Ar.col(j).transpose();
        }
        pack(F, d, J + (j * (j + 1) / 2 + i) * N);
      }
    }
    return true;
  }
};

}  // namespace

GramianReport computeControllabilityGramian(const Model& model, const Trajectory& reference,
                                            double t0, double t1,
                                            const TangentTransportOptions& options) {
  options.validate();
  if (!(t0 < t1) || !std::isfinite(t0) || !std::isfinite(t1)) {
    std::ostringstream m;
    m << "computeControllabilityGramian: need finite t0 < t1, got t0 = " << t0 << ", t1 = " << t1;
    throw std::invalid_argument(m.str());
  }
  reference.checkCompatible(model);
  if (reference.size() > 0 && (t0 < reference.startTime() || t1 > reference.endTime())) {
    std::ostringstream m;
    m << "computeControllabilityGramian: [" << t0 << ", " << t1
      << "] is not inside the trajectory's span [" << reference.startTime() << ", "
      << reference.endTime() << "]";
    throw std::invalid_argument(m.str());
  }
  GramianReport report;
  const TangentBasisTrajectory basis = transportTangentBasis(model, reference, options);
  report.dimension = basis.dimension();
  const Eigen::Index d = basis.dimension();
  report.W.setZero(d, d);
  if (basis.validUntil() < t1) {
    report.ok = false;
    report.message = "Gramian: " + basis.message();
    return report;
  }
  GramianProblem problem(basis, d);
  const Eigen::Index N = d * (d + 1) / 2;
  const ForwardResult r = integrateForward(problem, N, Eigen::VectorXd::Zero(N), t0, t1,
                                           options.rtol, options.atol, options.maxSteps, false,
                                           "Gramian integration");
  if (!r.message.empty()) {
    report.ok = false;
    report.message = r.message;
    return report;
  }
  GramianProblem::unpack(r.yEnd.data(), d, report.W);
  const Eigen::VectorXd ev =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(report.W, Eigen::EigenvaluesOnly).eigenvalues();
  report.minEigenvalue = ev(0);
  report.maxEigenvalue = ev(d - 1);
  report.ok = true;
  return report;
}

}  // namespace trellis
