// examples/hand/hand_feedback.hpp — the hand's feedback design as the main job, the benchmarks
// and the tests use it (one place for the choices below).
//
// Weights Q = diag(100·I_n, I_n) (angles matter more than rates), R = I (tensions in N), Qf = Q;
// the tangent basis by discrete transport on the knots (kProjected, 2 substeps: the reference
// satisfies the dynamics only at and near its knots); Riccati rtol 1e-6, atol 1e-8.
//
// Gains. The manifold TV-LQR's K(t) has a boundary layer at the end time (K(T) from Qf is ~1e4,
// and it relaxes within a few ms), far narrower than the knot spacing. The schedule therefore
// samples K at the reference's knots and bisects each interval where K's midpoint is off the
// chord by more than 1e-3 of the gain's size (rows go into the layer and nowhere else), with the
// C¹ cubic rule between rows (no closed-loop restart at a row). Cubic on the knots alone
// overshoots in the boundary layer (measured: the closed loop blew up at t = 2.98 s); linear on
// the knots misses the layer; every Riccati step time as a row (1440 rows) writes a 28 MB file.
//
// Closed loop: BDF (the hand is stiff), rtol 1e-7, atol 5e-10 — the simulator integrates the
// deviation from the reference, so atol bounds the absolute local error once the perturbation has
// decayed (final error ~1e-8…1e-7 on the hand, measured; see the report of issue 11), tensions
// clipped at 0.
#pragma once

#include <trellis/control.hpp>

#include <Eigen/Core>

#include <vector>

namespace trellis::hand {

LqrWeights feedbackWeights(const Model& model);
TangentTransportOptions feedbackTransport();
RiccatiOptions feedbackRiccatiOptions();

/// K(t) of `lqr` at the reference's knots and the bisection points of the file comment, cubic
/// rule. Throws what the GainSchedule constructor throws.
GainSchedule feedbackGains(const ManifoldRiccatiSolution& lqr, const Trajectory& reference);

/// BDF, rtol 1e-7, atol 5e-10, inputs clipped to [0, ∞) (m inputs), projection onto the
/// constraints where the drift exceeds 3e-11: the drift the transient leaves would otherwise stay
/// (the exact dynamics keep h and A q̇; the tangent-space feedback cannot see them) and, through the
/// light phalanges, show as ~1e-7 rad in the joints; each projection moves q by ~100× the drift it
/// removes, so a small tolerance also keeps those steps small (test_hand_closed_loop.cpp).
SimulationOptions closedLoopOptions(int m);

/// `runs` starts x0 + T0 z with z ~ N(0, I) (mt19937 seeded with `seed`, drawn run after run)
/// scaled to ‖z‖ = size: tangent to the manifold at x0 (T0: 2n×d orthonormal tangent basis).
std::vector<Eigen::VectorXd> perturbedStarts(const Eigen::MatrixXd& T0, const Eigen::VectorXd& x0,
                                             int runs, unsigned seed, double size);

}  // namespace trellis::hand
