// Files written complete or not at all (writeFileAtomically) and read with a limit (readTextFile).
#include "trellis/core/io.hpp"
#include "trellis/core/json_integer.hpp"

#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>

#include <filesystem>
#include <functional>
#include <fstream>
#include <iterator>
#include <string>

namespace {

namespace fs = std::filesystem;

/// A fresh empty directory for one test case.
fs::path scratch(const std::string& name) {
  // Per process: two test runs on one machine (two build trees) must not share a directory.
  const fs::path dir = fs::temp_directory_path() / ("trellis_test_io_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string contents(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const trellis::FileError& e) {
    return e.what();
  }
  return "(no error)";
}

}  // namespace

TEST_CASE("writeFileAtomically writes a new file and replaces an existing one, keeping its mode", "[io]") {
  const fs::path dir = scratch("replace");
  const std::string path = (dir / "out.csv").string();
  trellis::writeFileAtomically(path, "a,b\n1,2\n");
  CHECK(contents(path) == "a,b\n1,2\n");
  ::chmod(path.c_str(), 0640);
  trellis::writeFileAtomically(path, "x\n");
  CHECK(contents(path) == "x\n");
  struct stat info {};
  REQUIRE(::stat(path.c_str(), &info) == 0);
  CHECK((info.st_mode & 0777) == 0640);
  // Only the target is left: no temporary beside it.
  CHECK(std::distance(fs::directory_iterator(dir), fs::directory_iterator()) == 1);
  fs::remove_all(dir);
}

TEST_CASE("writeFileAtomically follows a symbolic link and replaces the file it names", "[io]") {
  const fs::path dir = scratch("link");
  trellis::writeFileAtomically((dir / "real.txt").string(), "old");
  fs::create_symlink(dir / "real.txt", dir / "link.txt");
  trellis::writeFileAtomically((dir / "link.txt").string(), "new");
  CHECK(fs::is_symlink(dir / "link.txt"));
  CHECK(contents(dir / "real.txt") == "new");
  fs::remove_all(dir);
}

TEST_CASE("writeFileAtomically reports a failed write with the path and the OS error, leaving nothing", "[io]") {
  const fs::path dir = scratch("fail");
  // A directory that does not exist.
  const std::string missing = (dir / "no" / "such" / "out.csv").string();
  CHECK_THAT(errorOf([&] { trellis::writeFileAtomically(missing, "x"); }),
             Catch::Contains(missing) && Catch::Contains("No such file or directory"));
  // A directory as the target.
  CHECK_THAT(errorOf([&] { trellis::writeFileAtomically(dir.string(), "x"); }),
             Catch::Contains("is a directory"));
  // A full device, written in place (it is not a regular file) and left a device.
  if (fs::exists("/dev/full")) {
    CHECK_THAT(errorOf([&] { trellis::writeFileAtomically("/dev/full", std::string(100000, 'x')); }),
               Catch::Contains("/dev/full: write failed") && Catch::Contains("No space left on device"));
    CHECK(fs::is_character_file("/dev/full"));
  }
  CHECK(fs::is_empty(dir));
  fs::remove_all(dir);
}

TEST_CASE("readTextFile reads a file, and names a directory, a missing file and one above the limit", "[io]") {
  const fs::path dir = scratch("read");
  const std::string path = (dir / "in.json").string();
  trellis::writeFileAtomically(path, "0123456789");
  CHECK(trellis::readTextFile(path, 10, "test file") == "0123456789");
  CHECK_THAT(errorOf([&] { trellis::readTextFile(path, 9, "test file"); }),
             Catch::Contains(path) && Catch::Contains("larger than the limit of 9 bytes"));
  CHECK_THAT(errorOf([&] { trellis::readTextFile(dir.string(), 100, "test file"); }),
             Catch::Contains("is a directory, not a test file"));
  CHECK_THAT(errorOf([&] { trellis::readTextFile((dir / "none").string(), 100, "test file"); }),
             Catch::Contains("cannot open the test file") && Catch::Contains("No such file or directory"));
  // An endless stream stops at the limit.
  CHECK_THAT(errorOf([&] { trellis::readTextFile("/dev/zero", 1 << 20, "test file"); }),
             Catch::Contains("larger than the limit"));
  fs::remove_all(dir);
}

TEST_CASE("writeFileAtomically appends to an open stream as the shell set it up, never replacing the file", "[io]") {
  const fs::path dir = scratch("stream");
  const std::string log = (dir / "app.log").string();
  trellis::writeFileAtomically(log, "old line\n");
  struct stat before {};
  REQUIRE(::stat(log.c_str(), &before) == 0);
  // `>> app.log`: the descriptor is opened for appending; each name of it appends.
  const int fd = ::open(log.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  REQUIRE(fd >= 0);
  fs::create_symlink("/dev/fd/" + std::to_string(fd), dir / "link_to_fd");
  trellis::writeFileAtomically("/dev/fd/" + std::to_string(fd), "a\n");
  trellis::writeFileAtomically("/proc/self/fd/" + std::to_string(fd), "b\n");
  trellis::writeFileAtomically((dir / "link_to_fd").string(), "c\n");
  CHECK(trellis::isStreamPath("/dev/stdout"));
  CHECK(trellis::isStreamPath("-"));
  CHECK_FALSE(trellis::isStreamPath(log));
  ::close(fd);
  CHECK(contents(log) == "old line\na\nb\nc\n");
  struct stat after {};
  REQUIRE(::stat(log.c_str(), &after) == 0);
  CHECK(after.st_ino == before.st_ino);  // the same file, not one renamed over it
  // A descriptor that is not open is an error, not a file created somewhere.
  CHECK_THAT(errorOf([&] { trellis::writeFileAtomically("/dev/fd/987", "x"); }), Catch::Contains("not an open stream"));
  // "-" and /dev/stdout: standard output, here redirected (`>`) to a file that already holds text.
  const std::string out = (dir / "stdout.txt").string();
  std::fflush(stdout);
  const int saved = ::dup(STDOUT_FILENO);
  const int target = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  REQUIRE(target >= 0);
  ::dup2(target, STDOUT_FILENO);
  std::printf("summary\n");  // buffered text goes first
  trellis::writeFileAtomically("-", "csv1\n");
  trellis::writeFileAtomically("/dev/stdout", "csv2\n");
  std::fflush(stdout);
  ::dup2(saved, STDOUT_FILENO);
  ::close(saved);
  ::close(target);
  CHECK(contents(out) == "summary\ncsv1\ncsv2\n");
  fs::remove_all(dir);
}

TEST_CASE("writeFileAtomically refuses what it must not replace: read-only, another user's, a dangling link", "[io]") {
  const fs::path dir = scratch("refuse");
  const std::string ro = (dir / "ro.csv").string();
  trellis::writeFileAtomically(ro, "keep");
  ::chmod(ro.c_str(), 0444);
  CHECK_THAT(errorOf([&] { trellis::writeFileAtomically(ro, "new"); }),
             Catch::Contains(ro) && Catch::Contains("is read-only (mode 0444)"));
  CHECK(contents(ro) == "keep");
  ::chmod(ro.c_str(), 0644);
  if (::geteuid() == 0) {  // only root can give a file away; as root the rule still holds
    const std::string other = (dir / "other.csv").string();
    trellis::writeFileAtomically(other, "theirs");
    REQUIRE(::chown(other.c_str(), 65534, 65534) == 0);
    CHECK_THAT(errorOf([&] { trellis::writeFileAtomically(other, "new"); }),
               Catch::Contains("belongs to another user (uid 65534)"));
    CHECK(contents(other) == "theirs");
  }
  fs::create_symlink(dir / "missing" / "target.csv", dir / "dangling");
  CHECK_THAT(errorOf([&] { trellis::writeFileAtomically((dir / "dangling").string(), "x"); }),
             Catch::Contains("is a symbolic link to") && Catch::Contains("cannot be resolved"));
  CHECK(fs::is_symlink(dir / "dangling"));
  // Nothing but the three files (no temporary, no file created through the link).
  CHECK(std::distance(fs::directory_iterator(dir), fs::directory_iterator()) == (::geteuid() == 0 ? 3 : 2));
  fs::remove_all(dir);
}

TEST_CASE("removeTemporaryFilesOnSignals: SIGTERM or SIGINT during a write leaves no temporary", "[io]") {
  for (const int signal : {SIGTERM, SIGINT}) {
    const fs::path dir = scratch("signal" + std::to_string(signal));
    bool caught = false;
    // The child writes 256 MiB; the parent signals it as soon as the hidden temporary exists.
    // A child that finished first (a fast disk) leaves the complete file: try again, larger.
    for (int attempt = 0; attempt < 4 && !caught; ++attempt) {
      fs::remove_all(dir);
      fs::create_directories(dir);
      const pid_t child = ::fork();
      REQUIRE(child >= 0);
      if (child == 0) {
        trellis::removeTemporaryFilesOnSignals();
        try {
          trellis::writeFileAtomically((dir / "big.csv").string(), std::string(std::size_t{256} << (20 + attempt), 'x'));
        } catch (...) {
        }
        ::_exit(0);
      }
      bool seen = false;
      for (int poll = 0; poll < 200000 && !seen; ++poll) {
        for (const auto& entry : fs::directory_iterator(dir))
          if (entry.path().filename().string().rfind(".big.csv.tmp-", 0) == 0) seen = true;
        if (!seen) ::usleep(50);
      }
      if (seen) ::kill(child, signal);
      int status = 0;
      ::waitpid(child, &status, 0);
      if (seen && WIFSIGNALED(status)) {
        caught = true;
        CHECK(WTERMSIG(status) == signal);  // died by the signal, as without the handler
        CHECK(fs::is_empty(dir));            // and took its temporary with it
      }
    }
    CHECK(caught);
    fs::remove_all(dir);
  }
}

TEST_CASE("readTextStream bounds what it reads from a descriptor without a size", "[io]") {
  const int fd = ::open("/dev/zero", O_RDONLY | O_CLOEXEC);
  REQUIRE(fd >= 0);
  CHECK_THAT(errorOf([&] { trellis::readTextStream(fd, 100000, "<stdin>", "scene"); }),
             Catch::Contains("<stdin>: the scene is larger than the limit of 100000 bytes"));
  ::close(fd);
}

TEST_CASE("jsonInteger checks the range before converting: no count wraps around", "[io]") {
  const auto check = [](const char* text, long long min, long long max, std::string& problem) {
    long long value = -1;
    const bool ok = trellis::jsonInteger(nlohmann::json::parse(text), min, max, value, problem);
    return ok ? value : -1;
  };
  std::string problem;
  CHECK(check("31", 2, 100000, problem) == 31);
  CHECK(check("4294967298", 2, 100000, problem) == -1);  // 2^32 + 2: would be 2 as a 32-bit int
  CHECK(problem == "4294967298 is out of the range [2, 100000]");
  CHECK(check("-5", 2, 100000, problem) == -1);
  CHECK(problem == "-5 is out of the range [2, 100000]");
  CHECK(check("18446744073709551615", 0, 9223372036854775807LL, problem) == -1);
  CHECK(check("2.5", 2, 10, problem) == -1);
  CHECK(problem == "expected an integer in [2, 10], got 2.5");
  CHECK(check("1e3", 0, 10000, problem) == -1);  // a float, even if integral
  CHECK(check("\"7\"", 0, 10, problem) == -1);
}
