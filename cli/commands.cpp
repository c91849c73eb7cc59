// cli/commands.cpp — the registry of subcommands.
#include "command.hpp"

#include <algorithm>
#include <vector>

namespace trellis::cli {
namespace {

// A function-local static: registrations from other translation units may run before any
// namespace-scope object of this file is initialized.
std::vector<Command>& registry() {
  static std::vector<Command> table;
  return table;
}

}  // namespace

CommandRegistration::CommandRegistration(const Command& command) {
  std::vector<Command>& table = registry();
  table.push_back(command);
  std::sort(table.begin(), table.end(),
            [](const Command& a, const Command& b) { return a.name < b.name; });
}

std::span<const Command> commands() { return registry(); }

bool wantsHelp(std::span<const std::string> args) {
  for (const std::string& a : args) {
    if (a == "--") return false;
    if (a == "-h" || a == "--help") return true;
  }
  return false;
}

}  // namespace trellis::cli
