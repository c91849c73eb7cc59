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
// T is integrated forward with CVODES (BDF, dense Newton with the exact, block-diagonal Jacobian
// E ↦ (I − P)A E, tight tolerances) on vec(T) (2n·d unknowns), keeping each step's Nordsieck data
// (CVodeGetDky) for dense output T̃(t). The reference x(t) comes from cubic Hermite interpolation
// and is only approximately on M, so a query corrects the stored T̃ onto the actual tangent space
// at x(t): T = polar(P(x(t)) T̃), the nearest orthonormal matrix (U Vᵀ of the SVD U Σ Vᵀ), where
// P(x) is the projector of the core's basis at x. maxCorrection() reports max ‖T − T̃‖_F seen.
//
// Without constraints the core's basis is I, so T(t) = I (d = 2n): the same code works for every
// scene, and solveManifoldRiccati then solves the full-state problem.
//
// Manifold Riccati. With Qr = TᵀQT, Qfr = T(tf)ᵀ Qf T(tf), R unchanged, solveRiccati integrates
//   −Ṡr = ArᵀSr + Sr Ar − Sr Br R⁻¹ Brᵀ Sr + Qr,   Sr(tf) = Qfr        (d×d)
// and the full-state feedback is δu = −K δx with K = Kr Tᵀ = R⁻¹ Brᵀ Sr Tᵀ (m×2n); its action on
// off-manifold directions (I − TTᵀ) is zero. The full cost-to-go matrix is S = T Sr Tᵀ (2n×2n).
#pragma once

#include "trellis/control/riccati.hpp"

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

struct TangentTransportOptions {
  TangentTransport method = TangentTransport::kIntegrated;
  int substeps = 1;           ///< kProjected: steps per reference interval (≥ 1)
  double rtol = 1e-10;        ///< CVODES relative tolerance (> 0)
  double atol = 1e-12;        ///< CVODES absolute tolerance on each entry of T (> 0)
  long maxSteps = 100000;     ///< total internal steps over the trajectory (> 0)
  /// Throws std::invalid_argument naming the field and its value.
  void validate() const;
};

/// T(t) along a reference trajectory. Holds a copy of the trajectory and a pointer to the model
/// (which must outlive it), plus its own workspace: queries are not thread safe (a copy gets a
/// fresh workspace and can be used on another thread).
class TangentBasisTrajectory {
 public:
  TangentBasisTrajectory();
  ~TangentBasisTrajectory();
  TangentBasisTrajectory(const TangentBasisTrajectory& other);
  TangentBasisTrajectory& operator=(const TangentBasisTrajectory& other);
  TangentBasisTrajectory(TangentBasisTrajectory&&) noexcept;
  TangentBasisTrajectory& operator=(TangentBasisTrajectory&&) noexcept;

  int dimension() const { return d_; }   ///< d
  int nx() const { return nx_; }         ///< 2n
  double startTime() const { return t0_; }
  double endTime() const { return tf_; }

  /// True when the transport covered the whole trajectory (false for a default-constructed object).
  /// Otherwise message() names the time and the cause (dynamics failure at x(t), CVODES error), and
  /// T is available on [t0, validUntil()].
  bool ok() const { return trajectory_ != nullptr && message_.empty(); }
  const std::string& message() const { return message_; }
  double validUntil() const;
  long steps() const { return steps_; }  ///< CVODES internal steps

  /// T(t), 2n×d, orthonormal, spanning the tangent space at x_ref(t) (corrected as described in
  /// the file comment). Throws std::out_of_range outside [t0, validUntil()], std::runtime_error if
  /// the dynamics fail at x_ref(t).
  Eigen::MatrixXd basis(double t) const;
  /// The stored (uncorrected) transported basis T̃(t) from the dense output.
  Eigen::MatrixXd transportedBasis(double t) const;
  /// T(t), and Ar = TᵀAT (d×d), Br = TᵀB (d×m) with A, B the exact linearization at x_ref(t),
  /// u_ref(t) — one evaluation of the dynamics. Outputs are resized as needed.
  void reducedLinearization(double t, Eigen::MatrixXd& T, Eigen::MatrixXd& Ar,
                            Eigen::MatrixXd& Br) const;
  /// max ‖T − T̃‖_F seen at the knots (checked on construction) and at every query since.
  double maxCorrection() const { return maxCorrection_; }

 private:
  friend TangentBasisTrajectory transportTangentBasis(const Model&, const Trajectory&,
                                                      const TangentTransportOptions&);
  struct Workspace;
  struct Step {
    double t;            // step end
    Eigen::MatrixXd D;   // (2n·d) × (q+1): d^k vec(T)/dt^k at t
  };
  void evaluateStored(double t, Eigen::MatrixXd& Ttilde) const;
  void correct(double t, const Eigen::MatrixXd& Ttilde, Eigen::MatrixXd& T) const;

  const Model* model_ = nullptr;
  std::shared_ptr<const Trajectory> trajectory_;  // immutable, shared between copies
  int nx_ = 0, d_ = 0;
  double t0_ = 0.0, tf_ = 0.0;
  bool identity_ = false;      // no constraints: T = I, nothing stored
  std::vector<Step> stored_;   // ascending t; stored_[0] is t0
  std::string message_;
  long steps_ = 0;
  mutable double maxCorrection_ = 0.0;
  mutable std::unique_ptr<Workspace> work_;
};

/// Transports the tangent basis along the reference (see the file comment). The trajectory must
/// match the model and have state derivatives (computeStateDerivatives). Throws
/// TrajectoryError / std::logic_error / std::invalid_argument for bad input and std::runtime_error
/// if the dynamics fail at t0; later numerical failure is reported by ok() / message().
/// For an unconstrained model T = I (d = 2n), without integrating.
TangentBasisTrajectory transportTangentBasis(const Model& model, const Trajectory& reference,
                                             const TangentTransportOptions& options = {});

/// The reduced solution's callbacks share one TangentBasisTrajectory workspace (with copies of
/// this struct too): K(t) and S(t) are not thread safe.
struct ManifoldRiccatiSolution {
  RiccatiSolution reduced;          ///< on z (d states): Sr(t), Kr(t)
  TangentBasisTrajectory basis;     ///< T(t)
  /// False when the transport failed (then `reduced` is empty: the Riccati solve needs T on the
  /// whole horizon) or the reduced Riccati solve failed.
  bool ok() const { return basis.ok() && reduced.ok(); }
  /// Empty when ok; otherwise the transport's or the Riccati solve's message (with the time).
  const std::string& message() const;
  int nx() const { return basis.nx(); }
  int dimension() const { return basis.dimension(); }
  /// K(t) = Kr(t) T(t)ᵀ (m×2n).
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
