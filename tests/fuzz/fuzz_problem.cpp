// fuzz_problem.cpp — the optimal-control problem file (parseProblem), with scene paths resolved
// against examples/problems/ (as the seeds from there expect): bad text is a ProblemError or a
// ModelError (its scene) naming the field; nothing is solved.
#include "fuzz_support.hpp"

#include "trellis/optimization/problem.hpp"

#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  trellis::fuzz::rejectsCleanly([&] {
    const trellis::OptimalControlProblem problem =
        trellis::parseProblem(text, "<fuzz>", TRELLIS_SOURCE_DIR "/examples/problems");
    if (problem.knots < 2) trellis::fuzz::finding("a problem with fewer than 2 knots was accepted", "");
  });
  return 0;
}
