// fuzz_weights.cpp — the weight arguments of `trellis gains` (--Q, --R, --Qf: parseWeight). The
// first byte chooses the matrix size (1 to 8), the kind (semidefinite or definite) and whether the
// rest is the command-line text or the content of a weight file (written to a temporary file).
// Bad input is a UsageError or a runtime_error naming the option; an accepted weight is a finite
// symmetric matrix of the requested size.
#include "fuzz_support.hpp"

#include "weights.hpp"

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const int matrixSize = 1 + (data[0] & 7);
  const auto kind = (data[0] & 8) ? trellis::cli::WeightKind::kDefinite : trellis::cli::WeightKind::kSemidefinite;
  const bool asFile = (data[0] & 16) != 0;
  std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  std::string path;
  if (asFile) {
    char name[] = "/tmp/trellis_fuzz_weight_XXXXXX";
    const int fd = ::mkstemp(name);
    if (fd < 0) return 0;
    const bool written = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
    ::close(fd);
    path = name;
    if (!written) {
      std::remove(name);
      return 0;
    }
    text = path;
  }
  trellis::fuzz::rejectsCleanly([&] {
    const Eigen::MatrixXd W =
        trellis::cli::parseWeight("gains", "--Q", text, matrixSize, "the test size", kind);
    if (W.rows() != matrixSize || W.cols() != matrixSize || !W.allFinite()) {
      trellis::fuzz::finding("an accepted weight of the wrong size or not finite", text.c_str());
    }
  });
  if (!path.empty()) std::remove(path.c_str());
  return 0;
}
