// trellis/control/manifold_lqr.hpp — TV-LQR on the constraint manifold along a trajectory.
//
// A constrained state x = [q; q̇] (2n) lives on M = {h(q) = 0, A(q) q̇ = 0}; the core's
// computeConstraintTangentBasis gives an orthonormal basis T(x) (2n×d) of its tangent space, and
// computeLinearization the exact A(t), B(t) of the full-state ODE ẋ = f(x, u) (with the constraint
// forces). The ODE keeps M invariant (d/dt h = A q̇, d/dt (A q̇) = A q̈ + Ȧ q̇ = 0), so along a
// reference x(t) on M its linearization maps tangent vectors to tangent vectors, while directions
// that leave M cannot be steered by any input: the full-state Riccati equation is the wrong problem
// (its (A, B) is not stabilizable). The LQR is posed on the tangent space instead.
//
// Transport of the basis. Choose T(t) (2n×d, orthonormal) so that δx = T z is tangent for all t.
// Differentiating (I − P) δx = 0, P = T Tᵀ, along solutions of δẋ = A δx gives Ṗ T = (I − P) A T,
// which is met by the parallel transport
//   Ṫ = (I − P(t)) A(t) T,    T(t0) = T(x(t0)) (the core's basis),
// with P(t) the projector onto the tangent space at x(t) (from the core's basis there; any basis
// gives the same P) — no second derivatives of the constraints are needed. The equation is linear
// in T: T(t) = Φ(t, t0) T0 up to the normal component, the span is the image of the tangent space
// under the flow, and d/dt (TᵀT) = Tᵀ(I − P)AT + (·)ᵀ = 0 for tangent T, so T stays orthonormal.
// With this choice TᵀṪ = 0, and z = Tᵀ δx obeys exactly
//   ż = (TᵀAT + ṪᵀT) z + TᵀB δu = Ar z + Br δu,   Ar = TᵀAT (d×d), Br = TᵀB (d×m)
// (the ṪᵀT term is zero for the transported basis).
// The algebraically equivalent Ṫ = (I − TTᵀ)AT = AT − T(TᵀAT) is NOT used: it is unstable off
// the orthonormal matrices (a perturbation T S, S symmetric, grows like −S·TᵀAT, the negated
// tangent dynamics — +1e4 s⁻¹ on the stiff hand), while with P(t) a perturbation stays bounded.
//
// T is integrated forward with CVODES (BDF; Newton with matrix-free GMRES on the exact product
// E ↦ (I − P)A E, preconditioned by the exact solve with the block-diagonal Newton matrix
// I − γ(I − P)A, so no difference quotient is ever taken; tight tolerances) on vec(T) (2n·d
// unknowns), keeping each step's Nordsieck data for the dense output T̃(t). The reference x(t)
// comes from cubic Hermite interpolation and is only approximately on M, so at every node of the
// grid below the stored T̃ is corrected onto the actual tangent space at x(t):
// T = polar(P(x(t)) T̃), the nearest orthonormal matrix (U Vᵀ of the SVD U Σ Vᵀ), where P(x) is
// the projector of the core's basis at x. maxCorrection() reports max ‖T − T̃‖_F over the nodes.
//
// A plain-data result. The basis owns what it needs and keeps no reference to the model: the
// corrected T_i and Ṫ_i = (I − P_i) A_i T_i (the transport's derivative) at the nodes t_i — the
// reference's knots, each interval split into `substeps` — and basis(t) is the cubic Hermite
// interpolant of these, made orthonormal again by its polar factor. Its error is
// O(h⁴ max‖T⁗‖/384) for node spacing h (exact at the nodes); it is tangent to M to that accuracy.
// The model-bound evaluator ReducedLinearization (used by the solvers) corrects the interpolant
// onto the exact tangent space at x(t) and returns Ar = TᵀAT, Br = TᵀB there.
//
// Without constraints the core's basis is I, so T(t) = I (d = 2n): the same code works for every
// scene, and solveManifoldRiccati then solves the full-state problem.
//
// Manifold Riccati. With Qr = TᵀQT, Qfr = T(tf)ᵀ Qf T(tf), R unchanged, solveRiccati integrates
//   −Ṡr = ArᵀSr + Sr Ar − Sr Br R⁻¹ Brᵀ Sr + Qr,   Sr(tf) = Qfr        (d×d)
// and the full-state feedback is δu = −K δx with K = Kr Tᵀ = R⁻¹ Brᵀ Sr Tᵀ (m×2n); its action on
// off-manifold directions (I − TTᵀ) is zero. The full cost-to-go matrix is S = T Sr Tᵀ (2n×2n).
#pragma once

#include "trellis/analysis/dense_output.hpp"
#include "trellis/control/riccati.hpp"
#include "trellis/core/reference.hpp"

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

namespace trellis {

class Model;
class Trajectory;

/// How T(t) is carried along the reference.
///  kIntegrated: the ODE above with CVODES (TᵀṪ = 0 to the integration tolerance). It relies on
///    the reference satisfying the dynamics between knots (ṖT = (I − P)AT holds only there).
///  kProjected: discrete transport on the reference's knots (each interval split into
///    `substeps`): T_{k+1} = polar(P_{k+1} T_k), and T(t) = polar(P(t) T_k) inside [t_k, t_{k+1}]
///    — continuous, orthonormal and tangent by construction, and uses no A. Since
///    P_{k+1}T_k = T_k + ṖT_k h + O(h²) and TᵀṖT = 0, it is a first-order approximation of the
///    parallel transport (TᵀṪ = O(h) instead of 0). Use it for a reference whose interpolation
///    between knots does not satisfy the dynamics (e.g. tensions from a per-knot inverse-dynamics
///    distribution on a stiff model, where the mismatch is amplified by M⁻¹).
enum class TangentTransport { kIntegrated, kProjected };

/// How solvers (manifold Riccati, Gramian, sampled-data discretization) get Ar(t), Br(t).
///  kExact: the core's linearization at x_ref(t), u_ref(t) at every t the integrator asks for
///    (one dynamics evaluation per distinct t), T corrected onto the exact tangent space there.
///  kNodes: Ar_i = T_iᵀA_iT_i, Br_i = T_iᵀB_i stored at the nodes during the transport (which
///    linearizes there anyway) and interpolated by the C¹ cubic Hermite with three-point slopes
///    (error O(h³) for node spacing h on a smooth reference; exact at the nodes); T(t) is the held
///    basis. No dynamics evaluation during the solve, and Ar, Br are C¹ in t (no kinks for the
///    integrator). Suited where the reference is only trustworthy at its knots — the case of
///    kProjected (a reference that does not satisfy the dynamics between knots).
///  kAuto: kNodes with kProjected, kExact with kIntegrated.
enum class ReducedLinearizationMode { kAuto, kExact, kNodes };

/// Options of transportTangentBasis: how the tangent basis T(t) is carried along the reference,
/// and how the reduced linearization is then evaluated.
struct TangentTransportOptions {
  TangentTransport method = TangentTransport::kIntegrated;  ///< integrated transport (CVODES) or projected steps
  ReducedLinearizationMode linearization = ReducedLinearizationMode::kAuto;  ///< exact at every t, or from the nodes
  /// Steps per reference interval (≥ 1): kProjected's transport steps, and for both methods the
  /// nodes where the held basis is stored (the knots split `substeps` times).
  int substeps = 1;
  double rtol = 1e-10;        ///< CVODES relative tolerance (> 0)
  double atol = 1e-12;        ///< CVODES absolute tolerance on each entry of T (> 0)
  long maxSteps = 100000;     ///< total internal steps over the trajectory (> 0)
  /// Throws std::invalid_argument naming the field and its value.
  void validate() const;
};

/// Outcome codes of transportTangentBasis (status.t: where the transport stopped).
enum class TransportCode {
  kOk,
  kDynamicsFailure,    ///< the dynamics or the tangent basis failed at x_ref(t) (t0 included)
  kIntegratorFailure,  ///< CVODES stopped (error test, convergence, more than maxSteps steps)
  kNonFinite,          ///< the transported basis became NaN/Inf
  kTurnedTooFast,      ///< the tangent space turned by more than the transport can follow
  kNotTransported,     ///< default-constructed: no transport ran
};

/// Names: ok, dynamics_failure, integrator_failure, non_finite, turned_too_fast, not_transported.
inline EnumNameTable<TransportCode> enumNames(TransportCode) {
  static constexpr EnumName<TransportCode> table[] = {
      {TransportCode::kOk, "ok"},
      {TransportCode::kDynamicsFailure, "dynamics_failure"},
      {TransportCode::kIntegratorFailure, "integrator_failure"},
      {TransportCode::kNonFinite, "non_finite"},
      {TransportCode::kTurnedTooFast, "turned_too_fast"},
      {TransportCode::kNotTransported, "not_transported"}};
  return table;
}

/// T(t) along a reference trajectory: plain data (see "A plain-data result" above), safe to copy,
/// to share between threads (every query is const and uses no shared workspace) and to keep after
/// the model is gone.
class TangentBasisTrajectory {
 public:
  int dimension() const { return d_; }   ///< d
  int nx() const { return nx_; }         ///< 2n
  double startTime() const { return t0_; }  ///< t_0 of the reference [s]
  double endTime() const { return tf_; }    ///< t_{N−1} of the reference [s]

  /// status().ok(): the transport covered the whole trajectory. Otherwise status() names the
  /// cause, its time (t) and message, and T is available on [t0, validUntil()] — nowhere when the
  /// dynamics already fail at t0 (hasBasis() is false then).
  bool ok() const { return status_.ok(); }
  const Status<TransportCode>& status() const { return status_; }  ///< code, message, t
  /// One line: "ok: …" or the failure with its time (Status::describe).
  std::string describe() const;
  /// One JSON object: status fields, d, nx, the valid range, steps and the largest correction.
  std::string json() const;
  /// True when T(t) is available somewhere (on [startTime(), validUntil()]).
  bool hasBasis() const { return nx_ > 0 && (identity_ || !nodeTimes_.empty()); }
  /// True when the scene has no constraints: T(t) = I (d = 2n) at every t.
  bool isIdentity() const { return identity_; }
  double validUntil() const { return validUntil_; }         ///< T is available on [startTime(), validUntil()]
  long steps() const { return steps_; }  ///< CVODES internal steps (kProjected: transport steps)
  /// Right-hand sides spent on difference-quotient Jacobian products (0: the exact ones were used).
  long differenceQuotientEvaluations() const { return linearRhsEvaluations_; }

  /// T(t), 2n×d, orthonormal: the Hermite interpolant of the stored nodes, polar-corrected (see the
  /// file comment; tangent to M to the interpolation accuracy, exactly at the nodes). Throws
  /// std::out_of_range outside [t0, validUntil()].
  Eigen::MatrixXd basis(double t) const;
  /// The same into out, which is resized; allocation-free once out and the internal scratch sizes
  /// match (the polar factor's d×d eigen-decomposition aside).
  void basis(double t, Eigen::MatrixXd& out) const;
  /// The transported basis T̃(t) before any correction (kIntegrated: the CVODES dense output;
  /// kProjected: T_k on (t_k, t_{k+1}]).
  Eigen::MatrixXd transportedBasis(double t) const;
  /// T(t) corrected onto the exact tangent space at x_ref(t), and Ar = TᵀAT (d×d), Br = TᵀB (d×m)
  /// from the exact linearization at x_ref(t), u_ref(t) of `model` (which must be the model the
  /// basis was transported with). Convenience for one-off queries (allocates a Data); solvers use
  /// ReducedLinearization. Throws std::out_of_range outside the valid range, std::runtime_error
  /// if the dynamics fail at x_ref(t).
  void reducedLinearization(const Model& model, double t, Eigen::MatrixXd& T, Eigen::MatrixXd& Ar,
                            Eigen::MatrixXd& Br) const;
  /// max ‖T − T̃‖_F over the nodes (the correction onto the tangent space).
  double maxCorrection() const { return maxCorrection_; }

  /// The reference the basis was transported along (an owned, immutable copy).
  const Trajectory& reference() const;
  /// Node times (ascending, t0 first) with the corrected T and Ṫ there.
  const std::vector<double>& nodeTimes() const { return nodeTimes_; }
  /// True when solvers interpolate Ar, Br between the nodes (ReducedLinearizationMode::kNodes).
  bool usesNodeLinearization() const { return nodeLinearization_; }

 private:
  friend class ReducedLinearization;
  friend TangentBasisTrajectory transportTangentBasis(const Model&, const Trajectory&,
                                                      const TangentTransportOptions&);
  void checkRange(double t, const char* what) const;
  void interpolate(double t, Eigen::MatrixXd& T) const;  // Hermite, not yet orthonormal

  std::shared_ptr<const Trajectory> trajectory_;  // immutable, shared between copies
  int nx_ = 0, d_ = 0;
  double t0_ = 0.0, tf_ = 0.0, validUntil_ = 0.0;
  bool identity_ = false;      // no constraints: T = I, nothing stored
  DenseOutput stored_;         // transported vec(T̃) (2n·d) in t, ascending; the first step is t0
  std::vector<double> nodeTimes_;
  std::vector<Eigen::MatrixXd> nodeT_, nodeDT_;  // corrected T and Ṫ at the nodes
  std::vector<Eigen::MatrixXd> nodeAr_, nodeBr_;  // TᵀAT, TᵀB at the nodes
  bool nodeLinearization_ = false;                // solvers interpolate nodeAr_/nodeBr_ (kNodes)
  Status<TransportCode> status_{TransportCode::kNotTransported, "no transport ran"};
  long steps_ = 0, linearRhsEvaluations_ = 0;
  double maxCorrection_ = 0.0;
};

/// Transports the tangent basis along the reference (see the file comment). The trajectory must
/// match the model and have state derivatives (computeStateDerivatives). Throws
/// TrajectoryError / std::logic_error / std::invalid_argument for bad input and std::runtime_error
/// if the dynamics fail at t0; later numerical failure is reported by ok() / message().
/// For an unconstrained model T = I (d = 2n), without integrating.
TangentBasisTrajectory transportTangentBasis(const Model& model, const Trajectory& reference,
                                             const TangentTransportOptions& options = {});

/// The reduced linearization along a transported basis, bound to a model (like a Data: the model
/// must outlive it; one per thread). evaluate(t) computes, for t in the basis's valid range,
///   T = polar(P(x_ref(t)) T_h(t))   (T_h: the basis's Hermite interpolant),
///   Ar = TᵀA T,  Br = TᵀB           (A, B: the core's exact linearization at x_ref(t), u_ref(t)),
/// with one dynamics evaluation per distinct t (the last t is cached) — or, when the basis uses
/// node linearizations (kNodes), T = basis(t) and Ar, Br interpolated from the nodes, with no
/// dynamics evaluation. Allocation-free after the first call, except the d×d SVD/eigensolver.
class ReducedLinearization {
 public:
  /// Binds `basis` to `model` (which must outlive this object); sizes the workspace.
  ReducedLinearization(const Model& model, TangentBasisTrajectory basis);
  ~ReducedLinearization();
  ReducedLinearization(const ReducedLinearization&) = delete;
  ReducedLinearization& operator=(const ReducedLinearization&) = delete;

  /// Throws std::out_of_range outside the valid range (bad input). A failure of the dynamics, a
  /// change of the tangent space's dimension or a basis drifted off it is the returned status
  /// naming t (then T, Ar, Br are not valid).
  ReferenceStatus evaluate(double t);
  const Eigen::MatrixXd& T() const { return T_; }    ///< 2n×d tangent basis at the last t
  const Eigen::MatrixXd& Ar() const { return Ar_; }  ///< d×d: TᵀA T at the last t
  const Eigen::MatrixXd& Br() const { return Br_; }  ///< d×m: TᵀB at the last t
  const Eigen::MatrixXd& A() const;  ///< the full-state A at the last t
  const TangentBasisTrajectory& basis() const { return basis_; }  ///< the transported basis it uses
  long evaluations() const { return evaluations_; }  ///< dynamics evaluations so far

 private:
  struct Work;
  const Model& model_;
  TangentBasisTrajectory basis_;
  std::unique_ptr<Work> work_;
  Eigen::MatrixXd T_, Ar_, Br_;
  bool cached_ = false;
  double cachedTime_ = 0.0;
  long evaluations_ = 0;
};

/// The manifold TV-LQR: plain data (the reduced solution and the basis own everything they need;
/// nothing refers to the model, the weights' callbacks or the trajectory passed in). Copyable,
/// thread safe for queries.
/// Which part of the manifold TV-LQR failed.
enum class ManifoldRiccatiCode {
  kOk,
  kTransportFailure,  ///< the tangent basis transport failed (`reduced` is empty: the Riccati
                      ///< solve needs T on the whole horizon); t: where it stopped
  kTerminalFailure,   ///< the reduced linearization failed at tf (no terminal weight Tᵀ Qf T)
  kRiccatiFailure,    ///< the reduced Riccati solve failed (reduced.status says how)
  kNotSolved,         ///< default-constructed: no solve ran
};

/// Names: ok, transport_failure, terminal_failure, riccati_failure, not_solved.
inline EnumNameTable<ManifoldRiccatiCode> enumNames(ManifoldRiccatiCode) {
  static constexpr EnumName<ManifoldRiccatiCode> table[] = {
      {ManifoldRiccatiCode::kOk, "ok"},
      {ManifoldRiccatiCode::kTransportFailure, "transport_failure"},
      {ManifoldRiccatiCode::kTerminalFailure, "terminal_failure"},
      {ManifoldRiccatiCode::kRiccatiFailure, "riccati_failure"},
      {ManifoldRiccatiCode::kNotSolved, "not_solved"}};
  return table;
}

/// The Riccati solution on the constraint manifold: the reduced solve on the tangent coordinates z
/// (d states) with the tangent basis T(t) that maps them to the full state, and one status for both.
struct ManifoldRiccatiSolution {
  RiccatiSolution reduced;          ///< on z (d states): Sr(t), Kr(t)
  TangentBasisTrajectory basis;     ///< T(t)
  long linearizations = 0;          ///< dynamics evaluations during the Riccati solve
  /// code; message (empty when ok; the transport's or the Riccati solve's message, with the
  /// time); t: where it failed; index unused.
  Status<ManifoldRiccatiCode> status{ManifoldRiccatiCode::kNotSolved, "no solve ran"};
  bool ok() const { return status.ok(); }  ///< status.ok(): the result is complete and right
  /// One line: the status, the tangent dimension and the reduced solve's work.
  std::string describe() const;
  /// {"status", "ok", "message", "t", "index", "nx", "tangent_dimension", "transport_steps",
  /// "max_basis_correction", "linearizations", "riccati": RiccatiSolution::json()}.
  std::string json() const;
  int nx() const { return basis.nx(); }                ///< 2n (full state)
  int dimension() const { return basis.dimension(); }  ///< d (tangent space)
  /// K(t) = Kr(t) T(t)ᵀ (m×2n), T(t) the held basis (Hermite + polar, see above): exact at the
  /// nodes, and within O(h⁴) of the basis the solve used elsewhere; Kr(t) as RiccatiSolution::K.
  Eigen::MatrixXd K(double t) const;
  /// S(t) = T(t) Sr(t) T(t)ᵀ (2n×2n, symmetric PSD, rank ≤ d).
  Eigen::MatrixXd S(double t) const;
};

/// Full-state weights (Q, Qf: 2n×2n; R: m×m; Qfun/Rfun callbacks allowed), reduced internally to
/// Qr(t) = T(t)ᵀ Q(t) T(t), Qfr = T(tf)ᵀ Qf T(tf). Throws as solveRiccati and
/// transportTangentBasis do for bad input (weights are checked at full size); numerical failure
/// (transport or Riccati) is reported in the result with its time, never thrown.
ManifoldRiccatiSolution solveManifoldRiccati(const Model& model, const Trajectory& reference,
                                             const LqrWeights& weights,
                                             const RiccatiOptions& options = {},
                                             const TangentTransportOptions& transport = {});

}  // namespace trellis
