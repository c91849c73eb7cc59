// Numbers in status lines (status.hpp).
#include "trellis/core/status.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace trellis {

std::string formatStatusNumber(double value) {
  // The shortest of %.1g … %.17g that reads back as the same double.
  // Whole-number magnitudes below 1e16 keep their positional form ("50", not "5e+01"): %g
  // switches to an exponent as soon as the exponent reaches the precision.
  char text[40];
  int digits = 1;
  for (; digits <= 17; ++digits) {
    std::snprintf(text, sizeof text, "%.*g", digits, value);
    if (std::strtod(text, nullptr) == value) break;
  }
  if (std::isfinite(value) && value != 0.0) {
    const int exponent = static_cast<int>(std::floor(std::log10(std::abs(value))));
    if (exponent >= digits && exponent < 16) std::snprintf(text, sizeof text, "%.*g", exponent + 1, value);
  }
  return text;
}

}  // namespace trellis
