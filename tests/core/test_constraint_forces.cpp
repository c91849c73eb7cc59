// tests/core/test_constraint_forces.cpp — trellis/core/constraint_forces.hpp: the constraint
// forces Aᵀλ split into point forces. Legs: the split sums back to Aᵀλ through the points'
// Jacobians (central differences, the identity Σ (∂p/∂q)ᵀ F = Aᵀλ), and closed forms per kind.
#include <catch2/catch.hpp>

#include "support/finite_difference.hpp"
#include "support/random_state.hpp"
#include "support/test_models.hpp"

#include <trellis/core.hpp>
#include <trellis/core/constraint_forces.hpp>

#include <algorithm>
#include <random>

using namespace trellis;
using namespace trellis::test;

TEST_CASE("constraint point forces sum to A^T lambda and follow each kind's formula", "[constraint_forces]") {
  // Every kind: knife edge, distance, point, point on plane.
  const Model model = kitchenSink().model;
  REQUIRE(model.nc() == 4);
  std::mt19937 rng(41);
  const State s = randomState(model, rng);
  Data data(model);
  REQUIRE(computeDynamics(model, data, s.q, s.dq, s.u).ok());
  const std::vector<ConstraintPointForce> forces = computeConstraintPointForces(model, data, data.lambda);

  SECTION("Σ (∂p/∂q)ᵀ F = Aᵀλ") {
    // ∂p/∂q of the material point of the force's body at the listed point (a force on body a may
    // act at a point of body b, as for a point on a plane), by central differences: the point
    // moved with the body's joint frame, X(q') = T(q') T(q)⁻¹ X. Error ~1e-10 relative (support/
    // finite_difference.hpp); 1e-7 relative to Σ |∂p/∂q|ᵀ |F| leaves three orders of margin.
    Eigen::VectorXd generalized = Eigen::VectorXd::Zero(model.nq()), scale = generalized;
    Data work(model);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq());
    for (const ConstraintPointForce& force : forces) {
      if (force.joint == kWorld) continue;  // the world does not move
      const int frame = model.frameIndex(model.joints()[force.joint].frame);
      computeKinematics(model, work, s.q, zero);
      const Eigen::Vector3d local = work.framePose[frame].inverse() * force.point;
      const Eigen::MatrixXd J = centralDifferenceJacobian(
          [&](const Eigen::VectorXd& q) -> Eigen::VectorXd {
            computeKinematics(model, work, q, zero);
            return work.framePose[frame] * local;
          },
          s.q);
      generalized += J.transpose() * force.force;
      scale += J.cwiseAbs().transpose() * force.force.cwiseAbs();
    }
    const Eigen::VectorXd expected = data.constraintJacobian.transpose() * data.lambda;
    for (int i = 0; i < model.nq(); ++i) {
      INFO("coordinate " << model.joints()[i].config << ": split " << generalized(i) << ", A^T lambda " << expected(i));
      CHECK(std::abs(generalized(i) - expected(i)) <= 1e-7 * std::max(scale(i), 1e-12));
    }
  }

  SECTION("per kind: rows in order, the force on the first body first, closed forms") {
    // knife edge: 1 force; distance, point, point on plane: 2 each.
    REQUIRE(forces.size() == 7);
    const std::vector<int> rows{0, 1, 1, 2, 2, 3, 3};
    const std::vector<int> sides{0, 0, 1, 0, 1, 1, 1};
    for (std::size_t f = 0; f < forces.size(); ++f) {
      CHECK(forces[f].row == rows[f]);
      CHECK(forces[f].side == sides[f]);
    }
    for (int r = 0; r < 4; ++r) {
      const Constraint& c = model.constraints()[r];
      const auto first = std::find_if(forces.begin(), forces.end(), [&](const auto& x) { return x.row == r; });
      CHECK(first->joint == c.a.joint);
      const double lambda = data.lambda(r);
      switch (c.type) {
        case ConstraintType::kDistance: {
          const Eigen::Vector3d pa = first->point, pb = (first + 1)->point;
          CHECK((first->force - lambda * 2.0 * (pa - pb)).norm() <= 1e-14 * first->force.norm());
          CHECK((first->force + (first + 1)->force).norm() == 0.0);
          CHECK(std::abs((pa - pb).norm() - c.distance) < 1.0);  // sanity: the points are the constraint's
          break;
        }
        case ConstraintType::kPoint:
          CHECK(first->force == lambda * Eigen::Vector3d::Unit(c.axis));
          CHECK((first + 1)->force == -lambda * Eigen::Vector3d::Unit(c.axis));
          break;
        case ConstraintType::kPointOnPlane:
          CHECK(first->point == (first + 1)->point);  // both at the point body's point
          CHECK(std::abs(first->force.norm() - std::abs(lambda) * c.direction.norm()) <= 1e-14 * first->force.norm());
          break;
        case ConstraintType::kKnifeEdge:
          CHECK(std::abs(first->force.norm() - std::abs(lambda) * c.direction.norm()) <= 1e-14 * first->force.norm());
          break;
      }
    }
  }

  SECTION("a lambda of the wrong size is an error naming both sizes") {
    CHECK_THROWS_WITH(computeConstraintPointForces(model, data, Eigen::VectorXd::Zero(3)),
                      Catch::Matchers::Contains("lambda has 3 entries, the model has 4 constraint rows"));
  }
}
