// cloudbake_bench_service_load: the load test as a benchmark. Starts cloudbake-server on a
// free loopback port, runs N concurrent real `cloudctl submit --out` clients (each a distinct
// small shot: different seeds, so no cache hits), and prints throughput, p50/p99 latency, the
// server's peak resident memory (VmHWM) and how many jobs failed or were lost. Exit status 1 when
// any failed or was lost. Not registered with ctest (docs/api.md, "Load benchmark").
//
// Usage: cloudbake_bench_service_load [CLIENTS=50] [RESOLUTION=16] [SPP=16] [RUNNERS]
// Without RUNNERS the server runs with its default settings (one runner, queue bound 16), so most
// clients find the queue full at first and pass only through cloudctl's retries (--retry-seconds,
// default 30 s, exponential backoff with jitter); with RUNNERS the queue is sized for every
// client, which measures the server alone.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "tests/server/server_fixture.h"

namespace {
using cloudbake::testing::CmdResult;
using cloudbake::testing::run;
using cloudbake::testing::ServerProc;
using cloudbake::testing::sphereShot;
using cloudbake::testing::Workspace;
using Json = nlohmann::json;

int arg(int argc, char** argv, int i, int fallback) {
  if (argc <= i) return fallback;
  const int v = std::atoi(argv[i]);
  if (v < 1) {
    std::fprintf(stderr, "argument %d: must be a positive integer, got '%s'\n", i, argv[i]);
    std::exit(2);
  }
  return v;
}

double percentile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  const size_t i = std::min(v.size() - 1, size_t(p * double(v.size() - 1) + 0.5));
  return v[i];
}

}  // namespace

int main(int argc, char** argv) {
  const int clients = arg(argc, argv, 1, 50);
  const int resolution = arg(argc, argv, 2, 16);
  const int spp = arg(argc, argv, 3, 16);
  const bool defaults = argc <= 4;
  const int runners = arg(argc, argv, 4, 1);
  Workspace ws;
  ServerProc server(ws.path("state"));
  // Errors only: with the default queue, refused submits are expected and would flood the log.
  std::vector<std::string> flags = {"--log-level=error"};
  if (!defaults) {
    flags.push_back("--max-concurrent-jobs=" + std::to_string(runners));
    flags.push_back("--queue-bound=" + std::to_string(clients + 8));
  }
  if (!server.start(flags)) {
    std::fprintf(stderr, "cloudbake-server did not start\n");
    return 1;
  }
  const long idle_kib = server.peakRssKib();
  std::vector<std::string> shots;
  for (int i = 0; i < clients; ++i) {
    std::string text = sphereShot(resolution, spp, "[1, 1, 1]", "front", -5, false);
    text.replace(text.find("\"seed\": 7"), 9, "\"seed\": " + std::to_string(100 + i));
    shots.push_back(ws.write("load/" + std::to_string(i) + ".json", text));
  }
  std::vector<double> latency(size_t(clients), 0);
  std::vector<CmdResult> results(static_cast<size_t>(clients));
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::thread> threads;
  for (int i = 0; i < clients; ++i) {
    threads.emplace_back([&, i] {
      const auto start = std::chrono::steady_clock::now();
      results[size_t(i)] = run(server.cloudctl(60) + " --json submit " + shots[size_t(i)] +
                               " --quiet --out " + ws.path("load/out" + std::to_string(i)));
      latency[size_t(i)] =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    });
  }
  for (auto& t : threads) t.join();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  int failed = 0;
  for (int i = 0; i < clients; ++i) {
    const CmdResult& r = results[size_t(i)];
    bool ok = r.code == 0;
    if (ok) {
      const Json j = Json::parse(r.out, nullptr, false);
      ok = !j.is_discarded() && j.value("state", "") == "SUCCEEDED" &&
           std::filesystem::exists(ws.path("load/out" + std::to_string(i) + "/front.exr"));
    }
    if (!ok) {
      ++failed;
      std::fprintf(stderr, "client %d failed (exit %d): %s", i, r.code, r.err.c_str());
    }
  }
  // Lost: submitted jobs the server does not list as SUCCEEDED afterwards.
  const CmdResult listed = run(server.cloudctl() + " --json list --state SUCCEEDED");
  const Json list = Json::parse(listed.out, nullptr, false);
  const int succeeded = list.is_array() ? int(list.size()) : 0;
  const int lost = std::max(0, clients - succeeded - failed);
  const long peak_kib = server.peakRssKib();
  std::printf(
      "service load: %d clients (cloudctl submit --out; %dx%d px, %d spp, %d runner(s)%s, %u "
      "cores)\n"
      "  wall %.2f s, throughput %.2f jobs/s\n"
      "  latency p50 %.3f s, p99 %.3f s, max %.3f s\n"
      "  server VmHWM %ld MiB (idle %ld MiB)\n"
      "  failed %d, lost %d, succeeded on the server %d\n",
      clients, resolution, resolution, spp, runners,
      defaults ? ", the server's default settings" : ", queue sized for every client",
      std::thread::hardware_concurrency(), wall, clients / wall, percentile(latency, 0.5),
      percentile(latency, 0.99), *std::max_element(latency.begin(), latency.end()), peak_kib / 1024,
      idle_kib / 1024, failed, lost, succeeded);
  server.stop();
  return failed == 0 && lost == 0 ? 0 : 1;
}
