#include "core/job/file_util.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "core/error.h"

namespace cloudbake {
namespace fs = std::filesystem;

std::string uniqueSuffix() {
  static std::atomic<unsigned long> counter{0};
  const auto now = std::chrono::steady_clock::now().time_since_epoch().count();
  std::ostringstream s;
  s << getpid() << "-" << now << "-" << counter.fetch_add(1);
  return s.str();
}

void makeWritableFolder(const std::string& dir, const std::string& what) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) {
    throw InputError(what + ": cannot create folder '" + dir + "'" +
                     (ec ? ": " + ec.message() : ""));
  }
  std::string probe = (fs::path(dir) / ".cloudbake-write-test-XXXXXX").string();
  const int fd = ::mkostemp(probe.data(), O_CLOEXEC);
  if (fd < 0) {
    throw InputError(what + ": cannot write in folder '" + dir + "': " + std::strerror(errno));
  }
  ::close(fd);
  ::unlink(probe.c_str());
}

void writeFileAtomic(const std::string& path, const std::string& data) {
  const std::string tmp = path + ".tmp." + uniqueSuffix();
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error(path + ": cannot create: " + std::strerror(errno));
  size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const int saved = errno;
      const std::string err = std::strerror(saved);
      ::close(fd);
      ::unlink(tmp.c_str());
      throwIfNoSpace(saved, path + ": write failed: " + err);
      throw std::runtime_error(path + ": write failed: " + err);
    }
    done += size_t(n);
  }
  // fsync before rename: otherwise a crash can leave the new name pointing at empty data.
  int failed = ::fsync(fd) == 0 ? 0 : errno;
  if (::close(fd) != 0 && failed == 0) failed = errno;
  if (failed != 0) {
    ::unlink(tmp.c_str());
    throwIfNoSpace(failed, path + ": sync failed: " + std::strerror(failed));
    throw std::runtime_error(path + ": sync failed: " + std::strerror(failed));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string err = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw std::runtime_error(path + ": rename failed: " + err);
  }
}

std::string readWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw MissingFileError(path + ": no such file");
    throw InputError(path + ": cannot open for reading");
  }
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) throw InputError(path + ": read error");
  return s.str();
}

std::string readRegularFile(const std::string& path, uint64_t max_bytes) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (!fs::exists(st)) throw MissingFileError(path + ": no such file");
  if (!fs::is_regular_file(st)) throw InputError(path + ": not a regular file");
  const uintmax_t size = fs::file_size(path, ec);
  if (ec) throw InputError(path + ": cannot read its size (" + ec.message() + ")");
  if (size > max_bytes) {
    throw InputError(path + ": " + std::to_string(size) + " bytes, more than the " +
                     std::to_string(max_bytes) + " allowed");
  }
  return readWholeFile(path);
}

void linkOrCopy(const std::string& from, const std::string& to) {
  std::error_code ec;
  fs::create_directories(fs::path(to).parent_path(), ec);
  fs::remove(to, ec);
  fs::create_hard_link(from, to, ec);
  if (!ec) return;
  fs::copy_file(from, to, fs::copy_options::overwrite_existing, ec);
  if (ec) {
    throwIfNoSpace(ec.value(), "cannot copy " + from + " to " + to + ": " + ec.message());
    throw std::runtime_error("cannot link or copy " + from + " to " + to + ": " + ec.message());
  }
}

}  // namespace cloudbake
