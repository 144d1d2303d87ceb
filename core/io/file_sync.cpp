#include "core/io/file_sync.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include "core/error.h"

namespace cloudbake {

void syncFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  int failed = fd < 0 ? errno : ::fsync(fd) == 0 ? 0 : errno;
  if (fd >= 0 && ::close(fd) != 0 && failed == 0) failed = errno;
  if (failed == 0) return;
  throwIfNoSpace(failed, path + ": sync failed: " + std::strerror(failed));
  throw std::runtime_error(path + ": sync failed: " + std::strerror(failed));
}

}  // namespace cloudbake
