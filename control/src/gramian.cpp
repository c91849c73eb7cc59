// gramian.cpp — the reduced reachability Gramian (controllability.hpp): the Lyapunov differential
// equation Ẇ = Ar W + W Arᵀ + Br Brᵀ on the one CVODES driver, with Newton by matrix-free GMRES on
// the exact Lyapunov product and the exact Newton-matrix solve as preconditioner — O(d³) per
// product or solve, where a dense Newton matrix on the N = d(d+1)/2 unknowns costs O(d⁶) per
// factorization.
#include "ode_driver.hpp"
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
/// Jacobian: the Lyapunov operator L(E) = Ar E + E Arᵀ (products only). Preconditioner: the exact
/// solve of the Newton matrix, (I − γL) X = R. With the complex Schur form Ar = U Tu Uᴴ (once per
/// Newton-matrix update) and X = U Y Uᴴ this is M Y + Y Mᴴ = Uᴴ R U, M = ½I − γTu upper
/// triangular, solved column by column from the last: (M + conj(M_jj) I) y_j = c_j −
/// Σ_{k>j} conj(M_jk) y_k (back substitution; Bartels–Stewart).
class GramianSystem final : public detail::OdeSystem {
 public:
  GramianSystem(const Model& model, const TangentBasisTrajectory& basis)
      : lin(model, basis), d(basis.dimension()), W(d, d), F(d, d), G(d, d), Y(d, d), C(d, d),
        Mj(d, d), c(d) {}

  int rhs(double t, detail::ConstVectorMap y, detail::VectorMap ydot) override {
    if (!ready(t)) return -1;
    unpack(y.data(), W);
    F.noalias() = lin.Ar() * W;
    G.noalias() = lin.Br() * lin.Br().transpose();
    for (Eigen::Index j = 0; j < d; ++j) {  // (ArW + (ArW)ᵀ + BrBrᵀ)_ij, i ≤ j
      double* col = ydot.data() + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = F(i, j) + F(j, i) + G(i, j);
    }
    return 0;
  }
  bool hasJacTimes() const override { return true; }
  int jacTimesSetup(double t, detail::ConstVectorMap, detail::ConstVectorMap) override {
    return ready(t) ? 0 : -1;
  }
  int jacTimes(double t, detail::ConstVectorMap, detail::ConstVectorMap, detail::ConstVectorMap v,
               detail::VectorMap Jv) override {
    if (!ready(t)) return -1;
    unpack(v.data(), W);
    F.noalias() = lin.Ar() * W;
    for (Eigen::Index j = 0; j < d; ++j) {
      double* col = Jv.data() + j * (j + 1) / 2;
      for (Eigen::Index i = 0; i <= j; ++i) col[i] = F(i, j) + F(j, i);
    }
    return 0;
  }
  bool hasPreconditioner() const override { return true; }
  int preconditionerSetup(double t, detail::ConstVectorMap, detail::ConstVectorMap, bool jacOk,
                          bool* jacUpdated, double g) override {
    if (!ready(t)) return -1;
    if (!(jacOk && schurTime == t && haveSchur)) {
      schur.compute(lin.Ar().cast<std::complex<double>>());
      if (schur.info() != Eigen::Success) {
        failure = "the Schur form of Ar did not converge";
        return 1;
      }
      haveSchur = true;
      schurTime = t;
      *jacUpdated = true;
    } else {
      *jacUpdated = false;
    }
    gamma = g;
    return 0;
  }
  int preconditionerSolve(double, detail::ConstVectorMap, detail::ConstVectorMap,
                          detail::ConstVectorMap r, detail::VectorMap z, double) override {
    const auto& U = schur.matrixU();
    const auto& Tu = schur.matrixT();
    unpack(r.data(), W);
    C.noalias() = U.adjoint() * W.cast<std::complex<double>>() * U;
    for (Eigen::Index j = d; j-- > 0;) {
      // rhs c_j − Σ_{k>j} conj(M_jk) y_k with M = ½I − γTu (off-diagonal: −γTu).
      c = C.col(j);
      for (Eigen::Index k = j + 1; k < d; ++k) c += gamma * std::conj(Tu(j, k)) * Y.col(k);
      // (M + conj(M_jj) I), upper triangular.
      const std::complex<double> shift = 0.5 - gamma * std::conj(Tu(j, j));
      Mj.noalias() = (-gamma) * Tu;
      Mj.triangularView<Eigen::StrictlyLower>().setZero();
      Mj.diagonal().array() += 0.5 + shift;
      for (Eigen::Index i = 0; i < d; ++i) {
        if (std::abs(Mj(i, i)) < 1e-14) return 1;  // (near) singular Newton matrix: smaller step
      }
      Mj.triangularView<Eigen::Upper>().solveInPlace(c);
      Y.col(j) = c;
    }
    G = (U * Y * U.adjoint()).real();
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
    try {
      lin.evaluate(t);
      return true;
    } catch (const std::exception& e) {
      failure = e.what();
      return false;
    }
  }
  Eigen::Index d;
  Eigen::MatrixXd W, F, G;
  Eigen::MatrixXcd Y, C, Mj;
  Eigen::VectorXcd c;
  Eigen::ComplexSchur<Eigen::MatrixXcd> schur;
  bool haveSchur = false;
  double schurTime = 0.0, gamma = 0.0;
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
    report.ok = false;
    report.message = "Gramian: " + basis.message();
    return report;
  }
  GramianSystem system(model, basis);
  const Eigen::Index N = d * (d + 1) / 2;
  detail::OdeOptions o;
  o.method = detail::OdeMethod::Bdf;
  o.linearSolver = detail::OdeLinearSolver::Gmres;
  o.rtol = options.rtol;
  o.atol = options.atol;
  o.maxSteps = options.transport.maxSteps;
  o.what = "Gramian integration";
  detail::OdeDriver driver(system, N, o);
  driver.start(t0, Eigen::VectorXd::Zero(N));
  const detail::OdeStatus st = driver.advanceTo(t1);
  const detail::OdeStats stats = driver.stats();
  report.steps = stats.steps;
  report.linearizations = system.lin.evaluations();
  report.differenceQuotientEvaluations = stats.linearRhsEvaluations;
  if (!st.ok()) {
    report.ok = false;
    report.message = st.message;
    return report;
  }
  system.unpack(driver.state().data(), report.W);
  const Eigen::VectorXd ev =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(report.W, Eigen::EigenvaluesOnly).eigenvalues();
  report.minEigenvalue = ev(0);
  report.maxEigenvalue = ev(d - 1);
  report.ok = true;
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
