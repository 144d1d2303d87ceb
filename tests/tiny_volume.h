// A tmpfs of a few MiB mounted for one test, so a test can fill a disk for real. Needs root and
// mount permission (CI runs as root); where it cannot mount, ok() is false and the test skips,
// saying why.
#pragma once

#include <sys/mount.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>

namespace cloudbake::testing {

class TinyVolume {
 public:
  TinyVolume(std::string dir, int mib) : dir_(std::move(dir)) {
    std::filesystem::create_directories(dir_);
    const std::string options = "size=" + std::to_string(mib) + "m";
    if (::mount("tmpfs", dir_.c_str(), "tmpfs", 0, options.c_str()) == 0) {
      mounted_ = true;
    } else {
      why_ = std::string("cannot mount a tmpfs to fill (needs root): ") + std::strerror(errno);
    }
  }
  ~TinyVolume() {
    if (mounted_) ::umount2(dir_.c_str(), MNT_DETACH);
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  TinyVolume(const TinyVolume&) = delete;
  TinyVolume& operator=(const TinyVolume&) = delete;

  bool ok() const { return mounted_; }
  const std::string& why() const { return why_; }
  const std::string& dir() const { return dir_; }

 private:
  std::string dir_;
  bool mounted_ = false;
  std::string why_;
};

}  // namespace cloudbake::testing
