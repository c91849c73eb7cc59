// cli/weights.hpp — the weight matrices of `trellis gains` (--Q, --R, --Qf) from their text.
//
// A weight W is written in one of three forms:
//   "2"             2·I (size×size)
//   "1,1,10,10"     diag(1, 1, 10, 10) (exactly `size` numbers)
//   "weights.json"  a JSON file holding the full matrix as a list of `size` rows of `size` numbers
// The text is read as numbers when it consists only of digits, signs, '.', 'e'/'E', commas and
// blanks; anything else is a file path (so a file named like a number must be given as ./NAME).
#pragma once

#include <Eigen/Core>

#include <string>

namespace trellis::cli {

enum class WeightKind {
  kSemidefinite,  ///< Q, Qf: symmetric, eigenvalues ≥ 0 (diagonal entries ≥ 0)
  kDefinite,      ///< R: symmetric, eigenvalues > 0 (diagonal entries > 0)
};

/// The size×size matrix of `text` given to `option` of `command`. Mistakes in the command-line
/// text itself (not a number, a list of the wrong length, a diagonal entry of the wrong sign)
/// throw UsageError; a weight file that cannot be read, is not valid JSON, is not a size×size
/// matrix of finite numbers, is not symmetric or not (semi)definite throws std::runtime_error.
/// Every message names the option, the offending text or file, and what is wrong; `sizeMeaning`
/// says what the size counts ("2n = 4 states").
Eigen::MatrixXd parseWeight(const std::string& command, const std::string& option,
                            const std::string& text, int size, const std::string& sizeMeaning,
                            WeightKind kind);

}  // namespace trellis::cli
