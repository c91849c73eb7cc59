// Files written complete or not at all (writeFileAtomically) and read with a limit (readTextFile).
#include "trellis/core/io.hpp"
#include "trellis/core/json_integer.hpp"

#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>

#include <sys/stat.h>

#include <filesystem>
#include <functional>
#include <fstream>
#include <iterator>
#include <string>

namespace {

namespace fs = std::filesystem;

/// A fresh empty directory for one test case.
fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("trellis_test_io_" + name);
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
