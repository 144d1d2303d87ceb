// Two cloudbake-server replicas on one shared folder (--shared-dir), as behind one address: a
// job submitted to one is seen, watched and fetched through the other, and the other's bake of
// the same shot is a cache hit (docs/deployment.md, "Replicas").
#include <gtest/gtest.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <thread>

#include "tests/server/server_fixture.h"

namespace cloudbake::testing {
namespace {

using Json = nlohmann::json;

TEST(ServerReplicas, EitherReplicaAnswersForAJobAndSharesItsBake) {
  Workspace ws;
  ServerProc a(ws.path("a")), b(ws.path("b"));
  const std::string shared = "--shared-dir=" + ws.path("shared");
  ASSERT_TRUE(a.start({shared}));
  ASSERT_TRUE(b.start({shared}));
  const std::string shot = ws.write("shot.json", bakedSphereShot("single", "[1, 1, 1]", "front"));

  CmdResult r = run(a.cloudctl(120) + " --json submit " + shot + " --out " + ws.path("out-a"));
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string id = Json::parse(r.out).at("id");

  r = run(b.cloudctl() + " --json status " + id);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(Json::parse(r.out).at("state"), "SUCCEEDED") << r.out;
  r = run(b.cloudctl(30) + " watch " + id);
  EXPECT_EQ(r.code, 0) << r.err;
  r = run(b.cloudctl(30) + " fetch " + id + " --out " + ws.path("out-b"));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(slurp(ws.path("out-b/front.exr")), slurp(ws.path("out-a/front.exr")));
  EXPECT_EQ(slurp(ws.path("out-b/bake.vdb")), slurp(ws.path("out-a/bake.vdb")));

  // The same shot submitted to the other replica: its bake comes from the shared cache.
  r = run(b.cloudctl(120) + " --json submit " + shot + " --out " + ws.path("out-b2"));
  ASSERT_EQ(r.code, 0) << r.err;
  const Json second = Json::parse(r.out);
  r = run(b.cloudctl() + " --json status " + second.at("id").get<std::string>());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(Json::parse(r.out).at("bakes_cached"), 1) << r.out;
  EXPECT_EQ(Json::parse(r.out).at("bakes_computed"), 0) << r.out;

  r = run(b.cloudctl() + " status j0123456789abcdef");
  EXPECT_EQ(r.code, 3) << r.err;
}

Json statusOf(const ServerProc& server, const std::string& id) {
  const CmdResult r = run(server.cloudctl() + " --json status " + id);
  EXPECT_EQ(r.code, 0) << r.err;
  return r.code == 0 ? Json::parse(r.out) : Json::object();
}

// Both replicas bake the same view at once; the one holding its lease is killed with SIGKILL in
// the middle. The other takes the lease over at once (its holder is dead on this host), bakes it
// and serves it, and nothing corrupt is ever read.
TEST(ServerReplicas, AReplicaKilledMidBakeLeavesTheOtherToFinishIt) {
  Workspace ws;
  ServerProc a(ws.path("a")), b(ws.path("b"));
  const std::string shared = "--shared-dir=" + ws.path("shared");
  ASSERT_TRUE(a.start({shared}));
  ASSERT_TRUE(b.start({shared}));
  const std::string shot = ws.write("long.json", sphereShot(64, 4096));
  CmdResult r = run(a.cloudctl() + " --json submit " + shot + " --detach");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string id_a = Json::parse(r.out).at("id");
  for (int i = 0; i < 300 && statusOf(a, id_a).value("stage", "") != "render"; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  r = run(b.cloudctl() + " --json submit " + shot + " --detach");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string id_b = Json::parse(r.out).at("id");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_NE(statusOf(b, id_a).value("state", ""), "SUCCEEDED") << "the bake was too quick";
  a.killHard();
  r = run(b.cloudctl(120) + " watch " + id_b);
  EXPECT_EQ(r.code, 0) << r.err;
  const Json done = statusOf(b, id_b);
  EXPECT_EQ(done.value("state", ""), "SUCCEEDED") << done.dump();
  r = run(b.cloudctl(60) + " fetch " + id_b + " --out " + ws.path("out"));
  EXPECT_EQ(r.code, 0) << r.err;
  r = run(b.cloudctl() + " --json info");
  ASSERT_EQ(r.code, 0) << r.err;
  const Json stats = Json::parse(r.out).at("stats");
  EXPECT_EQ(stats.at("cache_corrupt_dropped"), 0);
  // It waited on the killed replica's live lease rather than baking the view beside it, then
  // took the lease over.
  EXPECT_EQ(stats.at("cache_shared_across_processes"), 1) << stats.dump();
  EXPECT_EQ(stats.at("cache_leases_taken_over"), 1) << stats.dump();
  // The killed replica's job, restarted on its state folder, is FAILED (interrupted), and
  // the other replica reads that too.
  ASSERT_TRUE(a.start({shared}));
  EXPECT_EQ(statusOf(b, id_a).value("state", ""), "FAILED");
}

}  // namespace
}  // namespace cloudbake::testing
