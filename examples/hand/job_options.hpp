// examples/hand/job_options.hpp — the hand jobs' command-line values (hand_main_job,
// hand_hold_job, hand_ball_feedback): a whole argument read as an integer in a range, a finite
// number, or a positive finite number,
// or std::invalid_argument naming the option and the text ("--runs '3x' is not an integer",
// "--runs 0 must be in 1..1000") — never a prefix taken silently, never a wrapped negative.
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>

namespace trellis::hand {

/// The value after option argv[i] (i advanced), or invalid_argument "option X needs a value".
inline std::string optionValue(int argc, char** argv, int& i) {
  const std::string option = argv[i];
  if (i + 1 >= argc) throw std::invalid_argument("option " + option + " needs a value");
  return argv[++i];
}

/// `text` whole as an integer in [lo, hi].
inline long integerOption(const std::string& option, const std::string& text, long lo, long hi) {
  std::size_t used = 0;
  long x = 0;
  try {
    x = std::stol(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (text.empty() || used != text.size()) throw std::invalid_argument(option + " '" + text + "' is not an integer");
  if (x < lo || x > hi) {
    throw std::invalid_argument(option + " " + text + " must be in " + std::to_string(lo) + ".." + std::to_string(hi));
  }
  return x;
}

/// `text` whole as a number (std::stod over all of it), or NaN.
inline double wholeNumber(const std::string& text) {
  std::size_t used = 0;
  double x = NAN;
  try {
    x = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  return !text.empty() && used == text.size() ? x : NAN;
}

/// `text` whole as a finite number > 0.
inline double positiveOption(const std::string& option, const std::string& text) {
  const double x = wholeNumber(text);
  if (!(x > 0.0) || !std::isfinite(x)) throw std::invalid_argument(option + " '" + text + "' must be a number > 0");
  return x;
}

/// `text` whole as a finite number (its sign is the caller's options' validate() to judge).
inline double numberOption(const std::string& option, const std::string& text) {
  const double x = wholeNumber(text);
  if (!std::isfinite(x)) throw std::invalid_argument(option + " '" + text + "' is not a finite number");
  return x;
}

}  // namespace trellis::hand
