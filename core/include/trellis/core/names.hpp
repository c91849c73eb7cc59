// trellis/core/names.hpp — the one rule for names that files must carry back.
//
// Configuration and input names become CSV column headers (trajectories: t, <configs>,
// d<configs>, <inputs>, rate_<inputs>; gain schedules: K[<input>|<state>], uff[<input>]) and JSON keys (states,
// command output); frame names appear in JSON and messages. A name is accepted only if every
// writer can write it and every reader read it back as the same name:
//   - every name (frames, configurations, inputs): not empty, valid UTF-8 (JSON carries only
//     UTF-8), no control character (a newline would split a CSV line or a message), no ',' or
//     '"' (CSV field separator and quote), no blank at either end (CSV readers trim fields), so
//     not only blanks;
//   - configuration and input names together (checkColumnNames): the columns c, d<c> all
//     distinct (the reader infers the number of configurations from the d<c> block) — so no
//     pair x / dx of configurations; no input name beginning with "rate_"
//     (the input-derivative columns). Inputs are read by position, so an input may share a
//     configuration's name (a URDF robot's joint inputs do).
// ModelBuilder applies both (addFrame, the inputs, finalize), so scenes, URDF robots and code
// that builds models directly follow the same rule; their messages name the element.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace trellis {

/// Why `name` cannot round-trip through trellis's files (see the file comment), or "" if it can.
std::string nameProblem(std::string_view name);

/// The offset of the first byte of `text` that does not begin a valid UTF-8 sequence, or
/// std::string_view::npos when all of it is UTF-8.
std::size_t invalidUtf8Offset(std::string_view text);

/// `name` for a message: bytes that are not printable UTF-8 as \xNN, so the message itself is
/// valid UTF-8 and on one line.
std::string printableName(std::string_view name);

/// Throws ModelError when the CSV columns of a model with these configuration and input names
/// would be ambiguous: an input name beginning with "rate_", or two columns among c, d<c> with the
/// same name. The message names both.
void checkColumnNames(const std::vector<std::string>& configNames, const std::vector<std::string>& inputNames);

}  // namespace trellis
