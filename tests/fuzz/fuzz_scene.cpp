// fuzz_scene.cpp — the scene loader (parseScene), then the exact linearization at the scene's
// state for a small model: bad text is rejected with a ModelError; a scene that loads is
// linearized without undefined behaviour, and an ok status comes with finite A and B.
#include "fuzz_support.hpp"

#include "trellis/core/data.hpp"
#include "trellis/core/linearization.hpp"
#include "trellis/core/scene.hpp"

#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  trellis::fuzz::rejectsCleanly([&] {
    const trellis::Scene scene = trellis::parseScene(text, "<fuzz>");
    const trellis::Model& model = scene.model;
    if (model.nq() > 30) return;  // keep each execution cheap
    trellis::Data workspace(model);
    const trellis::DynamicsStatus status =
        trellis::computeLinearization(model, workspace, scene.q, scene.dq, scene.u);
    if (status.ok() && !(workspace.A.allFinite() && workspace.B.allFinite())) {
      trellis::fuzz::finding("an ok linearization that is not finite", "");
    }
  });
  return 0;
}
