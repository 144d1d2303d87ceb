// The bake cache shared by processes (core/job/bake_cache.h, core/job/lease.h): entries another
// process committed are found, a live lease is waited for (nothing computed twice), a killed
// holder's lease and staging are taken over, and eviction spares recently used entries.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/job/bake_cache.h"
#include "core/job/file_util.h"
#include "core/job/lease.h"

extern char** environ;

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using std::chrono::milliseconds;

fs::path freshDir(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("cloudbake-shared-" + name + "-" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

BakeCacheOptions fastOptions() {
  BakeCacheOptions o;
  o.lease.heartbeat = milliseconds(50);
  o.lease.stale_after = milliseconds(400);
  o.poll = milliseconds(20);
  return o;
}

std::string readAll(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A cache_worker process; its stdout goes to `out`.
struct Worker {
  pid_t pid = -1;
  std::string out;
  Worker(const fs::path& root, const std::string& key, int ms, const std::string& content,
         const std::string& out_path, bool kill_self = false)
      : out(out_path) {
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    std::vector<std::string> args = {CACHE_WORKER_BIN, root.string(), key, std::to_string(ms),
                                     content};
    if (kill_self) args.push_back("kill");
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    EXPECT_EQ(posix_spawn(&pid, CACHE_WORKER_BIN, &actions, nullptr, argv.data(), environ), 0);
    posix_spawn_file_actions_destroy(&actions);
  }
  int wait() {
    int status = 0;
    waitpid(pid, &status, 0);
    return status;
  }
};

bool waitFor(const fs::path& path, milliseconds limit) {
  const auto end = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < end) {
    if (fs::exists(path)) return true;
    std::this_thread::sleep_for(milliseconds(5));
  }
  return false;
}

TEST(SharedCache, AnotherInstanceFindsWhatOneCommitted) {
  const fs::path dir = freshDir("two");
  BakeCache a(dir.string(), fastOptions()), b(dir.string(), fastOptions());
  a.getOrCompute("k", [](const std::string& s) { writeFileAtomic(s + "/data", "from a"); });
  int computed = 0;
  const std::string entry = b.getOrCompute("k", [&](const std::string&) { ++computed; });
  EXPECT_EQ(computed, 0);
  EXPECT_EQ(readAll(entry + "/data"), "from a");
  EXPECT_TRUE(b.lookup("k").has_value());
  fs::remove_all(dir);
}

// An outside probe removed the cache's folders under a running server: every later job failed
// ("cannot create the lease") until a restart. They are made again when needed.
TEST(SharedCache, FoldersRemovedWhileOpenAreMadeAgain) {
  const fs::path dir = freshDir("removed");
  BakeCache cache(dir.string(), fastOptions());
  fs::remove_all(dir);
  const std::string entry =
      cache.getOrCompute("k", [](const std::string& s) { writeFileAtomic(s + "/data", "again"); });
  EXPECT_EQ(readAll(entry + "/data"), "again");
  EXPECT_TRUE(cache.lookup("k").has_value());
  fs::remove_all(dir);
}

TEST(SharedCache, ALiveLeaseOfAnotherProcessIsWaitedForNotComputedAgain) {
  const fs::path dir = freshDir("live");
  BakeCache cache(dir.string(), fastOptions());  // creates the folders before the worker
  Worker w(dir, "k", 1500, "computed-by-worker", (dir / "w.out").string());
  ASSERT_TRUE(waitFor(dir / "leases" / "k.lease", milliseconds(10000)));
  int computed = 0;
  const std::string entry = cache.getOrCompute("k", [&](const std::string&) { ++computed; });
  EXPECT_EQ(computed, 0) << "a live lease (1.5 s, beating every 50 ms, stale after 0.4 s)";
  EXPECT_EQ(readAll(entry + "/data"), "computed-by-worker");
  EXPECT_EQ(cache.stats().shared_across_processes, 1u);
  EXPECT_EQ(w.wait(), 0);
  EXPECT_EQ(readAll(w.out), "computed computed-by-worker\n");
  EXPECT_FALSE(fs::exists(dir / "leases" / "k.lease")) << "released";
  fs::remove_all(dir);
}

TEST(SharedCache, AHolderKilledMidWriteIsTakenOverAndItsDebrisNeverServed) {
  const fs::path dir = freshDir("killed");
  { BakeCache create(dir.string(), fastOptions()); }
  Worker w(dir, "k", 300, "half-then-killed", (dir / "w.out").string(), true);
  const int status = w.wait();
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  ASSERT_TRUE(fs::exists(dir / "leases" / "k.lease")) << "the killed holder's lease remains";
  BakeCache cache(dir.string(), fastOptions());  // reopening removes the dead process's staging
  size_t staging = 0;
  for (const auto& e : fs::directory_iterator(dir / "staging")) staging += e.exists();
  EXPECT_EQ(staging, 0u);
  EXPECT_FALSE(cache.lookup("k").has_value());
  const auto t0 = std::chrono::steady_clock::now();
  const std::string entry = cache.getOrCompute(
      "k", [](const std::string& s) { writeFileAtomic(s + "/data", "recomputed"); });
  // A dead holder on this host is stale at once, without waiting out stale_after.
  EXPECT_LT(std::chrono::steady_clock::now() - t0, milliseconds(350));
  EXPECT_EQ(readAll(entry + "/data"), "recomputed");
  EXPECT_EQ(cache.stats().leases_taken_over, 1u);
  fs::remove_all(dir);
}

TEST(SharedCache, ALeaseThatStopsBeatingOnAnotherHostGoesStaleByTheObserversClock) {
  const fs::path dir = freshDir("stale");
  BakeCache cache(dir.string(), fastOptions());
  writeFileAtomic((dir / "leases" / "k.lease").string(), "holder=elsewhere:1\nbeat=7\n");
  const auto t0 = std::chrono::steady_clock::now();
  cache.getOrCompute("k", [](const std::string& s) { writeFileAtomic(s + "/data", "x"); });
  const auto waited = std::chrono::steady_clock::now() - t0;
  EXPECT_GE(waited, milliseconds(400));
  EXPECT_LT(waited, milliseconds(5000));
  EXPECT_EQ(cache.stats().leases_taken_over, 1u);
  fs::remove_all(dir);
}

TEST(SharedCache, ABeatingLeaseIsNeverTakenOver) {
  const fs::path dir = freshDir("beating");
  fs::create_directories(dir);
  LeaseOptions o;
  o.heartbeat = milliseconds(50);
  o.stale_after = milliseconds(300);
  LeaseObserver mine, other;
  const std::string path = (dir / "k.lease").string();
  auto held = Lease::tryAcquire(path, o, mine);
  ASSERT_TRUE(held);
  for (int i = 0; i < 40; ++i) {  // 1.2 s: four times stale_after
    EXPECT_FALSE(Lease::tryAcquire(path, o, other));
    std::this_thread::sleep_for(milliseconds(30));
  }
  EXPECT_TRUE(held->held());
  held.reset();
  EXPECT_FALSE(fs::exists(path));
  EXPECT_TRUE(Lease::tryAcquire(path, o, other));
  EXPECT_THROW(Lease::tryAcquire(path, LeaseOptions{milliseconds(100), milliseconds(200)}, other),
               std::exception);
  fs::remove_all(dir);
}

TEST(SharedCache, ManyProcessesOnOneKeyComputeItOnce) {
  const fs::path dir = freshDir("many");
  { BakeCache create(dir.string(), fastOptions()); }
  std::vector<std::unique_ptr<Worker>> workers;
  for (int i = 0; i < 4; ++i) {
    workers.push_back(std::make_unique<Worker>(dir, "k", 600, "w" + std::to_string(i),
                                               (dir / ("w" + std::to_string(i))).string()));
  }
  int computed = 0;
  std::string content;
  for (auto& w : workers) {
    EXPECT_EQ(w->wait(), 0);
    const std::string out = readAll(w->out);
    computed += out.rfind("computed ", 0) == 0;
    const std::string got = out.substr(out.find(' ') + 1);
    if (content.empty()) content = got;
    EXPECT_EQ(got, content) << "every process reads the one entry";
  }
  EXPECT_EQ(computed, 1);
  fs::remove_all(dir);
}

// Three keys, each first taken by a process killed mid-write, then wanted by two more at once:
// every key is computed once after the kill, and every process reads its key's whole content.
TEST(SharedCache, KilledHoldersAndConcurrentReadersNeverSeeACorruptEntry) {
  const fs::path dir = freshDir("stress");
  { BakeCache create(dir.string(), fastOptions()); }
  std::vector<std::unique_ptr<Worker>> killed, normal;
  std::vector<std::string> keys = {"k0", "k1", "k2"};
  for (const std::string& k : keys) {
    killed.push_back(std::make_unique<Worker>(dir, k, 200, "content-of-" + k,
                                              (dir / ("killed-" + k)).string(), true));
    ASSERT_TRUE(waitFor(dir / "leases" / (k + ".lease"), milliseconds(10000)));
  }
  for (int round = 0; round < 2; ++round) {
    for (const std::string& k : keys) {
      normal.push_back(
          std::make_unique<Worker>(dir, k, 300, "content-of-" + k,
                                   (dir / ("w" + std::to_string(round) + "-" + k)).string()));
    }
  }
  for (auto& w : killed) w->wait();
  std::map<std::string, int> computed;
  for (size_t i = 0; i < normal.size(); ++i) {
    EXPECT_EQ(normal[i]->wait(), 0);
    const std::string k = keys[i % keys.size()];
    const std::string out = readAll(normal[i]->out);
    EXPECT_EQ(out.substr(out.find(' ') + 1), "content-of-" + k + "\n") << "a corrupt read";
    computed[k] += out.rfind("computed ", 0) == 0;
  }
  for (const std::string& k : keys) EXPECT_EQ(computed[k], 1) << k;
  BakeCache after(dir.string(), fastOptions());
  for (const std::string& k : keys) {
    const auto entry = after.lookup(k);
    ASSERT_TRUE(entry.has_value()) << k;
    EXPECT_EQ(readAll(*entry + "/data"), "content-of-" + k);
  }
  EXPECT_EQ(after.stats().corrupt, 0u);
  fs::remove_all(dir);
}

TEST(SharedCache, EvictionSparesEntriesUsedRecently) {
  const fs::path dir = freshDir("evict");
  BakeCacheOptions o = fastOptions();
  o.max_bytes = 1500;
  BakeCache cache(dir.string(), o);  // min_evict_age: the default 10 minutes
  auto fill = [](const std::string& s) { writeFileAtomic(s + "/data", std::string(1000, 'x')); };
  cache.getOrCompute("a", fill);
  cache.getOrCompute("b", fill);
  EXPECT_TRUE(cache.lookup("a").has_value()) << "a reader may still hold a";
  EXPECT_EQ(cache.stats().evicted, 0u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace cloudbake
