// constraint_forces.cpp — see trellis/core/constraint_forces.hpp. The point forces are the ones the
// dynamics applies (constraint_kinds.hpp: each kind's forces()), so the split is exact by construction.
#include "trellis/core/constraint_forces.hpp"

#include "constraint_kinds.hpp"

#include <stdexcept>
#include <string>

namespace trellis {

std::vector<ConstraintPointForce> computeConstraintPointForces(const Model& model, const Data& data,
                                                               const Eigen::VectorXd& lambda) {
  if (lambda.size() != model.nc()) {
    throw std::invalid_argument("computeConstraintPointForces: lambda has " + std::to_string(lambda.size()) +
                                " entries, the model has " + std::to_string(model.nc()) + " constraint rows");
  }
  std::vector<ConstraintPointForce> out;
  for (int r = 0; r < model.nc(); ++r) {
    const Constraint& c = model.constraints()[r];
    // The kinds emit the force on a first, then the one on b (header); a point on a plane acts at
    // the point body's point b on both.
    int emitted = 0;
    detail::withConstraintKind(c, [&](auto kind) {
      decltype(kind)::forces(data, c, [&](int joint, const Eigen::Vector3d& p, const Eigen::Vector3d& g, double) {
        const int side = c.type == ConstraintType::kPointOnPlane ? 1 : emitted;
        out.push_back({r, joint, side, p, lambda(r) * g});
        ++emitted;
      });
    });
  }
  return out;
}

}  // namespace trellis
