// transcription.cpp — the direct-collocation NLP (layout and formulas in transcription.hpp).
#include "trellis/optimization/transcription.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/dynamics.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/numdiff.hpp"
#include "trellis/core/second_order.hpp"

#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

namespace trellis {

namespace {

/// Writes the Jacobian in triplet form: in structure mode it records (row, col) and ignores the
/// value; in value mode it writes the values in the same order. One routine for both keeps the
/// pattern and the values consistent by construction.
struct TripletWriter {
  bool structure = false;
  std::vector<int>* rows = nullptr;
  std::vector<int>* cols = nullptr;
  double* values = nullptr;
  int next = 0;
  void put(int r, int c, double v) {
    if (structure) {
      rows->push_back(r);
      cols->push_back(c);
    } else {
      values[next++] = v;
    }
  }
};

/// Whether some constraint row of `model` is nonholonomic (a knife edge): its third-derivative
/// terms then come from the recorded implicit residual (Impl::thirdTerm).
bool anyNonholonomic(const Model& model) {
  for (const auto& c : model.constraints())
    if (!c.holonomic()) return true;
  return false;
}

}  // namespace

namespace {
// Radau IIA, 3 stages (Hairer & Wanner, Solving ODEs II, Table IV.5.6): nodes c and matrix A; the
// weights b are A's last row (stiffly accurate: the last stage is the step's end).
const double kSqrt6 = std::sqrt(6.0);
const double kRadauC[3] = {(4.0 - kSqrt6) / 10.0, (4.0 + kSqrt6) / 10.0, 1.0};
const double kRadauA[3][3] = {
    {(88.0 - 7.0 * kSqrt6) / 360.0, (296.0 - 169.0 * kSqrt6) / 1800.0, (-2.0 + 3.0 * kSqrt6) / 225.0},
    {(296.0 + 169.0 * kSqrt6) / 1800.0, (88.0 + 7.0 * kSqrt6) / 360.0, (-2.0 - 3.0 * kSqrt6) / 225.0},
    {(16.0 - kSqrt6) / 36.0, (16.0 + kSqrt6) / 36.0, 1.0 / 9.0}};
}  // namespace

struct Transcription::Impl {
  OptimalControlProblem problem;
  DerivativeMode derivatives;
  bool implicit;           // DynamicsForm::kImplicit: per point [x; u; q̈; λ] and the rows r = 0, c = 0
  bool accelerationCost;   // problem.accelerationWeights given (implicit form only: validate())
  mutable Eigen::VectorXd costError, costQe, costRu;  // cost(): x − x_g, Q e (or Qf e), R u (nx, nx, m)
  const Model& model;
  int n, nx, m, nc, N, P;
  int ncH;                 // holonomic rows (h rows and γ slack); all nc rows get A q̇ rows and μ
  std::vector<int> holonomicRows;
  bool nonholonomic = false;
  Eigen::VectorXd tau;     // mesh τ_k (N)
  int intervalRows;        // rows per interval block: nx (trapezoidal), 2nx + m (Hermite–Simpson),
                           // 3nx + 2m (Radau: the end stage's defect first, then stages 1, 2, the inputs)
  bool hermiteSimpson, radau, freeT;
  int perInterval;         // points per interval after its first knot: 1, 2 (HS), 3 (Radau)
  int stride;         // nx + m: one point's variables
  int slackStart;     // first slack variable
  int horizonIdx;     // −1 when fixed
  int numVars, numCons, defectRows;
  int dynStart = 0, dynRows = 0;  // implicit: rows [r; c] (n + nc) per point from dynStart on
  std::vector<int> forceRows;  // constraint rows r with a finite bound on λ_r (nF of them)
  int nF = 0, forceStart = 0;  // nF rows per point, from row forceStart on (point by point)
  // Every force row j at a point is c_jᵀλ: unit rows for forceRows, then the problem's
  // forceCombinations; bounds [forceLo_j, forceHi_j]. CF (nF×nc), per-point scratch CDL (nF×stride).
  Eigen::MatrixXd CF;
  Eigen::VectorXd forceLo, forceHi;
  mutable Eigen::MatrixXd CDL;  // scratch of the const evaluations
  mutable Eigen::VectorXd forceValues;

  std::vector<int> jacRows, jacCols;

  Data data;
  // Cache of the last point at which the dynamics were evaluated.
  Eigen::VectorXd cachedZ;
  bool haveDynamics = false, haveLinearization = false;
  Eigen::MatrixXd F;                        // nx×P: f at every point
  std::vector<Eigen::MatrixXd> Ap, Bp;      // P blocks: ∂f/∂x (nx×nx), ∂f/∂u (nx×m)
  Eigen::MatrixXd Lam;                      // nc×P: λ at every point (with force bounds)
  std::vector<Eigen::MatrixXd> DL;          // P blocks nc×(nx + m): ∂λ/∂[x; u] (with force bounds)
  Eigen::MatrixXd hValue;                   // nc×N: h(q_k)
  std::vector<Eigen::MatrixXd> Ac, Avq;     // N blocks nc×n: A_c(q_k), ∂(A_c q̇)/∂q at knot k
  // N·nc blocks n×n: S_r(q_k)(i, j) = ∂A_{r,i}/∂q_j (= ∇²h_r for a holonomic row)
  std::vector<Eigen::MatrixXd> hessian;
  Eigen::MatrixXd slackTop, slackBottom;    // n×n: Σ γ_r ∇²h_r, Σ μ_r ∇²h_r (scratch)
  Eigen::VectorXd q, dq, u;
  // Implicit form: the point's q̈ and λ, the core's residuals and derivatives, per point the
  // residuals R (n + nc)×P and their Jacobian DR (n + nc)×stride.
  Eigen::VectorXd acc, lam;
  ImplicitDynamics idyn;
  Eigen::MatrixXd R;
  std::vector<Eigen::MatrixXd> DR;
  NumDiffWorkspace numdiff;
  Eigen::MatrixXd fdJ;  // n×(2n + m)
  std::string error;
  long dynamicsCount = 0, linearizationCount = 0, secondOrderCount = 0;

  // ---- Lagrangian Hessian (lower triangle, structure fixed at construction) -------------------
  std::vector<int> hessRows, hessCols;
  Data hessData;
  SecondOrderWorkspace secondOrder;
  std::vector<Eigen::MatrixXd> Hp;          // P blocks stride×stride: ∇² w.r.t. [x_p; u_p]
  Eigen::MatrixXd C;                        // nx×P: Σ_d (coefficient of f_p in defect d) μ_d
  Eigen::MatrixXd Hz;                       // (2n + m)×(2n + m): one contraction
  Eigen::MatrixXd slackCross;               // (ncH + nc)×n per interval, stacked: ∂²L/∂s∂q_b
  Eigen::VectorXd horizonRow;               // P·stride: ∂²L/∂T∂z_p
  Eigen::VectorXd hq, hdq, hu, hw, hwScaled, stateError, noRho, rhoPoint;
  // The implicit form's per-point blocks ∇²_z (νᵀr + ηᵀc) ((2n + m)×(2n + m)) and ∂²/∂y∂[q; q̇]
  // ((n + nc)×2n) with their status, computed on `threads` lanes (setThreads); each lane owns a
  // Worker (a Data, a second-order workspace and its buffers).
  int threads = 1;
  std::vector<Eigen::MatrixXd> HzzP, HyzP;
  std::vector<DynamicsStatus> statusP;
  std::vector<char> activeP;
  struct Worker {
    Worker(const Model& model, int n, int m, int nc, bool recording)
        : data(model), secondOrder(model, false, recording), q(n), dq(n), u(m), acc(n), lam(nc), nu(n), eta(nc), hw(n),
          thirdV(n), Hz(Eigen::MatrixXd::Zero(2 * n + m, 2 * n + m)), HzzI(Eigen::MatrixXd::Zero(2 * n + m, 2 * n + m)),
          HyzI(Eigen::MatrixXd::Zero(n + nc, 2 * n)), sumS(n, n), third(n, n), scratch(n, n) {}
    Data data;
    SecondOrderWorkspace secondOrder;
    Eigen::VectorXd q, dq, u, acc, lam, nu, eta, hw, thirdV;
    Eigen::MatrixXd Hz, HzzI, HyzI, sumS, third, scratch;
  };
  std::vector<std::unique_ptr<Worker>> workers;  // workers[w] serves lane w (grown to `threads`)
  // The third-derivative terms of the knots as tasks: computed on the lanes, added in the serial
  // order (thirdDerivatives, applyThird).
  struct ThirdTask {
    int k = 0;                     // knot
    const double* v = nullptr;     // the velocity-like vector
    Eigen::VectorXd rho;           // the rows' weights
    double scale = 0.0;
    bool skip = true;              // v = 0 or ρ = 0: no term
    DynamicsStatus status;
    bool finite = true;
    Eigen::MatrixXd increment;     // n×n, added to the point's q–q block
  };
  std::vector<ThirdTask> thirdTasks;
  // knotConstraintHessians' per-knot outcome (gathered in knot order).
  std::vector<std::string> knotFailure;
  std::vector<char> knotOk;
  std::vector<long> knotLinearizations;
  /// Lanes for `items` independent pieces of work: at most `threads`, at least 1.
  int lanesFor(int items) const { return std::max(1, std::min(threads, items)); }
  void growWorkers(int count) {
    // Recording as the transcription's own workspace: the implicit form and knife edges need it.
    while (static_cast<int>(workers.size()) < count)
      workers.push_back(std::make_unique<Worker>(model, n, m, nc, implicit || nonholonomic));
  }
  /// Runs lane(w) for w = 0 … count − 1, lane 0 on the calling thread; lanes no thread could be
  /// started for (the system's limit) run there too, so every lane's work is done.
  template <class Lane>
  static void onLanes(int count, const Lane& lane) {
    std::vector<std::thread> pool;
    int started = 1;
    try {
      for (; started < count; ++started) pool.emplace_back(lane, started);
    } catch (const std::system_error&) {
    }
    lane(0);
    for (int w = started; w < count; ++w) lane(w);
    for (std::thread& t : pool) t.join();
  }
  Eigen::VectorXd zeroN, zeroNc;  // nonholonomic: q̇ = 0, λ = 0, ν = 0 (thirdTerm)

  Impl(OptimalControlProblem p, DerivativeMode mode)
      : problem((p.validate(), std::move(p))),
        derivatives(mode),
        implicit(problem.dynamics == DynamicsForm::kImplicit),
        accelerationCost(problem.accelerationWeights.size() > 0),
        model(*problem.model),
        n(model.nq()),
        nx(2 * n),
        m(model.nu()),
        nc(model.nc()),
        N(problem.knots),
        P(problem.method == CollocationMethod::kHermiteSimpson ? 2 * problem.knots - 1
          : problem.method == CollocationMethod::kRadau      ? 3 * problem.knots - 2
                                                             : problem.knots),
        hermiteSimpson(problem.method == CollocationMethod::kHermiteSimpson),
        radau(problem.method == CollocationMethod::kRadau),
        freeT(problem.freeHorizon()),
        perInterval(hermiteSimpson ? 2 : radau ? 3 : 1),
        stride(2 * model.nq() + model.nu() + (implicit ? model.nq() + model.nc() : 0)),
        data(model),
        numdiff(model),
        hessData(model),
        secondOrder(model, false, problem.dynamics == DynamicsForm::kImplicit || anyNonholonomic(model)) {
    for (int r = 0; r < nc; ++r) {
      if (model.constraints()[r].holonomic()) {
        holonomicRows.push_back(r);
      } else {
        nonholonomic = true;
      }
    }
    ncH = static_cast<int>(holonomicRows.size());
    tau = problem.meshFractions();
    slackStart = P * stride;
    const int slackVars = (N - 1) * (ncH + nc);
    horizonIdx = freeT ? slackStart + slackVars : -1;
    numVars = slackStart + slackVars + (freeT ? 1 : 0);
    intervalRows = hermiteSimpson ? 2 * nx + m : radau ? 3 * nx + 2 * m : nx;
    defectRows = (N - 1) * intervalRows;
    for (int r = 0; r < nc; ++r) {
      if (std::isfinite(problem.forceLower(r)) || std::isfinite(problem.forceUpper(r))) forceRows.push_back(r);
    }
    const int nBox = static_cast<int>(forceRows.size());
    const int nComb = static_cast<int>(problem.forceCombinations.size());
    nF = nBox + nComb;
    CF = Eigen::MatrixXd::Zero(nF, nc);
    forceLo.resize(nF);
    forceHi.resize(nF);
    for (int j = 0; j < nBox; ++j) {
      CF(j, forceRows[j]) = 1.0;
      forceLo(j) = problem.forceLower(forceRows[j]);
      forceHi(j) = problem.forceUpper(forceRows[j]);
    }
    for (int j = 0; j < nComb; ++j) {
      CF.row(nBox + j) = problem.forceCombinations[j].coefficients.transpose();
      forceLo(nBox + j) = problem.forceCombinations[j].lower;
      forceHi(nBox + j) = problem.forceCombinations[j].upper;
    }
    CDL = Eigen::MatrixXd::Zero(nF, stride);
    forceValues = Eigen::VectorXd::Zero(nF);
    forceStart = defectRows + N * (ncH + nc);
    numCons = forceStart + P * nF;
    if (implicit) {
      if (derivatives == DerivativeMode::kFiniteDifference)
        throw ProblemError("dynamics: the implicit form has exact derivatives only (no finite-difference mode)");
      dynStart = numCons;
      dynRows = n + nc;
      numCons += P * dynRows;
      acc = Eigen::VectorXd::Zero(n);
      lam = Eigen::VectorXd::Zero(nc);
      idyn = ImplicitDynamics(model);
      R = Eigen::MatrixXd::Zero(dynRows, P);
      DR.assign(P, Eigen::MatrixXd::Zero(dynRows, stride));
    }

    cachedZ = Eigen::VectorXd::Constant(numVars, std::numeric_limits<double>::quiet_NaN());
    F = Eigen::MatrixXd::Zero(nx, P);
    Ap.assign(P, Eigen::MatrixXd::Zero(nx, nx));
    Bp.assign(P, Eigen::MatrixXd::Zero(nx, m));
    Lam = Eigen::MatrixXd::Zero(nc, P);
    DL.assign(nF > 0 ? P : 0, Eigen::MatrixXd::Zero(nc, nx + m));
    hValue = Eigen::MatrixXd::Zero(nc, N);
    Ac.assign(N, Eigen::MatrixXd::Zero(nc, n));
    Avq.assign(N, Eigen::MatrixXd::Zero(nc, n));
    hessian.assign(static_cast<std::size_t>(N) * nc, Eigen::MatrixXd::Zero(n, n));
    slackTop = Eigen::MatrixXd::Zero(n, n);
    slackBottom = Eigen::MatrixXd::Zero(n, n);
    q.resize(n); dq.resize(n); u.resize(m);
    fdJ.resize(n, nx + m);

    // The pattern: run the value routine in structure mode (values are not looked at).
    const Eigen::VectorXd z = initialGuessVector();
    TripletWriter w;
    w.structure = true;
    w.rows = &jacRows;
    w.cols = &jacCols;
    writeJacobian(z.data(), w);
    setUpHessian();
  }

  double horizonOf(const double* z) const { return freeT ? z[horizonIdx] : problem.horizon; }
  int knotPoint(int k) const { return perInterval * k; }
  double pointFraction(int p) const {
    const int k = p / perInterval, i = p % perInterval;
    if (i == 0) return tau(k);
    return tau(k) + (radau ? kRadauC[i - 1] : 0.5) * intervalFraction(k);
  }
  double pointTime(int p, double T) const { return T * pointFraction(p); }
  double intervalFraction(int k) const { return tau(k + 1) - tau(k); }  // h_k / T
  int slackOf(int k) const { return slackStart + k * (ncH + nc); }       // γ_k (ncH), then μ_k (nc)
  int knotRow(int k) const { return defectRows + k * (ncH + nc); }        // h rows, then A q̇ rows

  std::string describePoint(int p, double T) const {
    std::ostringstream s;
    if (p % perInterval != 0) {
      if (radau) s << "stage " << p % perInterval << " of interval " << p / perInterval;
      else s << "midpoint of interval " << p / 2;
    } else {
      s << "knot " << p / perInterval;
    }
    s << " (t = " << pointTime(p, T) << ")";
    return s.str();
  }

  Eigen::VectorXd initialGuessVector() const {
    Eigen::VectorXd z = Eigen::VectorXd::Zero(numVars);
    const double T = problem.horizon;
    for (int p = 0; p < P; ++p) {
      const double s = pointFraction(p);
      Eigen::VectorXd x(nx), uu(m);
      if (problem.initialGuess) {
        // Linear interpolation of the guess's knots, its time span mapped onto [0, T].
        const Trajectory& g = *problem.initialGuess;
        const double t = g.startTime() + s * (g.endTime() - g.startTime());
        int k = 0;
        while (k + 2 < g.size() && g.times()(k + 1) <= t) ++k;
        if (g.size() == 1) {
          x = g.states().col(0);
          uu = g.inputs().col(0);
        } else if (g.hasStateDerivatives()) {
          // A guess with knot derivatives (a previous solution, mesh refinement): the readers'
          // Hermite spline for the state, linear input.
          g.evaluate(std::clamp(t, g.startTime(), g.endTime()), x, uu);
        } else {
          const double a = std::clamp((t - g.times()(k)) / (g.times()(k + 1) - g.times()(k)), 0.0, 1.0);
          x = (1 - a) * g.states().col(k) + a * g.states().col(k + 1);
          uu = (1 - a) * g.inputs().col(k) + a * g.inputs().col(k + 1);
        }
      } else {
        x = (1 - s) * problem.initialState + s * problem.finalState;
        uu.setZero();
      }
      x = x.cwiseMax(problem.stateLower).cwiseMin(problem.stateUpper);
      uu = uu.cwiseMax(problem.inputLower).cwiseMin(problem.inputUpper);
      z.segment(p * stride, nx) = x;
      z.segment(p * stride + nx, m) = uu;
    }
    // Fixed boundary entries exactly at their values.
    const int last = knotPoint(N - 1) * stride;
    for (int i = 0; i < nx; ++i) {
      if (problem.initialFixed[i]) z(i) = problem.initialState(i);
      if (problem.finalFixed[i]) z(last + i) = problem.finalState(i);
    }
    if (freeT) z(horizonIdx) = T;
    if (implicit) {
      // q̈ of the guess: the slope of its velocities between the neighbouring points (so the
      // velocity defects start near zero), and λ the least-squares balance Aᵀλ ≈ M q̈ + b at the
      // guess's u: what the guess leaves unbalanced starts in the equations of motion, in force
      // units, not in the defects. (The forward dynamics' q̈ of a guess that is no equilibrium is
      // ~10⁴ rad/s² on a light phalanx: defects of that size.) Where the dynamics cannot be
      // evaluated at the guess, λ = 0.
      Data guessData(model);
      for (int p = 0; p < P; ++p) {
        const int a = std::max(0, p - 1), b = std::min(P - 1, p + 1);
        const double dt = T * (pointFraction(b) - pointFraction(a));
        const Eigen::VectorXd qdd = (z.segment(b * stride + n, n) - z.segment(a * stride + n, n)) / dt;
        z.segment(p * stride + nx + m, n) = qdd;
        const Eigen::VectorXd x = z.segment(p * stride, nx), uu = z.segment(p * stride + nx, m);
        const DynamicsStatus st = computeDynamics(model, guessData, x.head(n), x.tail(n), uu);
        if (nc > 0 && st.ok()) {
          const Eigen::VectorXd rhs = guessData.M * qdd + guessData.bias;
          const Eigen::VectorXd lambda =
              guessData.constraintJacobian.transpose().completeOrthogonalDecomposition().solve(rhs);
          if (lambda.allFinite()) z.segment(p * stride + nx + m + n, nc) = lambda;
        }
      }
      for (int i = 0; i < n && !problem.initialAccelerationFixed.empty(); ++i)
        if (problem.initialAccelerationFixed[i]) z(nx + m + i) = 0.0;
      for (int i = 0; i < n && !problem.finalAccelerationFixed.empty(); ++i)
        if (problem.finalAccelerationFixed[i]) z(knotPoint(N - 1) * stride + nx + m + i) = 0.0;
    }
    return z;
  }

  void bounds(Eigen::VectorXd& lower, Eigen::VectorXd& upper) const {
    constexpr double inf = std::numeric_limits<double>::infinity();
    lower = Eigen::VectorXd::Constant(numVars, -inf);
    upper = Eigen::VectorXd::Constant(numVars, inf);
    for (int p = 0; p < P; ++p) {
      lower.segment(p * stride, nx) = problem.stateLower;
      upper.segment(p * stride, nx) = problem.stateUpper;
      lower.segment(p * stride + nx, m) = problem.inputLower;
      upper.segment(p * stride + nx, m) = problem.inputUpper;
    }
    const int last = knotPoint(N - 1) * stride;
    for (int i = 0; i < nx; ++i) {
      if (problem.initialFixed[i]) lower(i) = upper(i) = problem.initialState(i);
      if (problem.finalFixed[i]) lower(last + i) = upper(last + i) = problem.finalState(i);
    }
    // Flagged accelerations at the end knots: q̈_i (implicit form, after x and u in the point's block) = 0.
    for (int i = 0; i < n && !problem.initialAccelerationFixed.empty(); ++i)
      if (problem.initialAccelerationFixed[i]) lower(nx + m + i) = upper(nx + m + i) = 0.0;
    for (int i = 0; i < n && !problem.finalAccelerationFixed.empty(); ++i)
      if (problem.finalAccelerationFixed[i]) lower(last + nx + m + i) = upper(last + nx + m + i) = 0.0;
    if (freeT) {
      lower(horizonIdx) = problem.minHorizon;
      upper(horizonIdx) = problem.maxHorizon;
    }
  }

  // ---- Core evaluations ------------------------------------------------------------------------

  bool statusOk(const DynamicsStatus& status, int p, double T) {
    if (status.ok() && data.qdd.allFinite()) return true;
    error = "the dynamics failed at " + describePoint(p, T) + ": " +
            (status.message.empty() ? std::string("non-finite q''") : status.message);
    return false;
  }

  /// ∂q̈/∂[x; u] by central differences of computeDynamics (DerivativeMode::kFiniteDifference;
  /// the core's numdiff, step ε^(1/3)·max(1, |v|)).
  bool finiteDifferenceBlocks(int p, double T) {
    dynamicsCount += 2 * (nx + m);
    const DynamicsStatus status = differenceDynamics(model, data, q, dq, u, NumDiffOptions{}, numdiff, fdJ);
    if (!status.ok()) {
      error = "the finite-difference dynamics failed at " + describePoint(p, T) + ": " + status.message;
      return false;
    }
    Eigen::MatrixXd& A = Ap[p];
    Eigen::MatrixXd& B = Bp[p];
    A.setZero();
    A.topRightCorner(n, n).setIdentity();
    A.bottomRows(n) = fdJ.leftCols(nx);
    B.setZero();
    B.bottomRows(n) = fdJ.rightCols(m);
    return true;
  }

  /// ∇²h_r(q) for every constraint row, exactly: Ȧ q̇ = q̇ᵀ ∇²h q̇ (holonomic rows), so
  /// ∇²h_ii = drift(e_i) and ∇²h_ij = (drift(e_i + e_j) − drift(e_i) − drift(e_j)) / 2.
  bool constraintHessians(int k, double T, Worker& w, std::string& failure, long& linearizations) {
    const int p = knotPoint(k);
    w.q = state(cachedZ.data(), p).head(n);
    if (nonholonomic) {
      // S_r(i, ·) = ∂(A q̇)_r/∂q at q̇ = e_i: the core's ∂(A q̇)/∂q, one unit velocity at a time.
      w.u = input(cachedZ.data(), p);
      for (int i = 0; i < n; ++i) {
        w.dq.setZero();
        w.dq(i) = 1.0;
        ++linearizations;
        const DynamicsStatus status = computeLinearization(model, w.data, w.q, w.dq, w.u);
        if (!status.ok() || !w.data.constraintVelocityJacobian.allFinite()) {
          failure = "the constraint derivatives failed at knot " + std::to_string(k) + " (t = " +
                    std::to_string(T * tau(k)) + "): " + status.message;
          return false;
        }
        for (int r = 0; r < nc; ++r) {
          hessian[k * nc + r].row(i) = w.data.constraintVelocityJacobian.row(r);
        }
      }
      return true;
    }
    Eigen::VectorXd& v = w.dq;
    for (int i = 0; i < n; ++i) {
      v.setZero();
      v(i) = 1.0;
      computeConstraints(model, w.data, w.q, v);
      for (int r = 0; r < nc; ++r) hessian[k * nc + r](i, i) = w.data.constraintDrift(r);
    }
    for (int i = 0; i < n; ++i) {
      for (int j = i + 1; j < n; ++j) {
        v.setZero();
        v(i) = 1.0;
        v(j) = 1.0;
        computeConstraints(model, w.data, w.q, v);
        for (int r = 0; r < nc; ++r) {
          Eigen::MatrixXd& H = hessian[k * nc + r];
          H(i, j) = H(j, i) = 0.5 * (w.data.constraintDrift(r) - H(i, i) - H(j, j));
        }
      }
    }
    return true;
  }

  /// S_r at every knot (constraintHessians), the knots on the lanes (each writes its own blocks);
  /// the first failing knot's message, in knot order.
  bool knotConstraintHessians(double T) {
    const int count = lanesFor(N);
    growWorkers(count);
    knotFailure.assign(N, std::string());
    knotOk.assign(N, 1);
    knotLinearizations.assign(N, 0);
    onLanes(count, [&](int lane) {
      for (int k = lane; k < N; k += count)
        knotOk[k] = constraintHessians(k, T, *workers[lane], knotFailure[k], knotLinearizations[k]);
    });
    for (int k = 0; k < N; ++k) {
      linearizationCount += knotLinearizations[k];
      if (!knotOk[k]) {
        error = knotFailure[k];
        return false;
      }
    }
    return true;
  }

  /// f (and with `linearize` A, B and the constraint derivatives) at every point, once per z.
  bool evaluate(const double* z, bool linearize) {
    if (std::memcmp(cachedZ.data(), z, sizeof(double) * numVars) != 0) {
      std::memcpy(cachedZ.data(), z, sizeof(double) * numVars);
      haveDynamics = haveLinearization = false;
    }
    if (linearize ? haveLinearization : (haveDynamics || haveLinearization)) return true;
    const double T = horizonOf(z);
    for (int p = 0; p < P; ++p) {
      const double* x = z + p * stride;
      q = Eigen::Map<const Eigen::VectorXd>(x, n);
      dq = Eigen::Map<const Eigen::VectorXd>(x + n, n);
      u = Eigen::Map<const Eigen::VectorXd>(x + nx, m);
      const bool isKnot = p % perInterval == 0;
      const int k = p / perInterval;
      if (implicit) {
        if (!evaluateImplicit(x, p, k, isKnot, linearize, T)) return false;
        continue;
      }
      if (linearize && (derivatives == DerivativeMode::kExact || (isKnot && nc > 0) || nF > 0)) {
        ++linearizationCount;
        if (!statusOk(computeLinearization(model, data, q, dq, u), p, T)) return false;
        if (!data.A.allFinite() || !data.B.allFinite()) {
          error = "the linearization is not finite at " + describePoint(p, T);
          return false;
        }
        if (derivatives == DerivativeMode::kExact) {
          Ap[p] = data.A;
          Bp[p] = data.B;
        }
        if (isKnot && nc > 0) Avq[k] = data.constraintVelocityJacobian;
        if (nF > 0) DL[p] = data.dlambda_dx;
      } else {
        ++dynamicsCount;
        if (!statusOk(computeDynamics(model, data, q, dq, u), p, T)) return false;
      }
      F.col(p).head(n) = dq;
      F.col(p).tail(n) = data.qdd;
      if (nc > 0) Lam.col(p) = data.lambda;
      if (isKnot && nc > 0) {
        hValue.col(k) = data.constraintValue;
        Ac[k] = data.constraintJacobian;
      }
      if (linearize && derivatives == DerivativeMode::kFiniteDifference) {
        if (!finiteDifferenceBlocks(p, T)) return false;
      }
    }
    // The constraints' second derivatives at the knots (after every point: on the lanes).
    if (linearize && nc > 0 && !knotConstraintHessians(T)) return false;
    haveDynamics = true;
    haveLinearization = haveLinearization || linearize;
    return true;
  }

  /// The implicit form at point p: r, c (and their Jacobian over the point's variables) at the
  /// point's own q̈ and λ; f = [q̇; q̈] and λ are read from z.
  bool evaluateImplicit(const double* x, int p, int k, bool isKnot, bool linearize, double T) {
    acc = Eigen::Map<const Eigen::VectorXd>(x + nx + m, n);
    lam = Eigen::Map<const Eigen::VectorXd>(x + nx + m + n, nc);
    ++linearizationCount;
    const DynamicsStatus status = computeImplicitDynamics(model, data, q, dq, acc, u, lam, idyn);
    if (!status.ok()) {
      error = "the implicit dynamics failed at " + describePoint(p, T) + ": " + status.message;
      return false;
    }
    F.col(p).head(n) = dq;
    F.col(p).tail(n) = acc;
    if (nc > 0) Lam.col(p) = lam;
    R.col(p).head(n) = idyn.r;
    R.col(p).tail(nc) = idyn.c;
    if (linearize) {
      // Columns [x (2n) | u (m) | q̈ (n) | λ (nc)]: ∂r = [∂r/∂x, −B_u, M, −Aᵀ], ∂c = [∂c/∂x, 0, A, 0].
      Eigen::MatrixXd& D = DR[p];
      D.topLeftCorner(n, nx) = idyn.dr_dx;
      D.block(0, nx, n, m) = -data.inputMatrix;
      D.block(0, nx + m, n, n) = data.M;
      if (nc > 0) {
        D.block(0, nx + m + n, n, nc) = -data.constraintJacobian.transpose();
        D.bottomLeftCorner(nc, nx) = idyn.dc_dx;
        D.block(n, nx + m, nc, n) = data.constraintJacobian;
      }
    }
    if (isKnot && nc > 0) {
      hValue.col(k) = data.constraintValue;
      Ac[k] = data.constraintJacobian;
      Avq[k] = data.constraintVelocityJacobian;
    }
    return true;
  }

  // ---- Cost ------------------------------------------------------------------------------------

  /// Quadrature weight of point p divided by h (Simpson 1/6, 4/6, 1/6 per interval; trapezoid ½, ½).
  /// Quadrature weight of point p divided by T (Simpson Δτ/6, 4Δτ/6, Δτ/6 per interval;
  /// trapezoid Δτ/2, Δτ/2), Δτ_k = τ_{k+1} − τ_k.
  double weightOverT(int p) const {
    if (radau) {  // the stages' weights b_i = a_3i of the interval they close (the first knot: 0)
      const int i = p % 3, k = p / 3;
      return i == 0 ? (k > 0 ? kRadauA[2][2] * intervalFraction(k - 1) : 0.0) : kRadauA[2][i - 1] * intervalFraction(k);
    }
    if (hermiteSimpson && p % 2 == 1) return 4.0 / 6.0 * intervalFraction(p / 2);
    const int k = hermiteSimpson ? p / 2 : p;
    const double c = hermiteSimpson ? 1.0 / 6.0 : 0.5;
    double w = 0.0;
    if (k > 0) w += c * intervalFraction(k - 1);
    if (k < N - 1) w += c * intervalFraction(k);
    return w;
  }

  double cost(const double* z, double* gradient) const {
    const double T = horizonOf(z);
    double running = 0.0;
    if (gradient) std::fill(gradient, gradient + numVars, 0.0);
    Eigen::VectorXd& e = costError;  // workspace: no allocation per evaluation
    for (int p = 0; p < P; ++p) {
      const Eigen::Map<const Eigen::VectorXd> x(z + p * stride, nx), uu(z + p * stride + nx, m);
      e = x - problem.goalState;
      const double w = weightOverT(p) * T;
      costQe.noalias() = problem.Q * e;
      costRu.noalias() = problem.R * uu;
      running += w * (uu.dot(costRu) + e.dot(costQe));
      if (gradient) {
        Eigen::Map<Eigen::VectorXd>(gradient + p * stride, nx) = 2.0 * w * costQe;
        Eigen::Map<Eigen::VectorXd>(gradient + p * stride + nx, m) = 2.0 * w * costRu;
      }
      if (accelerationCost) {  // q̈ᵀ W_a q̈ (implicit form: q̈ follows u in the point's block)
        const Eigen::Map<const Eigen::VectorXd> acc(z + p * stride + nx + m, n);
        running += w * acc.dot(problem.accelerationWeights.cwiseProduct(acc));
        if (gradient)
          Eigen::Map<Eigen::VectorXd>(gradient + p * stride + nx + m, n) = 2.0 * w * problem.accelerationWeights.cwiseProduct(acc);
      }
    }
    const int last = knotPoint(N - 1) * stride;
    e = Eigen::Map<const Eigen::VectorXd>(z + last, nx) - problem.goalState;
    costQe.noalias() = problem.Qf * e;
    const double terminal = e.dot(costQe);
    if (gradient) {
      Eigen::Map<Eigen::VectorXd>(gradient + last, nx) += 2.0 * costQe;
      // The running cost is proportional to T: ∂/∂T = running / T.
      if (freeT) gradient[horizonIdx] = running / T + problem.timeWeight;
    }
    return running + terminal + problem.timeWeight * T;
  }

  // ---- Constraints -----------------------------------------------------------------------------

  Eigen::Map<const Eigen::VectorXd> state(const double* z, int p) const {
    return Eigen::Map<const Eigen::VectorXd>(z + p * stride, nx);
  }

  Eigen::Map<const Eigen::VectorXd> input(const double* z, int p) const {
    return Eigen::Map<const Eigen::VectorXd>(z + p * stride + nx, m);
  }

  void constraints(const double* z, double* g) const {
    const double T = horizonOf(z);
    for (int k = 0; k < N - 1; ++k) {
      const double h = T * intervalFraction(k);
      const int a = knotPoint(k), b = knotPoint(k + 1);
      Eigen::Map<Eigen::VectorXd> defect(g + k * intervalRows, nx);
      if (hermiteSimpson) {
        const int mid = a + 1;
        defect = state(z, b) - state(z, a) - h / 6.0 * (F.col(a) + 4.0 * F.col(mid) + F.col(b));
        Eigen::Map<Eigen::VectorXd>(g + k * intervalRows + nx, nx) =
            state(z, mid) - 0.5 * (state(z, a) + state(z, b)) - h / 8.0 * (F.col(a) - F.col(b));
        // The input is linear between knots (the rule every trajectory reader applies).
        Eigen::Map<Eigen::VectorXd>(g + k * intervalRows + 2 * nx, m) =
            input(z, mid) - 0.5 * (input(z, a) + input(z, b));
      } else if (radau) {
        // Stage i: x_{a+i} − x_a − h Σ_j a_ij f_{a+j}; the end stage (x_b) first, where the slacks go.
        for (int i = 0; i < 3; ++i) {
          Eigen::Map<Eigen::VectorXd> d(g + k * intervalRows + (i == 2 ? 0 : (i + 1) * nx), nx);
          d = state(z, a + i + 1) - state(z, a) -
              h * (kRadauA[i][0] * F.col(a + 1) + kRadauA[i][1] * F.col(a + 2) + kRadauA[i][2] * F.col(b));
        }
        // The inputs at the inner stages: linear between knots, like every trajectory reader's.
        for (int i = 0; i < 2; ++i)
          Eigen::Map<Eigen::VectorXd>(g + k * intervalRows + 3 * nx + i * m, m) =
              input(z, a + i + 1) - ((1.0 - kRadauC[i]) * input(z, a) + kRadauC[i] * input(z, b));
      } else {
        defect = state(z, b) - state(z, a) - h / 2.0 * (F.col(a) + F.col(b));
      }
      if (nc > 0) {
        const double* gamma = z + slackOf(k);
        const Eigen::Map<const Eigen::VectorXd> mu(z + slackOf(k) + ncH, nc);
        for (int j = 0; j < ncH; ++j) defect.head(n) -= Ac[k + 1].row(holonomicRows[j]).transpose() * gamma[j];
        defect.tail(n) -= Ac[k + 1].transpose() * mu;
      }
    }
    for (int k = 0; k < N && nc > 0; ++k) {
      const Eigen::Map<const Eigen::VectorXd> dqk(z + knotPoint(k) * stride + n, n);
      for (int j = 0; j < ncH; ++j) g[knotRow(k) + j] = hValue(holonomicRows[j], k);
      Eigen::Map<Eigen::VectorXd>(g + knotRow(k) + ncH, nc) = Ac[k] * dqk;
    }
    for (int p = 0; p < P && nF > 0; ++p) {
      forceValues.noalias() = CF * Lam.col(p);
      for (int j = 0; j < nF; ++j) g[forceStart + p * nF + j] = forceValues(j);
    }
    for (int p = 0; p < P && implicit; ++p) Eigen::Map<Eigen::VectorXd>(g + dynStart + p * dynRows, dynRows) = R.col(p);
  }

  // ---- Constraint Jacobian ---------------------------------------------------------------------

  /// Columns col0 … col0 + nx − 1, rows row0 … row0 + nx − 1: d·I + c·A (A = [[0, I], [·, ·]]),
  /// plus `top`/`bottom` (n×n, added to the q columns of the q / q̇ rows) when given. Entries
  /// that are structurally zero (d = 0 or c = 0) are not written.
  void stateBlock(TripletWriter& w, int row0, int col0, double d, double c, const Eigen::MatrixXd& A,
                  const Eigen::MatrixXd* top, const Eigen::MatrixXd* bottom) const {
    for (int i = 0; i < n; ++i) {
      if (top) {
        for (int j = 0; j < n; ++j) w.put(row0 + i, col0 + j, (i == j ? d : 0.0) + (*top)(i, j));
      } else if (d != 0.0) {
        w.put(row0 + i, col0 + i, d);
      }
      if (c != 0.0) w.put(row0 + i, col0 + n + i, c);
    }
    for (int i = n; i < nx; ++i) {
      if (c == 0.0) {
        if (d != 0.0) w.put(row0 + i, col0 + i, d);
        continue;
      }
      for (int j = 0; j < nx; ++j) {
        double v = (i == j ? d : 0.0) + c * A(i, j);
        if (bottom && j < n) v += (*bottom)(i - n, j);
        w.put(row0 + i, col0 + j, v);
      }
    }
  }

  /// c·B in the q̇ rows (the q rows of B are zero).
  void inputBlock(TripletWriter& w, int row0, int col0, double c, const Eigen::MatrixXd& B) const {
    for (int i = n; i < nx; ++i)
      for (int j = 0; j < m; ++j) w.put(row0 + i, col0 + j, c * B(i, j));
  }

  /// A defect's block on point p: d·I on x_p and c·∂f_p/∂[x_p; u_p] (plus top/bottom as in
  /// stateBlock). Explicit: stateBlock and inputBlock. Implicit: f_p = [q̇_p; q̈_p] is linear in the
  /// point's variables, so c sits on q̇_p (q rows) and on q̈_p (q̇ rows).
  void pointBlock(TripletWriter& w, int row0, int p, double d, double c, const Eigen::MatrixXd* top,
                  const Eigen::MatrixXd* bottom) const {
    const int col0 = p * stride;
    if (!implicit) {
      stateBlock(w, row0, col0, d, c, Ap[p], top, bottom);
      if (c != 0.0) inputBlock(w, row0, col0 + nx, c, Bp[p]);
      return;
    }
    for (int i = 0; i < n; ++i) {
      if (top) {
        for (int j = 0; j < n; ++j) w.put(row0 + i, col0 + j, (i == j ? d : 0.0) + (*top)(i, j));
      } else if (d != 0.0) {
        w.put(row0 + i, col0 + i, d);
      }
      if (c != 0.0) w.put(row0 + i, col0 + n + i, c);
    }
    for (int i = 0; i < n; ++i) {
      if (bottom)
        for (int j = 0; j < n; ++j) w.put(row0 + n + i, col0 + j, (*bottom)(i, j));
      if (d != 0.0) w.put(row0 + n + i, col0 + n + i, d);
      if (c != 0.0) w.put(row0 + n + i, col0 + nx + m + i, c);
    }
  }

  template <typename Vector>
  void horizonColumn(TripletWriter& w, int row0, const Vector& v) const {
    if (!freeT) return;
    for (int i = 0; i < nx; ++i) w.put(row0 + i, horizonIdx, v(i));
  }

  void writeJacobian(const double* z, TripletWriter& w) {
    const double T = horizonOf(z);
    for (int k = 0; k < N - 1; ++k) {
      const double dhdT = intervalFraction(k);
      const double h = T * dhdT;
      const int a = knotPoint(k), b = knotPoint(k + 1);
      const int row0 = k * intervalRows;
      const Eigen::MatrixXd* top = nullptr;
      const Eigen::MatrixXd* bottom = nullptr;
      if (nc > 0) {
        // −∂(A_c(q_b)ᵀ γ)/∂q_b = −Σ_r γ_r ∇²h_r(q_b), likewise for μ.
        slackTop.setZero();
        slackBottom.setZero();
        for (int j = 0; j < ncH; ++j) {
          slackTop -= z[slackOf(k) + j] * hessian[(k + 1) * nc + holonomicRows[j]];
        }
        for (int r = 0; r < nc; ++r) {
          slackBottom -= z[slackOf(k) + ncH + r] * hessian[(k + 1) * nc + r];
        }
        top = &slackTop;
        bottom = &slackBottom;
      }
      if (radau) {
        // Stage i's rows (the end stage's at row0): −I on x_a, then δ_ij I − h a_ij ∂f on x_{a+j}.
        for (int i = 0; i < 3; ++i) {
          const int r = row0 + (i == 2 ? 0 : (i + 1) * nx);
          pointBlock(w, r, a, -1.0, 0.0, nullptr, nullptr);
          for (int j = 0; j < 3; ++j)
            pointBlock(w, r, a + j + 1, i == j ? 1.0 : 0.0, -h * kRadauA[i][j], i == 2 && j == 2 ? top : nullptr,
                       i == 2 && j == 2 ? bottom : nullptr);
          horizonColumn(w, r, -dhdT * (kRadauA[i][0] * F.col(a + 1) + kRadauA[i][1] * F.col(a + 2) +
                                       kRadauA[i][2] * F.col(b)));
        }
      } else {
        const double ws = hermiteSimpson ? h / 6.0 : h / 2.0;  // weight of f_a and f_b
        pointBlock(w, row0, a, -1.0, -ws, nullptr, nullptr);
        if (hermiteSimpson) pointBlock(w, row0, a + 1, 0.0, -4.0 * ws, nullptr, nullptr);
        pointBlock(w, row0, b, 1.0, -ws, top, bottom);
      }
      if (hermiteSimpson) {
        horizonColumn(w, row0, -dhdT / 6.0 * (F.col(a) + 4.0 * F.col(a + 1) + F.col(b)));
      } else if (!radau) {
        horizonColumn(w, row0, -dhdT / 2.0 * (F.col(a) + F.col(b)));
      }
      if (nc > 0) {
        const int s = slackOf(k);
        for (int i = 0; i < n; ++i)
          for (int j = 0; j < ncH; ++j) w.put(row0 + i, s + j, -Ac[k + 1](holonomicRows[j], i));
        for (int i = 0; i < n; ++i)
          for (int r = 0; r < nc; ++r) w.put(row0 + n + i, s + ncH + r, -Ac[k + 1](r, i));
      }
      if (hermiteSimpson) {
        const int row1 = row0 + nx;
        pointBlock(w, row1, a, -0.5, -h / 8.0, nullptr, nullptr);
        pointBlock(w, row1, a + 1, 1.0, 0.0, nullptr, nullptr);
        pointBlock(w, row1, b, -0.5, h / 8.0, nullptr, nullptr);
        horizonColumn(w, row1, -dhdT / 8.0 * (F.col(a) - F.col(b)));
        const int row2 = row1 + nx;  // u_m − (u_a + u_b)/2
        for (int j = 0; j < m; ++j) {
          w.put(row2 + j, a * stride + nx + j, -0.5);
          w.put(row2 + j, (a + 1) * stride + nx + j, 1.0);
          w.put(row2 + j, b * stride + nx + j, -0.5);
        }
      }
      if (radau) {  // u_{a+i} − ((1 − c_i) u_a + c_i u_b), i = 1, 2
        for (int i = 0; i < 2; ++i) {
          const int r = row0 + 3 * nx + i * m;
          for (int j = 0; j < m; ++j) {
            w.put(r + j, a * stride + nx + j, -(1.0 - kRadauC[i]));
            w.put(r + j, (a + i + 1) * stride + nx + j, 1.0);
            w.put(r + j, b * stride + nx + j, -kRadauC[i]);
          }
        }
      }
    }
    for (int k = 0; k < N && nc > 0; ++k) {
      const int row0 = knotRow(k);
      const int col0 = knotPoint(k) * stride;
      for (int j = 0; j < ncH; ++j)
        for (int c = 0; c < n; ++c) w.put(row0 + j, col0 + c, Ac[k](holonomicRows[j], c));
      for (int r = 0; r < nc; ++r) {
        for (int j = 0; j < n; ++j) w.put(row0 + ncH + r, col0 + j, Avq[k](r, j));
        for (int j = 0; j < n; ++j) w.put(row0 + ncH + r, col0 + n + j, Ac[k](r, j));
      }
    }
    // c_jᵀλ at point p: c_jᵀ ∂λ/∂[x_p; u_p] (the core's dlambda_dx).
    for (int p = 0; p < P && nF > 0; ++p) {
      if (implicit) {  // c_jᵀλ_p: linear in the point's λ (CF is constant, so are its zeros)
        for (int j = 0; j < nF; ++j)
          for (int r = 0; r < nc; ++r)
            if (CF(j, r) != 0.0) w.put(forceStart + p * nF + j, p * stride + nx + m + n + r, CF(j, r));
        continue;
      }
      if (!w.structure) CDL.noalias() = CF * DL[p];
      for (int j = 0; j < nF; ++j)
        for (int c = 0; c < stride; ++c) w.put(forceStart + p * nF + j, p * stride + c, CDL(j, c));
    }
    // Implicit rows [r; c] at point p over its variables (c has no u or λ columns).
    for (int p = 0; p < P && implicit; ++p) {
      const int row0 = dynStart + p * dynRows;
      for (int i = 0; i < dynRows; ++i) {
        const int cols = i < n ? stride : nx + m + n;
        for (int c = 0; c < cols; ++c) {
          if (i >= n && c >= nx && c < nx + m) continue;
          w.put(row0 + i, p * stride + c, DR[p](i, c));
        }
      }
    }
  }

  // ---- Lagrangian Hessian ----------------------------------------------------------------------
  //
  // (With constraint-force bounds, the rows λ_r(x_p, u_p) add ρ_p = their multipliers to the
  // point's contraction: Σ_i w_i ∇²q̈_i + Σ_r ρ_r ∇²λ_r in one call.)
  //
  // L = σ J + Σ_c μ_c g_c. The defects are linear in the point variables except through f_p (the
  // separated Hermite–Simpson form makes the midpoint state a variable: no midpoint map to
  // compose), through h = T Δτ, and through the closed-chain terms. Hence:
  //  - point p: ∇²_{[x_p; u_p]} L = σ ∇²J_p + Σ_i c_{p,n+i} ∇²q̈_i, c_p = Σ_d α_{d,p} μ_d (α: −h/6,
  //    −4h/6, −h/6 in the Simpson defect, −h/8, +h/8 in the Hermite one, −h/2 in the trapezoid):
  //    one computeSecondOrderContraction per point (the q̇ half of f is linear);
  //  - free T: h/T = Δτ, so ∂²L/∂T∂z_p = c_pᵀ ∂f_p/∂z_p / T + σ ∂²J/∂T∂z_p, and ∂²L/∂T² = 0;
  //  - closed chains (holonomic rows): the slack terms −γ_j λ_qᵀ ∇h_j(q_b) − μ_r λ_q̇ᵀ A_r(q_b)ᵀ
  //    of interval k (λ its Simpson/trapezoid multipliers) give ∂²/∂γ_j∂q_b = −S_jᵀ λ_q,
  //    ∂²/∂μ_r∂q_b = −S_rᵀ λ_q̇, ∂²/∂q_b² = −Σ γ_j T_j[λ_q] − Σ μ_r T_r[λ_q̇]; the knot rows
  //    ν_j h_j(q) + ν'_r A_r(q) q̇ give ∂²/∂q² = Σ ν_j S_j + Σ ν'_r T_r[q̇] and ∂²/∂q̇_i∂q_a =
  //    Σ ν'_r S_r(i, a), with T_r[v](a, b) = Σ_i v_i ∂³h_r/∂q_i∂q_a∂q_b (thirdTerm).

  void setUpHessian() {
    const int blockRows = ncH + nc;
    Hp.assign(P, Eigen::MatrixXd::Zero(stride, stride));
    C = Eigen::MatrixXd::Zero(nx, P);
    Hz = Eigen::MatrixXd::Zero(nx + m, nx + m);
    slackCross = Eigen::MatrixXd::Zero(std::max(0, (N - 1) * blockRows), n);
    horizonRow = Eigen::VectorXd::Zero(P * stride);
    hq = Eigen::VectorXd::Zero(n);
    hdq = Eigen::VectorXd::Zero(n);
    hu = Eigen::VectorXd::Zero(m);
    hw = Eigen::VectorXd::Zero(n);
    hwScaled = Eigen::VectorXd::Zero(n);
    stateError = Eigen::VectorXd::Zero(nx);
    costError = Eigen::VectorXd::Zero(nx);
    costQe = Eigen::VectorXd::Zero(nx);
    costRu = Eigen::VectorXd::Zero(m);
    noRho.resize(0);
    rhoPoint = Eigen::VectorXd::Zero(nc);
    if (nonholonomic) {
      zeroN = Eigen::VectorXd::Zero(n);
      zeroNc = Eigen::VectorXd::Zero(nc);
    }
    // Structure, lower triangle (row ≥ column): each point's [x; u] block whole, the slack rows
    // against the end knot's q, and the T row against every point variable.
    for (int p = 0; p < P; ++p)
      for (int i = 0; i < stride; ++i)
        for (int j = 0; j <= i; ++j) {
          hessRows.push_back(p * stride + i);
          hessCols.push_back(p * stride + j);
        }
    for (int k = 0; k + 1 < N && nc > 0; ++k)
      for (int r = 0; r < blockRows; ++r)
        for (int a = 0; a < n; ++a) {
          hessRows.push_back(slackOf(k) + r);
          hessCols.push_back(knotPoint(k + 1) * stride + a);
        }
    if (freeT) {
      for (int c = 0; c < P * stride; ++c) {
        hessRows.push_back(horizonIdx);
        hessCols.push_back(c);
      }
    }
  }

  bool secondOrderOk(const DynamicsStatus& status, int p, double T, const Eigen::MatrixXd& result) {
    if ((status.ok() || status.code == DynamicsCode::kRedundantConstraints) && result.allFinite()) return true;
    error = "the second derivatives of the dynamics failed at " + describePoint(p, T) + ": " +
            (status.message.empty() ? std::string("non-finite values") : status.message);
    return false;
  }


  /// The implicit form's second-order blocks ∇²_z(νᵀr + ηᵀc), ∂²/∂y∂x of every point whose
  /// multipliers are not all zero (activeP), into HzzP, HyzP and statusP: the points are
  /// independent, so they run on `threads` threads (point p on worker p mod threads; the first
  /// worker is the transcription's own hessData/secondOrder) — the same values on any count.
  void implicitBlocks(const double* z, const double* mult) {
    const int count = lanesFor(P);
    if (static_cast<int>(HzzP.size()) != P) {
      HzzP.assign(P, Eigen::MatrixXd::Zero(nx + m, nx + m));
      HyzP.assign(P, Eigen::MatrixXd::Zero(n + nc, nx));
      statusP.assign(P, DynamicsStatus{});
      activeP.assign(P, 0);
    }
    growWorkers(count);
    onLanes(count, [&](int lane) {
      Worker& w = *workers[lane];
      for (int p = lane; p < P; p += count) {
        w.nu = Eigen::Map<const Eigen::VectorXd>(mult + dynStart + p * dynRows, n);
        w.eta = Eigen::Map<const Eigen::VectorXd>(mult + dynStart + p * dynRows + n, nc);
        activeP[p] = !w.nu.isZero(0.0) || !w.eta.isZero(0.0);
        if (!activeP[p]) continue;
        const double* zp = z + p * stride;
        w.q = Eigen::Map<const Eigen::VectorXd>(zp, n);
        w.dq = Eigen::Map<const Eigen::VectorXd>(zp + n, n);
        w.u = Eigen::Map<const Eigen::VectorXd>(zp + nx, m);
        w.acc = Eigen::Map<const Eigen::VectorXd>(zp + nx + m, n);
        w.lam = Eigen::Map<const Eigen::VectorXd>(zp + nx + m + n, nc);
        statusP[p] = computeImplicitSecondOrder(model, w.data, w.secondOrder, w.q, w.dq, w.acc, w.u, w.lam, w.nu, w.eta,
                                                HzzP[p], HyzP[p]);
      }
    });
  }

  /// The knots' third-derivative terms (thirdTerm, in the Hessian's order: per interval the
  /// defects' two, then per knot the constraint rows' one) computed on the lanes into thirdTasks.
  void thirdDerivatives(const double* z, const double* mult) {
    const std::size_t count = static_cast<std::size_t>(2 * (N - 1) + N);
    if (thirdTasks.size() != count) {
      thirdTasks.assign(count, ThirdTask{});
      for (ThirdTask& t : thirdTasks) {
        t.rho = Eigen::VectorXd::Zero(nc);
        t.increment = Eigen::MatrixXd::Zero(n, n);
      }
    }
    std::size_t i = 0;
    for (int k = 0; k + 1 < N; ++k) {
      const double* lamQ = mult + k * intervalRows;
      ThirdTask& a = thirdTasks[i++];
      a.k = k + 1;
      a.v = lamQ;
      a.rho.setZero();
      for (int j = 0; j < ncH; ++j) a.rho(holonomicRows[j]) = z[slackOf(k) + j];
      a.scale = -1.0;
      ThirdTask& b = thirdTasks[i++];
      b.k = k + 1;
      b.v = lamQ + n;
      b.rho = Eigen::Map<const Eigen::VectorXd>(z + slackOf(k) + ncH, nc);
      b.scale = -1.0;
    }
    for (int k = 0; k < N; ++k) {
      ThirdTask& c = thirdTasks[i++];
      c.k = k;
      c.v = z + knotPoint(k) * stride + n;
      c.rho = Eigen::Map<const Eigen::VectorXd>(mult + knotRow(k) + ncH, nc);
      c.scale = 1.0;
    }
    const int lanesUsed = lanesFor(static_cast<int>(count));
    growWorkers(lanesUsed);
    onLanes(lanesUsed, [&](int lane) {
      for (std::size_t t = static_cast<std::size_t>(lane); t < count; t += static_cast<std::size_t>(lanesUsed))
        thirdTerm(*workers[lane], thirdTasks[t]);
    });
  }

  /// One term: task.increment = scale · Σ_r ρ_r T_r[v] at knot k (holonomic rows). c_r = A_r(q) q̈ + q̇ᵀ ∇²h_r q̇
  /// vanishes identically along the forward dynamics, so its q–q̇ block of second derivatives is
  /// zero: S_rᵀ ∂q̈/∂q̇ + Σ_i A_{r,i} ∇²_{qq̇} q̈_i + 2 T_r[q̇] = 0. At q̇ = v/‖v‖ and the contraction
  /// w = A(q)ᵀ ρ this gives Σ_r ρ_r T_r[v] = −‖v‖/2 ((Σ ρ_r S_r)ᵀ ∂q̈/∂q̇ + H_{qq̇}) — exact, from
  /// one more contraction (T_r[v] is linear in v; the unit velocity keeps the dynamics' scale).
  ///
  /// With nonholonomic rows that identity does not hold (A_r is no gradient, so ∂A_r,b/∂q_i ≠
  /// ∂A_r,i/∂q_b). Then Σ_r ρ_r T_r[v] = ∇²_q (ρᵀ A(q) v) with T_r[v](a, b) = Σ_i v_i ∂²A_r,i/∂q_a∂q_b
  /// comes from the implicit residual c = A(q) q̈ + Ȧ q̇ at q̇ = 0 (the drift and all its
  /// q-derivatives vanish there), q̈ = v: the (q, q) block of ∇²(ηᵀc) with η = ρ, ν = 0
  /// (computeImplicitSecondOrder on the recorded pass) — for every row kind alike.
  void thirdTerm(Worker& w, ThirdTask& task) {
    const Eigen::Map<const Eigen::VectorXd> vel(task.v, n);
    const double norm = vel.norm();
    task.skip = norm == 0.0 || task.rho.isZero(0.0);
    if (task.skip) return;
    const int k = task.k, p = knotPoint(k);
    w.q = state(cachedZ.data(), p).head(n);
    w.u = input(cachedZ.data(), p);
    if (nonholonomic) {
      w.thirdV = vel;
      task.status = computeImplicitSecondOrder(model, w.data, w.secondOrder, w.q, zeroN, w.thirdV, w.u, zeroNc, zeroN,
                                               task.rho, w.HzzI, w.HyzI);
      task.finite = w.HzzI.allFinite();
      task.increment = task.scale * w.HzzI.topLeftCorner(n, n);
      return;
    }
    w.dq = vel / norm;
    w.hw.noalias() = Ac[k].transpose() * task.rho;
    w.sumS.setZero();
    for (int r = 0; r < nc; ++r) w.sumS += task.rho(r) * hessian[k * nc + r];
    task.status = computeSecondOrderContraction(model, w.data, w.secondOrder, w.q, w.dq, w.u, w.hw, noRho, w.Hz);
    task.finite = w.Hz.allFinite();
    w.third.noalias() = w.sumS.transpose() * w.data.dqdd_ddq;
    w.third += w.Hz.block(0, n, n, n);
    w.scratch = w.third.transpose();
    w.third += w.scratch;  // symmetric part, ×2
    task.increment = (-(0.25 * task.scale * norm)) * w.third;
  }

  /// Adds a computed term to its point's block (false, with the error, where its second
  /// derivatives failed).
  bool applyThird(const ThirdTask& task, Eigen::Ref<Eigen::MatrixXd> out) {
    if (task.skip) return true;
    ++secondOrderCount;
    const int p = knotPoint(task.k);
    if (!((task.status.ok() || task.status.code == DynamicsCode::kRedundantConstraints) && task.finite)) {
      error = "the second derivatives of the dynamics failed at " + describePoint(p, horizonOf(cachedZ.data())) + ": " +
              (task.status.message.empty() ? std::string("non-finite values") : task.status.message);
      return false;
    }
    out += task.increment;
    return true;
  }

  bool hessianValues(const double* z, double sigma, const double* mult, double* values) {
    if (!evaluate(z, true)) return false;  // f, and S_r at the knots
    const double T = horizonOf(z);
    C.setZero();
    for (int k = 0; k < N - 1; ++k) {
      const double h = T * intervalFraction(k);
      const int a = knotPoint(k), b = knotPoint(k + 1);
      const Eigen::Map<const Eigen::VectorXd> lam(mult + k * intervalRows, nx);
      if (hermiteSimpson) {
        const Eigen::Map<const Eigen::VectorXd> lamH(mult + k * intervalRows + nx, nx);
        C.col(a) += (-h / 6.0) * lam + (-h / 8.0) * lamH;
        C.col(a + 1) += (-4.0 * h / 6.0) * lam;
        C.col(b) += (-h / 6.0) * lam + (h / 8.0) * lamH;
      } else if (radau) {
        // Stage i's multipliers (the end stage's first) weigh f_{a+j} by −h a_ij.
        const Eigen::Map<const Eigen::VectorXd> lam1(mult + k * intervalRows + nx, nx),
            lam2(mult + k * intervalRows + 2 * nx, nx);
        for (int j = 0; j < 3; ++j)
          C.col(a + j + 1) += (-h * kRadauA[0][j]) * lam1 + (-h * kRadauA[1][j]) * lam2 + (-h * kRadauA[2][j]) * lam;
      } else {
        C.col(a) += (-h / 2.0) * lam;
        C.col(b) += (-h / 2.0) * lam;
      }
    }
    const int lastPoint = knotPoint(N - 1);
    if (implicit) implicitBlocks(z, mult);
    for (int p = 0; p < P; ++p) {
      Eigen::MatrixXd& H = Hp[p];
      H.setZero();
      const double wT = weightOverT(p);
      const Eigen::Map<const Eigen::VectorXd> x = state(z, p), uu = input(z, p);
      H.topLeftCorner(nx, nx) += (2.0 * sigma * wT * T) * problem.Q;
      H.block(nx, nx, m, m) += (2.0 * sigma * wT * T) * problem.R;
      if (accelerationCost) H.block(nx + m, nx + m, n, n).diagonal() += (2.0 * sigma * wT * T) * problem.accelerationWeights;
      if (p == lastPoint) H.topLeftCorner(nx, nx) += (2.0 * sigma) * problem.Qf;
      bool dynamics = false;
      if (implicit) {
        // The implicit rows' multipliers (ν, η) weigh ∇²(νᵀr + ηᵀc) over [x; u; q̈; λ]; the defects
        // and the force rows are linear in the point's variables. Blocks from implicitBlocks.
        if (activeP[p]) {
          ++secondOrderCount;
          if (!secondOrderOk(statusP[p], p, T, HzzP[p]) || !secondOrderOk(statusP[p], p, T, HyzP[p])) return false;
          H.topLeftCorner(nx + m, nx + m) += HzzP[p];
          H.block(nx + m, 0, n + nc, nx) += HyzP[p];
          H.block(0, nx + m, nx, n + nc) += HyzP[p].transpose();
        }
      } else {
        hw = C.col(p).tail(n);
        // The force rows' multipliers weigh ∇²λ_r at this point (ρ of the contraction).
        rhoPoint.setZero();
        // Σ_j ρ_j c_jᵀλ = (CFᵀρ)ᵀλ: the contraction weighs ∇²λ by CFᵀρ.
        if (nF > 0) rhoPoint.noalias() = CF.transpose() * Eigen::Map<const Eigen::VectorXd>(mult + forceStart + p * nF, nF);
        const bool forces = nF > 0 && !rhoPoint.isZero(0.0);
        dynamics = !hw.isZero(0.0) || forces;
        if (dynamics) {
          hq = x.head(n);
          hdq = x.tail(n);
          hu = uu;
          const DynamicsStatus status = computeSecondOrderContraction(model, hessData, secondOrder, hq, hdq, hu,
                                                                      hw, forces ? rhoPoint : noRho, Hz);
          ++secondOrderCount;
          if (!secondOrderOk(status, p, T, Hz)) return false;
          H += Hz;
        }
      }
      if (freeT) {
        // c_pᵀ ∂f_p/∂z_p / T (f = [q̇; q̈]) and σ ∂²J/∂T∂z_p = 2σ w/T (Q e, R u, W_a q̈).
        Eigen::Map<Eigen::VectorXd> row(horizonRow.data() + p * stride, stride);
        row.setZero();
        row.segment(n, n) = C.col(p).head(n) / T;
        if (implicit) row.segment(nx + m, n) = C.col(p).tail(n) / T;  // f = [q̇; q̈] read from z
        if (dynamics) {
          hwScaled = hw / T;  // the products below then need no temporary
          row.segment(0, n).noalias() += hessData.dqdd_dq.transpose() * hwScaled;
          row.segment(n, n).noalias() += hessData.dqdd_ddq.transpose() * hwScaled;
          row.segment(nx, m).noalias() += hessData.dqdd_du.transpose() * hwScaled;
        }
        stateError = x - problem.goalState;
        row.head(nx).noalias() += (2.0 * sigma * wT) * problem.Q * stateError;
        row.segment(nx, m).noalias() += (2.0 * sigma * wT) * problem.R * uu;
        if (accelerationCost)
          row.segment(nx + m, n) += (2.0 * sigma * wT) * problem.accelerationWeights.cwiseProduct(
                                        Eigen::Map<const Eigen::VectorXd>(z + p * stride + nx + m, n));
      }
    }
    if (nc > 0) {
      // The third-derivative terms on the lanes first, then added in this serial order (the
      // same sums, bit for bit, on any number of threads).
      thirdDerivatives(z, mult);
      std::size_t task = 0;
      const int blockRows = ncH + nc;
      for (int k = 0; k + 1 < N; ++k) {
        const int b = knotPoint(k + 1);
        const double* lamQ = mult + k * intervalRows;
        const double* lamV = lamQ + n;
        const Eigen::Map<const Eigen::RowVectorXd> lq(lamQ, n), lv(lamV, n);
        for (int j = 0; j < ncH; ++j) {
          slackCross.row(k * blockRows + j).noalias() = -lq * hessian[(k + 1) * nc + holonomicRows[j]];
        }
        for (int r = 0; r < nc; ++r) {
          slackCross.row(k * blockRows + ncH + r).noalias() = -lv * hessian[(k + 1) * nc + r];
        }
        if (!applyThird(thirdTasks[task++], Hp[b].topLeftCorner(n, n))) return false;  // γ_k with λ_q
        if (!applyThird(thirdTasks[task++], Hp[b].topLeftCorner(n, n))) return false;  // μ_k with λ_v
      }
      for (int k = 0; k < N; ++k) {
        const int p = knotPoint(k);
        const double* nu = mult + knotRow(k);
        Eigen::MatrixXd& H = Hp[p];
        for (int j = 0; j < ncH; ++j) H.topLeftCorner(n, n) += nu[j] * hessian[k * nc + holonomicRows[j]];
        for (int r = 0; r < nc; ++r) {
          H.block(n, 0, n, n) += nu[ncH + r] * hessian[k * nc + r];
          H.block(0, n, n, n) += nu[ncH + r] * hessian[k * nc + r].transpose();
        }
        if (!applyThird(thirdTasks[task++], H.topLeftCorner(n, n))) return false;  // the knot's rows with q̇
      }
    }
    // Values in the structure's order.
    int next = 0;
    for (int p = 0; p < P; ++p)
      for (int i = 0; i < stride; ++i)
        for (int j = 0; j <= i; ++j) values[next++] = Hp[p](i, j);
    for (int k = 0; k + 1 < N && nc > 0; ++k)
      for (int r = 0; r < ncH + nc; ++r)
        for (int a = 0; a < n; ++a) values[next++] = slackCross(k * (ncH + nc) + r, a);
    if (freeT) {
      for (int c = 0; c < P * stride; ++c) values[next++] = horizonRow(c);
    }
    return true;
  }
};

Transcription::Transcription(OptimalControlProblem problem, DerivativeMode derivatives)
    : impl_(std::make_unique<Impl>(std::move(problem), derivatives)) {}
Transcription::~Transcription() = default;
Transcription::Transcription(Transcription&&) noexcept = default;
Transcription& Transcription::operator=(Transcription&&) noexcept = default;

const OptimalControlProblem& Transcription::problem() const { return impl_->problem; }
int Transcription::numVariables() const { return impl_->numVars; }
int Transcription::numConstraints() const { return impl_->numCons; }
int Transcription::numPoints() const { return impl_->P; }
int Transcription::numKnots() const { return impl_->N; }
int Transcription::stateIndex(int point) const { return point * impl_->stride; }
int Transcription::inputIndex(int point) const { return point * impl_->stride + impl_->nx; }
int Transcription::slackIndex(int interval) const {
  return impl_->nc > 0 ? impl_->slackOf(interval) : -1;
}
int Transcription::horizonIndex() const { return impl_->horizonIdx; }
int Transcription::knotPoint(int knot) const { return impl_->knotPoint(knot); }
int Transcription::knotConstraintRow(int knot) const {
  return impl_->nc > 0 ? impl_->knotRow(knot) : -1;
}
const std::vector<int>& Transcription::jacobianRows() const { return impl_->jacRows; }
const std::vector<int>& Transcription::jacobianCols() const { return impl_->jacCols; }

void Transcription::variableBounds(Eigen::VectorXd& lower, Eigen::VectorXd& upper) const {
  impl_->bounds(lower, upper);
}
Eigen::VectorXd Transcription::initialGuess() const { return impl_->initialGuessVector(); }

bool Transcription::evalCost(const double* z, double& cost) {
  cost = impl_->cost(z, nullptr);
  return std::isfinite(cost);
}

bool Transcription::evalCostGradient(const double* z, double* gradient) {
  impl_->cost(z, gradient);
  return true;
}

bool Transcription::evalConstraints(const double* z, double* g) {
  if (!impl_->evaluate(z, false)) return false;
  impl_->constraints(z, g);
  return true;
}

bool Transcription::evalJacobian(const double* z, double* values) {
  if (!impl_->evaluate(z, true)) return false;
  TripletWriter w;
  w.values = values;
  impl_->writeJacobian(z, w);
  return true;
}

void Transcription::constraintBounds(Eigen::VectorXd& lower, Eigen::VectorXd& upper) const {
  const Impl& s = *impl_;
  lower = Eigen::VectorXd::Zero(s.numCons);
  upper = Eigen::VectorXd::Zero(s.numCons);
  for (int p = 0; p < s.P; ++p) {
    for (int j = 0; j < s.nF; ++j) {
      lower(s.forceStart + p * s.nF + j) = s.forceLo(j);
      upper(s.forceStart + p * s.nF + j) = s.forceHi(j);
    }
  }
}
int Transcription::forceRowsPerPoint() const { return impl_->nF; }
int Transcription::forceRow(int point) const { return impl_->nF > 0 ? impl_->forceStart + point * impl_->nF : -1; }

// Every model and form the constructor accepts has its exact Hessian (knife edges included).
bool Transcription::hessianAvailable() const { return true; }
const std::string& Transcription::hessianUnavailableReason() const {
  static const std::string none;
  return none;
}
const std::vector<int>& Transcription::hessianRows() const { return impl_->hessRows; }
const std::vector<int>& Transcription::hessianCols() const { return impl_->hessCols; }

bool Transcription::evalHessian(const double* z, double objectiveFactor, const double* multipliers,
                                double* values) {
  return impl_->hessianValues(z, objectiveFactor, multipliers, values);
}

long Transcription::secondOrderEvaluations() const { return impl_->secondOrderCount; }

void Transcription::setThreads(int threads) {
  if (threads < 1 || threads > kMaxThreads) {
    throw std::invalid_argument("Transcription::setThreads: threads = " + std::to_string(threads) + " must be in 1.." +
                                std::to_string(kMaxThreads));
  }
  impl_->threads = threads;
}

const std::string& Transcription::lastError() const { return impl_->error; }
long Transcription::dynamicsEvaluations() const { return impl_->dynamicsCount; }
long Transcription::linearizationEvaluations() const { return impl_->linearizationCount; }

double Transcription::horizon(const double* z) const { return impl_->horizonOf(z); }

Trajectory Transcription::trajectory(const double* z) const {
  const Impl& s = *impl_;
  const double T = s.horizonOf(z);
  Eigen::VectorXd times(s.N);
  Eigen::MatrixXd states(s.nx, s.N), inputs(s.m, s.N);
  for (int k = 0; k < s.N; ++k) {
    times(k) = T * s.tau(k);
    const int p = s.knotPoint(k);
    states.col(k) = Eigen::Map<const Eigen::VectorXd>(z + p * s.stride, s.nx);
    inputs.col(k) = Eigen::Map<const Eigen::VectorXd>(z + p * s.stride + s.nx, s.m);
  }
  return Trajectory(s.model.configNames(), s.model.inputNames(), std::move(times), std::move(states),
                    std::move(inputs));
}

Eigen::MatrixXd Transcription::midpointStates(const double* z) const {
  const Impl& s = *impl_;
  if (!s.hermiteSimpson) return Eigen::MatrixXd(s.nx, 0);
  Eigen::MatrixXd out(s.nx, s.N - 1);
  for (int k = 0; k < s.N - 1; ++k) out.col(k) = Eigen::Map<const Eigen::VectorXd>(z + (2 * k + 1) * s.stride, s.nx);
  return out;
}

Eigen::MatrixXd Transcription::midpointInputs(const double* z) const {
  const Impl& s = *impl_;
  if (!s.hermiteSimpson) return Eigen::MatrixXd(s.m, 0);
  Eigen::MatrixXd out(s.m, s.N - 1);
  for (int k = 0; k < s.N - 1; ++k) {
    out.col(k) = Eigen::Map<const Eigen::VectorXd>(z + (2 * k + 1) * s.stride + s.nx, s.m);
  }
  return out;
}

double Transcription::maxSlack(const double* z) const {
  const Impl& s = *impl_;
  if (s.nc == 0) return 0.0;
  const int count = (s.N - 1) * (s.ncH + s.nc);
  return Eigen::Map<const Eigen::VectorXd>(z + s.slackStart, count).cwiseAbs().maxCoeff();
}

Eigen::MatrixXd Transcription::slackContributions(const double* z) const {
  const Impl& s = *impl_;
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(s.nx, s.N - 1);
  if (s.nc == 0) return out;
  Data data(s.model);
  for (int k = 0; k + 1 < s.N; ++k) {
    const Eigen::Map<const Eigen::VectorXd> xb(z + s.knotPoint(k + 1) * s.stride, s.nx);
    computeConstraints(s.model, data, xb.head(s.n), xb.tail(s.n));
    for (int j = 0; j < s.ncH; ++j) {
      out.col(k).head(s.n) += data.constraintJacobian.row(s.holonomicRows[j]).transpose() * z[s.slackOf(k) + j];
    }
    out.col(k).tail(s.n) =
        data.constraintJacobian.transpose() * Eigen::Map<const Eigen::VectorXd>(z + s.slackOf(k) + s.ncH, s.nc);
  }
  return out;
}

}  // namespace trellis
