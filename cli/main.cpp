// cli/main.cpp — `trellis COMMAND [ARGS]`: finds the subcommand and turns failures into one line
// on stderr ("trellis: error: ...") with nothing on stdout.
#include "command.hpp"

#include "trellis/core/io.hpp"

#include <csignal>
#include <iostream>
#include <new>
#include <sstream>

namespace {

constexpr std::string_view kUsage = R"(usage: trellis <command> [options] [arguments]

Exact linearizations of constrained mechanical systems (Johnson & Murphey 2010): the Jacobians
A = df/dx and B = df/du of x' = f(x, u), x = [q; dq], for a system described by a scene file
(JSON, format in SCENE_FORMAT.md).

commands:
)";

constexpr std::string_view kUsageTail = R"(
options:
  -h, --help   show this help
  --version    print the version

Run 'trellis <command> --help' for a command's conventions and output.
Exit status: 0 on success, 1 on a bad scene or a numerical failure, 2 on a usage error.
)";

void printUsage(std::ostream& out) {
  out << kUsage;
  for (const trellis::cli::Command& c : trellis::cli::commands()) {
    out << "  " << c.name << std::string(c.name.size() < 12 ? 12 - c.name.size() : 1, ' ')
        << c.summary << '\n';
  }
  out << kUsageTail;
}

/// The message on one line: a scene path or a builder message never breaks the "one line" promise.
std::string oneLine(std::string text) {
  for (char& c : text)
    if (c == '\n' || c == '\r') c = ' ';
  return text;
}

int fail(const std::string& message, int status) {
  std::cerr << "trellis: error: " << oneLine(message) << '\n';
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  // Under a file-size limit (ulimit -f) a write beyond it must fail with EFBIG, which the writer
  // reports, instead of SIGXFSZ killing the process with a partial file.
  std::signal(SIGXFSZ, SIG_IGN);
  // Ctrl-C or a kill during a write removes the hidden temporary before the process dies.
  trellis::removeTemporaryFilesOnSignals();
  const std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty()) {
    printUsage(std::cerr);
    return 2;
  }
  const std::string& name = args[0];
  if (name == "-h" || name == "--help" || name == "help") {
    if (name == "help" && args.size() > 1) {
      for (const auto& c : trellis::cli::commands())
        if (c.name == args[1]) return (std::cout << c.help, 0);
      return fail("unknown command '" + args[1] + "' (see 'trellis --help')", 2);
    }
    printUsage(std::cout);
    return 0;
  }
  if (name == "--version") {
    std::cout << "trellis " << TRELLIS_VERSION << '\n';
    return 0;
  }
  const trellis::cli::Command* command = nullptr;
  for (const auto& c : trellis::cli::commands())
    if (c.name == name) command = &c;
  if (!command) {
    return fail(std::string(name.starts_with("-") ? "unknown option '" : "unknown command '") + name +
                    "' (see 'trellis --help')",
                2);
  }

  const std::span<const std::string> rest(args.begin() + 1, args.end());
  if (trellis::cli::wantsHelp(rest)) {
    std::cout << command->help;
    return 0;
  }
  std::ostringstream out;
  int status = 0;
  try {
    status = command->run(rest, out);
  } catch (const trellis::cli::UsageError& e) {
    return fail(std::string(e.what()) + " (see 'trellis " + name + " --help')", 2);
  } catch (const std::bad_alloc&) {
    return fail(name + ": out of memory (the input implies more memory than is available)", 1);
  } catch (const std::exception& e) {
    return fail(e.what(), 1);
  } catch (...) {
    return fail("unexpected failure", 1);
  }
  std::cout << out.str() << std::flush;
  if (!std::cout) return fail("cannot write the output", 1);
  return status;
}
