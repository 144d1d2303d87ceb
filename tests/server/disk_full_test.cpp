// A server whose cache volume fills up (issue 15, defect 2): the job fails as RESOURCE_EXHAUSTED
// "no space left on the server's cache volume" (cloudctl exit 4) without a server path, no
// client ever sees a success that a restart would take back, and the server keeps serving.
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "tests/server/server_fixture.h"
#include "tests/tiny_volume.h"

namespace cloudbake::testing {
namespace {

using Json = nlohmann::json;

// A server whose state lies on a tmpfs of 6 MiB (skipped, saying why, where none can be
// mounted); its log is printed when a test fails.
class ServerDiskFull : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!volume.ok()) GTEST_SKIP() << volume.why();
    server.logTo(ws.path("server.log"));
    ASSERT_TRUE(server.start({"--log-level=info"}));
  }
  void TearDown() override {
    if (HasFailure()) std::cerr << slurp(ws.path("server.log"));
  }
  Workspace ws;
  TinyVolume volume{ws.path("cache"), 6};
  ServerProc server{volume.dir() + "/state"};
};

TEST_F(ServerDiskFull, FullCacheVolumeFailsTheJobAsNoSpaceAndKeepsServing) {
  // About 8 MB of path-traced EXR (1 sample per pixel) for a 6 MiB volume.
  const std::string big = ws.write("big.json", sphereShot(1600, 1));
  CmdResult r = run(server.cloudctl(60) + " submit " + big + " --out " + ws.path("out-big"));
  EXPECT_EQ(r.code, 4) << r.err;
  EXPECT_NE(r.err.find("no space left on the server's cache volume"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find(volume.dir()), std::string::npos) << "a server path leaked: " << r.err;
  EXPECT_EQ(r.err.find(".tmp"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(ws.path("out-big/front.exr")));

  r = run(server.cloudctl() + " --json list");
  ASSERT_EQ(r.code, 0) << r.err;
  const Json jobs = Json::parse(r.out);
  ASSERT_EQ(jobs.size(), 1u) << r.out;
  const std::string id = jobs[0].at("id");
  EXPECT_EQ(jobs[0].at("state"), "FAILED");
  EXPECT_TRUE(jobs[0].at("error_no_space").get<bool>());

  // The failed job's partial outputs are gone, so a small job fits and succeeds.
  const std::string small = ws.write("small.json", sphereShot(16, 4));
  r = run(server.cloudctl(60) + " submit " + small + " --out " + ws.path("out-small"));
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_GT(std::filesystem::file_size(ws.path("out-small/front.exr")), 0u);

  // After a restart the job reads as it did before: failed, for the same reason.
  ASSERT_TRUE(server.stop());
  ASSERT_TRUE(server.start());
  r = run(server.cloudctl() + " --json status " + id);
  ASSERT_EQ(r.code, 0) << r.err;
  const Json job = Json::parse(r.out);
  EXPECT_EQ(job.at("state"), "FAILED");
  EXPECT_TRUE(job.at("error_no_space").get<bool>());
}

// An outside probe: with the volume full, a cancel of a queued job was answered CANCELLED but
// not saved, and a restart ran the job; a submit was accepted without its record, and a
// restart lost it. Both are now refused as no space, and nothing changes.
TEST_F(ServerDiskFull, AFullVolumeRefusesSubmitsAndCancelsItCannotRecord) {
  const std::string slow = ws.write("slow.json", sphereShot(256, 65536, "[1, 1, 1]", "a"));
  const std::string queued = ws.write("queued.json", sphereShot(8, 4, "[1, 1, 1]", "b"));
  CmdResult r = run(server.cloudctl() + " submit --detach " + slow);
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string running_id = r.out.substr(0, r.out.find_first_of(" \n"));
  r = run(server.cloudctl() + " submit --detach " + queued);
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string queued_id = r.out.substr(0, r.out.find_first_of(" \n"));
  {
    // Fill what is left of the volume.
    std::ofstream filler(volume.dir() + "/filler", std::ios::binary);
    const std::string block(1 << 16, '\0');
    while (filler.write(block.data(), std::streamsize(block.size()))) {
    }
  }
  r = run(server.cloudctl() + " cancel " + queued_id);
  EXPECT_EQ(r.code, 4) << r.out << r.err;
  EXPECT_NE(r.err.find("no space left"), std::string::npos) << r.err;
  r = run(server.cloudctl() + " --json status " + queued_id);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out).at("state"), "QUEUED") << r.out;
  r = run(server.cloudctl() + " --retry-seconds 0 submit --detach " + queued);
  EXPECT_EQ(r.code, 4) << r.out << r.err;
  r = run(server.cloudctl() + " --json list");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out).size(), 2u) << r.out;
  // With space again, the cancel is recorded and holds across a restart.
  std::filesystem::remove(volume.dir() + "/filler");
  r = run(server.cloudctl() + " cancel " + queued_id);
  EXPECT_EQ(r.code, 0) << r.err;
  r = run(server.cloudctl() + " cancel " + running_id);
  EXPECT_EQ(r.code, 0) << r.err;
  ASSERT_TRUE(server.stop());
  ASSERT_TRUE(server.start());
  r = run(server.cloudctl() + " --json status " + queued_id);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out).at("state"), "CANCELLED") << r.out;
}

}  // namespace
}  // namespace cloudbake::testing
