// cli/funnel_command.hpp — how `funnel` spreads its samples over processes. The plain `trellis`
// runs every sample in its one process (on threads); `trellis-mpi` (cli/mpi/) installs a
// distribution backed by MPI before it runs the same command, so both share one command line,
// one set of checks and one writer.
#pragma once

#include "trellis/analysis/funnel.hpp"

#include <functional>
#include <string>
#include <vector>

namespace trellis::cli {

struct FunnelDistribution {
  int rank = 0;  ///< this process
  int size = 1;  ///< processes; rank r runs the samples r, r + size, r + 2 size, ...
  /// Called by every process once its set-up ended, with "" or its error: returns "" when every
  /// process succeeded, else the failures ("rank R: ...", joined). Collective.
  std::function<std::string(const std::string& error)> agree;
  /// Collective: every process passes its samples (or its error, naming its samples and the
  /// cause). On rank 0 it returns every sample, sorted by index, or throws std::runtime_error
  /// listing the processes that failed; on the others it returns an empty vector.
  std::function<std::vector<FunnelSample>(std::vector<FunnelSample> local, const std::string& error)> gather;
};

/// Installs (or, with nullptr, removes) the distribution `funnel` uses; not owned.
void setFunnelDistribution(const FunnelDistribution* distribution);

}  // namespace trellis::cli
