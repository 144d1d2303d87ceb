#include "core/io/file_sync.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
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

std::string temporaryNameFor(const std::string& path) {
  static std::atomic<unsigned long> counter{0};
  return path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
}

void writeTextAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = temporaryNameFor(path);
  try {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << text;
    out.close();
    if (!out) {
      const int err = errno;
      throwIfNoSpace(err, path + ": write failed");
      throw std::runtime_error(path + ": write failed");
    }
    syncFile(tmp);
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
      throw std::runtime_error(path + ": rename failed: " + std::strerror(errno));
    }
  } catch (...) {
    std::remove(tmp.c_str());
    throw;
  }
}

}  // namespace cloudbake
