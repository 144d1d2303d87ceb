// Runs cloudbake-server as a child process on a free loopback port and cloudctl against it.
#pragma once

#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace cloudbake::testing {

inline int freePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
  socklen_t len = sizeof addr;
  getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  close(fd);
  return ntohs(addr.sin_port);
}

struct CmdResult {
  int code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

inline std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline std::string tempName(const std::string& stem) {
  static int counter = 0;
  return (std::filesystem::temp_directory_path() /
          (stem + "_" + std::to_string(getpid()) + "_" + std::to_string(++counter)))
      .string();
}

/// Runs a shell command; returns exit code, stdout and stderr.
inline CmdResult run(const std::string& cmd) {
  const std::string err_file = tempName("cloudctl_stderr");
  CmdResult r;
  FILE* p = popen((cmd + " 2>" + err_file).c_str(), "r");
  std::array<char, 4096> buf{};
  size_t n;
  while (p && (n = fread(buf.data(), 1, buf.size(), p)) > 0) r.out.append(buf.data(), n);
  const int status = p ? pclose(p) : -1;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.err = slurp(err_file);
  std::filesystem::remove(err_file);
  return r;
}

/// A cloudbake-server child process with its own state folder.
class ServerProc {
 public:
  explicit ServerProc(std::string state_dir) : state_dir_(std::move(state_dir)) {}
  ~ServerProc() { stop(); }

  /// Starts on a fresh port (or `port` when non-zero) and waits until healthy.
  bool start(const std::vector<std::string>& extra = {}, int port = 0) {
    port_ = port ? port : freePort();
    address_ = "127.0.0.1:" + std::to_string(port_);
    std::vector<std::string> args = {CLOUDBAKE_SERVER_BIN, "--listen=" + address_,
                                     "--cache-dir=" + state_dir_, "--threads=2"};
    bool has_level = false;
    for (const std::string& a : extra) has_level |= a.rfind("--log-level", 0) == 0;
    if (!has_level) args.push_back("--log-level=warn");
    args.insert(args.end(), extra.begin(), extra.end());
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    if (!log_path_.empty()) {
      posix_spawn_file_actions_addopen(&actions, 2, log_path_.c_str(),
                                       O_WRONLY | O_CREAT | O_APPEND, 0644);
    }
    const int spawned =
        posix_spawn(&pid_, CLOUDBAKE_SERVER_BIN, &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (spawned != 0) return false;
    for (int i = 0; i < 100; ++i) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {  // exited: it will never answer
        pid_ = -1;
        return false;
      }
      if (run(cloudctl(0.5) + " health").code == 0) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
  }
  /// SIGTERM and wait; returns true when it exited normally with status 0.
  bool stop() {
    if (pid_ <= 0) return true;
    kill(pid_, SIGTERM);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    return WIFEXITED(status) && WEXITSTATUS(status) == 0;
  }
  void killHard() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
  }
  std::string cloudctl(double timeout_s = 5) const {
    return std::string(CLOUDCTL_BIN) + " --server " + address_ + " --timeout " +
           std::to_string(timeout_s) + client_flags_;
  }
  /// Flags every cloudctl() command line carries from now on (e.g. " --tls-ca ca.pem").
  void clientFlags(std::string flags) { client_flags_ = std::move(flags); }
  /// Sends the server's stderr (its log) to `path` from the next start() on.
  void logTo(std::string path) { log_path_ = std::move(path); }
  const std::string& address() const { return address_; }
  const std::string& stateDir() const { return state_dir_; }
  pid_t pid() const { return pid_; }
  /// Peak resident memory of the server process (VmHWM) in KiB, or -1.
  long peakRssKib() const {
    std::ifstream in("/proc/" + std::to_string(pid_) + "/status");
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("VmHWM:", 0) == 0) return std::stol(line.substr(6));
    }
    return -1;
  }

 private:
  std::string state_dir_;
  std::string log_path_;
  std::string client_flags_;
  int port_ = 0;
  pid_t pid_ = -1;
  std::string address_;
};

/// A shot: a sphere of cloud seen from the front, `w` x `w` pixels at `spp` samples.
inline std::string sphereShot(int w, int spp, const std::string& irradiance = "[1, 1, 1]",
                              const std::string& view = "front", double cam_y = -5,
                              bool vdb = true) {
  return R"({"version": 1, "name": "sphere",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 2, "albedo": 0.9, "phase": {"type": "hg", "g": 0.5}},
    "lighting": {"sun": {"direction": [0.3, 0, 1], "irradiance": )" +
         irradiance + R"(}},
    "bake": {"method": "pathtrace", "samples": )" +
         std::to_string(spp) + R"(, "seed": 7},
    "views": [{"name": ")" +
         view + R"(", "camera": {"type": "orthographic", "position": [0, )" +
         std::to_string(cam_y) +
         R"(, 0], "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [)" +
         std::to_string(w) + ", " + std::to_string(w) + R"(]}],
    "outputs": {"exr": true, "vdb": )" +
         (vdb ? "true" : "false") + R"(, "vdb_voxel_size": 0.1}})";
}

/// A small sphere shot baked by `method` (single or pointcloud) with one orthographic view
/// looking along +y from y = cam_y (or along -x from x = -cam_y when view is "side").
inline std::string bakedSphereShot(const std::string& method, const std::string& irradiance,
                                   const std::string& view) {
  const bool side = view == "side";
  return R"({"version": 1, "name": "baked",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 4, "albedo": 0.95, "phase": {"type": "hg", "g": 0.7}},
    "lighting": {"sun": {"direction": [0.3, 0, 1], "irradiance": )" +
         irradiance + R"(}},
    "bake": {"method": ")" +
         method + R"(", "light_resolution": 32)" +
         (method == "pointcloud" ? R"(, "points": 4096, "passes": 4)" : "") + R"(},
    "views": [{"name": ")" +
         view + R"(", "camera": {"type": "orthographic", "position": )" +
         (side ? "[5, 0, 0]" : "[0, -5, 0]") +
         R"(, "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [48, 48]}],
    "outputs": {"exr": true, "vdb": true}})";
}

/// A temporary folder removed with everything in it at the end.
class Workspace {
 public:
  Workspace() : dir_(tempName("cloudbake_server_test")) {
    std::filesystem::create_directories(dir_);
  }
  ~Workspace() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string write(const std::string& name, const std::string& text) const {
    const std::filesystem::path p = std::filesystem::path(dir_) / name;
    std::filesystem::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }
  std::string path(const std::string& name) const {
    return (std::filesystem::path(dir_) / name).string();
  }

 private:
  std::string dir_;
};

}  // namespace cloudbake::testing
