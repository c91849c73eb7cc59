// bench/models.hpp — the systems the benchmarks sweep over.
//
// Each builder returns a finalized Model together with a seeded random state (q, q̇, u) at which
// to evaluate it. Constrained variants anchor the constrained point to a world-fixed frame placed
// where that point is at the sampled q, and project q̇ onto the null space of A(q), so the state
// lies on the constraint manifold (h(q) = 0, A(q) q̇ = 0) — the states where every formulation of
// the constraint gives the same linearization (docs/paper_errata.md).
#pragma once

#include "trellis/core/model.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <string>

namespace trellis::bench {

/// Which family of system.
enum class ModelKind {
  kPlanarChain,  ///< N revolute joints about z, links hanging along −y, gravity −y
  kSpatialChain, ///< N revolute joints cycling x, y, z, links along −y, full inertia, gravity −z
  kHandTree,     ///< 20 joints: a fixed palm with 5 fingers × (1 abduction + 3 flexion joints)
};

/// Which rows a constrained chain's tip gets (ignored for the hand and for free models).
enum class TipRows {
  kOne,        ///< one scalar row: the tip's world x (planar chain) or z (3D chain)
  kPinned,     ///< the tip pinned: rows x, y, z (3D chain); x, y (planar chain, in its plane)
  kRedundant,  ///< planar chain only: x, y and the z row, identically zero (a degenerate row)
};

/// What to build. `links` is ignored for kHandTree (always 20 joints).
struct ModelSpec {
  ModelKind kind = ModelKind::kPlanarChain;
  int links = 2;
  /// Chains: point-constraint rows on the tip's world coordinates (see `tip`).
  /// Hand: a 3D point constraint (three rows x, y, z) on the index fingertip.
  bool constrained = false;
  TipRows tip = TipRows::kOne;
};

/// The number of constraint rows of spec's model.
int constraintRows(const ModelSpec& spec);

/// A model with the state to evaluate it at.
struct BenchModel {
  Model model;
  Eigen::VectorXd q, dq, u;  ///< nq, nq, nu
  std::string label;         ///< short name of the family: "planar", "spatial", "hand"
};

/// Short family name used in benchmark names and tables ("planar", "spatial", "hand").
const char* kindName(ModelKind kind);

/// Builds the model of `spec` and a state drawn from std::mt19937(seed): q, q̇, u uniform in
/// [−1, 1] (hand: flexion angles in [−0.2, 1.2], abductions in [−0.3, 0.3], inputs in
/// [−1, 1]·10⁻³ N·m). Gravity is on, and
/// every configuration variable carries one input (a configuration force). Throws whatever
/// ModelBuilder throws, and std::runtime_error when the sampled state cannot be made consistent.
BenchModel makeBenchModel(const ModelSpec& spec, std::uint32_t seed = 20100503u);

/// The profile drivers' model arguments: kind (planar, spatial, hand, or scene = the hand scene),
/// links (ignored for scene) and constrained (0 free, 1 one tip row, 2 the tip pinned, 3 the
/// planar tip pinned with its redundant z row: TipRows). Returns false, having printed why, for an
/// unknown kind.
bool parseProfileModel(const char* kind, const char* links, const char* constrained, ModelSpec& spec);

}  // namespace trellis::bench
