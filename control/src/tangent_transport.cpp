// tangent_transport.cpp — transportTangentBasis: the parallel transport Ṫ = (I − P(t)) A(t) T on
// the one CVODES driver (kIntegrated), or the discrete projection on the knots (kProjected); then
// the corrected basis and its derivative at the nodes the held result interpolates.
#include "trellis/analysis/detail/ode_driver.hpp"
#include "trellis/core/reference.hpp"
#include "trellis/control/manifold_lqr.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>

#include <algorithm>
#include <sstream>
#include <stdexcept>

namespace trellis {

namespace {

/// Ṫ = (I − P(t)) A(t) T on vec(T) (column-major, 2n·d unknowns), P(t) = Tc Tcᵀ the orthogonal
/// projector onto the tangent space at x_ref(t) (P does not depend on which basis Tc). For T
/// tangent, (I − P)AT = ṖT (see the header), so the solution is the parallel transport; and the
/// equation is LINEAR in T, with the constant-in-T Jacobian
///   E ↦ (I − P) A E   (block diagonal: d copies of W = (I − P)A).
/// Why P(t) rather than TTᵀ: with TTᵀ, Ṫ = AT − T(TᵀAT) has the exact solution but a
/// non-orthonormal perturbation δT = T S (S symmetric) grows like −S·TᵀAT, i.e. with the NEGATED
/// tangent dynamics: on a stiff scene (the hand: damped modes at −1e4 s⁻¹) an unstable mode at
/// +1e4 s⁻¹. With P(t) a tangent perturbation obeys δṪ = (I − P)A δT ∈ normal space (bounded).
/// Newton: matrix-free GMRES with the exact product W V and the exact preconditioner
/// (I − γW)⁻¹ applied blockwise (one nx×nx LU per Newton-matrix update): GMRES converges in one
/// iteration and no difference quotient is ever taken.
class TransportSystem final : public detail::LinearOdeSystem {
 public:
  TransportSystem(const Model& m, const Trajectory& tr, Eigen::Index d)
      : point(m, tr), nx(tr.nx()), d(d), W(nx, nx), M(nx, nx), R(nx, d), lu(nx) {}

  /// W = (I − P)A at t (evaluated once per t: W depends on t only); the reference's status.
  ReferenceStatus prepare(double t) {
    if (prepared && t == preparedTime) return {};
    prepared = false;
    const ReferenceStatus st = point.linearizeWithTangentBasis(t, d);
    if (!st.ok()) return st;
    const Eigen::MatrixXd& Tc = point.tangentBasis();
    W = point.A();
    W.noalias() -= Tc * (Tc.transpose() * point.A());
    prepared = true;
    preparedTime = t;
    return st;
  }

  // Ẏ = W Y: a linear ODE (detail::LinearOdeSystem) without forcing.
  bool prepareAt(double t) override { return ready(t); }
  void applyJacobian(detail::ConstVectorMap v, detail::VectorMap Jv) override {
    Eigen::Map<Eigen::MatrixXd>(Jv.data(), nx, d).noalias() =
        W * Eigen::Map<const Eigen::MatrixXd>(v.data(), nx, d);
  }
  bool hasPreconditioner() const override { return true; }
  int preconditionerSetup(double t, detail::ConstVectorMap, detail::ConstVectorMap, bool,
                          bool* jacUpdated, double gamma) override {
    if (!ready(t)) return -1;
    M.setIdentity();
    M.noalias() -= gamma * W;
    lu.compute(M);
    *jacUpdated = true;
    return 0;
  }
  int preconditionerSolve(double, detail::ConstVectorMap, detail::ConstVectorMap,
                          detail::ConstVectorMap r, detail::VectorMap z, double) override {
    R = Eigen::Map<const Eigen::MatrixXd>(r.data(), nx, d);
    Eigen::Map<Eigen::MatrixXd>(z.data(), nx, d) = lu.solve(R);
    return 0;
  }

  ReferenceEvaluator point;
  Eigen::Index nx, d;
  Eigen::MatrixXd W, M, R;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu;

 private:
  bool ready(double t) {
    const ReferenceStatus st = prepare(t);
    if (!st.ok()) failure = st.message;
    return st.ok();
  }
  bool prepared = false;
  double preparedTime = 0.0;
};

/// The node times: the knots, each interval split into `substeps`.
std::vector<double> nodeGrid(const Eigen::VectorXd& times, int substeps) {
  std::vector<double> grid;
  grid.reserve(static_cast<std::size_t>(times.size() - 1) * substeps + 1);
  grid.push_back(times(0));
  for (Eigen::Index k = 0; k + 1 < times.size(); ++k) {
    for (int s = 1; s <= substeps; ++s) {
      grid.push_back(s == substeps ? times(k + 1)
                                   : times(k) + (times(k + 1) - times(k)) * s / substeps);
    }
  }
  return grid;
}

/// polar(P T̃) = Tc U Vᵀ (Tcᵀ T̃ = U Σ Vᵀ). False, with `why` set, when T̃ has drifted off the
/// tangent space.
bool correctOnto(const Eigen::MatrixXd& Tc, const Eigen::MatrixXd& Ttilde, double t,
                 Eigen::JacobiSVD<Eigen::MatrixXd>& svd, Eigen::MatrixXd& T, std::string& why) {
  svd.compute(Tc.transpose() * Ttilde, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const double smin = svd.singularValues()(svd.singularValues().size() - 1);
  if (!(smin > 1e-3)) {
    std::ostringstream m;
    m << "the tangent space turned by more than the transport can follow at t = " << t
      << " (smallest singular value of the projected basis " << smin << ")";
    why = m.str();
    return false;
  }
  T.noalias() = Tc * (svd.matrixU() * svd.matrixV().transpose());
  return true;
}

}  // namespace

TangentBasisTrajectory transportTangentBasis(const Model& model, const Trajectory& reference,
                                             const TangentTransportOptions& options) {
  options.validate();
  // The one check of the reference (names, supplied state derivatives), by its evaluator.
  ReferenceOptions checks;
  checks.stateDerivatives = ReferenceOptions::StateDerivatives::kRequireSupplied;
  checks.caller = "transportTangentBasis";
  ReferenceEvaluator start(model, reference, checks);
  if (reference.size() < 2) {
    throw std::invalid_argument("transportTangentBasis: the trajectory needs at least 2 knots, got " +
                                std::to_string(reference.size()));
  }
  TangentBasisTrajectory out;
  out.trajectory_ = std::make_shared<const Trajectory>(reference);
  out.nx_ = reference.nx();
  out.t0_ = reference.startTime();
  out.tf_ = reference.endTime();
  out.validUntil_ = out.tf_;
  out.status_ = {};

  if (model.nc() == 0) {  // T = I: Ṫ = (I − I) A I = 0
    out.identity_ = true;
    out.d_ = out.nx_;
    return out;
  }

  // T(t0): the core's basis at x(t0). Where the dynamics fail already there, there is no basis
  // anywhere: a status (hasBasis() false), like a failure later on.
  const ReferenceStatus first = start.linearizeWithTangentBasis(out.t0_);
  if (!first.ok()) {
    out.validUntil_ = out.t0_;
    out.status_.set(TransportCode::kDynamicsFailure,
                    "tangent basis transport: no basis at t0: " + first.message, out.t0_);
    return out;
  }
  const Eigen::Index d = start.tangentBasis().cols();
  if (d == 0) {
    throw std::invalid_argument(
        "transportTangentBasis: the constraint manifold has no tangent directions at t0 = " +
        std::to_string(out.t0_));
  }
  out.d_ = static_cast<int>(d);
  const Eigen::Index nx = out.nx_, N = nx * d;
  const std::vector<double> grid = nodeGrid(reference.times(), options.substeps);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd;
  Eigen::MatrixXd T = start.tangentBasis(), Ttilde(nx, d);

  // Stores node t with the corrected T there and Ṫ = (I − P)A T (point evaluated at t).
  auto addNode = [&](double t, const Eigen::MatrixXd& corrected, const ReferenceEvaluator& p,
                     const Eigen::MatrixXd& uncorrected) {
    const Eigen::MatrixXd AT = p.A() * corrected;
    out.nodeTimes_.push_back(t);
    out.nodeT_.push_back(corrected);
    out.nodeDT_.push_back(AT - p.tangentBasis() * (p.tangentBasis().transpose() * AT));
    out.nodeAr_.push_back(corrected.transpose() * AT);
    out.nodeBr_.push_back(corrected.transpose() * p.B());
    out.maxCorrection_ = std::max(out.maxCorrection_, (corrected - uncorrected).norm());
    out.validUntil_ = t;
  };
  out.nodeLinearization_ =
      options.linearization == ReducedLinearizationMode::kNodes ||
      (options.linearization == ReducedLinearizationMode::kAuto &&
       options.method == TangentTransport::kProjected);
  out.nodeTimes_.reserve(grid.size());
  out.nodeT_.reserve(grid.size());
  out.nodeDT_.reserve(grid.size());

  if (options.method == TangentTransport::kProjected) {
    // Steps stored as {t_{k+1}, T_k}: transportedBasis returns T_k on (t_k, t_{k+1}], and the
    // node at t_{k+1} holds T_{k+1} = polar(P_{k+1} T_k) (see the header).
    out.stored_.reserve(grid.size());
    out.stored_.append(out.t0_, Eigen::Map<const Eigen::VectorXd>(T.data(), N));
    addNode(grid[0], T, start, T);
    for (std::size_t i = 1; i < grid.size(); ++i) {
      const double t = grid[i];
      const ReferenceStatus st = start.linearizeWithTangentBasis(t, d);
      if (!st.ok()) {
        out.status_.set(TransportCode::kDynamicsFailure, "tangent basis transport: " + st.message, t);
        break;
      }
      std::string why;
      Ttilde = T;
      if (!correctOnto(start.tangentBasis(), Ttilde, t, svd, T, why)) {
        out.status_.set(TransportCode::kTurnedTooFast, "tangent basis transport: " + why, t);
        break;
      }
      out.stored_.append(t, Eigen::Map<const Eigen::VectorXd>(Ttilde.data(), N));
      addNode(t, T, start, Ttilde);
      ++out.steps_;
    }
    return out;
  }

  TransportSystem system(model, *out.trajectory_, d);
  const detail::OdeOptions o = detail::makeOdeOptions(
      "tangent basis transport", detail::OdeMethod::Bdf, detail::OdeLinearSolver::Gmres,
      options.rtol, options.atol, options.maxSteps);
  detail::OdeDriver driver(system, N, o);
  driver.start(out.t0_, Eigen::Map<const Eigen::VectorXd>(T.data(), N));
  out.stored_.append(out.t0_, Eigen::Map<const Eigen::VectorXd>(T.data(), N));
  addNode(grid[0], T, start, T);
  Eigen::VectorXd dky(N);
  for (std::size_t i = 1; i < grid.size() && out.status_.ok(); ++i) {
    const double tn = grid[i];
    while (driver.time() < tn) {
      const detail::OdeStatus st = driver.step(tn);
      if (!st.ok()) {
        std::string why = st.message;
        if (st.flag == -1) why += " (more than maxSteps = " + std::to_string(o.maxSteps) + " steps)";
        out.status_.set(TransportCode::kIntegratorFailure, std::move(why), st.t);
        break;
      }
      if (!driver.state().allFinite()) {
        out.status_.set(TransportCode::kNonFinite, "tangent basis transport became non-finite", st.t);
        break;
      }
      const int q = driver.stats().lastOrder;
      Eigen::MatrixXd D(N, q + 1);
      for (int k = 0; k <= q; ++k) driver.interpolate(st.t, k, dky), D.col(k) = dky;
      out.stored_.append(st.t, std::move(D));
    }
    if (!out.status_.ok()) break;
    Ttilde = Eigen::Map<const Eigen::MatrixXd>(driver.state().data(), nx, d);
    const ReferenceStatus st = system.prepare(tn);
    if (!st.ok()) {
      out.status_.set(TransportCode::kDynamicsFailure, "tangent basis transport: " + st.message, tn);
      break;
    }
    std::string why;
    if (!correctOnto(system.point.tangentBasis(), Ttilde, tn, svd, T, why)) {
      out.status_.set(TransportCode::kTurnedTooFast, "tangent basis transport: " + why, tn);
      break;
    }
    addNode(tn, T, system.point, Ttilde);
  }
  const detail::OdeStats stats = driver.stats();
  out.steps_ = stats.steps;
  out.linearRhsEvaluations_ = stats.linearRhsEvaluations;
  return out;
}

}  // namespace trellis
