// fuzz_trajectory_csv.cpp — the trajectory CSV reader (Trajectory::readCsv): bad text is a
// TrajectoryError; a trajectory that reads back is written and read again to the same numbers
// (17 significant digits round-trip a double).
#include "fuzz_support.hpp"

#include "trellis/core/trajectory.hpp"

#include <cstdint>
#include <sstream>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  trellis::fuzz::rejectsCleanly([&] {
    std::istringstream in(text);
    const trellis::Trajectory trajectory = trellis::Trajectory::readCsv(in, "<fuzz>");
    std::ostringstream out;
    trajectory.writeCsv(out);
    std::istringstream again(out.str());
    const trellis::Trajectory copy = trellis::Trajectory::readCsv(again, "<round trip>");
    if (copy.configNames() != trajectory.configNames() || copy.inputNames() != trajectory.inputNames() ||
        copy.times() != trajectory.times() || copy.states() != trajectory.states() ||
        copy.inputs() != trajectory.inputs()) {
      trellis::fuzz::finding("the CSV round trip changed the trajectory", out.str().c_str());
    }
  });
  return 0;
}
