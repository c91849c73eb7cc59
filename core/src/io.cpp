// io.cpp — see trellis/core/io.hpp. POSIX calls, so that every failure has its errno.
#include "trellis/core/io.hpp"

#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <fcntl.h>
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

void writeFileAtomically(const std::string& requested, std::string_view content) {
  if (requested.empty()) throw FileError("cannot write a file with an empty name");
  std::string path = requested;
  struct stat info {};
  mode_t mode = newFileMode();
  if (::lstat(path.c_str(), &info) == 0 && S_ISLNK(info.st_mode)) {
    // Replace the file the link names, not the link.
    char* resolved = ::realpath(path.c_str(), nullptr);
    if (resolved != nullptr) {
      path = resolved;
      std::free(resolved);
    }
  }
  if (::stat(path.c_str(), &info) == 0) {
    if (S_ISDIR(info.st_mode)) throw FileError(path + ": is a directory (expected a file name to write)");
    if (!S_ISREG(info.st_mode)) return writeInPlace(path, content);
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
  const int fd = ::mkstemp(buffer.data());
  if (fd < 0) {
    const int error = errno;
    struct stat dirInfo {};
    if (::stat(directory.c_str(), &dirInfo) != 0) {
      const int dirError = errno;
      throw FileError(describeOsError(path, "cannot write: the directory '" + directory + "' is not accessible",
                                      dirError));
    }
    throw FileError(describeOsError(path, "cannot create a file in '" + directory + "'", error));
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

std::string readTextFile(const std::string& path, std::size_t maxBytes, const std::string& what) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw FileError(describeOsError(path, "cannot open the " + what, errno));
  struct stat info {};
  if (::fstat(fd, &info) == 0 && S_ISDIR(info.st_mode)) {
    ::close(fd);
    throw FileError(path + ": is a directory, not a " + what);
  }
  std::string text;
  char chunk[65536];
  while (true) {
    const ssize_t got = ::read(fd, chunk, sizeof chunk);
    if (got < 0) {
      if (errno == EINTR) continue;
      const int error = errno;
      ::close(fd);
      throw FileError(describeOsError(path, "cannot read the " + what, error));
    }
    if (got == 0) break;
    if (text.size() + static_cast<std::size_t>(got) > maxBytes) {
      ::close(fd);
      throw FileError(path + ": the " + what + " is larger than the limit of " + std::to_string(maxBytes) +
                      " bytes");
    }
    text.append(chunk, static_cast<std::size_t>(got));
  }
  ::close(fd);
  return text;
}

}  // namespace trellis
