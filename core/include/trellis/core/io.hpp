// trellis/core/io.hpp — files that are complete or absent, and text files read with a limit.
//
// Every file trellis writes (gain schedules, trajectories, the examples' reports) goes through
// writeFileAtomically: the text is written to a temporary file beside the target, every write and
// the close are checked, the data is flushed to the disk (fsync), and only then is the temporary
// renamed onto the target. A failure (disk full, file-size limit, missing or read-only directory)
// removes the temporary and throws FileError naming the path and the operating system's reason,
// so a reader never sees a partial file under the target's name.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>

namespace trellis {

/// A file that cannot be read or written; the message names the path and the OS error.
class FileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Replaces (or creates) the file `path` with `content`, atomically as described above. Rules:
/// - A stream of this process — "-" (standard output), /dev/stdout, /dev/stderr, /dev/fd/N,
///   /proc/self/fd/N, directly or through links — is written to the open descriptor as the shell
///   set it up (appended with `>>`, at its offset with `>`), never reopened, truncated or renamed
///   over; text buffered in std::cout/stdout (std::cerr/stderr) is flushed first.
/// - Another existing non-regular file (a device such as /dev/null, a FIFO) is written in place,
///   still checking every write and the close.
/// - A symbolic link is followed (the file it names is replaced); a dangling link is refused.
/// - An existing regular file is replaced only if it belongs to the effective user and its
///   owner-write bit is set (a read-only file, or another user's, is refused — also for root);
///   it keeps its permissions. A new file gets 0666 minus the umask.
/// Throws FileError naming the path and the reason.
///
/// A process that may run under a file-size limit (ulimit -f) should ignore SIGXFSZ (the command
/// line does), so that exceeding the limit is the write error EFBIG rather than a silent kill.
/// With removeTemporaryFilesOnSignals installed, SIGINT/SIGTERM/SIGHUP/SIGQUIT during the write
/// remove the temporary before the process dies.
void writeFileAtomically(const std::string& path, std::string_view content);

/// True when writeFileAtomically(path, ...) would write to an open stream of this process ("-",
/// /dev/stdout, /dev/fd/N, ...) rather than to a file.
bool isStreamPath(const std::string& path);

/// Installs handlers for SIGINT, SIGTERM, SIGHUP and SIGQUIT (those not ignored) that remove the
/// temporary files of writeFileAtomically calls in progress, then restore the default action and
/// re-raise the signal (the process dies by it, as without the handler). For programs (the CLI);
/// a library caller with its own handlers should not call it.
void removeTemporaryFilesOnSignals();

/// The whole content of the regular file `path`, at most `maxBytes` bytes. Throws FileError
/// naming the path: it does not exist or cannot be opened (with the OS error), it is a directory,
/// it is larger than `maxBytes` (`what` names the kind of file in messages: "scene file").
/// Devices and pipes (/dev/zero) are read in 64 KiB chunks and refused at the first byte beyond
/// the limit: memory stays below maxBytes + 64 KiB whatever the input.
std::string readTextFile(const std::string& path, std::size_t maxBytes, const std::string& what);

/// As readTextFile, for an open descriptor (standard input: fd 0), named `source` in messages.
/// The descriptor stays open.
std::string readTextStream(int fd, std::size_t maxBytes, const std::string& source, const std::string& what);

/// "path: REASON" with REASON the text of the current errno, for messages.
std::string describeOsError(const std::string& path, const std::string& action, int error);

}  // namespace trellis
