// Two cloudbake-server replicas on one shared folder (--shared-dir), as behind one address: a
// job submitted to one is seen, watched and fetched through the other, and the other's bake of
// the same shot is a cache hit (docs/deployment.md, "Replicas").
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

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

}  // namespace
}  // namespace cloudbake::testing
