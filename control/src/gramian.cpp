// gramian.cpp — the reduced reachability Gramian (controllability.hpp): the Lyapunov differential
// equation Ẇ = Ar W + W Arᵀ + Br Brᵀ on the one CVODES driver, with Newton by matrix-free GMRES on
// the exact Lyapunov product and the exact Newton-matrix solve as preconditioner — O(d³) per
// product or solve, where a dense Newton matrix on the N = d(d+1)/2 unknowns costs O(d⁶) per
// factorization.
#include "trellis/analysis/detail/ode_driver.hpp"
#include "riccati_lyapunov.hpp"
#include "trellis/control/controllability.hpp"
#include "trellis/core/trajectory.hpp"

#include <Eigen/Eigenvalues>

#include <cmath>
#include <complex>
#include <sstream>
#include <stdexcept>

namespace trellis {

void GramianOptions::validate() const {
  transport.validate();
  auto bad = [](const char* field, double v) {
    std::ostringstream m;
    m << "GramianOptions." << field << " = " << v << " must be > 0 and finite";
    throw std::invalid_argument(m.str());
  };
  if (!(rtol > 0.0) || !std::isfinite(rtol)) bad("rtol", rtol);
  if (!(atol > 0.0) || !std::isfinite(atol)) bad("atol", atol);
}

namespace {

/// Ẇ = Ar W + W Arᵀ + Br Brᵀ on the packed upper triangle of W (column by column).
/// A linear ODE (detail::LinearOdeSystem): J = the Lyapunov operator L(E) = Ar E + E Arᵀ (products
/// only), g = Br Brᵀ. Linear solver: the exact
/// solve of the Newton matrix, (I − γL) X = R, by detail::SchurLyapunov (real Schur form of Arᵀ,
/// Bartels–Stewart; shared with the Riccati solver).
class GramianSystem final : public detail::LinearOdeSystem {
 public:
  GramianSystem(const Model& model, const TangentBasisTrajectory& basis)
      : lin(model, basis), d(basis.dimension()), W(d, d), F(d, d), G(d, d), ArT(d, d), lyap(d) {}

  bool prepareAt(double t) override { return ready(t); }
  // Packed L(V) = Ar V + V Arᵀ, entries i ≤ j.
  void applyJacobian(detail::ConstVectorMap v, detail::VectorMap Jv) override {
    unpack(v.data(), W);
    F.noalias() = lin.Ar() * W;
    for (Eigen::Index j = 0; j < d; ++j) {
      double* col = Jv.data() + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = F(i, j) + F(j, i);
    }
  }
  // Packed Br Brᵀ.
  void addForcing(detail::VectorMap ydot) override {
    G.noalias() = lin.Br() * lin.Br().transpose();
    for (Eigen::Index j = 0; j < d; ++j) {
      double* col = ydot.data() + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] += G(i, j);
    }
  }
  bool hasPreconditioner() const override { return true; }
  // The Newton matrix I − γL acts on symmetric X as X − γ(ArX + XArᵀ): the Riccati solver's
  // Newton matrix with A_cl = Arᵀ, solved by the same real-Schur Bartels–Stewart (O(d³) per
  // factorization and per solve; riccati_lyapunov.hpp). The Schur form is refreshed only when
  // CVODES asks for a new Newton matrix (jacOk false); γ enters each solve.
  int preconditionerSetup(double t, detail::ConstVectorMap, detail::ConstVectorMap, bool jacOk,
                          bool* jacUpdated, double) override {
    if (!ready(t)) return -1;
    if (jacOk && haveSchur) {
      *jacUpdated = false;
      return 0;
    }
    ArT = lin.Ar().transpose();
    if (!lyap.factor(ArT)) {
      failure = "the Schur form of Ar did not converge";
      haveSchur = false;
      return 1;
    }
    haveSchur = true;
    *jacUpdated = true;
    return 0;
  }
  int preconditionerSolve(double, detail::ConstVectorMap, detail::ConstVectorMap,
                          detail::ConstVectorMap r, detail::VectorMap z, double gamma) override {
    unpack(r.data(), G);
    if (!lyap.solve(gamma, G)) return 1;  // (near) singular Newton matrix: smaller step
    for (Eigen::Index j = 0; j < d; ++j) {
      double* col = z.data() + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = 0.5 * (G(i, j) + G(j, i));
    }
    return 0;
  }

  void unpack(const double* y, Eigen::MatrixXd& S) const {
    for (Eigen::Index j = 0; j < d; ++j) {
      const double* col = y + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) S(i, j) = S(j, i) = col[i];
    }
  }

  ReducedLinearization lin;

 private:
  bool ready(double t) {
    const ReferenceStatus st = lin.evaluate(t);
    if (!st.ok()) failure = st.message;
    return st.ok();
  }
  Eigen::Index d;
  Eigen::MatrixXd W, F, G, ArT;
  detail::SchurLyapunov lyap;
  bool haveSchur = false;
};

}  // namespace

GramianReport computeControllabilityGramian(const Model& model, const Trajectory& reference,
                                            double t0, double t1, const GramianOptions& options) {
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
  const TangentBasisTrajectory basis = transportTangentBasis(model, reference, options.transport);
  report.dimension = basis.dimension();
  const Eigen::Index d = basis.dimension();
  report.W.setZero(d, d);
  if (basis.validUntil() < t1) {
    report.status.set(ControllabilityCode::kTransportFailure, "Gramian: " + basis.status().message,
                      basis.status().t);
    return report;
  }
  GramianSystem system(model, basis);
  const Eigen::Index N = d * (d + 1) / 2;
  // The Schur solve is exact for the Newton matrix (L depends on t only): the direct solver, no
  // Krylov iterations (a stale Schur form, from an earlier t, is CVODES's modified Newton).
  const detail::OdeOptions o = detail::makeOdeOptions(
      "Gramian integration", detail::OdeMethod::Bdf, detail::OdeLinearSolver::SystemSolve,
      options.rtol, options.atol, options.transport.maxSteps);
  detail::OdeDriver driver(system, N, o);
  driver.start(t0, Eigen::VectorXd::Zero(N));
  const detail::OdeStatus st = driver.advanceTo(t1);
  const detail::OdeStats stats = driver.stats();
  report.steps = stats.steps;
  report.linearizations = system.lin.evaluations();
  report.differenceQuotientEvaluations = stats.linearRhsEvaluations;
  if (!st.ok()) {
    report.status.set(ControllabilityCode::kIntegratorFailure, st.message, st.t);
    return report;
  }
  system.unpack(driver.state().data(), report.W);
  const Eigen::VectorXd ev =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(report.W, Eigen::EigenvaluesOnly).eigenvalues();
  report.minEigenvalue = ev(0);
  report.maxEigenvalue = ev(d - 1);
  report.status = {};
  return report;
}

GramianReport computeControllabilityGramian(const Model& model, const Trajectory& reference,
                                            double t0, double t1,
                                            const TangentTransportOptions& options) {
  GramianOptions g;
  g.transport = options;
  g.rtol = options.rtol;
  g.atol = options.atol;
  return computeControllabilityGramian(model, reference, t0, t1, g);
}

}  // namespace trellis
