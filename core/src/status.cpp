// Numbers in status lines (status.hpp).
#include "trellis/core/status.hpp"

#include <cstdio>
#include <cstdlib>

namespace trellis {

std::string formatStatusNumber(double value) {
  // The shortest of %.1g … %.17g that reads back as the same double.
  char text[32];
  for (int digits = 1; digits <= 17; ++digits) {
    std::snprintf(text, sizeof text, "%.*g", digits, value);
    if (std::strtod(text, nullptr) == value) break;
  }
  return text;
}

}  // namespace trellis
