// cli/mpi/main.cpp — `mpirun -n K trellis-mpi funnel ...`: the `funnel` command of trellis with its
// samples split over K MPI processes (docs/funnels.md). A separate program so that the plain
// `trellis` neither links nor starts MPI (see docs/funnels.md, "Why a separate program").
//
// Every rank parses the same command line and reads the same files; the ranks agree that the
// set-up succeeded everywhere (MPI_Allgather of the error texts), each runs its contiguous block
// of sample indices (r, r + K, ...) on its threads, and rank 0 gathers them (MPI_Gatherv of a flat byte
// record per sample), summarizes and writes. A rank whose samples could not be run sends its
// error instead: rank 0 then fails naming the rank, its samples and the cause, and writes nothing.
#include "../command.hpp"
#include "../funnel_command.hpp"

#include "trellis/core/io.hpp"

#include <mpi.h>

#include <algorithm>
#include <climits>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <sstream>
#include <stdexcept>

namespace {

using trellis::FunnelSample;
using trellis::SimulationCode;

/// All ranks' texts (Allgather of sizes, Allgatherv of bytes), in rank order.
std::vector<std::string> allTexts(const std::string& mine, int size) {
  const int length = static_cast<int>(mine.size());
  std::vector<int> lengths(static_cast<std::size_t>(size)), offsets(static_cast<std::size_t>(size));
  MPI_Allgather(&length, 1, MPI_INT, lengths.data(), 1, MPI_INT, MPI_COMM_WORLD);
  int total = 0;
  for (int r = 0; r < size; ++r) {
    offsets[static_cast<std::size_t>(r)] = total;
    total += lengths[static_cast<std::size_t>(r)];
  }
  std::string all(static_cast<std::size_t>(total), '\0');
  MPI_Allgatherv(mine.data(), length, MPI_CHAR, all.data(), lengths.data(), offsets.data(), MPI_CHAR, MPI_COMM_WORLD);
  std::vector<std::string> texts;
  for (int r = 0; r < size; ++r) {
    texts.push_back(all.substr(static_cast<std::size_t>(offsets[static_cast<std::size_t>(r)]),
                               static_cast<std::size_t>(lengths[static_cast<std::size_t>(r)])));
  }
  return texts;
}

std::string joinFailures(const std::vector<std::string>& texts) {
  std::string out;
  for (std::size_t r = 0; r < texts.size(); ++r) {
    if (!texts[r].empty()) out += (out.empty() ? "" : "; ") + std::string("rank ") + std::to_string(r) + ": " + texts[r];
  }
  return out;
}

template <class T>
void put(std::string& bytes, const T& value) {
  bytes.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <class T>
T take(const char*& p, const char* end) {
  if (static_cast<std::size_t>(end - p) < sizeof(T)) throw std::runtime_error("trellis-mpi: a truncated sample record");
  T value;
  std::memcpy(&value, p, sizeof(T));
  p += sizeof(T);
  return value;
}

/// One byte record per sample: index, start, level, success, code, final level, failure time,
/// nx, δx (native byte order: the ranks of one run share one build).
std::string pack(const std::vector<FunnelSample>& samples) {
  std::string bytes;
  for (const FunnelSample& s : samples) {
    put<std::int64_t>(bytes, s.index);
    put<std::int32_t>(bytes, s.start);
    put<std::int32_t>(bytes, s.level);
    put<std::uint8_t>(bytes, s.success ? 1 : 0);
    put<std::int32_t>(bytes, static_cast<std::int32_t>(s.code));
    put<double>(bytes, s.finalLevel);
    put<double>(bytes, s.failureTime);
    put<std::int32_t>(bytes, static_cast<std::int32_t>(s.dx0.size()));
    bytes.append(reinterpret_cast<const char*>(s.dx0.data()), sizeof(double) * static_cast<std::size_t>(s.dx0.size()));
  }
  return bytes;
}

void unpack(const char* p, const char* end, std::vector<FunnelSample>& out) {
  while (p < end) {
    FunnelSample s;
    s.index = static_cast<long>(take<std::int64_t>(p, end));
    s.start = take<std::int32_t>(p, end);
    s.level = take<std::int32_t>(p, end);
    s.success = take<std::uint8_t>(p, end) != 0;
    s.code = static_cast<SimulationCode>(take<std::int32_t>(p, end));
    s.finalLevel = take<double>(p, end);
    s.failureTime = take<double>(p, end);
    const int nx = take<std::int32_t>(p, end);
    s.dx0.resize(nx);
    for (int i = 0; i < nx; ++i) s.dx0(i) = take<double>(p, end);
    out.push_back(std::move(s));
  }
}

std::string oneLine(std::string text) {
  for (char& c : text)
    if (c == '\n' || c == '\r') c = ' ';
  return text;
}

constexpr std::string_view kUsage = R"(usage: mpirun -n K trellis-mpi funnel SCENE.json [the options of 'trellis funnel']

The `funnel` command of trellis over K MPI processes: the samples are split by index (rank r
runs r, r + K, r + 2K, ...), every sample's random stream depends only on --seed and its index, and rank 0
gathers and writes (rank r runs the samples r, r + K, ...), so the output is bit-identical to `trellis funnel` and to any other K and
--threads. Each rank runs its block on --threads threads (default: every hardware thread; with
several ranks per machine give --threads = cores / ranks per machine). See docs/funnels.md.
)";

}  // namespace

int main(int argc, char** argv) {
  std::signal(SIGXFSZ, SIG_IGN);
  MPI_Init(&argc, &argv);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  if (rank == 0) trellis::removeTemporaryFilesOnSignals();

  const std::vector<std::string> args(argv + 1, argv + argc);
  int status = 0;
  if (args.empty() || args[0] != "funnel") {
    if (rank == 0) {
      if (!args.empty() && (args[0] == "-h" || args[0] == "--help")) {
        std::cout << kUsage;
      } else {
        std::cerr << "trellis-mpi: error: the command must be 'funnel' (got '" << (args.empty() ? "" : args[0])
                  << "')\n" << kUsage;
        status = 2;
      }
    }
    MPI_Bcast(&status, 1, MPI_INT, 0, MPI_COMM_WORLD);
    MPI_Finalize();
    return status;
  }
  const trellis::cli::Command* command = nullptr;
  for (const auto& c : trellis::cli::commands())
    if (c.name == "funnel") command = &c;
  const std::span<const std::string> rest(args.begin() + 1, args.end());
  if (trellis::cli::wantsHelp(rest)) {
    if (rank == 0) std::cout << command->help;
    MPI_Finalize();
    return 0;
  }

  trellis::cli::FunnelDistribution distribution;
  distribution.rank = rank;
  distribution.size = size;
  distribution.agree = [size](const std::string& error) { return joinFailures(allTexts(error, size)); };
  // TRELLIS_MPI_FAIL_RANK=r (tests only): rank r reports its samples as failed to run, to check
  // that one rank's failure fails the whole run with nothing written.
  const char* injected = std::getenv("TRELLIS_MPI_FAIL_RANK");
  const int failRank = injected ? std::atoi(injected) : -1;
  distribution.gather = [rank, size, failRank](std::vector<FunnelSample> local, std::string error) {
    if (rank == failRank && error.empty() && !local.empty()) {
      error = "samples " + std::to_string(local.front().index) + ", " + std::to_string(local.front().index + size) +
              ", ...: injected failure (TRELLIS_MPI_FAIL_RANK=" + std::to_string(failRank) + ")";
    }
    // The errors first (every rank learns whether the run failed), then the records to rank 0.
    const std::string failures = joinFailures(allTexts(error, size));
    if (!failures.empty()) throw std::runtime_error("funnel: a process could not run its samples: " + failures);
    const std::string bytes = pack(local);
    if (bytes.size() > static_cast<std::size_t>(INT_MAX)) {
      throw std::runtime_error("trellis-mpi: rank " + std::to_string(rank) + "'s samples take " + std::to_string(bytes.size()) +
                               " bytes, more than one MPI message carries (2^31 - 1): use more ranks");
    }
    const int length = static_cast<int>(bytes.size());
    std::vector<int> lengths(static_cast<std::size_t>(size)), offsets(static_cast<std::size_t>(size));
    MPI_Gather(&length, 1, MPI_INT, lengths.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
    long long total = 0;
    for (int r = 0; r < size; ++r) {
      offsets[static_cast<std::size_t>(r)] = static_cast<int>(std::min<long long>(total, INT_MAX));
      total += lengths[static_cast<std::size_t>(r)];
    }
    int tooLarge = rank == 0 && total > INT_MAX ? 1 : 0;
    MPI_Bcast(&tooLarge, 1, MPI_INT, 0, MPI_COMM_WORLD);
    if (tooLarge) throw std::runtime_error("trellis-mpi: the samples take more than 2^31 - 1 bytes on rank 0 (use --samples-out less, fewer samples per run)");
    std::string all(rank == 0 ? static_cast<std::size_t>(total) : 0, '\0');
    MPI_Gatherv(bytes.data(), length, MPI_CHAR, all.data(), lengths.data(), offsets.data(), MPI_CHAR, 0, MPI_COMM_WORLD);
    std::vector<FunnelSample> samples;
    if (rank == 0) {
      unpack(all.data(), all.data() + all.size(), samples);
      std::sort(samples.begin(), samples.end(), [](const FunnelSample& a, const FunnelSample& b) { return a.index < b.index; });
    }
    return samples;
  };
  trellis::cli::setFunnelDistribution(&distribution);

  std::ostringstream out;
  std::string error;
  try {
    status = command->run(rest, out);
  } catch (const trellis::cli::UsageError& e) {
    error = std::string(e.what()) + " (see 'trellis-mpi funnel --help')";
    status = 2;
  } catch (const std::bad_alloc&) {
    error = "funnel: out of memory";
    status = 1;
  } catch (const std::exception& e) {
    error = e.what();
    status = 1;
  }
  if (rank == 0) {
    if (status != 0) {
      std::cerr << "trellis-mpi: error: " << oneLine(error) << '\n';
    } else {
      std::cout << out.str() << std::flush;
      if (!std::cout) {
        std::cerr << "trellis-mpi: error: cannot write the output\n";
        status = 1;
      }
    }
  }
  // Every rank exits with rank 0's verdict (a failure anywhere reaches rank 0 through the gather).
  MPI_Bcast(&status, 1, MPI_INT, 0, MPI_COMM_WORLD);
  trellis::cli::setFunnelDistribution(nullptr);
  MPI_Finalize();
  return status;
}
