// replay_driver.cpp — main() for a fuzz target when it is not built with libFuzzer (GCC, the
// default preset): runs LLVMFuzzerTestOneInput on every file of the seed corpora given as
// arguments, then on a fixed number of deterministic mutations of them, so that CTest keeps the
// targets compiling and running in every build. The libFuzzer build (preset `fuzz`) replaces this
// file with libFuzzer's own main, which explores far more inputs.
//
//   fuzz_TARGET [--mutations N] [--seed S] PATH...   (PATH: a file or a directory of files)
//
// The mutations are those of a simple mutational fuzzer: flip a bit, set a byte to an
// interesting value (0, 0xff, '\n', ',', '"', digits, '-', 'e'), insert or erase a byte or a
// run, duplicate a run, and splice two seeds; 1 to 4 of them per input, from a 64-bit
// SplitMix generator seeded by --seed, so a failure is reproduced by the same command line.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

struct SplitMix64 {
  std::uint64_t state;
  std::uint64_t operator()() {
    std::uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  std::size_t below(std::size_t n) { return n == 0 ? 0 : static_cast<std::size_t>((*this)() % n); }
};

void addFile(const std::filesystem::path& path, std::vector<std::string>& seeds) {
  std::ifstream in(path, std::ios::binary);
  seeds.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void run(const std::string& input) {
  LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(input.data()), input.size());
}

std::string mutate(const std::vector<std::string>& seeds, SplitMix64& rng) {
  static const char kInteresting[] = {'\0', '\xff', '\n', ',', '"', '0', '1', '9', '-', 'e', '.', '[', '{', ' '};
  std::string s = seeds[rng.below(seeds.size())];
  const std::size_t count = 1 + rng.below(4);
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t at = rng.below(s.size() + 1);
    switch (rng.below(7)) {
      case 0:
        if (!s.empty()) s[rng.below(s.size())] ^= static_cast<char>(1u << rng.below(8));
        break;
      case 1:
        if (!s.empty()) s[rng.below(s.size())] = kInteresting[rng.below(sizeof kInteresting)];
        break;
      case 2: s.insert(at, 1, kInteresting[rng.below(sizeof kInteresting)]); break;
      case 3:
        if (at < s.size()) s.erase(at, 1 + rng.below(std::min<std::size_t>(16, s.size() - at)));
        break;
      case 4:
        if (at < s.size()) {
          const std::string run = s.substr(at, 1 + rng.below(32));
          s.insert(rng.below(s.size() + 1), run);
        }
        break;
      case 5: {
        const std::string& other = seeds[rng.below(seeds.size())];
        const std::size_t from = rng.below(other.size() + 1);
        s = s.substr(0, at) + other.substr(from);
        break;
      }
      default: s.insert(at, std::to_string(static_cast<long long>(rng()) >> rng.below(64))); break;
    }
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  long mutations = 1000;
  std::uint64_t seed = 1;
  std::vector<std::string> seeds;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--mutations" && i + 1 < argc) {
      mutations = std::strtol(argv[++i], nullptr, 10);
    } else if (arg == "--seed" && i + 1 < argc) {
      seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (std::filesystem::is_directory(arg)) {
      std::vector<std::filesystem::path> files;  // sorted: the same seeds order on every system
      for (const auto& entry : std::filesystem::directory_iterator(arg))
        if (entry.is_regular_file()) files.push_back(entry.path());
      std::sort(files.begin(), files.end());
      for (const auto& file : files) addFile(file, seeds);
    } else {
      addFile(arg, seeds);
    }
  }
  if (seeds.empty()) {
    std::fprintf(stderr, "usage: %s [--mutations N] [--seed S] CORPUS_FILE_OR_DIR...\n", argv[0]);
    return 2;
  }
  for (const std::string& s : seeds) run(s);
  SplitMix64 rng{seed};
  for (long k = 0; k < mutations; ++k) run(mutate(seeds, rng));
  std::printf("%zu seeds and %ld mutations ran without a finding\n", seeds.size(), mutations);
  return 0;
}
