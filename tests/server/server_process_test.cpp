// Starts cloudbake-server on a free loopback port and talks to it with cloudctl.
#include <arpa/inet.h>
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
#include <string>
#include <thread>

extern char** environ;

namespace {

int freePort() {
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

// Runs a command, returns (exit code, stdout).
std::pair<int, std::string> run(const std::string& cmd) {
  std::string out;
  FILE* p = popen(cmd.c_str(), "r");
  std::array<char, 512> buf{};
  while (p && fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = p ? pclose(p) : -1;
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

class ServerProcess : public ::testing::Test {
 protected:
  void SetUp() override {
    port_ = freePort();
    address_ = "127.0.0.1:" + std::to_string(port_);
    std::string listen = "--listen=" + address_;
    const char* argv[] = {CLOUDBAKE_SERVER_BIN, listen.c_str(), "--log-level=warn", nullptr};
    ASSERT_EQ(posix_spawn(&pid_, CLOUDBAKE_SERVER_BIN, nullptr, nullptr,
                          const_cast<char**>(argv), environ),
              0);
    // Wait until it answers (at most ~10 s).
    for (int i = 0; i < 100; ++i) {
      if (run(cloudctl() + " health").first == 0) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    FAIL() << "server did not become healthy on " << address_;
  }
  void TearDown() override {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      int status = 0;
      waitpid(pid_, &status, 0);
      EXPECT_TRUE(WIFEXITED(status)) << "server did not exit cleanly on SIGTERM";
    }
  }
  std::string cloudctl() const {
    return std::string(CLOUDCTL_BIN) + " --server " + address_ + " --timeout 2";
  }
  int port_ = 0;
  pid_t pid_ = -1;
  std::string address_;
};

TEST_F(ServerProcess, HealthAndInfo) {
  auto [code, out] = run(cloudctl() + " health");
  EXPECT_EQ(code, 0);
  EXPECT_NE(out.find("SERVING"), std::string::npos) << out;
  std::tie(code, out) = run(cloudctl() + " info");
  EXPECT_EQ(code, 0);
  EXPECT_NE(out.find("pathtrace"), std::string::npos) << out;
  std::tie(code, out) = run(cloudctl() + " --json health");
  EXPECT_EQ(code, 0);
  EXPECT_NE(out.find("\"serving\":true"), std::string::npos) << out;
}

TEST(ServerUnavailable, CloudctlReportsUnavailableExitCode) {
  const std::string addr = "127.0.0.1:" + std::to_string(freePort());
  auto [code, out] = run(std::string(CLOUDCTL_BIN) + " --server " + addr +
                         " --timeout 1 health 2>/dev/null");
  EXPECT_EQ(code, 4);  // kUnavailable
}

}  // namespace
