// fuzz_urdf.cpp — the URDF importer (importUrdf, then sceneFromUrdf), then the exact linearization
// at a nonzero state for a small model: bad XML or an unsupported feature is rejected with a
// ModelError; a robot that loads is linearized without undefined behaviour, and an ok status
// comes with finite A and B.
#include "fuzz_support.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/urdf.hpp"

#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  trellis::fuzz::rejectsCleanly([&] {
    const trellis::Scene scene = trellis::sceneFromUrdf(trellis::importUrdf(text, "<fuzz>"));
    const trellis::Model& model = scene.model;
    if (model.nq() > 30) return;  // keep each execution cheap
    trellis::Data workspace(model);
    // Off the zero pose, where many terms vanish: q_i = 0.1 i, q̇_i = 0.3 − 0.05 i.
    Eigen::VectorXd q = scene.q, dq = scene.dq;
    for (Eigen::Index i = 0; i < q.size(); ++i) {
      q[i] += 0.1 * static_cast<double>(i);
      dq[i] += 0.3 - 0.05 * static_cast<double>(i);
    }
    const trellis::DynamicsStatus status =
        trellis::computeLinearization(model, workspace, q, dq, scene.u);
    if (status.ok() && !(workspace.A.allFinite() && workspace.B.allFinite())) {
      trellis::fuzz::finding("an ok linearization that is not finite", "");
    }
  });
  return 0;
}
