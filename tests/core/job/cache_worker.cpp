// A separate process on a shared bake cache, for tests/core/job/shared_cache_test.cpp:
//   cache_worker ROOT KEY MILLISECONDS CONTENT [kill]
// computes KEY by writing half of CONTENT to the staging folder, sleeping MILLISECONDS, then
// writing the rest; with `kill` it SIGKILLs itself mid-way instead. Prints "computed" or
// "served" (another process's entry) and the entry's content.
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "core/job/bake_cache.h"
#include "core/job/file_util.h"

int main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr, "usage: cache_worker ROOT KEY MILLISECONDS CONTENT [kill]\n");
    return 2;
  }
  const std::string key = argv[2], content = argv[4];
  const int ms = std::atoi(argv[3]);
  const bool kill_self = argc > 5 && std::string(argv[5]) == "kill";
  cloudbake::BakeCacheOptions options;
  options.lease.heartbeat = std::chrono::milliseconds(50);
  options.lease.stale_after = std::chrono::milliseconds(400);
  options.poll = std::chrono::milliseconds(20);
  cloudbake::BakeCache cache(argv[1], options);
  bool computed = false;
  const std::string dir = cache.getOrCompute(key, [&](const std::string& staging) {
    computed = true;
    std::ofstream(staging + "/data") << content.substr(0, content.size() / 2);
    std::this_thread::sleep_for(std::chrono::milliseconds(ms));
    if (kill_self) ::kill(getpid(), SIGKILL);
    std::ofstream(staging + "/data", std::ios::app) << content.substr(content.size() / 2);
  });
  std::ifstream in(dir + "/data");
  std::stringstream s;
  s << in.rdbuf();
  std::printf("%s %s\n", computed ? "computed" : "served", s.str().c_str());
  return 0;
}
