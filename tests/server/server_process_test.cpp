// Starts cloudbake-server on a free loopback port and drives it with the real cloudctl: submit
// and fetch, cache hits, single flight, cancellation, bad inputs, queue bound, restarts.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "core/io/exr_io.h"
#include "core/io/vdb_io.h"
#include "tests/server/server_fixture.h"

namespace cloudbake::testing {
namespace {
namespace fs = std::filesystem;
using Json = nlohmann::json;

/// A shot: a sphere of cloud seen from the front, `w` x `w` pixels at `spp` samples.
std::string sphereShot(int w, int spp, const std::string& irradiance = "[1, 1, 1]",
                       const std::string& view = "front", double cam_y = -5, bool vdb = true) {
  return R"({"version": 1, "name": "sphere",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 2, "albedo": 0.9, "phase": {"type": "hg", "g": 0.5}},
    "lighting": {"sun": {"direction": [0.3, 0, 1], "irradiance": )" +
         irradiance + R"(}},
    "bake": {"method": "pathtrace", "samples": )" +
         std::to_string(spp) + R"(, "seed": 7},
    "views": [{"name": ")" +
         view + R"(", "camera": {"type": "orthographic", "position": [0, )" +
         std::to_string(cam_y) +
         R"(, 0], "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [)" +
         std::to_string(w) + ", " + std::to_string(w) + R"(]}],
    "outputs": {"exr": true, "vdb": )" +
         (vdb ? "true" : "false") + R"(, "vdb_voxel_size": 0.1}})";
}

class Workspace {
 public:
  Workspace() : dir_(tempName("cloudbake_server_test")) { fs::create_directories(dir_); }
  ~Workspace() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path p = fs::path(dir_) / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }
  std::string path(const std::string& name) const { return (fs::path(dir_) / name).string(); }

 private:
  std::string dir_;
};

Json infoStats(const ServerProc& server) {
  const CmdResult r = run(server.cloudctl() + " --json info");
  EXPECT_EQ(r.code, 0) << r.err;
  return Json::parse(r.out).at("stats");
}

Json status(const ServerProc& server, const std::string& id) {
  const CmdResult r = run(server.cloudctl() + " --json status " + id);
  EXPECT_EQ(r.code, 0) << r.err;
  return Json::parse(r.out);
}

std::string submitDetached(const ServerProc& server, const std::string& shot) {
  const CmdResult r = run(server.cloudctl() + " --json submit " + shot + " --detach");
  EXPECT_EQ(r.code, 0) << r.err;
  return Json::parse(r.out).at("id").get<std::string>();
}

// Polls until `pred(status)` or the timeout; returns the last status.
template <typename Pred>
Json waitFor(const ServerProc& server, const std::string& id, Pred pred, double timeout_s) {
  const auto end =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(int(timeout_s * 1000));
  Json s = status(server, id);
  while (!pred(s) && std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    s = status(server, id);
  }
  return s;
}

class ServerTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(server_.start({"--max-concurrent-jobs=4"})); }
  void TearDown() override { EXPECT_TRUE(server_.stop()) << "server did not exit cleanly"; }
  Workspace ws_;
  ServerProc server_{ws_.path("state")};
};

TEST_F(ServerTest, HealthAndInfo) {
  CmdResult r = run(server_.cloudctl() + " health");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("SERVING"), std::string::npos) << r.out;
  r = run(server_.cloudctl() + " info");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("pathtrace"), std::string::npos) << r.out;
  r = run(server_.cloudctl() + " --json health");
  EXPECT_EQ(r.code, 0);
  EXPECT_TRUE(Json::parse(r.out).at("serving").get<bool>());
}

TEST_F(ServerTest, SubmitWaitFetchAndOpenTheOutputs) {
  const std::string shot = ws_.write("shot/tiny.json", sphereShot(16, 4));
  const std::string out = ws_.path("out");
  const CmdResult r = run(server_.cloudctl() + " submit " + shot + " --out " + out);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find(out + "/front.exr"), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("SUCCEEDED"), std::string::npos) << r.err;  // progress on stderr
  const ExrContents exr = readExr(out + "/front.exr");
  EXPECT_EQ(exr.width, 16);
  EXPECT_EQ(exr.height, 16);
  for (const char* layer : {"", "sun", "sky", "single", "multiple"}) {
    EXPECT_TRUE(exr.layers.count(layer)) << layer;
  }
  double sum = 0;
  for (float v : exr.layers.at("").data) sum += v;
  EXPECT_GT(sum, 0);
  VdbFileReader vdb(out + "/bake.vdb");
  ASSERT_FALSE(vdb.grids().empty());
  EXPECT_EQ(vdb.grids()[0].name, "density");
  EXPECT_GT(vdb.grids()[0].active_voxels, 0u);

  // --json: machine-readable, with checksums; fetch again (resumable download) gives the same.
  const CmdResult list = run(server_.cloudctl() + " --json list");
  ASSERT_EQ(list.code, 0);
  const Json jobs = Json::parse(list.out);
  ASSERT_EQ(jobs.size(), 1u);
  const std::string id = jobs[0].at("id");
  const std::string original = slurp(out + "/bake.vdb");
  // Resume: a valid prefix in DIR/NAME.part is continued from its size.
  ws_.write("again/bake.vdb.part", original.substr(0, original.size() / 2));
  CmdResult fetch = run(server_.cloudctl() + " --json fetch " + id + " --out " + ws_.path("again"));
  ASSERT_EQ(fetch.code, 0) << fetch.err;
  EXPECT_EQ(slurp(ws_.path("again/bake.vdb")), original);
  EXPECT_FALSE(fs::exists(ws_.path("again/bake.vdb.part")));
  // A stale .part that is not a prefix fails the checksum and is removed; a retry succeeds.
  ws_.write("again/front.exr.part", "junk that is not a prefix");
  fetch = run(server_.cloudctl() + " fetch " + id + " --name front.exr --out " + ws_.path("again"));
  EXPECT_EQ(fetch.code, 1);
  EXPECT_NE(fetch.err.find("checksum mismatch"), std::string::npos) << fetch.err;
  EXPECT_FALSE(fs::exists(ws_.path("again/front.exr.part")));
  fetch = run(server_.cloudctl() + " fetch " + id + " --name front.exr --out " + ws_.path("again"));
  EXPECT_EQ(fetch.code, 0) << fetch.err;
  EXPECT_EQ(slurp(ws_.path("again/front.exr")), slurp(out + "/front.exr"));
}

TEST_F(ServerTest, SecondSunColourAndSecondViewRecomputeNoCachedPart) {
  const std::string first = ws_.write("a.json", sphereShot(64, 256));
  std::string first_id;
  auto timed = [&](const std::string& args, const std::string& out) {
    const auto t0 = std::chrono::steady_clock::now();
    const CmdResult r = run(server_.cloudctl(30) + " --json " + args + " --quiet --out " + out);
    EXPECT_EQ(r.code, 0) << r.err;
    if (first_id.empty()) first_id = Json::parse(r.out).at("id");
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  const double t_first = timed("submit " + first, ws_.path("a"));
  const Json s1 = infoStats(server_);
  EXPECT_EQ(s1.at("scatter_computations"), 1);

  const double t_colour =
      timed("submit " + ws_.write("b.json", sphereShot(64, 256, "[2, 1, 0.25]")), ws_.path("b"));
  const Json s2 = infoStats(server_);
  EXPECT_EQ(s2.at("scatter_computations"), 1) << "a new sun colour recomputed scattering";
  EXPECT_EQ(s2.at("views_from_cache"), 1);
  const Image a = readExr(ws_.path("a/front.exr")).layers.at("sun");
  const Image b = readExr(ws_.path("b/front.exr")).layers.at("sun");
  double sum = 0;
  for (size_t i = 0; i < a.data.size(); i += 3) {
    EXPECT_NEAR(b.data[i], 2 * a.data[i], 1e-5 * (1 + a.data[i]));
    EXPECT_NEAR(b.data[i + 2], 0.25 * a.data[i + 2], 1e-5 * (1 + a.data[i + 2]));
    sum += a.data[i];
  }
  EXPECT_GT(sum, 0);

  // A second view: path tracing renders it (one more computation), the volume and bake.vdb
  // come from the caches.
  const double t_view = timed(
      "submit " + ws_.write("c.json", sphereShot(64, 256, "[1, 1, 1]", "side", -6)), ws_.path("c"));
  const Json s3 = infoStats(server_);
  EXPECT_EQ(s3.at("scatter_computations"), 2);
  EXPECT_EQ(s3.at("volume_builds"), 1);

  // RenderView from the first job: a new sun colour is free, a new view costs one render.
  const double t_render_colour = timed("render " + first_id + " --sun 0.5 0.5 0.5", ws_.path("d"));
  EXPECT_EQ(infoStats(server_).at("scatter_computations"), 2);
  const Image d = readExr(ws_.path("d/front.exr")).layers.at("sun");
  EXPECT_NEAR(d.data[a.data.size() / 2], 0.5 * a.data[a.data.size() / 2], 1e-5);
  const std::string views = ws_.write("views.json", R"([{"name": "top", "camera": {
      "type": "orthographic", "position": [0, 0, 5], "look_at": [0, 0, 0], "up": [0, 1, 0],
      "width": 2.5}, "resolution": [16, 16]}])");
  timed("render " + first_id + " --views " + views, ws_.path("e"));
  EXPECT_TRUE(fs::exists(ws_.path("e/top.exr")));
  EXPECT_EQ(infoStats(server_).at("scatter_computations"), 3);
  std::printf(
      "[ timing ] first bake %.3f s; new sun colour %.3f s; new view %.3f s; RenderView new "
      "colour %.3f s (64x64, 256 spp, client wall time incl. download)\n",
      t_first, t_colour, t_view, t_render_colour);

  // Dry run reports the cached view.
  const CmdResult plan = run(server_.cloudctl() + " --json submit " + first + " --dry-run");
  ASSERT_EQ(plan.code, 0) << plan.err;
  EXPECT_TRUE(Json::parse(plan.out).at("views")[0].at("cached").get<bool>());
}

TEST_F(ServerTest, TenIdenticalConcurrentSubmitsRunOneBake) {
  const std::string shot =
      ws_.write("same.json", sphereShot(48, 256, "[1, 1, 1]", "front", -5, false));
  std::vector<std::thread> clients;
  std::vector<CmdResult> results(10);
  for (int i = 0; i < 10; ++i) {
    clients.emplace_back([&, i] {
      results[size_t(i)] = run(server_.cloudctl(30) + " --json submit " + shot + " --out " +
                               ws_.path("out" + std::to_string(i)) + " --quiet");
    });
  }
  for (auto& t : clients) t.join();
  std::string sha;
  for (const CmdResult& r : results) {
    ASSERT_EQ(r.code, 0) << r.err;
    const Json j = Json::parse(r.out);
    EXPECT_EQ(j.at("state"), "SUCCEEDED");
    if (sha.empty()) sha = j.at("files")[0].at("sha256");
    EXPECT_EQ(j.at("files")[0].at("sha256"), sha);
  }
  const Json s = infoStats(server_);
  EXPECT_EQ(s.at("scatter_computations"), 1);
  EXPECT_EQ(s.at("jobs_submitted"), 10);
}

TEST_F(ServerTest, CancelMidBakeStopsWithinASecond) {
  const std::string id = submitDetached(server_, ws_.write("long.json", sphereShot(128, 8192)));
  Json s = waitFor(
      server_, id,
      [](const Json& j) {
        return j.at("state") == "RUNNING" && j.at("stage") == "render" &&
               j.at("fraction").get<double>() > 0;
      },
      30);
  ASSERT_EQ(s.at("state"), "RUNNING");
  const auto t0 = std::chrono::steady_clock::now();
  const CmdResult c = run(server_.cloudctl() + " cancel " + id);
  EXPECT_EQ(c.code, 0) << c.err;
  s = waitFor(
      server_, id, [](const Json& j) { return j.at("state") != "RUNNING"; }, 10);
  const double stop_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(s.at("state"), "CANCELLED");
  EXPECT_LT(stop_s, 1.5);
  std::printf("[ timing ] cancel took effect after %.3f s\n", stop_s);
  EXPECT_EQ(run(server_.cloudctl() + " watch " + id).code, 6);  // kCancelled
  EXPECT_EQ(run(server_.cloudctl() + " fetch " + id).code, 6);
  EXPECT_EQ(infoStats(server_).at("jobs_running"), 0);
}

struct BadCase {
  const char* label;
  std::string shot;     // shot text ("" : the file is not created)
  int code;             // cloudctl exit code
  const char* message;  // expected in stderr
  std::vector<std::pair<std::string, std::string>> files = {};  // extra files next to the shot
};

std::string replaced(std::string s, const std::string& from, const std::string& to) {
  const size_t at = s.find(from);
  if (at == std::string::npos)
    ADD_FAILURE() << "no '" << from << "' in the base shot";
  else
    s.replace(at, from.size(), to);
  return s;
}

TEST_F(ServerTest, BadInputsAreAnsweredClearlyAndTheServerKeepsServing) {
  const std::string base = sphereShot(8, 1);
  const std::string vol =
      R"("volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})";
  auto withVolume = [&](const std::string& v) {
    return replaced(replaced(base, vol, "\"volume\": " + v),
                    R"("vdb": true, "vdb_voxel_size": 0.1)", R"("vdb": false)");
  };
  // A real VDB, then a truncated copy of it.
  std::string vdb_bytes;
  {
    const std::string good = ws_.write("good/g.json", sphereShot(8, 1));
    ASSERT_EQ(
        run(server_.cloudctl() + " submit " + good + " --quiet --out " + ws_.path("good/out")).code,
        0);
    vdb_bytes = slurp(ws_.path("good/out/bake.vdb"));
    ASSERT_GT(vdb_bytes.size(), 1000u);
  }
  const std::vector<BadCase> cases = {
      {"malformed JSON", "{\"version\": 1, \"name\": ", 2, "shot.json"},
      {"not an object", "[1, 2, 3]", 2, "must be a JSON object"},
      {"empty file", " ", 2, "shot.json"},
      {"wrong version", replaced(base, "\"version\": 1", "\"version\": 2"), 2, "/version"},
      {"unknown top-level key", replaced(base, "\"version\": 1", "\"version\": 1, \"colour\": 3"),
       2, "colour"},
      {"unknown method", replaced(base, "\"pathtrace\"", "\"magic\""), 2, "/bake/method"},
      {"method not implemented", replaced(base, "\"pathtrace\"", "\"single\""), 2,
       "not implemented"},
      {"infinite extinction", replaced(base, "\"extinction\": 2", "\"extinction\": 1e999"), 2,
       "1e999"},
      {"albedo above 1", replaced(base, "\"albedo\": 0.9", "\"albedo\": 1.5"), 2, "/medium/albedo"},
      {"unknown phase", replaced(base, "\"type\": \"hg\"", "\"type\": \"rayleighish\""), 2,
       "/medium/phase"},
      {"zero sun direction", replaced(base, "[0.3, 0, 1]", "[0, 0, 0]"), 2, "direction"},
      {"negative radius", replaced(base, "\"radius\": 1", "\"radius\": -1"), 2, "radius"},
      {"negative voxel size", replaced(base, "\"vdb_voxel_size\": 0.1", "\"vdb_voxel_size\": -0.1"),
       2, "/outputs/vdb_voxel_size"},
      {"10^12 voxels", replaced(base, "\"vdb_voxel_size\": 0.1", "\"vdb_voxel_size\": 0.0002"), 2,
       "/outputs/vdb_voxel_size"},
      {"zero-size image", replaced(base, "\"resolution\": [8, 8]", "\"resolution\": [0, 8]"), 2,
       "/resolution"},
      {"huge image", replaced(base, "\"resolution\": [8, 8]", "\"resolution\": [16384, 16384]"), 2,
       "/resolution"},
      {"image over the server limit",
       replaced(base, "\"resolution\": [8, 8]", "\"resolution\": [4096, 2048]"), 2, "limit"},
      {"zero samples", replaced(base, "\"samples\": 1", "\"samples\": 0"), 2, "/bake/samples"},
      {"samples over the server limit", replaced(base, "\"samples\": 1", "\"samples\": 500000"), 2,
       "limit"},
      {"unknown camera type", replaced(base, "\"orthographic\"", "\"fisheye\""), 2, "camera"},
      {"0 frames", withVolume(R"({"sequence": {"frames": 0, "paths": []}})"), 2,
       "/volume/sequence"},
      {"missing file", withVolume(R"({"vdb": {"path": "nope.vdb"}})"), 3, "file not found"},
      {"path escaping the shot folder", withVolume(R"({"vdb": {"path": "../outside.vdb"}})"), 2,
       "/volume/vdb"},
      {"absolute path", withVolume(R"({"vdb": {"path": "/etc/hostname"}})"), 2, "/volume/vdb"},
      {"non-VDB bytes",
       withVolume(R"({"vdb": {"path": "cloud.vdb"}})"),
       2,
       "cloud.vdb",
       {{"cloud.vdb", "this is not a VDB file, just some text\n"}}},
      {"truncated VDB",
       withVolume(R"({"vdb": {"path": "cut.vdb"}})"),
       2,
       "cut.vdb",
       {{"cut.vdb", vdb_bytes.substr(0, vdb_bytes.size() / 3)}}},
  };
  ASSERT_GE(cases.size(), 20u);
  int index = 0;
  for (const BadCase& c : cases) {
    const std::string dir = "bad" + std::to_string(index++);
    for (const auto& [name, bytes] : c.files) ws_.write(dir + "/" + name, bytes);
    ws_.write("outside.vdb", vdb_bytes);
    const std::string shot = ws_.write(dir + "/shot.json", c.shot);
    const CmdResult r =
        run(server_.cloudctl(30) + " submit " + shot + " --quiet --out " + ws_.path(dir + "/out"));
    EXPECT_EQ(r.code, c.code) << c.label << ": " << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << c.label << ": " << r.err;
    EXPECT_EQ(r.err.find("internal"), std::string::npos) << c.label << ": " << r.err;
    EXPECT_EQ(r.err.find(server_.stateDir()), std::string::npos)
        << c.label << " leaks a server path: " << r.err;
    EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << c.label << ": one line: " << r.err;
    EXPECT_EQ(run(server_.cloudctl() + " health").code, 0) << "after " << c.label;
  }
  // The escaping path is accepted when the client is asked to upload it (rewritten inside).
  const CmdResult outside = run(server_.cloudctl() + " submit " + ws_.path("bad22/shot.json") +
                                " --allow-outside --quiet --out " + ws_.path("bad22/out"));
  EXPECT_EQ(outside.code, 0) << outside.err;
  EXPECT_TRUE(fs::exists(ws_.path("bad22/out/front.exr")));
  // Bad requests beyond the shot: ids, names, commands.
  EXPECT_EQ(run(server_.cloudctl() + " status not-a-job").code, 2);
  EXPECT_EQ(run(server_.cloudctl() + " status j0123456789abcdef").code, 3);
  EXPECT_EQ(run(server_.cloudctl() + " cancel j0123456789abcdef").code, 3);
  EXPECT_EQ(run(server_.cloudctl() + " submit " + ws_.path("no-such-shot.json")).code, 3);
  EXPECT_EQ(run(server_.cloudctl() + " frobnicate").code, 2);
  EXPECT_EQ(run(server_.cloudctl() + " health").code, 0);
}

TEST(ServerQueue, FullQueueAnswersResourceExhausted) {
  Workspace ws;
  ServerProc server(ws.path("state"));
  ASSERT_TRUE(
      server.start({"--max-concurrent-jobs=1", "--queue-bound=1", "--max-upload-bytes=1000"}));
  // The upload limit: a 2000-byte asset is refused before it is stored.
  ws.write("big/blob.vdb", std::string(2000, 'x'));
  const std::string big =
      ws.write("big/shot.json",
               replaced(sphereShot(8, 1, "[1, 1, 1]", "front", -5, false),
                        R"("volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})",
                        R"("volume": {"vdb": {"path": "blob.vdb"}})"));
  const CmdResult refused = run(server.cloudctl() + " submit " + big + " --quiet");
  EXPECT_EQ(refused.code, 2) << refused.err;
  EXPECT_NE(refused.err.find("upload limit"), std::string::npos) << refused.err;
  EXPECT_TRUE(fs::is_empty(ws.path("state/assets")));
  const std::string long_shot = ws.write("long.json", sphereShot(128, 8192));
  const std::string running = submitDetached(server, long_shot);
  waitFor(
      server, running, [](const Json& j) { return j.at("state") == "RUNNING"; }, 30);
  const std::string queued = submitDetached(server, long_shot);
  const CmdResult full = run(server.cloudctl() + " submit " + long_shot + " --detach");
  EXPECT_EQ(full.code, 4) << full.err;  // kUnavailable: retry later
  EXPECT_NE(full.err.find("queue is full"), std::string::npos) << full.err;
  EXPECT_EQ(run(server.cloudctl() + " cancel " + queued).code, 0);
  EXPECT_EQ(status(server, queued).at("state"), "CANCELLED");
  EXPECT_EQ(run(server.cloudctl() + " cancel " + running).code, 0);
  EXPECT_TRUE(server.stop());
}

TEST(ServerRestart, ResultsSurviveRestartsAndCrashesServeNothingCorrupt) {
  Workspace ws;
  const std::string state = ws.path("state");
  const std::string shot = ws.write("s.json", sphereShot(16, 16));
  std::string done_id, exr_sha;
  {
    ServerProc server(state);
    ASSERT_TRUE(server.start());
    const CmdResult r = run(server.cloudctl() + " --json submit " + shot + " --quiet");
    ASSERT_EQ(r.code, 0) << r.err;
    const Json j = Json::parse(r.out);
    done_id = j.at("id");
    exr_sha = j.at("outputs")[0].at("sha256");
    ASSERT_TRUE(server.stop());
  }
  {
    // Clean restart: the finished job is listed and fetchable.
    ServerProc server(state);
    ASSERT_TRUE(server.start());
    EXPECT_EQ(status(server, done_id).at("state"), "SUCCEEDED");
    const CmdResult f =
        run(server.cloudctl() + " --json fetch " + done_id + " --out " + ws.path("f1"));
    ASSERT_EQ(f.code, 0) << f.err;
    EXPECT_EQ(Json::parse(f.out).at("files")[0].at("sha256"), exr_sha);
    // Crash mid-bake.
    const std::string id = submitDetached(server, ws.write("long.json", sphereShot(128, 8192)));
    waitFor(
        server, id, [](const Json& j) { return j.at("stage") == "render"; }, 30);
    server.killHard();
    // Corrupt the finished view's cache entry while the server is down.
    int corrupted = 0;
    for (const auto& f : fs::recursive_directory_iterator(state + "/cache/entries")) {
      if (f.path().filename() == "view.exr") {
        std::fstream io(f.path(), std::ios::binary | std::ios::in | std::ios::out);
        io.seekp(std::streamoff(fs::file_size(f.path()) / 2));
        io.put('\x5a');
        io.put('\xa5');
        ++corrupted;
      }
    }
    EXPECT_GE(corrupted, 1);
    ServerProc again(state);
    ASSERT_TRUE(again.start());
    const Json crashed = status(again, id);
    EXPECT_EQ(crashed.at("state"), "FAILED");
    EXPECT_NE(crashed.at("error").get<std::string>().find("interrupted"), std::string::npos);
    EXPECT_EQ(run(again.cloudctl() + " fetch " + id + " --out " + ws.path("f2")).code, 5);
    // The completed job's own result is intact and fetchable.
    EXPECT_EQ(run(again.cloudctl() + " fetch " + done_id + " --out " + ws.path("f3")).code, 0);
    // Resubmitting the shot does not serve the corrupt entry: it recomputes.
    const CmdResult r =
        run(again.cloudctl() + " --json submit " + shot + " --quiet --out " + ws.path("f4"));
    ASSERT_EQ(r.code, 0) << r.err;
    const Json st = infoStats(again);
    EXPECT_GE(st.at("cache_corrupt_dropped").get<int>(), 1);
    EXPECT_EQ(st.at("scatter_computations"), 1);
    EXPECT_EQ(Json::parse(r.out).at("files")[0].at("sha256"), exr_sha);  // deterministic
    EXPECT_NO_THROW(readExr(ws.path("f4/front.exr")));
    EXPECT_TRUE(again.stop());
  }
}

TEST(ServerRestart, GracefulStopInterruptsTheRunningJobAndRequeuesTheQueuedOne) {
  Workspace ws;
  const std::string state = ws.path("state");
  std::string running, queued;
  {
    ServerProc server(state);
    ASSERT_TRUE(server.start({"--max-concurrent-jobs=1"}));
    running = submitDetached(server, ws.write("long.json", sphereShot(128, 8192)));
    waitFor(
        server, running, [](const Json& j) { return j.at("state") == "RUNNING"; }, 30);
    queued = submitDetached(server, ws.write("small.json", sphereShot(8, 2)));
    EXPECT_EQ(status(server, queued).at("state"), "QUEUED");
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_TRUE(server.stop());
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5);
  }
  ServerProc server(state);
  ASSERT_TRUE(server.start());
  const Json r = status(server, running);
  EXPECT_EQ(r.at("state"), "FAILED");
  EXPECT_NE(r.at("error").get<std::string>().find("shutdown"), std::string::npos) << r.dump();
  const Json q = waitFor(
      server, queued, [](const Json& j) { return j.at("state") == "SUCCEEDED"; }, 30);
  EXPECT_EQ(q.at("state"), "SUCCEEDED");
  EXPECT_EQ(run(server.cloudctl() + " fetch " + queued + " --out " + ws.path("q")).code, 0);
  EXPECT_TRUE(server.stop());
}

// The load test of the issue, kept small enough for CI: 50 concurrent cloudctl clients, each
// submitting a distinct small shot (different seeds: no cache hits) and downloading its result.
TEST(ServerLoad, FiftyConcurrentClientsNothingFailsOrIsLost) {
  Workspace ws;
  ServerProc server(ws.path("state"));
  ASSERT_TRUE(server.start({"--max-concurrent-jobs=2", "--queue-bound=64"}));
  constexpr int kClients = 50;
  std::vector<std::string> shots;
  for (int i = 0; i < kClients; ++i) {
    std::string text = sphereShot(16, 16, "[1, 1, 1]", "front", -5, false);
    text.replace(text.find("\"seed\": 7"), 9, "\"seed\": " + std::to_string(100 + i));
    shots.push_back(ws.write("load/" + std::to_string(i) + ".json", text));
  }
  std::vector<double> latency(kClients);
  std::vector<CmdResult> results(kClients);
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::thread> clients;
  for (int i = 0; i < kClients; ++i) {
    clients.emplace_back([&, i] {
      const auto start = std::chrono::steady_clock::now();
      results[size_t(i)] = run(server.cloudctl(60) + " --json submit " + shots[size_t(i)] +
                               " --quiet --out " + ws.path("load/out" + std::to_string(i)));
      latency[size_t(i)] =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    });
  }
  for (auto& t : clients) t.join();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  int ok = 0;
  for (const CmdResult& r : results) {
    EXPECT_EQ(r.code, 0) << r.err;
    ok += r.code == 0;
  }
  const Json list = Json::parse(run(server.cloudctl() + " --json list --state SUCCEEDED").out);
  EXPECT_EQ(list.size(), size_t(kClients)) << "jobs lost";
  EXPECT_EQ(infoStats(server).at("scatter_computations"), kClients);
  std::sort(latency.begin(), latency.end());
  std::printf(
      "[ load ] %d clients: %d ok, %.2f jobs/s, latency p50 %.3f s p99 %.3f s, server peak RSS "
      "%ld MiB\n",
      kClients, ok, kClients / wall, latency[kClients / 2], latency[size_t(kClients * 0.99)],
      server.peakRssKib() / 1024);
  EXPECT_TRUE(server.stop());
}

TEST(ServerUnavailable, CloudctlReportsUnavailableExitCode) {
  const std::string addr = "127.0.0.1:" + std::to_string(freePort());
  const CmdResult r = run(std::string(CLOUDCTL_BIN) + " --server " + addr + " --timeout 1 health");
  EXPECT_EQ(r.code, 4);  // kUnavailable
  EXPECT_NE(r.err.find("unavailable"), std::string::npos) << r.err;
}

TEST(ServerState, SecondServerOnTheSameStateFolderRefusesToStart) {
  Workspace ws;
  ServerProc first(ws.path("state"));
  ASSERT_TRUE(first.start());
  ServerProc second(ws.path("state"));
  EXPECT_FALSE(second.start());
  EXPECT_TRUE(first.stop());
}

}  // namespace
}  // namespace cloudbake::testing
