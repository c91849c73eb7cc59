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

/// Replaces (or creates) the file `path` with `content`, atomically as described above. A target
/// that exists and is not a regular file (a device such as /dev/null or /dev/stdout, a FIFO) is
/// written in place, still checking every write and the close. A symbolic link is followed (the
/// file it names is replaced). A new file gets the permissions 0666 minus the umask; a replaced
/// one keeps its own. Throws FileError.
///
/// A process that may run under a file-size limit (ulimit -f) should ignore SIGXFSZ (the command
/// line does), so that exceeding the limit is the write error EFBIG rather than a silent kill.
void writeFileAtomically(const std::string& path, std::string_view content);

/// The whole content of the regular file `path`, at most `maxBytes` bytes. Throws FileError
/// naming the path: it does not exist or cannot be opened (with the OS error), it is a directory,
/// it is larger than `maxBytes` (`what` names the kind of file in messages: "scene file").
std::string readTextFile(const std::string& path, std::size_t maxBytes, const std::string& what);

/// "path: REASON" with REASON the text of the current errno, for messages.
std::string describeOsError(const std::string& path, const std::string& action, int error);

}  // namespace trellis
