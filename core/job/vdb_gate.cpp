#include "core/job/vdb_gate.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <optional>

#include "core/error.h"

extern char** environ;

namespace cloudbake {
namespace {

constexpr size_t kMaxMessage = 4096;  // of the child's output kept for the error

pid_t spawn(const std::vector<std::string>& args, int out_fd) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, out_fd, 1);
  posix_spawn_file_actions_adddup2(&actions, out_fd, 2);
  std::vector<std::string> copy = args;
  std::vector<char*> argv;
  for (std::string& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) {
    throw InternalError("the VDB reader " + args[0] + " cannot be started (errno " +
                        std::to_string(rc) + ")");
  }
  return pid;
}

// Reads the child's output until it closes it, or returns early to let the caller kill it.
// Returns why it stopped early ("cancelled", "timeout") or nothing at end of output.
std::optional<std::string> drain(int fd, std::string* output, double timeout_s,
                                 const std::function<bool()>& keep_going) {
  const auto start = std::chrono::steady_clock::now();
  char buf[4096];
  for (;;) {
    pollfd p{fd, POLLIN, 0};
    const int ready = ::poll(&p, 1, 100);
    if (ready > 0) {
      const ssize_t n = ::read(fd, buf, sizeof buf);
      if (n == 0) return std::nullopt;
      if (n > 0 && output->size() < kMaxMessage) output->append(buf, size_t(n));
      if (n < 0 && errno != EINTR && errno != EAGAIN) return std::nullopt;
    }
    if (keep_going && !keep_going()) return "cancelled";
    const double waited =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (waited > timeout_s) return "timeout";
  }
}

int wait(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return status;
}

// The child's last line (its error message), without a "prog: error: " prefix.
std::string lastLine(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  const size_t nl = s.rfind('\n');
  if (nl != std::string::npos) s = s.substr(nl + 1);
  const size_t tag = s.find("error: ");
  if (tag != std::string::npos) s = s.substr(tag + 7);
  return s;
}

}  // namespace

void rewriteVdbInChild(const VdbReaderOptions& options, const std::string& in,
                       const std::string& out, const std::function<bool()>& keep_going) {
  if (options.command.empty()) throw InternalError("rewriteVdbInChild: no reader command");
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw InternalError("rewriteVdbInChild: pipe failed");
  std::vector<std::string> args = options.command;
  args.push_back(in);
  args.push_back(out);
  pid_t pid = -1;
  try {
    pid = spawn(args, fds[1]);
  } catch (...) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw;
  }
  ::close(fds[1]);
  std::string output;
  const std::optional<std::string> stopped =
      drain(fds[0], &output, options.timeout_seconds, keep_going);
  ::close(fds[0]);
  if (stopped) ::kill(pid, SIGKILL);
  const int status = wait(pid);
  if (stopped && *stopped == "cancelled") throw Cancelled("cancelled while reading " + in);
  if (stopped) {
    throw InputError(in + ": reading the VDB file took more than " +
                     std::to_string(int(options.timeout_seconds)) + " s; refused");
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return;
  if (WIFEXITED(status) && WEXITSTATUS(status) == 2) throw InputError(lastLine(output));
  // The rewrite's volume is full (the child's exit code 4): not the file's fault; retry later.
  if (WIFEXITED(status) && WEXITSTATUS(status) == 4) throw StorageFullError(lastLine(output));
  throw InputError(in + ": not a readable OpenVDB file (the VDB reader failed on it: " +
                   (WIFSIGNALED(status) ? "signal " + std::to_string(WTERMSIG(status))
                                        : "exit " + std::to_string(WEXITSTATUS(status))) +
                   "; corrupt compressed data?)");
}

}  // namespace cloudbake
