// cli/command.hpp — what a subcommand of `trellis` provides, and the errors it reports.
#pragma once

#include <ostream>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace trellis::cli {

/// A mistake in the command line (unknown option, missing argument): exit status 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
/// Any other std::exception from a subcommand (bad scene, numerical failure): exit status 1.

/// One subcommand. `run` gets the arguments after the subcommand's name, writes its result to
/// `out` (buffered by the dispatcher: nothing reaches stdout unless run returns normally) and
/// returns the exit status; it reports failure by throwing.
struct Command {
  std::string_view name;
  std::string_view summary;  ///< one line for `trellis --help`
  std::string_view help;     ///< full text for `trellis NAME --help`
  int (*run)(std::span<const std::string> args, std::ostream& out);
};

/// Every registered subcommand, sorted by name (the order `trellis --help` lists them).
std::span<const Command> commands();

/// Registers a subcommand at static-initialization time. Each subcommand's source file ends with
///   const CommandRegistration kRegisterNAME{kNAMECommand};
/// so adding a command is adding its file (cli/CMakeLists.txt compiles every cli/*.cpp).
struct CommandRegistration {
  explicit CommandRegistration(const Command& command);
};

/// True if `args` asks for help (-h or --help anywhere before a "--").
bool wantsHelp(std::span<const std::string> args);

}  // namespace trellis::cli
