// cli/commands.cpp — the table of subcommands.
#include "command.hpp"

#include <array>

namespace trellis::cli {

std::span<const Command> commands() {
  static const std::array<Command, 1> table{
      kLinearizeCommand,
  };
  return table;
}

bool wantsHelp(std::span<const std::string> args) {
  for (const std::string& a : args) {
    if (a == "--") return false;
    if (a == "-h" || a == "--help") return true;
  }
  return false;
}

}  // namespace trellis::cli
