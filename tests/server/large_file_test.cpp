// Large files stream in constant memory: a ~200 MB asset is uploaded with cloudctl and a ~200 MB
// job output is fetched, and the server's peak resident memory (VmHWM) grows by far less than the
// file. No shot produces a 200 MB output cheaply, so the output is planted in a finished job's
// record while the server is down; FetchResult serves it exactly as it serves a baked file.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "core/job/sha256.h"
#include "tests/server/server_fixture.h"

namespace cloudbake::testing {
namespace {
namespace fs = std::filesystem;
using Json = nlohmann::json;

constexpr uint64_t kFileBytes = 200ull << 20;

/// Writes `bytes` of pseudo-random (incompressible) data, 1 MiB at a time.
void writeNoise(const std::string& path, uint64_t bytes) {
  std::ofstream out(path, std::ios::binary);
  std::vector<uint64_t> block((1 << 20) / 8);
  uint64_t x = 0x9e3779b97f4a7c15ull;
  for (uint64_t done = 0; done < bytes; done += 1 << 20) {
    for (uint64_t& v : block) {
      x ^= x << 13;
      x ^= x >> 7;
      x ^= x << 17;
      v = x;
    }
    out.write(reinterpret_cast<const char*>(block.data()),
              std::streamsize(std::min<uint64_t>(bytes - done, 1 << 20)));
  }
}

TEST(ServerLargeFiles, UploadAndFetch200MBInConstantMemory) {
  Workspace ws;
  const std::string state = ws.path("state");
  std::string id;
  {
    ServerProc server(state);
    ASSERT_TRUE(server.start());
    const CmdResult r =
        run(server.cloudctl(30) + " --json submit " +
            ws.write("small.json", sphereShot(8, 1, "[1, 1, 1]", "front", -5, false)) + " --quiet");
    ASSERT_EQ(r.code, 0) << r.err;
    id = Json::parse(r.out).at("id");
    ASSERT_TRUE(server.stop());
  }
  // Plant a 200 MB output in the finished job (file and record, as the store writes them).
  const std::string big_out = state + "/jobs/" + id + "/out/big.bin";
  writeNoise(big_out, kFileBytes);
  const std::string big_sha = sha256File(big_out);
  {
    const std::string record_path = state + "/jobs/" + id + "/job.json";
    Json record = Json::parse(slurp(record_path));
    record["outputs"].push_back({{"name", "big.bin"}, {"size", kFileBytes}, {"sha256", big_sha}});
    std::ofstream(record_path) << record.dump(1);
  }
  // The asset: the VDB a shot names (only uploaded and planned, never parsed).
  ws.write("asset/cloud.vdb", "");
  writeNoise(ws.path("asset/cloud.vdb"), kFileBytes);
  std::string shot = sphereShot(8, 1, "[1, 1, 1]", "front", -5, false);
  shot.replace(
      shot.find(R"("volume": {"sphere")"),
      std::string(R"("volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})")
          .size(),
      R"("volume": {"vdb": {"path": "cloud.vdb"}})");
  shot.replace(shot.find(R"("vdb": false, "vdb_voxel_size": 0.1)"),
               std::string(R"("vdb": false, "vdb_voxel_size": 0.1)").size(), R"("vdb": false)");
  const std::string shot_path = ws.write("asset/shot.json", shot);

  ServerProc server(state);
  const std::string log = ws.path("server.log");
  server.logTo(log);
  ASSERT_TRUE(server.start({"--log-level=debug"}));
  const long base_kib = server.peakRssKib();
  ASSERT_GT(base_kib, 0);
  // Deadlines cut both big transfers: cloudctl exits 4, the server's fetch handler stops (and
  // the fetch leaves what arrived as a .part that the next fetch resumes; the upload stores
  // nothing).
  const CmdResult cut_down = run(server.cloudctl(60) + " --deadline 0.15 fetch " + id +
                                 " --name big.bin --out " + ws.path("got"));
  EXPECT_EQ(cut_down.code, 4) << cut_down.err;
  // What arrived is kept for a resume; a fetch cut before its first chunk (a loaded machine)
  // keeps no empty .part.
  const std::string part = ws.path("got/big.bin.part");
  EXPECT_TRUE(!fs::exists(part) || fs::file_size(part) > 0);
  const CmdResult cut_up =
      run(server.cloudctl(60) + " --deadline 0.15 submit " + shot_path + " --dry-run");
  EXPECT_EQ(cut_up.code, 4) << cut_up.err;
  // The fetch is cut mid-stream (the .part above); the upload may expire while cloudctl still
  // hashes the file, before the server sees it, so only the fetch handler's stop is asserted.
  for (int i = 0; i < 100 && slurp(log).find("FetchResult: stream stopped") == std::string::npos;
       ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_NE(slurp(log).find("FetchResult: stream stopped: the client gave up"), std::string::npos)
      << slurp(log);
  EXPECT_TRUE(fs::is_empty(state + "/assets") ||
              !fs::exists(state + "/assets/" + sha256File(ws.path("asset/cloud.vdb"))));
  const CmdResult down =
      run(server.cloudctl(60) + " fetch " + id + " --name big.bin --out " + ws.path("got"));
  ASSERT_EQ(down.code, 0) << down.err;
  EXPECT_EQ(fs::file_size(ws.path("got/big.bin")), kFileBytes);
  EXPECT_EQ(sha256File(ws.path("got/big.bin")), big_sha);  // cloudctl checks it too
  const long after_fetch_kib = server.peakRssKib();

  const CmdResult up = run(server.cloudctl(60) + " --json submit " + shot_path + " --dry-run");
  ASSERT_EQ(up.code, 0) << up.err;
  const std::string asset_sha = sha256File(ws.path("asset/cloud.vdb"));
  EXPECT_EQ(fs::file_size(state + "/assets/" + asset_sha), kFileBytes);
  const long after_upload_kib = server.peakRssKib();

  std::printf(
      "[ memory ] server VmHWM: %ld MiB at start, %ld MiB after a %llu MiB fetch, %ld MiB after "
      "a %llu MiB upload\n",
      base_kib / 1024, after_fetch_kib / 1024, (unsigned long long)(kFileBytes >> 20),
      after_upload_kib / 1024, (unsigned long long)(kFileBytes >> 20));
  // Bounded memory: the peak grows by a few MiB whatever the size, never by the file. Measured
  // (2 cores): a whole fetch adds about 1 MiB, a cut one and its resumption 6..11 MiB; an upload
  // adds 9..14 MiB for 20, 200 or 600 MiB (the server pins each stream's receive window at
  // 4 MiB; with gRPC's BDP auto-tuning it was +15, +23..63 and +67 MiB). The bound leaves room
  // for a loaded machine.
  const long limit_kib = long(kFileBytes / 1024 / 4);  // 50 MiB
  EXPECT_LT(after_fetch_kib - base_kib, limit_kib);
  EXPECT_LT(after_upload_kib - base_kib, limit_kib);
  EXPECT_TRUE(server.stop());
}

}  // namespace
}  // namespace cloudbake::testing
