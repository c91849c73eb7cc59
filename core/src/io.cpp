// io.cpp — see trellis/core/io.hpp. POSIX calls, so that every failure has its errno.
#include "trellis/core/io.hpp"

#include <array>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdint>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>
#include <vector>

#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

namespace trellis {
namespace {

/// Writes all of `content` to `fd`, retrying partial writes and EINTR; the errno of a failure.
int writeAll(int fd, std::string_view content) {
  const char* data = content.data();
  std::size_t left = content.size();
  while (left > 0) {
    const ssize_t written = ::write(fd, data, left);
    if (written < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (written == 0) return EIO;  // no progress and no error: do not spin
    data += written;
    left -= static_cast<std::size_t>(written);
  }
  return 0;
}

/// The directory part of `path` ("." for a bare name) and the name part.
void splitPath(const std::string& path, std::string& directory, std::string& name) {
  const std::size_t slash = path.find_last_of('/');
  if (slash == std::string::npos) {
    directory = ".";
    name = path;
  } else {
    directory = slash == 0 ? "/" : path.substr(0, slash);
    name = path.substr(slash + 1);
  }
}

/// Writes to an existing non-regular file (device, FIFO) in place.
void writeInPlace(const std::string& path, std::string_view content) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) throw FileError(describeOsError(path, "cannot open for writing", errno));
  const int error = writeAll(fd, content);
  const int closeError = ::close(fd) == 0 ? 0 : errno;
  if (error != 0) throw FileError(describeOsError(path, "write failed", error));
  if (closeError != 0) throw FileError(describeOsError(path, "close failed", closeError));
}

mode_t newFileMode() {
  const mode_t mask = ::umask(0);  // read the umask (no other way in POSIX), then restore it
  ::umask(mask);
  return static_cast<mode_t>(0666 & ~mask);
}

}  // namespace

std::string describeOsError(const std::string& path, const std::string& action, int error) {
  return path + ": " + action + " (" + std::strerror(error) + ")";
}

namespace {

// The temporaries of writes in progress, for the signal handler: a fixed table of pointers (no
// allocation, no lock in the handler; unlink is async-signal-safe). A slot holds the name while
// the temporary exists and is cleared before the name's storage goes away.
constexpr std::size_t kTemporarySlots = 16;
std::atomic<const char*> temporarySlots[kTemporarySlots];

/// Registers a temporary's name for removal on a signal; RAII, so every exit path clears it.
class TemporaryRegistration {
 public:
  explicit TemporaryRegistration(const char* name) {
    if (name == nullptr) return;
    for (auto& slot : temporarySlots) {
      const char* expected = nullptr;
      if (slot.compare_exchange_strong(expected, name)) {
        slot_ = &slot;
        return;
      }
    }  // table full (more than 16 concurrent writes): the temporary is still removed on any error
  }
  ~TemporaryRegistration() {
    if (slot_ != nullptr) slot_->store(nullptr);
  }
  TemporaryRegistration(const TemporaryRegistration&) = delete;
  TemporaryRegistration& operator=(const TemporaryRegistration&) = delete;

 private:
  std::atomic<const char*>* slot_ = nullptr;
};

void removeTemporariesAndDie(int signal) {
  for (auto& slot : temporarySlots)
    if (const char* name = slot.load(); name != nullptr) ::unlink(name);
  ::signal(signal, SIG_DFL);  // die by the same signal: the parent sees the usual status
  ::raise(signal);
}

/// The descriptor N when `path` is "-" (standard output) or names an open stream of this process
/// — /dev/stdout, /dev/stderr, /dev/fd/N, /proc/self/fd/N, directly or through links — else −1.
/// Such a path must not be opened again: on Linux that reopens the file behind the descriptor at
/// offset 0, and a rename would replace what the shell opened (`--out /dev/stdout >> log`).
int streamDescriptor(const std::string& path) {
  if (path == "-") return STDOUT_FILENO;
  const std::string self = "/proc/" + std::to_string(::getpid()) + "/fd/";
  std::string current = path;
  for (int hop = 0; hop < 40; ++hop) {  // 40: the kernel's own limit on a chain of links
    for (const std::string& prefix : {std::string("/dev/fd/"), std::string("/proc/self/fd/"),
                                      std::string("/proc/thread-self/fd/"), self}) {
      if (current.size() > prefix.size() && current.compare(0, prefix.size(), prefix) == 0) {
        const std::string digits = current.substr(prefix.size());
        if (digits.size() <= 9 && digits.find_first_not_of("0123456789") == std::string::npos)
          return std::stoi(digits);
      }
    }
    std::array<char, PATH_MAX> target{};
    const ssize_t length = ::readlink(current.c_str(), target.data(), target.size() - 1);
    if (length < 0) return -1;  // not a link (or not there): an ordinary path
    std::string next(target.data(), static_cast<std::size_t>(length));
    if (!next.empty() && next[0] != '/') {
      const std::size_t slash = current.find_last_of('/');
      next = (slash == std::string::npos ? std::string() : current.substr(0, slash + 1)) + next;
    }
    current = next;
  }
  return -1;
}

/// Appends `content` to the open descriptor `fd` as the shell set it up (its offset, O_APPEND).
void writeToStream(const std::string& path, int fd, std::string_view content) {
  // Text already buffered for the same stream goes first, so the order on the stream is kept.
  if (fd == STDOUT_FILENO) {
    std::cout.flush();
    std::fflush(stdout);
  } else if (fd == STDERR_FILENO) {
    std::cerr.flush();
    std::fflush(stderr);
  }
  if (::fcntl(fd, F_GETFD) < 0) throw FileError(describeOsError(path, "is not an open stream", errno));
  if (const int error = writeAll(fd, content); error != 0) throw FileError(describeOsError(path, "write failed", error));
}

/// The file a link chain ends at; throws if the chain ends at nothing (a dangling link: writing
/// through it would create a file somewhere the user did not name) or loops.
std::string resolveLinkTarget(const std::string& path) {
  char* resolved = ::realpath(path.c_str(), nullptr);
  if (resolved != nullptr) {
    std::string result = resolved;
    std::free(resolved);
    return result;
  }
  const int error = errno;
  std::array<char, PATH_MAX> target{};
  const ssize_t length = ::readlink(path.c_str(), target.data(), target.size() - 1);
  const std::string where = length > 0 ? " '" + std::string(target.data(), static_cast<std::size_t>(length)) + "'" : "";
  throw FileError(describeOsError(path, "is a symbolic link to" + where +
                                            ", which cannot be resolved; trellis writes through a link only "
                                            "to a file that exists",
                                  error));
}

}  // namespace

void removeTemporaryFilesOnSignals() {
  struct sigaction action {};
  action.sa_handler = removeTemporariesAndDie;
  sigemptyset(&action.sa_mask);
  for (const int signal : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) {
    struct sigaction previous {};
    // A signal the caller ignores (nohup, a background job's SIGINT) stays ignored.
    if (::sigaction(signal, nullptr, &previous) == 0 && previous.sa_handler == SIG_IGN) continue;
    ::sigaction(signal, &action, nullptr);
  }
}

bool isStreamPath(const std::string& path) { return streamDescriptor(path) >= 0; }

void writeFileAtomically(const std::string& requested, std::string_view content) {
  if (requested.empty()) throw FileError("cannot write a file with an empty name");
  if (const int fd = streamDescriptor(requested); fd >= 0) return writeToStream(requested, fd, content);
  std::string path = requested;
  struct stat info {};
  mode_t mode = newFileMode();
  // Replace the file a link names, not the link; a dangling link is refused.
  if (::lstat(path.c_str(), &info) == 0 && S_ISLNK(info.st_mode)) path = resolveLinkTarget(path);
  if (::stat(path.c_str(), &info) == 0) {
    if (S_ISDIR(info.st_mode)) throw FileError(path + ": is a directory (expected a file name to write)");
    if (!S_ISREG(info.st_mode)) return writeInPlace(path, content);
    // An existing file is replaced only where the user could have edited it: it is the user's own
    // and its owner-write bit is set. The rename would otherwise bypass both (it needs only the
    // directory's permission), and root would replace anyone's file.
    if (info.st_uid != ::geteuid())
      throw FileError(path + ": belongs to another user (uid " + std::to_string(info.st_uid) +
                      "); trellis replaces only the user's own files (remove it first, or write elsewhere)");
    if ((info.st_mode & S_IWUSR) == 0)
      throw FileError(path + ": is read-only (mode " + [&] {
        char octal[8];
        std::snprintf(octal, sizeof octal, "%04o", static_cast<unsigned>(info.st_mode & 07777));
        return std::string(octal);
      }() + "); trellis does not replace a write-protected file");
    mode = info.st_mode & 07777;
  }

  std::string directory, name;
  splitPath(path, directory, name);
  if (name.empty()) throw FileError(path + ": is a directory name (expected a file name to write)");
  // The temporary lives in the target's directory (rename is atomic only within a file system)
  // and is hidden there: ".NAME.tmp-XXXXXX".
  std::string temporary = (directory == "/" ? "" : directory) + "/." + name + ".tmp-XXXXXX";
  if (path.find('/') == std::string::npos) temporary = "." + name + ".tmp-XXXXXX";
  std::vector<char> buffer(temporary.begin(), temporary.end());
  buffer.push_back('\0');
  // Signals are held while the temporary is created and registered, so that a signal handler
  // never misses a temporary that exists.
  sigset_t all, previousMask;
  sigfillset(&all);
  ::pthread_sigmask(SIG_BLOCK, &all, &previousMask);
  const int fd = ::mkstemp(buffer.data());
  const int createError = errno;
  TemporaryRegistration registration(fd >= 0 ? buffer.data() : nullptr);
  ::pthread_sigmask(SIG_SETMASK, &previousMask, nullptr);
  if (fd < 0) {
    struct stat dirInfo {};
    if (::stat(directory.c_str(), &dirInfo) != 0) {
      const int dirError = errno;
      throw FileError(describeOsError(path, "cannot write: the directory '" + directory + "' is not accessible",
                                      dirError));
    }
    throw FileError(describeOsError(path, "cannot create a file in '" + directory + "'", createError));
  }
  temporary.assign(buffer.data());

  // From here on, any failure removes the temporary.
  const auto fail = [&](const std::string& action, int error) {
    ::close(fd);
    ::unlink(temporary.c_str());
    throw FileError(describeOsError(path, action, error));
  };
  if (::fchmod(fd, mode) != 0) fail("cannot set the permissions", errno);
  if (const int error = writeAll(fd, content); error != 0) fail("write failed", error);
  // fsync: the data is on the disk before the name points at it (a crash after the rename must
  // not leave an empty file). EINVAL/EROFS: a file system without fsync, nothing to wait for.
  if (::fsync(fd) != 0 && errno != EINVAL && errno != EROFS) fail("cannot flush to the disk", errno);
  if (::close(fd) != 0) {
    const int error = errno;
    ::unlink(temporary.c_str());
    throw FileError(describeOsError(path, "close failed", error));
  }
  if (::rename(temporary.c_str(), path.c_str()) != 0) {
    const int error = errno;
    ::unlink(temporary.c_str());
    throw FileError(describeOsError(path, "cannot rename the temporary file into place", error));
  }
}

std::string readTextStream(int fd, std::size_t maxBytes, const std::string& source, const std::string& what) {
  struct stat info {};
  if (::fstat(fd, &info) == 0) {
    if (S_ISDIR(info.st_mode)) throw FileError(source + ": is a directory, not a " + what);
    // A regular file's size is known before reading: refuse it before allocating anything.
    if (S_ISREG(info.st_mode) && static_cast<std::uintmax_t>(info.st_size) > maxBytes)
      throw FileError(source + ": the " + what + " is larger than the limit of " + std::to_string(maxBytes) +
                      " bytes (" + std::to_string(info.st_size) + " bytes)");
  }
  // Devices and pipes (/dev/zero, an endless standard input) have no size: read in chunks and stop
  // at the first byte beyond the limit, so memory never exceeds maxBytes plus one chunk.
  std::string text;
  std::array<char, 65536> chunk{};
  while (true) {
    const ssize_t got = ::read(fd, chunk.data(), chunk.size());
    if (got < 0) {
      if (errno == EINTR) continue;
      throw FileError(describeOsError(source, "cannot read the " + what, errno));
    }
    if (got == 0) break;
    if (static_cast<std::size_t>(got) > maxBytes - text.size())
      throw FileError(source + ": the " + what + " is larger than the limit of " + std::to_string(maxBytes) +
                      " bytes");
    text.append(chunk.data(), static_cast<std::size_t>(got));
  }
  return text;
}

std::string readTextFile(const std::string& path, std::size_t maxBytes, const std::string& what) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw FileError(describeOsError(path, "cannot open the " + what, errno));
  try {
    std::string text = readTextStream(fd, maxBytes, path, what);
    ::close(fd);
    return text;
  } catch (...) {
    ::close(fd);
    throw;
  }
}

}  // namespace trellis
