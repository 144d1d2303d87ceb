#include "core/job/lease.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "core/error.h"
#include "core/job/file_util.h"

namespace cloudbake {
namespace {

// The host and its process-id namespace: a pid means the same process only within both.
std::string hostName() {
  char buf[256] = {};
  if (gethostname(buf, sizeof buf - 1) != 0) return "unknown-host";
  char ns[64] = {};
  const ssize_t n = ::readlink("/proc/self/ns/pid", ns, sizeof ns - 1);
  return std::string(buf) + "/" + (n > 0 ? std::string(ns, size_t(n)) : std::string("?"));
}

// False when the file does not exist (released or renamed away).
bool readSmallFile(const std::string& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream s;
  s << in.rdbuf();
  *out = s.str();
  return true;
}

// False when the file exists already; throws on any other failure.
bool createExclusive(const std::string& path, const std::string& content) {
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0 && errno == ENOENT) {
    // The leases' folder was removed while the server runs: make it again, once.
    std::error_code made;
    std::filesystem::create_directories(std::filesystem::path(path).parent_path(), made);
    fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  }
  if (fd < 0) {
    if (errno == EEXIST) return false;
    const int err = errno;
    throwIfNoSpace(err, path + ": cannot create the lease: " + std::strerror(err));
    throw std::runtime_error(path + ": cannot create the lease: " + std::strerror(err));
  }
  const ssize_t written = ::write(fd, content.data(), content.size());
  int err = written < 0 ? errno : 0;
  bool ok = written == ssize_t(content.size());
  if (ok && ::fsync(fd) != 0) {
    err = errno;
    ok = false;
  }
  if (::close(fd) != 0 && ok) {
    err = errno;
    ok = false;
  }
  if (!ok) {
    ::unlink(path.c_str());
    // A short write on a full volume sets no errno: count it as full, as the OS would on retry.
    if (written >= 0 && written < ssize_t(content.size()) && err == 0) err = ENOSPC;
    throwIfNoSpace(err, path + ": cannot write the lease");
    throw std::runtime_error(path + ": cannot write the lease: " + std::strerror(err));
  }
  return true;
}

std::string holderOf(const std::string& content) {
  const std::string prefix = "holder=";
  if (content.rfind(prefix, 0) != 0) return "";
  return content.substr(prefix.size(), content.find('\n') - prefix.size());
}

// A holder on this host whose process is gone (killed mid-compute): stale without waiting.
bool deadOnThisHost(const std::string& holder) {
  const size_t colon = holder.rfind(':');
  if (colon == std::string::npos || holder.substr(0, colon) != hostName()) return false;
  const long pid = std::strtol(holder.c_str() + colon + 1, nullptr, 10);
  if (pid <= 0 || pid == long(getpid())) return false;
  return ::kill(pid_t(pid), 0) != 0 && errno == ESRCH;
}

std::string leaseContent(unsigned long beat) {
  return "holder=" + leaseHolderName() + "\nbeat=" + std::to_string(beat) + "\n";
}

// Renames a lease judged stale out of the way. True when this caller moved exactly what it saw;
// a fresh lease moved by mistake (taken meanwhile) is put back.
bool moveStaleAside(const std::string& path, const std::string& seen) {
  const std::string aside = path + ".stale." + uniqueSuffix();
  if (::rename(path.c_str(), aside.c_str()) != 0) return false;
  std::string moved;
  const bool same = readSmallFile(aside, &moved) && moved == seen;
  if (!same && ::link(aside.c_str(), path.c_str()) != 0) {
    // Its holder sees the loss at its next beat and stops claiming it.
  }
  ::unlink(aside.c_str());
  return same;
}

}  // namespace

std::string leaseHolderName() { return hostName() + ":" + std::to_string(getpid()); }

std::unique_ptr<Lease> Lease::tryAcquire(const std::string& path, const LeaseOptions& options,
                                         LeaseObserver& observer, bool* took_over) {
  if (options.heartbeat.count() <= 0 || options.stale_after < 3 * options.heartbeat) {
    throw InputError("lease: stale_after must be at least three heartbeats");
  }
  bool stale_moved = false;
  for (int attempt = 0; attempt < 2; ++attempt) {
    const std::string content = leaseContent(0);
    if (createExclusive(path, content)) {
      if (took_over) *took_over = stale_moved;
      return std::unique_ptr<Lease>(new Lease(path, content, options));
    }
    std::string seen;
    if (!readSmallFile(path, &seen)) continue;  // released meanwhile
    const auto now = std::chrono::steady_clock::now();
    // Staleness is judged only over this observer's own sightings: a file just created and not
    // yet written (empty, as NFS may show it) is as live as any other.
    if (!observer.seen || seen != observer.content) observer = {true, seen, now};
    const bool stale =
        deadOnThisHost(holderOf(seen)) || now - observer.changed >= options.stale_after;
    if (!stale || !moveStaleAside(path, seen)) return nullptr;
    observer = {};
    stale_moved = true;
  }
  return nullptr;
}

Lease::Lease(std::string path, std::string content, const LeaseOptions& options)
    : path_(std::move(path)), content_(std::move(content)), options_(options) {
  thread_ = std::thread([this] { beat(); });
}

Lease::~Lease() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  thread_.join();
  std::string now;
  if (!lost_ && readSmallFile(path_, &now) && now == content_) ::unlink(path_.c_str());
}

bool Lease::held() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return !lost_;
}

void Lease::beat() {
  std::unique_lock<std::mutex> lock(mutex_);
  unsigned long count = 0;
  while (!cv_.wait_for(lock, options_.heartbeat, [this] { return stop_; })) {
    std::string now;
    if (!readSmallFile(path_, &now) || now != content_) {
      lost_ = true;  // taken over (we stalled past stale_after): stop claiming it
      return;
    }
    const std::string next = leaseContent(++count);
    try {
      writeFileAtomic(path_, next);
      content_ = next;
    } catch (const std::exception&) {
      // A missed beat; the next one retries. Observers wait stale_after, several beats.
    }
  }
}

}  // namespace cloudbake
