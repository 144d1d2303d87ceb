// A server whose cache volume fills up (issue 15, defect 2): the job fails as RESOURCE_EXHAUSTED
// "no space left on the server's cache volume" (cloudctl exit 4) without a server path, no
// client ever sees a success that a restart would take back, and the server keeps serving.
#include <nlohmann/json.hpp>

#include "tests/server/server_fixture.h"
#include "tests/tiny_volume.h"

namespace cloudbake::testing {
namespace {

using Json = nlohmann::json;

TEST(ServerDiskFull, FullCacheVolumeFailsTheJobAsNoSpaceAndKeepsServing) {
  Workspace ws;
  TinyVolume volume(ws.path("cache"), 6);
  if (!volume.ok()) GTEST_SKIP() << volume.why();
  ServerProc server(volume.dir() + "/state");
  server.logTo(ws.path("server.log"));
  ASSERT_TRUE(server.start({"--log-level=info"}));

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
  if (HasFailure()) std::cerr << slurp(ws.path("server.log"));
}

}  // namespace
}  // namespace cloudbake::testing
