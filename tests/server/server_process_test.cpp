// Starts cloudbake-server on a free loopback port and drives it with the real cloudctl: submit
// and fetch, cache hits, single flight, cancellation, bad inputs, queue bound, restarts.
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
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

// ---- raw gRPC (no generated stubs for the standard services) ------------------------------

/// One decoded protobuf field: number, wire type, and the varint value or the bytes.
struct PbField {
  uint32_t number = 0;
  int wire = 0;
  uint64_t varint = 0;
  std::string bytes;
};

bool pbVarint(const std::string& b, size_t* at, uint64_t* v) {
  *v = 0;
  for (int shift = 0; shift < 70 && *at < b.size(); shift += 7) {
    const auto byte = static_cast<unsigned char>(b[(*at)++]);
    *v |= uint64_t(byte & 0x7f) << shift;
    if (!(byte & 0x80)) return true;
  }
  return false;
}

/// The top-level fields of an encoded message; fails the test on malformed input.
std::vector<PbField> pbFields(const std::string& b) {
  std::vector<PbField> out;
  size_t at = 0;
  while (at < b.size()) {
    uint64_t tag = 0;
    PbField f;
    if (!pbVarint(b, &at, &tag)) break;
    f.number = uint32_t(tag >> 3);
    f.wire = int(tag & 7);
    if (f.wire == 0) {
      if (!pbVarint(b, &at, &f.varint)) break;
    } else if (f.wire == 2) {
      uint64_t n = 0;
      if (!pbVarint(b, &at, &n) || n > b.size() - at) break;
      f.bytes = b.substr(at, size_t(n));
      at += size_t(n);
    } else if (f.wire == 1 || f.wire == 5) {
      at += f.wire == 1 ? 8 : 4;
    } else {
      break;
    }
    out.push_back(f);
  }
  EXPECT_EQ(at, b.size()) << "malformed protobuf message";
  return out;
}

grpc::ByteBuffer toBuffer(const std::string& bytes) {
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

std::string fromBuffer(const grpc::ByteBuffer& buffer) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(buffer.Dump(&slices).ok());
  std::string out;
  for (const grpc::Slice& s : slices)
    out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return out;
}

/// Waits for the next completion of a one-at-a-time async call; returns its `ok`.
bool nextOk(grpc::CompletionQueue* cq) {
  void* tag = nullptr;
  bool ok = false;
  return cq->Next(&tag, &ok) && ok;
}

/// ServerReflectionInfo list_services over a raw bidi stream: the service names it lists.
std::vector<std::string> reflectionServices(const std::string& address, grpc::Status* status) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  auto call =
      stub.PrepareCall(&ctx, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  std::vector<std::string> names;
  void* tag = reinterpret_cast<void*>(1);
  call->StartCall(tag);
  if (nextOk(&cq)) {
    // ServerReflectionRequest{list_services: ""}: field 7, wire type 2, length 0.
    call->Write(toBuffer(std::string("\x3a\x00", 2)), tag);
    if (nextOk(&cq)) {
      call->WritesDone(tag);
      nextOk(&cq);
      grpc::ByteBuffer reply;
      call->Read(&reply, tag);
      if (nextOk(&cq)) {
        // ServerReflectionResponse.list_services_response (6) -> ListServiceResponse.service (1)
        // -> ServiceResponse.name (1).
        for (const PbField& f : pbFields(fromBuffer(reply))) {
          if (f.number != 6 || f.wire != 2) continue;
          for (const PbField& svc : pbFields(f.bytes)) {
            if (svc.number != 1 || svc.wire != 2) continue;
            for (const PbField& name : pbFields(svc.bytes)) {
              if (name.number == 1 && name.wire == 2) names.push_back(name.bytes);
            }
          }
        }
      }
    }
  }
  call->Finish(status, tag);
  nextOk(&cq);
  cq.Shutdown();
  bool ok = false;
  while (cq.Next(&tag, &ok)) {
  }
  return names;
}

/// grpc.health.v1.Health/Check for `service` over a raw unary call; returns the status field.
uint64_t healthStatus(const std::string& address, const std::string& service,
                      grpc::Status* status) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  // HealthCheckRequest{service}: field 1, wire type 2 (empty service: zero bytes).
  std::string request;
  if (!service.empty()) {
    request = std::string("\x0a", 1) + char(service.size()) + service;
  }
  auto call = stub.PrepareUnaryCall(&ctx, "/grpc.health.v1.Health/Check", toBuffer(request), &cq);
  call->StartCall();
  grpc::ByteBuffer reply;
  call->Finish(&reply, status, reinterpret_cast<void*>(1));
  nextOk(&cq);
  cq.Shutdown();
  void* tag = nullptr;
  bool ok = false;
  while (cq.Next(&tag, &ok)) {
  }
  if (!status->ok()) return 0;
  uint64_t serving = 0;
  for (const PbField& f : pbFields(fromBuffer(reply))) {
    if (f.number == 1 && f.wire == 0) serving = f.varint;
  }
  return serving;
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
  const Json health = Json::parse(r.out);
  EXPECT_TRUE(health.at("serving").get<bool>());
  EXPECT_EQ(health.at("status"), "SERVING");
  EXPECT_FALSE(health.contains("version")) << "health must not be GetServerInfo";
}

// The standard services a probe or grpcurl uses, called as they would (no cloudbake stubs).
TEST_F(ServerTest, StandardHealthServiceAndReflection) {
  grpc::Status st;
  EXPECT_EQ(healthStatus(server_.address(), "", &st), 1u) << "SERVING";
  EXPECT_TRUE(st.ok()) << st.error_message();
  // Per-service status is not registered: the standard answer is NOT_FOUND.
  healthStatus(server_.address(), "no.such.Service", &st);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND) << st.error_message();

  const std::vector<std::string> services = reflectionServices(server_.address(), &st);
  EXPECT_TRUE(st.ok()) << st.error_message();
  auto has = [&](const std::string& name) {
    return std::find(services.begin(), services.end(), name) != services.end();
  };
  EXPECT_TRUE(has("cloudbake.v1.BakeService")) << services.size() << " services";
  EXPECT_TRUE(has("grpc.health.v1.Health"));
}

// A streaming call whose client deadline passes ends with DEADLINE_EXCEEDED (cloudctl exit 4)
// at once, the server's handler stops streaming (its debug log says so), and the job goes on.
TEST_F(ServerTest, ClientDeadlinesEndStreamsPromptly) {
  ServerProc logged(ws_.path("logged-state"));
  const std::string log = ws_.path("server.log");
  logged.logTo(log);
  ASSERT_TRUE(logged.start({"--log-level=debug"}));
  const std::string watched =
      submitDetached(logged, ws_.write("long0.json", sphereShot(128, 8192)));
  waitFor(
      logged, watched, [](const Json& j) { return j.at("state") == "RUNNING"; }, 30);
  const auto t_watch = std::chrono::steady_clock::now();
  const CmdResult w = run(logged.cloudctl() + " --deadline 0.3 watch " + watched);
  EXPECT_EQ(w.code, 4) << w.err;
  const std::string stopped = "WatchJob: stream stopped: the client gave up";
  while (slurp(log).find(stopped) == std::string::npos &&
         std::chrono::steady_clock::now() - t_watch < std::chrono::seconds(3)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const double handler_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_watch).count();
  EXPECT_NE(slurp(log).find(stopped), std::string::npos) << slurp(log);
  EXPECT_LT(handler_s, 1.5) << "the server kept streaming after the client's deadline";
  std::printf("[ timing ] WatchJob with a 0.3 s deadline: handler stopped %.3f s after the call\n",
              handler_s);
  EXPECT_EQ(run(logged.cloudctl() + " cancel " + watched).code, 0);
  EXPECT_TRUE(logged.stop());

  const std::string id = submitDetached(server_, ws_.write("long.json", sphereShot(128, 8192)));
  waitFor(
      server_, id, [](const Json& j) { return j.at("state") == "RUNNING"; }, 30);
  const auto t0 = std::chrono::steady_clock::now();
  const CmdResult r = run(server_.cloudctl() + " --deadline 0.3 watch " + id);
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.code, 4) << r.err;  // kUnavailable: deadline exceeded
  EXPECT_NE(r.err.find("deadline exceeded"), std::string::npos) << r.err;
  EXPECT_LT(took, 2.0);
  // submit --wait with a deadline: the same, and the job stays (the deadline bounds the call,
  // not the job).
  const std::string shot = ws_.write("long2.json", sphereShot(128, 8192, "[1, 1, 1]", "front", -6));
  const CmdResult s =
      run(server_.cloudctl() + " --json --deadline 0.5 submit " + shot + " --quiet");
  EXPECT_EQ(s.code, 4) << s.err;
  EXPECT_EQ(status(server_, id).at("state"), "RUNNING");
  // The server is free of the abandoned streams: it answers and cancels normally.
  EXPECT_EQ(run(server_.cloudctl() + " health").code, 0);
  EXPECT_EQ(run(server_.cloudctl() + " cancel " + id).code, 0);
  for (const Json& j : Json::parse(run(server_.cloudctl() + " --json list").out)) {
    run(server_.cloudctl() + " cancel " + j.at("id").get<std::string>());
  }
  EXPECT_EQ(run(server_.cloudctl() + " watch " + id).code, 6);
  // A cancelled job has no bake to render views from: refused (exit 5), not run again whole.
  const CmdResult render = run(server_.cloudctl() + " render " + id + " --quiet");
  EXPECT_EQ(render.code, 5) << render.err;
  EXPECT_NE(render.err.find("is CANCELLED; views are rendered from SUCCEEDED jobs only"),
            std::string::npos)
      << render.err;
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
  // A stale .part that is not a prefix fails the checksum of the resume, and the whole file is
  // fetched again in the same call (it took a second run).
  fs::remove(ws_.path("again/front.exr"));
  ws_.write("again/front.exr.part", "junk that is not a prefix");
  fetch = run(server_.cloudctl() + " fetch " + id + " --name front.exr --out " + ws_.path("again"));
  EXPECT_EQ(fetch.code, 0) << fetch.err;
  EXPECT_EQ(slurp(ws_.path("again/front.exr")), slurp(out + "/front.exr"));
  EXPECT_FALSE(fs::exists(ws_.path("again/front.exr.part")));
  // A folder where the output goes is refused before the download, which left the whole file
  // as a .part after a failed rename (exit 1).
  fs::create_directories(ws_.path("folder/front.exr"));
  fetch =
      run(server_.cloudctl() + " fetch " + id + " --name front.exr --out " + ws_.path("folder"));
  EXPECT_EQ(fetch.code, 2) << fetch.err;
  EXPECT_NE(fetch.err.find("front.exr is a folder"), std::string::npos) << fetch.err;
  EXPECT_FALSE(fs::exists(ws_.path("folder/front.exr.part")));
  // An identical file already there is kept, not downloaded again (its time stays put).
  const fs::path kept = ws_.path("again/bake.vdb");
  const auto old_time = fs::file_time_type::clock::now() - std::chrono::hours(24);
  fs::last_write_time(kept, old_time);
  fetch = run(server_.cloudctl() + " fetch " + id + " --out " + ws_.path("again"));
  EXPECT_EQ(fetch.code, 0) << fetch.err;
  EXPECT_EQ(fs::last_write_time(kept), old_time);
  // --png: a preview beside each EXR, named in the output and the JSON.
  fetch = run(server_.cloudctl() + " --json fetch " + id + " --png --out " + ws_.path("png"));
  ASSERT_EQ(fetch.code, 0) << fetch.err;
  EXPECT_NE(fetch.out.find("\"preview\":\"" + ws_.path("png/front.png")), std::string::npos)
      << fetch.out;
  const std::string png = slurp(ws_.path("png/front.png"));
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
  EXPECT_FALSE(fs::exists(ws_.path("png/bake.png")));  // VDBs get none

  // --json submit: the result on stdout, progress on stderr as JSON lines, never going back.
  const CmdResult js =
      run(server_.cloudctl() + " --json submit " + shot + " --out " + ws_.path("json"));
  ASSERT_EQ(js.code, 0) << js.err;
  EXPECT_EQ(Json::parse(js.out).at("state"), "SUCCEEDED") << js.out;
  std::istringstream lines(js.err);
  std::string line, last_state;
  double last = -1;
  int events = 0;
  while (std::getline(lines, line)) {
    if (line.empty() || line[0] != '{') continue;
    const Json e = Json::parse(line);
    EXPECT_GE(e.at("fraction").get<double>(), last) << js.err;
    last = e.at("fraction");
    last_state = e.at("state");
    ++events;
  }
  EXPECT_GE(events, 2) << js.err;
  EXPECT_EQ(last_state, "SUCCEEDED") << js.err;
}

// Issue 5's cache contract for the bake methods: once a shot's light is baked for its sun
// direction, a second view, a new sun colour and a RenderView of a new view compute no
// scattering (the server's counter stays put); only the view's ray march runs.
TEST_F(ServerTest, BakedLightServesNewViewsAndSunColoursWithoutScattering) {
  for (const std::string method : {"single", "pointcloud"}) {
    SCOPED_TRACE(method);
    const uint64_t before = infoStats(server_).at("scatter_computations");
    std::string first_id;
    auto timed = [&](const std::string& args, const std::string& out) {
      const auto t0 = std::chrono::steady_clock::now();
      const CmdResult r = run(server_.cloudctl(60) + " --json " + args + " --quiet --out " + out);
      EXPECT_EQ(r.code, 0) << r.err;
      if (first_id.empty()) first_id = Json::parse(r.out).at("id");
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    };
    const double t_first = timed(
        "submit " + ws_.write(method + "a.json", bakedSphereShot(method, "[1, 1, 1]", "front")),
        ws_.path(method + "a"));
    const Json s1 = infoStats(server_);
    EXPECT_EQ(s1.at("scatter_computations"), before + 1);

    const double t_view = timed(
        "submit " + ws_.write(method + "b.json", bakedSphereShot(method, "[1, 1, 1]", "side")),
        ws_.path(method + "b"));
    const double t_colour = timed(
        "submit " + ws_.write(method + "c.json", bakedSphereShot(method, "[2, 1, 0.5]", "front")),
        ws_.path(method + "c"));
    const Json s2 = infoStats(server_);
    EXPECT_EQ(s2.at("scatter_computations"), before + 1)
        << "a second view or a new sun colour recomputed scattering";
    EXPECT_GE(s2.at("bakes_from_cache").get<uint64_t>(),
              s1.at("bakes_from_cache").get<uint64_t>() + 2);
    // The new colour is the same bake lit differently: exactly the scaled image.
    const Image a = readExr(ws_.path(method + "a/front.exr")).layers.at("");
    const Image c = readExr(ws_.path(method + "c/front.exr")).layers.at("");
    double sum = 0;
    for (size_t i = 0; i < a.data.size(); i += 4) {
      EXPECT_NEAR(c.data[i], 2 * a.data[i], 1e-5 * (1 + a.data[i]));
      EXPECT_NEAR(c.data[i + 2], 0.5 * a.data[i + 2], 1e-5 * (1 + a.data[i + 2]));
      sum += a.data[i];
    }
    EXPECT_GT(sum, 0);
    EXPECT_TRUE(fs::exists(ws_.path(method + "b/side.exr")));

    const std::string views = ws_.write(method + "views.json", R"([{"name": "top", "camera": {
        "type": "orthographic", "position": [0, 0, 5], "look_at": [0, 0, 0], "up": [0, 1, 0],
        "width": 2.5}, "resolution": [32, 32]}])");
    const double t_render =
        timed("render " + first_id + " --views " + views, ws_.path(method + "d"));
    EXPECT_TRUE(fs::exists(ws_.path(method + "d/top.exr")));
    EXPECT_EQ(infoStats(server_).at("scatter_computations"), before + 1);
    std::printf(
        "[ timing ] %s: first bake %.3f s; second view %.3f s; new sun colour %.3f s; "
        "RenderView new view %.3f s (client wall time incl. upload and download)\n",
        method.c_str(), t_first, t_view, t_colour, t_render);
  }
}

TEST_F(ServerTest, EndlessAnimationStreamsFramesAndReusesThePrecompute) {
  auto shot = [](const std::string& irradiance, int frames) {
    return R"({"version": 1, "name": "endless",
      "volume": {"sequence": {"procedural": {"type": "perlin_cloud", "size": [2, 2, 1],
                 "resolution": 20, "seed": 5}, "frames": 5, "time_step": 0.05}},
      "medium": {"extinction": 6, "albedo": 0.95, "phase": {"type": "hg", "g": 0.6}},
      "lighting": {"sun": {"direction": [0.3, 0.2, 1], "irradiance": )" +
           irradiance + R"(}, "sky": {"radiance": [0.1, 0.2, 0.3]}},
      "bake": {"method": "precomputed", "light_resolution": 16, "sample_points": 256,
               "transfer_resolution": 8, "frames": )" +
           std::to_string(frames) + R"(},
      "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 1],
                 "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 3}, "resolution": [16, 16]}],
      "outputs": {"exr": true, "vdb": true}})";
  };
  const uint64_t before = infoStats(server_).at("scatter_computations");
  CmdResult r =
      run(server_.cloudctl(60) + " submit " + ws_.write("anim_a.json", shot("[1, 1, 1]", 3)) +
          " --quiet --out " + ws_.path("anim_a"));
  ASSERT_EQ(r.code, 0) << r.err;
  for (int f = 0; f < 3; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "anim_a/v.%04d.exr", f);
    const ExrContents c = readExr(ws_.path(name));
    EXPECT_EQ(c.attributes.at("cloudbake:method"), "precomputed");
    std::snprintf(name, sizeof name, "anim_a/bake.%04d.vdb", f);
    EXPECT_TRUE(fs::exists(ws_.path(name))) << name;
  }
  EXPECT_TRUE(fs::exists(ws_.path("anim_a/animation.json")));
  EXPECT_EQ(infoStats(server_).at("scatter_computations"), before + 1);
  // A new sun colour and more frames: the precompute comes from the cache.
  r = run(server_.cloudctl(60) + " submit " + ws_.write("anim_b.json", shot("[2, 1, 1]", 4)) +
          " --quiet --out " + ws_.path("anim_b"));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(ws_.path("anim_b/v.0003.exr")));
  EXPECT_EQ(infoStats(server_).at("scatter_computations"), before + 1)
      << "the precompute was computed again";
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
  // A running job has no outputs yet: exit 5 like a job that did not succeed (it was 1, an
  // internal error, by an outside probe).
  const CmdResult early = run(server_.cloudctl() + " fetch " + id + " --out " + ws_.path("early"));
  EXPECT_EQ(early.code, 5) << early.err;
  EXPECT_NE(early.err.find("is RUNNING (no outputs yet"), std::string::npos) << early.err;
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

/// Submits each case with cloudctl from its own folder `<prefix><i>/` and checks the exit code
/// and the one-line message; the server must keep serving after each.
void expectBadCases(const ServerProc& server, const Workspace& ws,
                    const std::vector<BadCase>& cases, const std::string& prefix) {
  int index = 0;
  for (const BadCase& c : cases) {
    const std::string dir = prefix + std::to_string(index++);
    for (const auto& [name, bytes] : c.files) ws.write(dir + "/" + name, bytes);
    const std::string shot = ws.write(dir + "/shot.json", c.shot);
    const CmdResult r =
        run(server.cloudctl(30) + " submit " + shot + " --quiet --out " + ws.path(dir + "/out"));
    EXPECT_EQ(r.code, c.code) << c.label << ": " << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << c.label << ": " << r.err;
    EXPECT_EQ(r.err.find("internal"), std::string::npos) << c.label << ": " << r.err;
    // The user's file is named, whether the server refused the shot at submit or its job
    // failed on an asset (an outside probe: the latter said the server's "shot.json").
    if (c.code == 2) {
      EXPECT_NE(r.err.find(shot + ": "), std::string::npos) << c.label << ": " << r.err;
    }
    EXPECT_EQ(r.err.find(server.stateDir()), std::string::npos)
        << c.label << " leaks a server path: " << r.err;
    EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << c.label << ": one line: " << r.err;
    EXPECT_EQ(run(server.cloudctl() + " health").code, 0) << "after " << c.label;
  }
}

// A symbolic link inside the shot's folder to a file outside it is an outside file: cloudctl
// refuses to send it unless --allow-outside (it uploaded the link's target, e.g. /etc/passwd).
TEST_F(ServerTest, SymlinkOutOfTheShotFolderNeedsAllowOutside) {
  const std::string shot = ws_.write("linked/shot.json", sphereShot(8, 1));
  const std::string good = ws_.write("good/g.json", sphereShot(8, 1));
  ASSERT_EQ(
      run(server_.cloudctl() + " submit " + good + " --quiet --out " + ws_.path("good/out")).code,
      0);
  fs::copy_file(ws_.path("good/out/bake.vdb"), ws_.path("secret.vdb"));
  fs::create_symlink(ws_.path("secret.vdb"), ws_.path("linked/cloud.vdb"));
  const std::string text =
      replaced(replaced(slurp(shot),
                        R"("volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})",
                        R"("volume": {"vdb": {"path": "cloud.vdb"}})"),
               R"("vdb": true, "vdb_voxel_size": 0.1)", R"("vdb": false)");
  ws_.write("linked/shot.json", text);
  const CmdResult refused = run(server_.cloudctl() + " submit " + shot + " --quiet");
  EXPECT_EQ(refused.code, 2) << refused.err;
  EXPECT_NE(refused.err.find("leads outside the shot's folder"), std::string::npos) << refused.err;
  const CmdResult allowed =
      run(server_.cloudctl() + " submit " + shot + " --allow-outside --quiet");
  EXPECT_EQ(allowed.code, 0) << allowed.err;
}

TEST_F(ServerTest, BadInputsAreAnsweredClearlyAndTheServerKeepsServing) {
  const std::string base = sphereShot(8, 1);
  const std::string vol =
      R"("volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})";
  auto manyFrames = [](int n) {
    std::string paths;
    for (int i = 0; i < n; ++i) paths += (i ? ", \"f" : "\"f") + std::to_string(i) + ".vdb\"";
    return R"({"sequence": {"frames": )" + std::to_string(n) + R"(, "paths": [)" + paths + "]}}";
  };
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
      {"tolerance no method meets",
       replaced(replaced(base, "\"samples\": 1, ", ""), "\"pathtrace\"",
                "\"auto\", \"tolerance\": 1e-9"),
       2, "/bake/tolerance: no method is predicted to meet"},
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
      {"missing file", withVolume(R"({"vdb": {"path": "nope.vdb"}})"), 3,
       "/volume/vdb/path: 'nope.vdb'"},
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
      // A fuzzing find that aborts a process reading it with OpenVDB 10 (tests/data/fuzz): the
      // server's child reader dies instead of the server.
      {"VDB that crashes OpenVDB",
       withVolume(R"({"vdb": {"path": "crash.vdb"}})"),
       2,
       "/volume/vdb: crash.vdb: not a readable OpenVDB file",
       {{"crash.vdb",
         slurp(std::string(CLOUDBAKE_SOURCE_DIR) + "/tests/data/fuzz/vdb_blosc_abort.vdb")}}},
      // Counted before any is hashed or looked for: these 4097 do not exist.
      {"more files than a job may name", withVolume(manyFrames(4097)), 2,
       "names 4097 files (/volume/sequence/paths/4096 the last), more than the 4096"},
  };
  ASSERT_GE(cases.size(), 20u);
  ws_.write("outside.vdb", vdb_bytes);
  expectBadCases(server_, ws_, cases, "bad");
  // A job that failed on its input says so in --json too, as its exit code 2 does (the field
  // was left out, while error_no_space was there).
  const CmdResult listed = run(server_.cloudctl() + " --json list");
  ASSERT_EQ(listed.code, 0) << listed.err;
  int input_failures = 0;
  for (const Json& job : Json::parse(listed.out)) {
    ASSERT_TRUE(job.contains("error_is_input")) << job.dump();
    input_failures += job.at("state") == "FAILED" && job.at("error_is_input").get<bool>();
  }
  EXPECT_GE(input_failures, 1) << listed.out;
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
  // Every --samples out of range, -1 too (once the client's own "not given", so ignored).
  for (const char* samples : {"-1", "0", "1000001"}) {
    const CmdResult bad = run(server_.cloudctl() + " submit " + ws_.path("good/g.json") +
                              " --dry-run --samples=" + samples);
    EXPECT_EQ(bad.code, 2) << samples << ": " << bad.err;
    EXPECT_NE(bad.err.find("samples: must be in [1, 1000000], got " + std::string(samples)),
              std::string::npos)
        << bad.err;
  }
  // RenderView with views nested 100,000 deep: a clear error naming views_json (it was a
  // SIGSEGV in the handler thread, and UNAVAILABLE for everyone after it); likewise the irradiance.
  const CmdResult job = run(server_.cloudctl() + " --json submit " + ws_.path("good/g.json") +
                            " --quiet --out " + ws_.path("good/out2"));
  ASSERT_EQ(job.code, 0) << job.err;
  const std::string id = Json::parse(job.out).at("id");
  const std::string deep =
      ws_.write("deep.json", std::string(100000, '[') + std::string(100000, ']'));
  const CmdResult r = run(server_.cloudctl() + " render " + id + " --views " + deep +
                          " --quiet --out " + ws_.path("deep"));
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("views_json: nested deeper than"), std::string::npos) << r.err;
  // An empty views file is refused, not read as "the shot's own views" (an outside probe).
  const CmdResult empty = run(server_.cloudctl() + " render " + id + " --views " +
                              ws_.write("empty.json", "") + " --quiet --out " + ws_.path("e"));
  EXPECT_EQ(empty.code, 2) << empty.err;
  EXPECT_NE(empty.err.find("empty.json: the file is empty"), std::string::npos) << empty.err;
  // A shot that is not UTF-8 is bad input naming the byte (protobuf refused to send it, exit 1
  // with an empty message).
  std::string latin = sphereShot(8, 1);
  latin.replace(latin.find("\"name\": \"") + 9, 1, "\xe9");
  const CmdResult bytes = run(server_.cloudctl() + " submit " + ws_.write("latin.json", latin));
  EXPECT_EQ(bytes.code, 2) << bytes.err;
  EXPECT_NE(bytes.err.find("latin.json: invalid JSON: the byte at offset"), std::string::npos)
      << bytes.err;
  EXPECT_EQ(run(server_.cloudctl() + " health").code, 0);
}

// --max-voxels and --max-frames: each volume kind over the limit is refused naming the field
// (at submit when the shot tells, when the job runs when only the file does); under it runs.
TEST_F(ServerTest, VoxelAndFrameLimitsNameTheField) {
  // A VDB of about 4000 active voxels, baked by the unlimited server.
  ASSERT_EQ(run(server_.cloudctl() + " submit " + ws_.write("vdb/g.json", sphereShot(8, 1)) +
                " --quiet --out " + ws_.path("vdb/out"))
                .code,
            0);
  const std::string vdb_bytes = slurp(ws_.path("vdb/out/bake.vdb"));
  ServerProc limited(ws_.path("limited-state"));
  ASSERT_TRUE(limited.start({"--max-voxels=2000", "--max-frames=2", "--max-points=1000"}));
  {
    // The limits a client can read before submitting.
    const CmdResult info = run(limited.cloudctl() + " --json info");
    ASSERT_EQ(info.code, 0) << info.err;
    const Json limits = Json::parse(info.out).at("limits");
    EXPECT_EQ(limits.at("max_voxels"), 2000);
    EXPECT_EQ(limits.at("max_frames"), 2);
    EXPECT_EQ(limits.at("max_points"), 1000);
  }
  const std::string base = sphereShot(8, 1, "[1, 1, 1]", "front", -5, false);
  const std::string sphere =
      R"("volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})";
  auto withVolume = [&](const std::string& v) {
    return replaced(replaced(base, sphere, "\"volume\": " + v),
                    R"("vdb": false, "vdb_voxel_size": 0.1)", R"("vdb": false)");
  };
  const std::string tetra =
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  const std::vector<BadCase> cases = {
      {"pointcloud points over the limit",
       replaced(replaced(base, R"("method": "pathtrace")",
                         R"("method": "pointcloud", "points": 5000, "light_resolution": 8)"),
                R"("vdb": false, "vdb_voxel_size": 0.1)", R"("vdb": false)"),
       2, "/bake/points: 5000 points exceed this server's limit of 1000 (--max-points)"},
      {"bake lattice over the voxel limit",
       replaced(replaced(base, R"("method": "pathtrace")",
                         R"("method": "single", "light_resolution": 64)"),
                R"("vdb": false, "vdb_voxel_size": 0.1)", R"("vdb": false)"),
       2, "/bake/light_resolution: a bake lattice of up to (64 + 2)^3 gives 287496 voxels"},
      {"VDB active voxels over the limit",
       withVolume(R"({"vdb": {"path": "big.vdb"}})"),
       2,
       "/volume/vdb/path: big.vdb has ",
       {{"big.vdb", vdb_bytes}}},
      {"mesh resolution^3 over the limit",
       withVolume(R"({"mesh": {"path": "t.obj", "resolution": 13}})"),
       2,
       "/volume/mesh/resolution: resolution 13 (cubed) gives 2197 voxels, over the limit of "
       "2000 (--max-voxels)",
       {{"t.obj", tetra}}},
      {"mesh voxel size over the limit (known once the mesh is read)",
       withVolume(R"({"mesh": {"path": "t.obj", "voxel_size": 0.05}})"),
       2,
       "/volume/mesh/voxel_size",
       {{"t.obj", tetra}}},
      {"procedural grid over the limit",
       withVolume(R"({"procedural": {"type": "perlin_cloud", "resolution": 16}})"), 2,
       "/volume/procedural/resolution: resolution 16 gives 2048 voxels"},
      {"bake.vdb grid of a sphere over the limit",
       replaced(sphereShot(8, 1), "\"vdb_voxel_size\": 0.1", "\"vdb_voxel_size\": 0.1"), 2,
       "/outputs/vdb_voxel_size: voxel size 0.1 over the volume's bounds gives 8000 voxels"},
      {"sequence over the frame limit",
       withVolume(
           R"({"sequence": {"frames": 3, "procedural": {"type": "perlin_cloud", "resolution": 12}}})"),
       2, "/volume/sequence/frames: 3 frames exceed this server's limit of 2 (--max-frames)"},
      {"procedural sequence grid over the voxel limit",
       withVolume(
           R"({"sequence": {"frames": 2, "procedural": {"type": "perlin_cloud", "resolution": 20}}})"),
       2, "/volume/sequence/procedural/resolution"},
  };
  expectBadCases(limited, ws_, cases, "limit");
  // Under the limits the same kinds run: a 512-voxel bake.vdb, an 864-voxel procedural cloud.
  const std::string small_vdb =
      ws_.write("ok/a.json",
                replaced(sphereShot(8, 1), "\"vdb_voxel_size\": 0.1", "\"vdb_voxel_size\": 0.25"));
  CmdResult r = run(limited.cloudctl(30) + " submit " + small_vdb + " --quiet");
  EXPECT_EQ(r.code, 0) << r.err;
  r = run(limited.cloudctl(30) + " submit " +
          ws_.write("ok/b.json",
                    withVolume(R"({"procedural": {"type": "perlin_cloud", "resolution": 12}})")) +
          " --quiet");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(limited.stop());
}

// A job that runs past --max-job-seconds is stopped within about a second of it and FAILED,
// naming the flag; the runner is free for the next job.
TEST(ServerQueue, JobPastItsTimeLimitIsStoppedAndFailed) {
  Workspace ws;
  ServerProc server(ws.path("state"));
  ASSERT_TRUE(server.start({"--max-job-seconds=1"}));
  const auto t0 = std::chrono::steady_clock::now();
  const std::string id = submitDetached(server, ws.write("long.json", sphereShot(128, 8192)));
  const Json s = waitFor(
      server, id,
      [](const Json& j) { return j.at("state") != "RUNNING" && j.at("state") != "QUEUED"; }, 30);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(s.at("state"), "FAILED");
  EXPECT_NE(s.at("error").get<std::string>().find("--max-job-seconds"), std::string::npos) << s;
  EXPECT_LT(seconds, 10.0);
  const CmdResult next =
      run(server.cloudctl() + " submit " + ws.write("tiny.json", sphereShot(8, 1)) + " --quiet");
  EXPECT_EQ(next.code, 0) << next.err;
}

// `cloudctl submit --samples N` of an auto shot runs the chosen method at N, as `cloudbake
// render --samples` does: written into the auto shot, the choice replaced it (an outside probe's
// --samples 4 ran at 27625 paths a pixel). The dry run says so too.
TEST(ServerQueue, ASamplesOverrideOfAnAutoShotReachesTheChosenMethod) {
  Workspace ws;
  ServerProc server(ws.path("state"));
  ASSERT_TRUE(server.start());
  const std::string shot =
      ws.write("auto.json", replaced(replaced(sphereShot(8, 1), "\"samples\": 1, ", ""),
                                     "\"pathtrace\"", "\"auto\", \"tolerance\": 0.3"));
  const CmdResult plan = run(server.cloudctl() + " submit " + shot + " --samples 3 --dry-run");
  ASSERT_EQ(plan.code, 0) << plan.err;
  EXPECT_NE((plan.out + plan.err).find("samples: 3 from the request"), std::string::npos)
      << plan.out << plan.err;
  const CmdResult r =
      run(server.cloudctl() + " submit " + shot + " --samples 3 --quiet --out " + ws.path("out"));
  ASSERT_EQ(r.code, 0) << r.err;
  // The view's header: cloudbake:samples, a string attribute of one character, "3".
  const std::string exr = slurp(ws.path("out/front.exr"));
  const std::string attribute = std::string("cloudbake:samples") + '\0' + "string" + '\0' +
                                std::string("\x01\0\0\0", 4) + "3";
  EXPECT_NE(exr.find(attribute), std::string::npos);
}

// An output gone from the job and from the cache cannot be fetched: the error leaves no empty
// .part behind (it did, beside a message that the cache held it).
TEST(ServerQueue, AnOutputGoneEverywhereLeavesNoEmptyPart) {
  Workspace ws;
  ServerProc server(ws.path("state"));
  ASSERT_TRUE(server.start());
  const CmdResult job = run(server.cloudctl() + " --json submit " +
                            ws.write("tiny.json", sphereShot(8, 1)) + " --quiet");
  ASSERT_EQ(job.code, 0) << job.err;
  const std::string id = Json::parse(job.out).at("id");
  fs::remove(ws.path("state/jobs/" + id + "/out/front.exr"));
  fs::remove_all(ws.path("state/cache"));
  const CmdResult fetch =
      run(server.cloudctl() + " fetch " + id + " --name front.exr --out " + ws.path("f"));
  EXPECT_EQ(fetch.code, 5) << fetch.err;
  EXPECT_NE(fetch.err.find("gone from the server"), std::string::npos) << fetch.err;
  EXPECT_EQ(fetch.err.find("is in the server's cache"), std::string::npos) << fetch.err;
  EXPECT_FALSE(fs::exists(ws.path("f/front.exr.part"))) << fetch.err;
}

// Streams beyond --max-streams are answered RESOURCE_EXHAUSTED (exit 4, "retry later") instead
// of each taking a server thread without bound (1000 watchers made 1017 threads).
TEST(ServerQueue, StreamsBeyondTheBoundAreRefused) {
  Workspace ws;
  ServerProc server(ws.path("state"));
  ASSERT_TRUE(server.start({"--max-streams=1"}));
  const std::string id = submitDetached(server, ws.write("long.json", sphereShot(128, 8192)));
  CmdResult first;
  std::thread watcher([&] { first = run(server.cloudctl(60) + " watch " + id); });
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // the first stream is open
  const CmdResult second = run(server.cloudctl() + " watch " + id);
  EXPECT_EQ(second.code, 4) << second.err;
  EXPECT_NE(second.err.find("too many streams"), std::string::npos) << second.err;
  EXPECT_EQ(run(server.cloudctl() + " cancel " + id).code, 0);
  watcher.join();
  EXPECT_EQ(first.code, 6) << first.err;  // the first watch saw the job cancelled
}

TEST(ServerQueue, FullQueueAnswersResourceExhausted) {
  Workspace ws;
  ServerProc server(ws.path("state"));
  ASSERT_TRUE(
      server.start({"--max-concurrent-jobs=1", "--queue-bound=1", "--max-upload-bytes=1kb"}));
  // The upload limit (1kb: 1024 bytes): a 2000-byte asset is refused before it is stored.
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
  const CmdResult full =
      run(server.cloudctl() + " --retry-seconds 0 submit " + long_shot + " --detach");
  EXPECT_EQ(full.code, 4) << full.err;  // kUnavailable: retry later
  EXPECT_NE(full.err.find("queue is full"), std::string::npos) << full.err;
  // By default cloudctl retries a full queue with backoff for --retry-seconds, then gives up.
  const auto t0 = std::chrono::steady_clock::now();
  const CmdResult retried =
      run(server.cloudctl() + " --retry-seconds 2 submit " + long_shot + " --detach");
  const double retried_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(retried.code, 4) << retried.err;
  EXPECT_GE(retried_s, 1.0);
  EXPECT_LT(retried_s, 10.0);
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
    EXPECT_EQ(crashed.at("stage"), "interrupted");  // it had shown "build 0%"
    EXPECT_EQ(run(again.cloudctl() + " fetch " + id + " --out " + ws.path("f2")).code, 5);
    // The completed job's own result is intact and fetchable.
    EXPECT_EQ(run(again.cloudctl() + " fetch " + done_id + " --out " + ws.path("f3")).code, 0);
    // Damaged on disk after that fetch verified it: refused, never streamed as if intact.
    const std::string served = state + "/jobs/" + done_id + "/out/front.exr";
    {
      std::fstream io(served, std::ios::binary | std::ios::in | std::ios::out);
      io.seekp(std::streamoff(fs::file_size(served) / 2));
      for (int i = 0; i < 16; ++i) io.put('\x5a');
    }
    const CmdResult damaged =
        run(again.cloudctl() + " fetch " + done_id + " --out " + ws.path("f3b"));
    EXPECT_EQ(damaged.code, 5) << damaged.err;
    EXPECT_NE(damaged.err.find("damaged on the server"), std::string::npos) << damaged.err;
    EXPECT_FALSE(fs::exists(ws.path("f3b/front.exr")));
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

// A refused connection fails at once, not after --timeout (it waited the whole 10 s default);
// --wait-for-server keeps trying until --timeout.
TEST(ServerUnavailable, RefusedConnectionFailsAtOnceUnlessAskedToWait) {
  const std::string addr = "127.0.0.1:" + std::to_string(freePort());
  auto timed = [&](const std::string& args) {
    const auto t0 = std::chrono::steady_clock::now();
    const CmdResult r = run(std::string(CLOUDCTL_BIN) + " --server " + addr + " " + args);
    EXPECT_EQ(r.code, 4) << r.err;
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  EXPECT_LT(timed("--timeout 60 health"), 20.0);
  EXPECT_GE(timed("--timeout 2 --wait-for-server health"), 1.5);
}

// A shot larger than a request may be is bad input with the limit named (it read "server busy",
// exit 4, inviting a retry). Checked before connecting, so no server is needed.
TEST(CloudctlCommandLine, OversizedShotIsBadInputNotServerBusy) {
  Workspace ws;
  const std::string shot =
      ws.write("big.json", "{\"version\": 1, \"name\": \"" + std::string(5 << 20, 'a') + "\"}");
  const CmdResult r = run(std::string(CLOUDCTL_BIN) + " --server 127.0.0.1:1 submit " + shot);
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("shot too large"), std::string::npos) << r.err;
}

// A mistyped --server is bad input naming the option, not "server unavailable" (exit 4, which
// invites a retry); what gRPC resolves itself (a scheme it knows) is left to it.
TEST(CloudctlCommandLine, AMalformedServerAddressIsBadInputNamingTheOption) {
  for (const char* bad :
       {"garbage", "127.0.0.1", "host:", ":50051", "host:0", "host:65536", "host:5oo51",
        "a:b:50051", "host/x:50051", "[]:1", "]x:1", "[abc]:1", "[::1:1", "::1"}) {
    const CmdResult r =
        run(std::string(CLOUDCTL_BIN) + " --server '" + std::string(bad) + "' health");
    EXPECT_EQ(r.code, 2) << bad << ": " << r.err;
    EXPECT_NE(r.err.find("--server (or CLOUDBAKE_SERVER): expected HOST:PORT"), std::string::npos)
        << bad << ": " << r.err;
  }
  const CmdResult env = run("CLOUDBAKE_SERVER=nonsense " + std::string(CLOUDCTL_BIN) + " health");
  EXPECT_EQ(env.code, 2) << env.err;
  EXPECT_NE(env.err.find("got 'nonsense'"), std::string::npos) << env.err;
  // Well-formed addresses with nothing listening get as far as connecting: unavailable.
  const std::string port = std::to_string(freePort());
  for (const std::string& good :
       {"127.0.0.1:" + port, "localhost:" + port, "[::1]:" + port, "ipv4:127.0.0.1:" + port}) {
    const CmdResult r =
        run(std::string(CLOUDCTL_BIN) + " --server '" + good + "' --timeout 2 health");
    EXPECT_EQ(r.code, 4) << good << ": " << r.err;
  }
}

// Credential files that cannot serve are bad input naming their option: a folder read as
// "basic_filebuf::underflow error" (exit 1), a CA file with no certificate was taken silently.
TEST(CloudctlCommandLine, CredentialFilesThatCannotServeAreBadInputNamingTheOption) {
  Workspace ws;
  const std::string empty = ws.write("empty.pem", "");
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"--token-file " + ws.path(""), "--token-file " + ws.path("") + ": is a folder"},
      {"--tls-ca " + ws.path(""), "--tls-ca " + ws.path("") + ": is a folder"},
      {"--tls-ca " + empty, "--tls-ca " + empty + ": not a PEM certificate"},
      // An empty token file had read as no token at all ("this server requires a token").
      {"--token-file " + empty, "--token-file " + empty + ": holds no token"},
  };
  for (const auto& [args, needle] : bad) {
    const CmdResult r = run(std::string(CLOUDCTL_BIN) + " " + args + " --timeout 2 health");
    EXPECT_EQ(r.code, 2) << args << ": " << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << args << ": " << r.err;
  }
  // A missing one is exit 3, as a missing file is for every command (it was 2).
  for (const std::string option : {"--token-file", "--tls-ca"}) {
    const CmdResult r = run(std::string(CLOUDCTL_BIN) + " " + option + " " + ws.path("none") +
                            " --timeout 2 health");
    EXPECT_EQ(r.code, 3) << option << ": " << r.err;
    EXPECT_NE(r.err.find(ws.path("none") + ": file not found"), std::string::npos) << r.err;
  }
  // The server: a certificate that is not PEM was "cannot listen" (exit 4).
  const CmdResult server = run("timeout 30 " + std::string(CLOUDBAKE_SERVER_BIN) +
                               " --listen=127.0.0.1:0 --cache-dir=" + ws.path("state") +
                               " --tls-cert=" + empty + " --tls-key=" + empty);
  EXPECT_EQ(server.code, 2) << server.err;
  EXPECT_NE((server.out + server.err).find("--tls-cert " + empty + ": not a PEM certificate"),
            std::string::npos)
      << server.out << server.err;
}

// A server that accepts the connection and never answers: the wait ends at --timeout or at
// --deadline, whichever comes first, and the message says which and after how long (a
// --deadline 1 said "no connection within 10 s").
TEST(CloudctlCommandLine, ASilentServerIsReportedByTheLimitThatEndedTheWait) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  ASSERT_EQ(listen(fd, 16), 0);  // the kernel completes connections; nobody answers them
  socklen_t len = sizeof addr;
  getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  const std::string server = " --server 127.0.0.1:" + std::to_string(ntohs(addr.sin_port));
  const CmdResult by_deadline = run(std::string(CLOUDCTL_BIN) + server + " --deadline 1 health");
  EXPECT_EQ(by_deadline.code, 4) << by_deadline.err;
  EXPECT_NE(by_deadline.err.find("no connection within 1 s, --deadline)"), std::string::npos)
      << by_deadline.err;
  const CmdResult by_timeout = run(std::string(CLOUDCTL_BIN) + server + " --timeout 0.5 health");
  EXPECT_EQ(by_timeout.code, 4) << by_timeout.err;
  EXPECT_NE(by_timeout.err.find("no connection within 0.5 s, --timeout)"), std::string::npos)
      << by_timeout.err;
  close(fd);
}

TEST(CloudctlCommandLine, MistypedCommandIsNamedWithTheNearestOne) {
  // Flags take no value: the word after one is the command (a review found `--json sumbit`
  // reported as "A subcommand is required" and `--json --timeout 5 sumbit` as command '5').
  for (const char* before : {"--server 127.0.0.1:1", "--json", "--json --timeout 5", "--tls",
                             "--wait-for-server --retry-seconds=3", "--deadline 9 --json"}) {
    const CmdResult r = run(std::string(CLOUDCTL_BIN) + " " + before + " sumbit shot.json");
    EXPECT_EQ(r.code, 2) << before;
    EXPECT_NE(r.err.find("unknown command 'sumbit' (did you mean 'submit'?)"), std::string::npos)
        << before << ": " << r.err;
  }
}

// Seconds are read as numbers in a named range: CLI11's own checks let NaN through (a
// `--timeout nan` connected for "-2147483648 s") and one out of range, as the word after an
// option the command-typo check did not know, read as an unknown command.
TEST(CloudctlCommandLine, NumericOptionsRefuseNanInfAndOutOfRangeByName) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--timeout nan", "--timeout: must be a number in (0, 1e6], got nan"},
      {"--timeout 0", "--timeout: must be a number in (0, 1e6], got 0"},
      {"--timeout 1e300", "--timeout: must be a number in (0, 1e6], got 1e300"},
      {"--deadline -3", "--deadline: must be a number in (0, 1e7], got -3"},
      {"--deadline inf", "--deadline: must be a number in (0, 1e7], got inf"},
      {"--retry-seconds 1e9", "--retry-seconds: must be a number in [0, 86400], got 1e9"},
      {"--retry-seconds 5x", "--retry-seconds: must be a number in [0, 86400], got 5x"}};
  for (const auto& [args, message] : cases) {
    const CmdResult r =
        run(std::string(CLOUDCTL_BIN) + " --server 127.0.0.1:1 " + args + " health");
    EXPECT_EQ(r.code, 2) << args << ": " << r.err;
    EXPECT_NE(r.err.find(message), std::string::npos) << args << ": " << r.err;
  }
}

TEST(ServerCommandLine, SecondsOptionsRefuseNanFromTheFlagAndTheEnvironment) {
  for (const std::string& args :
       {std::string("--max-job-seconds=nan"), std::string("--keep-jobs-hours=inf"),
        std::string("--scrub-hours=-1")}) {
    // Under `timeout`: a server that took the value would start and serve, not fail the test.
    const CmdResult r = run("timeout 30 " + std::string(CLOUDBAKE_SERVER_BIN) +
                            " --listen=127.0.0.1:0 --cache-dir=/nonexistent/x " + args);
    EXPECT_EQ(r.code, 2) << args << ": " << r.err;
    EXPECT_NE(r.err.find("must be a number in [0, "), std::string::npos) << args << ": " << r.err;
  }
  const CmdResult env =
      run("CLOUDBAKE_MAX_JOB_SECONDS=nan timeout 30 " + std::string(CLOUDBAKE_SERVER_BIN) +
          " --listen=127.0.0.1:0 --cache-dir=/nonexistent/x");
  EXPECT_EQ(env.code, 2) << env.err;
  EXPECT_NE(env.err.find("--max-job-seconds: must be a number in [0, 1e9], got nan"),
            std::string::npos)
      << env.err;
}

// Ports past 65535 wrapped (70000 listened on 4464), an empty one listened on 443, and byte
// counts wrapped (-1 became 2^64 - 1): each is refused naming its flag.
TEST(ServerCommandLine, PortsAndByteCountsOutOfRangeAreRefused) {
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"--listen=127.0.0.1:70000", "--listen: expected HOST:PORT"},
      {"--listen=127.0.0.1:", "--listen: expected HOST:PORT"},
      {"--listen=127.0.0.1:0 --metrics-listen=127.0.0.1:99999", "--metrics-listen: expected"},
      {"--listen=127.0.0.1:0 --cache-size=-1", "--cache-size: expected a byte count"},
      {"--listen=127.0.0.1:0 --cache-size=18446744073709551616", "--cache-size: expected"},
      {"--listen=127.0.0.1:0 --max-upload-bytes=-1kb", "--max-upload-bytes: expected"},
      {"--listen=127.0.0.1:0 --max-upload-bytes=16777216tb", "--max-upload-bytes: more bytes"},
  };
  for (const auto& [args, needle] : bad) {
    const CmdResult r = run("timeout 30 " + std::string(CLOUDBAKE_SERVER_BIN) +
                            " --cache-dir=/nonexistent/x " + args);
    EXPECT_EQ(r.code, 2) << args << ": " << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << args << ": " << r.err;
  }
  const CmdResult env = run("CLOUDBAKE_LISTEN=127.0.0.1:70000 timeout 30 " +
                            std::string(CLOUDBAKE_SERVER_BIN) + " --cache-dir=/nonexistent/x");
  EXPECT_EQ(env.code, 2) << env.err;
  EXPECT_NE(env.err.find("--listen: expected HOST:PORT"), std::string::npos) << env.err;
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
