#include "common/base/file_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <random>

namespace sandtable {
namespace {

std::string Errno() { return std::strerror(errno); }

// Opens `path` for reading only if it is a regular file of at most max_bytes; returns the fd.
Expected<int> OpenRegular(const std::string& path, uint64_t max_bytes, std::string_view limit_name,
                          uint64_t* size_out) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT) return NotFoundError(path + ": no such file");
    return IoError(path + ": cannot open (" + Errno() + ")");
  }
  if (S_ISDIR(st.st_mode)) return IoError(path + ": is a directory, a regular file is expected");
  if (!S_ISREG(st.st_mode)) {
    return IoError(path + ": not a regular file (a FIFO, device or socket); a file is expected");
  }
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return IoError(path + ": cannot open (" + Errno() + ")");
  struct stat fst;
  if (::fstat(fd, &fst) != 0 || !S_ISREG(fst.st_mode)) {
    ::close(fd);
    return IoError(path + ": not a regular file (changed while opened)");
  }
  if (static_cast<uint64_t>(fst.st_size) > max_bytes) {
    ::close(fd);
    return IoError(path + ": " + std::to_string(fst.st_size) + " bytes, more than the limit of " +
                   std::to_string(max_bytes) + " bytes (" + std::string(limit_name) + ")");
  }
  *size_out = static_cast<uint64_t>(fst.st_size);
  return fd;
}

}  // namespace

Expected<std::string> ReadInputFile(const std::filesystem::path& path, uint64_t max_bytes,
                                    std::string_view limit_name) {
  const std::string name = path.string();
  uint64_t size = 0;
  Expected<int> fd = OpenRegular(name, max_bytes, limit_name, &size);
  if (!fd.ok()) return fd.status();
  std::string out;
  // One byte more than the bound, so a file that grows while read is noticed.
  out.resize(static_cast<size_t>(std::min(size, max_bytes)) + 1);
  size_t got = 0;
  for (;;) {
    if (got == out.size()) {
      if (out.size() > max_bytes) break;
      out.resize(static_cast<size_t>(std::min<uint64_t>(out.size() * 2, max_bytes + 1)));
    }
    const ssize_t n = ::read(*fd, out.data() + got, out.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const std::string why = Errno();
      ::close(*fd);
      return IoError(name + ": read failed (" + why + ")");
    }
    if (n == 0) break;
    got += static_cast<size_t>(n);
  }
  ::close(*fd);
  if (got > max_bytes) {
    return IoError(name + ": grew past the limit of " + std::to_string(max_bytes) + " bytes (" +
                   std::string(limit_name) + ") while read");
  }
  out.resize(got);
  return out;
}

Status CheckInputFile(const std::filesystem::path& path, uint64_t max_bytes,
                      std::string_view limit_name) {
  uint64_t size = 0;
  Expected<int> fd = OpenRegular(path.string(), max_bytes, limit_name, &size);
  if (!fd.ok()) return fd.status();
  ::close(*fd);
  return OkStatus();
}

Status WriteFileAtomically(const std::filesystem::path& path, std::string_view bytes,
                           unsigned mode) {
  const std::string target = path.string();
  std::filesystem::path folder = path.parent_path();
  if (folder.empty()) folder = ".";
  std::random_device random;
  const std::string temporary =
      (folder / ("." + path.filename().string() + ".tmp-" + std::to_string(random()))).string();
  const int fd =
      ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, static_cast<mode_t>(mode));
  if (fd < 0) return IoError(target + ": cannot create a temporary file (" + Errno() + ")");
  auto fail = [&](const std::string& what) {
    const std::string why = Errno();
    ::close(fd);
    ::unlink(temporary.c_str());
    return IoError(target + ": " + what + " (" + why + "); the previous file is unchanged");
  };
  // The creation mode is masked by the umask; set it exactly (0600 for secrets stays 0600).
  if (::fchmod(fd, static_cast<mode_t>(mode)) != 0) return fail("cannot set the file mode");
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return fail("write failed");
    done += static_cast<size_t>(n);
  }
  if (::fsync(fd) != 0) return fail("fsync failed");
  if (::close(fd) != 0) {
    const std::string why = Errno();
    ::unlink(temporary.c_str());
    return IoError(target + ": close failed (" + why + "); the previous file is unchanged");
  }
  if (::rename(temporary.c_str(), target.c_str()) != 0) {
    const std::string why = Errno();
    ::unlink(temporary.c_str());
    return IoError(target + ": cannot rename the temporary file over it (" + why +
                   "); the previous file is unchanged");
  }
  const int dir = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    ::fsync(dir);  // best effort: the rename is durable once the folder is synced
    ::close(dir);
  }
  return OkStatus();
}

}  // namespace sandtable
