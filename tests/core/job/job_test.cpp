// Unit tests of core/job: SHA-256, cache keys, the bake cache (atomicity, verification, LRU,
// single flight), runShot (outputs, cache reuse, cancellation) and the durable job store.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <future>
#include <nlohmann/json.hpp>
#include <thread>
#include <vector>

#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/io/vdb_io.h"
#include "core/job/asset_store.h"
#include "core/job/bake_cache.h"
#include "core/job/cache_key.h"
#include "core/job/direction_index.h"
#include "core/job/file_util.h"
#include "core/job/job_manager.h"
#include "core/job/phase_cache.h"
#include "core/job/run_shot.h"
#include "core/job/sha256.h"
#include "core/job/volume_cache.h"
#include "core/job/volume_limits.h"
#include "core/shot/shot_parser.h"
#include "core/transport/layers_exr.h"
#include "tests/core/job/job_test_util.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

std::string tinyShot(const std::string& extra_sun = "[1, 1, 1]", int width = 8,
                     const std::string& camera_y = "-5") {
  return R"({"version": 1, "name": "tiny",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 2, "albedo": 0.9, "phase": {"type": "hg", "g": 0.5}},
    "lighting": {"sun": {"direction": [0, 0, 1], "irradiance": )" +
         extra_sun + R"(}},
    "bake": {"method": "pathtrace", "samples": 2, "seed": 3},
    "views": [{"name": "front", "camera": {"type": "orthographic", "position": [0, )" +
         camera_y + R"(, 0], "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5},
               "resolution": [)" +
         std::to_string(width) + R"(, 8]}],
    "outputs": {"exr": true, "vdb": true, "vdb_voxel_size": 0.25}})";
}

ShotSpec parse(const std::string& text) { return parseShot(text, ""); }

// runShot refuses `shot` with an InputError whose message holds `expected`.
void expectRunRefused(const ShotSpec& shot, const RunOptions& opt, const std::string& expected) {
  try {
    runShot(shot, opt);
    ADD_FAILURE() << "ran; expected an error with '" << expected << "'";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
  }
}

TEST(VolumeLimits, CountsVoxelsAsTheBuildersAllocateThem) {
  PerlinCloudOptions p;  // 128 along the largest of (2, 2, 1)
  EXPECT_EQ(perlinCloudVoxels(p), 128u * 128u * 64u);
  p.size = Vec3(3, 1, 1);
  p.resolution = 30;
  EXPECT_EQ(perlinCloudVoxels(p), 30u * 10u * 10u);
  EXPECT_EQ(boxVoxels(Vec3(2, 2, 1), 0.25), 8.0 * 8 * 4);
  EXPECT_EQ(boxVoxels(Vec3(2, 2, 1), 0.3), 7.0 * 7 * 4);  // partial voxels count
  EXPECT_TRUE(std::isinf(boxVoxels(Vec3(1, 1, 1), 1e-300)));
}

// A bad mesh read for the server's voxel limit names the field, as the scene builder's read does
// in-process (it used to reach clients as a bare "<file>: mesh has no triangles").
TEST(VolumeLimits, BadMeshNamesTheField) {
  const fs::path dir = freshDir("bad-mesh");
  const std::string empty = (dir / "empty.obj").string();
  std::ofstream(empty) << "# no faces\nv 0 0 0\nv 1 0 0\n";
  // A mesh without triangles, and one removed after the parse.
  for (const std::string& path : {empty, (dir / "missing.obj").string()}) {
    ShotSpec shot = parse(tinyShot());
    MeshVolumeSpec mesh;
    mesh.path = path;
    shot.volume = mesh;
    try {
      checkMeshVoxels(shot, 1000, "shot.json");
      ADD_FAILURE() << path << ": no error";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("shot.json: /volume/mesh: " + path), std::string::npos)
          << e.what();
    }
  }
  fs::remove_all(dir);
}

TEST(VolumeLimits, ShotsOverTheLimitNameTheField) {
  const ShotSpec sphere = parse(tinyShot());  // bake.vdb of 8^3 = 512 voxels
  EXPECT_NO_THROW(checkShotVoxels(sphere, 512, "shot.json"));
  EXPECT_NO_THROW(checkShotVoxels(sphere, 0, "shot.json"));  // 0: no limit
  try {
    checkShotVoxels(sphere, 511, "shot.json");
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shot.json: /outputs/vdb_voxel_size: voxel size 0.25 "
                                         "over the volume's bounds gives 512 voxels, over the "
                                         "limit of 511 (--max-voxels)"),
              std::string::npos)
        << e.what();
  }
  ShotSpec procedural = sphere;
  procedural.outputs.vdb = false;
  procedural.volume = ProceduralVolumeSpec{};
  EXPECT_THROW(checkShotVoxels(procedural, 128 * 128 * 64 - 1, "shot.json"), InputError);
  EXPECT_NO_THROW(checkShotVoxels(procedural, 128 * 128 * 64, "shot.json"));
  SequenceVolumeSpec seq;
  seq.procedural = ProceduralVolumeSpec{};
  seq.frames = 5;
  procedural.volume = seq;
  EXPECT_NO_THROW(checkShotFrames(procedural, 5, "shot.json"));
  EXPECT_NO_THROW(checkShotFrames(procedural, 0, "shot.json"));
  try {
    checkShotFrames(procedural, 4, "shot.json");
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()),
              "shot.json: /volume/sequence/frames: 5 frames exceed this server's limit of 4 "
              "(--max-frames)");
  }
  try {
    checkShotVoxels(procedural, 1000, "shot.json");
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/volume/sequence/procedural/resolution"),
              std::string::npos)
        << e.what();
  }
}

TEST(Sha256, KnownVectors) {
  // FIPS 180-2 appendix B.1 and the empty message.
  EXPECT_EQ(sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  Sha256 h;  // incremental == one shot
  h.update("a");
  h.update("bc");
  EXPECT_EQ(h.hexDigest(), sha256Hex("abc"));
  EXPECT_TRUE(isSha256Hex(sha256Hex("x")));
  EXPECT_FALSE(isSha256Hex("ABC"));
  EXPECT_THROW(sha256File("/nonexistent/file"), InputError);
}

TEST(CacheKey, ViewSunColourAndImageSizeAreNotInTheBakeKey) {
  const ShotCacheKeys a = computeCacheKeys(parse(tinyShot()));
  const ShotCacheKeys colour = computeCacheKeys(parse(tinyShot("[3, 2, 1]")));
  const ShotCacheKeys size = computeCacheKeys(parse(tinyShot("[1, 1, 1]", 16)));
  const ShotCacheKeys view = computeCacheKeys(parse(tinyShot("[1, 1, 1]", 8, "-7")));
  EXPECT_EQ(a.bake, colour.bake);
  EXPECT_EQ(a.bake, size.bake);
  EXPECT_EQ(a.bake, view.bake);
  EXPECT_TRUE(a.sun_scaled);
  // Sun colour does not change the render key either (renders are scaled); view and size do.
  EXPECT_EQ(a.views, colour.views);
  EXPECT_NE(a.views, size.views);
  EXPECT_NE(a.views, view.views);
  EXPECT_EQ(a.volume, view.volume);
}

TEST(CacheKey, PhysicsAndQualityKnobsAreInTheBakeKey) {
  const std::string base = tinyShot();
  const std::string bake = computeCacheKeys(parse(base)).bake;
  auto keyWith = [&](const std::string& from, const std::string& to) {
    std::string s = base;
    const size_t at = s.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    s.replace(at, from.size(), to);
    return computeCacheKeys(parse(s)).bake;
  };
  EXPECT_NE(bake, keyWith(R"("albedo": 0.9)", R"("albedo": 0.8)"));
  EXPECT_NE(bake, keyWith(R"("g": 0.5)", R"("g": 0.6)"));
  EXPECT_NE(bake, keyWith(R"("samples": 2)", R"("samples": 3)"));
  EXPECT_NE(bake, keyWith(R"("seed": 3)", R"("seed": 4)"));
  EXPECT_NE(bake, keyWith(R"("radius": 1)", R"("radius": 0.9)"));
  EXPECT_NE(bake, keyWith(R"("direction": [0, 0, 1])", R"("direction": [0, 0.1, 1])"));
  // Float noise below the quantum shares the bake.
  EXPECT_EQ(bake, keyWith(R"("direction": [0, 0, 1])", R"("direction": [1e-9, 0, 1])"));
}

TEST(CacheKey, FilesAreKeyedByContentNotPath) {
  const fs::path dir = freshDir("key");
  const std::string sky = R"({"version": 1, "volume": {"sphere": {"center": [0,0,0], "radius": 1}},
    "medium": {"extinction": 1, "albedo": 1, "phase": {"type": "isotropic"}},
    "lighting": {"sky": {"map": "MAP", "scale": 1}},
    "views": [{"name": "v", "camera": {"type": "perspective", "position": [0,-5,0],
      "look_at": [0,0,0], "up": [0,0,1], "fov_deg": 30}, "resolution": [4, 4]}]})";
  Image img(4, 2, 3);
  for (float& v : img.data) v = 0.5f;
  writeExr((dir / "a.exr").string(), {{"", img}});
  fs::copy_file(dir / "a.exr", dir / "b.exr");
  auto keyFor = [&](const std::string& name) {
    std::string s = sky;
    s.replace(s.find("MAP"), 3, name);
    return computeCacheKeys(parseShot(s, dir.string())).bake;
  };
  EXPECT_EQ(keyFor("a.exr"), keyFor("b.exr"));
  img.data[0] = 0.25f;
  writeExr((dir / "b.exr").string(), {{"", img}});
  EXPECT_NE(keyFor("a.exr"), keyFor("b.exr"));
  fs::remove_all(dir);
}

// How a file is read belongs in the key: readers choose the format by the extension, so PLY
// bytes named m.obj (which fail to read) must not find the cache entry of m.ply (an outside test
// found a server answering from the cache what a fresh one refused). Case does not matter.
TEST(CacheKey, FilesAreKeyedByHowTheyAreReadToo) {
  const fs::path dir = freshDir("key-ext");
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  for (const char* name : {"m.ply", "m.obj", "n.PLY"}) std::ofstream(dir / name) << ply;
  auto keyFor = [&](const std::string& name) {
    const std::string s =
        R"({"version": 1, "volume": {"mesh": {"path": ")" + name + R"(", "resolution": 8}},
      "medium": {"extinction": 1, "albedo": 1, "phase": {"type": "isotropic"}},
      "lighting": {"sun": {"direction": [0, 0, 1], "irradiance": [1, 1, 1]}},
      "views": [{"name": "v", "camera": {"type": "perspective", "position": [0,-5,0],
        "look_at": [0,0,0], "up": [0,0,1], "fov_deg": 30}, "resolution": [4, 4]}]})";
    return computeCacheKeys(parseShot(s, dir.string())).volume;
  };
  EXPECT_NE(keyFor("m.ply"), keyFor("m.obj"));
  EXPECT_EQ(keyFor("m.ply"), keyFor("n.PLY"));
  fs::remove_all(dir);
}

TEST(BakeCache, ComputesOnceThenHitsAndSurvivesReopen) {
  const fs::path dir = freshDir("cache");
  int computed = 0;
  auto fill = [&](const std::string& staging) {
    ++computed;
    writeFileAtomic(staging + "/a.txt", "hello");
  };
  {
    BakeCache cache(dir.string(), 0);
    const std::string p1 = cache.getOrCompute("k1", fill);
    const std::string p2 = cache.getOrCompute("k1", fill);
    EXPECT_EQ(p1, p2);
    EXPECT_EQ(computed, 1);
    EXPECT_EQ(readWholeFile(p1 + "/a.txt"), "hello");
    EXPECT_EQ(cache.stats().hits, 1u);
  }
  BakeCache reopened(dir.string(), 0);
  EXPECT_TRUE(reopened.lookup("k1").has_value());
  EXPECT_EQ(reopened.stats().entries, 1u);
  fs::remove_all(dir);
}

TEST(BakeCache, CorruptEntryIsDroppedAndRebuiltNeverServed) {
  const fs::path dir = freshDir("corrupt");
  BakeCache cache(dir.string(), 0);
  int computed = 0;
  auto fill = [&](const std::string& staging) {
    ++computed;
    writeFileAtomic(staging + "/a.txt", "original content");
  };
  const std::string entry = cache.getOrCompute("k", fill);
  {
    std::ofstream f(entry + "/a.txt", std::ios::binary | std::ios::in);
    f.seekp(3);
    f.put('X');  // same size, different bytes: only the checksum can tell
  }
  EXPECT_FALSE(cache.lookup("k").has_value());
  EXPECT_EQ(cache.stats().corrupt, 1u);
  const std::string again = cache.getOrCompute("k", fill);
  EXPECT_EQ(computed, 2);
  EXPECT_EQ(readWholeFile(again + "/a.txt"), "original content");
  // A crash mid-compute leaves only staging debris, removed on open; never an entry.
  fs::create_directories(dir / "staging" / "debris");
  fs::create_directories(dir / "entries" / "half");  // no manifest
  BakeCache reopened(dir.string(), 0);
  EXPECT_FALSE(fs::exists(dir / "staging" / "debris"));
  EXPECT_FALSE(reopened.lookup("half").has_value());
  EXPECT_TRUE(reopened.lookup("k").has_value());
  fs::remove_all(dir);
}

TEST(BakeCache, EvictsLeastRecentlyUsedUnderTheSizeBound) {
  const fs::path dir = freshDir("lru");
  BakeCacheOptions options;
  options.max_bytes = 2500;  // room for two 1000-byte entries (+ manifests)
  options.min_evict_age = std::chrono::seconds(0);
  BakeCache cache(dir.string(), options);
  auto fill = [](const std::string& staging) {
    writeFileAtomic(staging + "/data", std::string(1000, 'x'));
  };
  cache.getOrCompute("a", fill);
  cache.getOrCompute("b", fill);
  cache.getOrCompute("a", fill);  // a is now the most recent
  cache.getOrCompute("c", fill);  // evicts b
  EXPECT_TRUE(cache.lookup("a").has_value());
  EXPECT_FALSE(cache.lookup("b").has_value());
  EXPECT_TRUE(cache.lookup("c").has_value());
  EXPECT_EQ(cache.stats().evicted, 1u);
  EXPECT_LE(cache.stats().bytes, 2500u);
  fs::remove_all(dir);
}

TEST(BakeCache, SingleFlightForConcurrentIdenticalRequests) {
  const fs::path dir = freshDir("flight");
  BakeCache cache(dir.string(), 0);
  std::atomic<int> computed{0};
  std::vector<std::thread> threads;
  std::vector<std::string> paths(8);
  for (int i = 0; i < 8; ++i) {
    threads.emplace_back([&, i] {
      paths[size_t(i)] = cache.getOrCompute("same", [&](const std::string& staging) {
        ++computed;
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
        writeFileAtomic(staging + "/r", "result");
      });
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(computed.load(), 1);
  for (const std::string& p : paths) EXPECT_EQ(p, paths[0]);
  fs::remove_all(dir);
}

TEST(BakeCache, CancelledLeaderHandsOverToAWaiter) {
  const fs::path dir = freshDir("handover");
  BakeCache cache(dir.string(), 0);
  std::atomic<bool> leader_started{false};
  std::thread leader([&] {
    EXPECT_THROW(cache.getOrCompute("k",
                                    [&](const std::string&) {
                                      leader_started = true;
                                      std::this_thread::sleep_for(std::chrono::milliseconds(200));
                                      throw Cancelled();
                                    }),
                 Cancelled);
  });
  while (!leader_started) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const std::string p = cache.getOrCompute(
      "k", [](const std::string& staging) { writeFileAtomic(staging + "/r", "waiter"); });
  leader.join();
  EXPECT_EQ(readWholeFile(p + "/r"), "waiter");
  fs::remove_all(dir);
}

TEST(RunShot, WritesViewsAndVdbAsCloudbakeRender) {
  const fs::path dir = freshDir("run");
  RunOptions opt;
  opt.out_dir = (dir / "out").string();
  std::vector<std::string> stages;
  opt.progress = [&](const RunProgress& p) {
    EXPECT_GE(p.fraction, 0.0);
    EXPECT_LE(p.fraction, 1.0);
    if (stages.empty() || stages.back() != p.stage) stages.push_back(p.stage);
    return true;
  };
  const RunResult r = runShot(parse(tinyShot()), opt);
  ASSERT_EQ(r.files.size(), 2u);
  EXPECT_EQ(r.files[0].name, "front.exr");
  EXPECT_EQ(r.files[1].name, "bake.vdb");
  EXPECT_EQ(r.views_rendered, 1);
  EXPECT_EQ(r.files[0].sha256, sha256File(r.files[0].path));
  const ExrContents exr = readExr(r.files[0].path);
  EXPECT_EQ(exr.width, 8);
  for (const char* layer : {"", "sun", "sky", "single", "multiple"}) {
    EXPECT_TRUE(exr.layers.count(layer)) << layer;
  }
  EXPECT_EQ(exr.attributes.at("cloudbake:view"), "front");
  // What a compositor needs in the header: the camera (OpenEXR's standard matrices) and the sun.
  EXPECT_TRUE(exr.matrices.count("worldToCamera"));
  EXPECT_TRUE(exr.matrices.count("worldToNDC"));
  EXPECT_TRUE(exr.attributes.count("cloudbake:sun_direction"));
  EXPECT_TRUE(exr.attributes.count("cloudbake:sun_irradiance"));
  for (const char* layer : {"background", "beauty"}) EXPECT_TRUE(exr.layers.count(layer)) << layer;
  VdbFileReader vdb(r.files[1].path);
  EXPECT_EQ(vdb.grids().at(0).name, "density");
  EXPECT_EQ(stages.front(), "build");
  EXPECT_EQ(stages.back(), "done");
  fs::remove_all(dir);
}

TEST(RunShot, OutputsExrCompressionChangesTheFilesNotThePixels) {
  const fs::path dir = freshDir("compression");
  RunOptions opt;
  ShotSpec shot = parse(tinyShot());
  std::map<std::string, RunResult> runs;
  for (const char* name : {"zip", "none", "piz"}) {
    shot.outputs.exr_compression = name;
    opt.out_dir = (dir / name).string();
    runs[name] = runShot(shot, opt);
  }
  const std::string zip = runs["zip"].files[0].path, none = runs["none"].files[0].path;
  EXPECT_GT(fs::file_size(none), fs::file_size(zip));
  for (const char* name : {"none", "piz"}) {
    const ExrContents a = readExr(zip), b = readExr(runs[name].files[0].path);
    for (const auto& [layer, image] : a.layers) {
      EXPECT_EQ(b.layers.at(layer).data, image.data) << name << " " << layer;
    }
  }
  // A shot built in code rather than parsed is checked too, before anything is written.
  shot.outputs.exr_compression = "b44";
  opt.out_dir = (dir / "b44").string();
  expectRunRefused(shot, opt, "/outputs/exr_compression");
  EXPECT_FALSE(fs::exists(dir / "b44" / "front.exr"));
  fs::remove_all(dir);
}

// outputs.exr_layers writes the layers it names, in the file's order, with the same pixels as a
// view of every layer, and says which they are; the preview is the beauty's, written or not.
TEST(RunShot, OutputsExrLayersWriteTheChosenLayersOnly) {
  const fs::path dir = freshDir("layers");
  RunOptions opt;
  opt.png = true;
  ShotSpec shot = parse(tinyShot());
  shot.outputs.vdb = false;
  opt.out_dir = (dir / "all").string();
  runShot(shot, opt);
  shot.outputs.exr_layers = {"cloud", "multiple"};
  opt.out_dir = (dir / "two").string();
  runShot(shot, opt);

  const ExrContents all = readExr((dir / "all" / "front.exr").string());
  const ExrContents two = readExr((dir / "two" / "front.exr").string());
  EXPECT_EQ(all.layers.size(), 7u);
  EXPECT_EQ(all.attributes.at("cloudbake:layers"),
            "cloud background beauty sun sky single multiple");
  ASSERT_EQ(two.layers.size(), 2u);
  EXPECT_EQ(two.attributes.at("cloudbake:layers"), "cloud multiple");
  for (const char* layer : {"", "multiple"}) {
    EXPECT_EQ(two.layers.at(layer).data, all.layers.at(layer).data) << layer;
  }
  const std::vector<float>& multiple = all.layers.at("multiple").data;
  EXPECT_GT(*std::max_element(multiple.begin(), multiple.end()), 0.0f);  // worth comparing
  // Read by meaning, the unprefixed layer is the cloud: the beauty was left out.
  EXPECT_EQ(beautyLayerName(two), "beauty");
  EXPECT_EQ(readWholeFile((dir / "two" / "front.png").string()),
            readWholeFile((dir / "all" / "front.png").string()));
  EXPECT_LT(fs::file_size(dir / "two" / "front.exr"), fs::file_size(dir / "all" / "front.exr"));
  fs::remove_all(dir);
}

// An outside probe: an empty box with bake.vdb failed as the file was written, naming no field,
// though an empty cloud is a valid shot; a box thinner than a voxel named none either.
TEST(RunShot, AnEmptyCloudsDensityVdbIsEmptyAndAThinBoxNamesTheVoxelSize) {
  const fs::path dir = freshDir("emptyvdb");
  RunOptions opt;
  opt.out_dir = (dir / "empty").string();
  ShotSpec shot = parse(tinyShot());
  shot.volume = BoxVolumeSpec{{-1, -1, -1}, {1, 1, 1}, 0.0};
  const RunResult r = runShot(shot, opt);
  ASSERT_EQ(r.files.size(), 2u);
  VdbFileReader vdb(r.files[1].path);
  EXPECT_EQ(vdb.grids().at(0).name, "density");
  EXPECT_EQ(vdb.grids().at(0).active_voxels, 0u);
  EXPECT_DOUBLE_EQ(vdb.grids().at(0).voxel_size, 0.25);

  shot.volume = BoxVolumeSpec{{-1, -1, 0.01}, {1, 1, 0.2}, 1.0};  // no voxel centre inside
  opt.out_dir = (dir / "thin").string();
  expectRunRefused(shot, opt, "/outputs/vdb_voxel_size: ");
  EXPECT_FALSE(fs::exists(dir / "thin" / "bake.vdb"));
  fs::remove_all(dir);
}

// A lattice a few voxels across the cloud blurs its light across them (an outside probe: a bar
// of 100:1:1 lost 61 % of its multiple scattering with photon): the log says so, naming the axes.
TEST(RunShot, ALatticeFewVoxelsAcrossTheCloudSaysSoInTheLog) {
  const fs::path dir = freshDir("thin_axes");
  std::string text = tinyShot();
  const std::string pt = R"("method": "pathtrace", "samples": 2)";
  text.replace(text.find(pt), pt.size(), R"("method": "single", "light_resolution": 16)");
  const std::string vdb = R"("vdb": true, "vdb_voxel_size": 0.25)";
  text.replace(text.find(vdb), vdb.size(), R"("vdb": false)");
  ShotSpec shot = parse(text);
  RunOptions opt;
  opt.out_dir = dir.string();
  std::string log;
  opt.progress = [&](const RunProgress& p) {
    log += p.message + "\n";
    return true;
  };
  runShot(shot, opt);  // the sphere: 16 voxels across every axis
  EXPECT_EQ(log.find("voxel(s) along"), std::string::npos) << log;
  shot.volume = BoxVolumeSpec{{-2, -0.05, -0.05}, {2, 0.05, 0.05}, 1.0};
  log.clear();
  runShot(shot, opt);
  EXPECT_NE(log.find("18x3x3 lattice; the cloud spans 1 voxel(s) along y and z"), std::string::npos)
      << log;
  fs::remove_all(dir);
}

// The command line's --samples is held to the method's own limit: 1024 rays per pixel for a
// view from a bake (it failed after the bake, as "samples_per_pixel").
TEST(RunShot, ASamplesOverrideBeyondTheMethodsLimitIsRefusedBeforeTheBake) {
  const fs::path dir = freshDir("samples");
  RunOptions opt;
  opt.out_dir = dir.string();
  opt.samples = 1025;
  std::string text = tinyShot();
  const std::string pt = R"("method": "pathtrace", "samples": 2)";
  text.replace(text.find(pt), pt.size(), R"("method": "single", "light_resolution": 8)");
  const std::string vdb = R"("vdb": true, "vdb_voxel_size": 0.25)";
  text.replace(text.find(vdb), vdb.size(), R"("vdb": false)");
  const ShotSpec shot = parse(text);
  expectRunRefused(shot, opt, "samples: method 'single' takes at most 1024");
  EXPECT_FALSE(fs::exists(dir / "front.exr"));
  opt.samples = 1024;
  EXPECT_NO_THROW(runShot(shot, opt));
  fs::remove_all(dir);
}

TEST(RunShot, CachedSunColourChangeIsScaledNotRecomputed) {
  const fs::path dir = freshDir("scaled");
  BakeCache cache((dir / "cache").string(), 0);
  VolumeCache volumes;
  RunOptions opt;
  opt.cache = &cache;
  opt.volumes = &volumes;
  opt.out_dir = (dir / "a").string();
  const RunResult a = runShot(parse(tinyShot("[1, 1, 1]")), opt);
  opt.out_dir = (dir / "b").string();
  const RunResult b = runShot(parse(tinyShot("[3, 2, 0.5]")), opt);
  EXPECT_EQ(a.views_rendered, 1);
  EXPECT_EQ(b.views_rendered, 0);
  EXPECT_EQ(b.views_cached, 1);
  EXPECT_TRUE(b.vdb_cached);
  EXPECT_EQ(volumes.builds(), 1u);
  const Image ia = readExr(a.files[0].path).layers.at("");
  const Image ib = readExr(b.files[0].path).layers.at("");
  double total = 0;
  for (size_t i = 0; i < ia.data.size(); ++i) {
    const int c = int(i % 4);
    const double scale = c == 0 ? 3 : c == 1 ? 2 : c == 2 ? 0.5 : 1;  // alpha unscaled
    EXPECT_NEAR(ib.data[i], ia.data[i] * scale, 1e-6 * (1 + std::abs(ia.data[i] * scale)));
    total += ia.data[i];
  }
  EXPECT_GT(total, 0);  // not a blank image
  // Without a cache the direct render agrees (same seed, linear in the irradiance).
  RunOptions direct;
  direct.out_dir = (dir / "c").string();
  const RunResult c = runShot(parse(tinyShot("[3, 2, 0.5]")), direct);
  const Image ic = readExr(c.files[0].path).layers.at("");
  for (size_t i = 0; i < ic.data.size(); ++i) {
    EXPECT_NEAR(ic.data[i], ib.data[i], 1e-5 * (1 + std::abs(ic.data[i])));
  }
  fs::remove_all(dir);
}

TEST(RunShot, ProgressReturningFalseCancels) {
  const fs::path dir = freshDir("cancel");
  RunOptions opt;
  opt.out_dir = dir.string();
  int calls = 0;
  opt.progress = [&](const RunProgress& p) { return p.stage != "render" || ++calls < 3; };
  std::string shot = tinyShot("[1, 1, 1]", 64);
  shot.replace(shot.find("\"samples\": 2"), 12, "\"samples\": 64");
  EXPECT_THROW(runShot(parse(shot), opt), Cancelled);
  fs::remove_all(dir);
}

// A Lorenz-Mie table of large droplets takes seconds to build (6.9 s measured for r_eff 50 um,
// v_eff 0.45): a cancel reaches inside the build, and a cache keeps nothing of it.
TEST(RunShot, CancelReachesALorenzMieTableBuild) {
  const fs::path dir = freshDir("cancel_mie");
  std::string shot = tinyShot();
  const std::string hg = R"({"type": "hg", "g": 0.5})";
  shot.replace(shot.find(hg), hg.size(),
               R"({"type": "mie", "effective_radius_um": 50, "effective_variance": 0.45})");
  PhaseCache phases;
  RunOptions opt;
  opt.out_dir = dir.string();
  opt.phases = &phases;
  const auto t0 = std::chrono::steady_clock::now();
  auto since = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  opt.progress = [&](const RunProgress&) { return since() < 0.2; };
  EXPECT_THROW(runShot(parse(shot), opt), Cancelled);
  // Generous for a loaded machine, and still far below the build (several seconds).
  EXPECT_LT(since(), 1.5) << "the Mie table build did not stop";
  EXPECT_FALSE(phases.contains(phaseKey(parse(shot).medium.phase)));
  fs::remove_all(dir);
}

// An auto shot runs its choice: the views carry the choice in their header, auto.json records
// it with its prediction, and the chosen method's files are written.
TEST(RunShot, AutoRunsItsChoiceAndRecordsIt) {
  std::string shot = tinyShot();
  // auto chooses the samples too: the shot names none.
  const std::string bake = "\"method\": \"pathtrace\", \"samples\": 2,";
  shot.replace(shot.find(bake), bake.size(), "\"method\": \"auto\", \"tolerance\": 0.3,");
  RunOptions opt;
  opt.out_dir = freshDir("method").string();
  const RunResult r = runShot(parse(shot), opt);
  const fs::path record = fs::path(opt.out_dir) / "auto.json";
  ASSERT_TRUE(fs::exists(record));
  const nlohmann::json j = nlohmann::json::parse(readWholeFile(record.string()));
  EXPECT_LE(j["chosen"]["predicted_error"].get<double>(), 0.3);
  const std::string method = j["chosen"]["method"];
  bool exr = false;
  for (const OutputFile& f : r.files) {
    if (f.name.size() > 4 && f.name.substr(f.name.size() - 4) == ".exr") {
      const ExrContents c = readExr(f.path);
      EXPECT_EQ(c.attributes.at("cloudbake:method"), method);
      EXPECT_EQ(c.attributes.at("cloudbake:auto").rfind(method, 0), 0u);
      exr = true;
    }
  }
  EXPECT_TRUE(exr);
  fs::remove_all(opt.out_dir);
}

TEST(JobStore, RecordsRoundTripAndIdsAreChecked) {
  const fs::path dir = freshDir("store");
  JobStore store(dir.string());
  JobRecord r;
  r.id = newJobId();
  EXPECT_TRUE(isJobId(r.id));
  EXPECT_FALSE(isJobId("../etc"));
  r.state = JobState::kSucceeded;
  r.shot_name = "s";
  r.views = {"a", "b"};
  r.outputs.push_back({"a.exr", "", 12, sha256Hex("x")});
  store.save(r);
  const std::vector<JobRecord> all = store.loadAll();
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(all[0].id, r.id);
  EXPECT_EQ(all[0].state, JobState::kSucceeded);
  EXPECT_EQ(all[0].outputs.at(0).sha256, sha256Hex("x"));
  EXPECT_EQ(all[0].views, r.views);
  fs::remove_all(dir);
}

// Asset paths a job cannot place are clear errors naming them (not INTERNAL from the file
// system), and one request cannot make the server create folders without bound. Checked before
// the assets are looked up, so none needs to be uploaded here.
TEST(JobManager, AssetPathsAreBoundedAndConflictsNamed) {
  const fs::path dir = freshDir("asset-paths");
  JobManagerOptions o;
  o.state_dir = dir.string();
  JobManager jobs(o);
  const std::string sha(64, 'a'), other(64, 'b');
  auto errorFor = [&](std::vector<std::pair<std::string, std::string>> assets) {
    SubmitInput in;
    in.shot_json = "{}";
    in.assets = std::move(assets);
    try {
      jobs.plan(in);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(errorFor({{"a.vdb", sha}, {"a.vdb/b", sha}})
                .find("assets[1].path: 'a.vdb/b' conflicts with assets[0].path 'a.vdb'"),
            std::string::npos);
  EXPECT_NE(errorFor({{"x/a.vdb", sha}, {"x/./a.vdb", other}}).find("one path, two contents"),
            std::string::npos);
  std::string deep;
  for (int i = 0; i < 40; ++i) deep += "d/";
  EXPECT_NE(errorFor({{deep + "a.vdb", sha}}).find("nested deeper than 32 folders"),
            std::string::npos);
  std::vector<std::pair<std::string, std::string>> many;
  for (int i = 0; i < 5000; ++i) many.push_back({"f" + std::to_string(i) + ".vdb", sha});
  EXPECT_NE(errorFor(many).find("more than the 4096"), std::string::npos);
  // The same file named twice (a sequence repeating a frame) is no conflict: the error is the
  // missing upload, not the path.
  EXPECT_NE(errorFor({{"a.vdb", sha}, {"a.vdb", sha}}).find("has not been uploaded"),
            std::string::npos);
  fs::remove_all(dir);
}

// A unit sphere seen in an 8x8 view, baked by `bake` (a JSON object).
std::string sphereShot(const std::string& bake) {
  return R"({"version": 1, "name": "a",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 2, "albedo": 0.9, "phase": {"type": "isotropic"}},
    "lighting": {"sun": {"direction": [0, 0, 1], "irradiance": [1, 1, 1]}},
    "bake": )" +
         bake + R"(,
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 0],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [8, 8]}]})";
}

// A submit or dry run whose client gave up stops staging and planning with Cancelled, leaving no
// temporary folder behind; one whose client still waits is unaffected.
TEST(JobManager, AbandonedSubmitStopsAndCleansUp) {
  const fs::path dir = freshDir("abandoned");
  JobManagerOptions o;
  o.state_dir = dir.string();
  JobManager jobs(o);
  SubmitInput in;
  in.shot_json = sphereShot(R"({"method": "single"})");
  int calls = 0;
  in.abandoned = [&] { return ++calls > 0; };  // gone before the first asset is staged
  in.assets = {{"a.vdb", std::string(64, 'a')}, {"b.vdb", std::string(64, 'b')}};
  EXPECT_THROW(jobs.plan(in), Cancelled);  // not NotFound: no asset was looked up
  EXPECT_EQ(calls, 1);
  in.assets.clear();
  calls = 0;
  in.abandoned = [&] { return ++calls > 1; };  // gives up after the first check
  EXPECT_THROW(jobs.plan(in), Cancelled);      // after the shot is read, before the plan
  EXPECT_THROW(jobs.submit(in), Cancelled);
  EXPECT_TRUE(jobs.list(std::nullopt, 10).empty());
  const fs::path tmp = dir / "tmp";
  EXPECT_TRUE(!fs::exists(tmp) || fs::is_empty(tmp));
  in.abandoned = [] { return false; };
  EXPECT_EQ(jobs.plan(in).method, "single");
  fs::remove_all(dir);
}

// The dry run of an auto shot measures the scene, says what it chose and plans that method; a
// tolerance no method meets within the server's limits names /bake/tolerance.
TEST(JobManager, AutoPlanSaysWhatItChose) {
  const fs::path dir = freshDir("auto-plan");
  JobManagerOptions o;
  o.state_dir = dir.string();
  o.worker_threads = 2;
  JobManager jobs(o);
  SubmitInput in;
  in.shot_json = sphereShot(R"({"method": "auto", "tolerance": 0.2})");
  const JobPlan plan = jobs.plan(in);
  EXPECT_NE(plan.method, "auto");
  ASSERT_FALSE(plan.components.empty());
  EXPECT_EQ(plan.components.front().rfind("auto: chose " + plan.method, 0), 0u)
      << plan.components.front();
  in.shot_json.replace(in.shot_json.find("0.2}"), 3, "1e-9");
  try {
    jobs.plan(in);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shot.json: /bake/tolerance: no method"),
              std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
}

JobRecord waitFinished(JobManager& jobs, const std::string& id) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  JobRecord r = jobs.get(id);
  while (!r.terminal() && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    r = jobs.get(id);
  }
  return r;
}

// Submits and dry runs being prepared count against the queue bound, so a burst of them cannot
// pile work up beside the queue; once one is done its place is free again.
TEST(JobManager, RequestsBeingPreparedCountAgainstTheQueue) {
  const fs::path dir = freshDir("preparing");
  JobManagerOptions o;
  o.state_dir = dir.string();
  o.queue_bound = 1;
  JobManager jobs(o);
  SubmitInput slow;
  slow.shot_json = sphereShot(R"({"method": "single", "light_resolution": 8})");
  std::promise<void> inside, release;
  std::shared_future<void> released = release.get_future().share();
  bool first = true;
  slow.abandoned = [&] {
    if (first) {
      first = false;
      inside.set_value();
      released.wait();
    }
    return false;
  };
  std::thread planning([&] { jobs.plan(slow); });
  inside.get_future().wait();  // the dry run holds the one place while it stages
  SubmitInput quick;
  quick.shot_json = slow.shot_json;
  try {
    jobs.submit(quick);
    ADD_FAILURE() << "a submit got past a full bound";
  } catch (const ResourceExhaustedError& e) {
    EXPECT_NE(std::string(e.what()).find("jobs waiting or being prepared, bound 1"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(jobs.plan(quick), ResourceExhaustedError);
  release.set_value();
  planning.join();
  EXPECT_NO_THROW(jobs.plan(quick));  // the place is free again
  fs::remove_all(dir);
}

// Finished jobs are pruned beyond the count and past the age the options give (records, inputs
// and outputs), oldest first, except those a client touched within the grace period.
TEST(JobManager, FinishedJobsArePrunedByCountAndAge) {
  const fs::path dir = freshDir("prune");
  JobManagerOptions o;
  o.state_dir = dir.string();
  o.worker_threads = 2;
  o.max_finished_jobs = 2;
  o.prune_grace_seconds = 0;
  std::vector<std::string> ids;
  {
    JobManager jobs(o);
    SubmitInput in;
    in.shot_json = sphereShot(R"({"method": "single", "light_resolution": 8})");
    for (int i = 0; i < 3; ++i) {
      ids.push_back(jobs.submit(in).id);
      ASSERT_EQ(waitFinished(jobs, ids.back()).state, JobState::kSucceeded);
    }
    // The third job's end pruned the first: the oldest beyond two. The runner prunes just after
    // it publishes the end that waitFinished saw, and deletes the files after it drops the record
    // (outside the lock), so allow it a moment for both.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while ((jobs.list(std::nullopt, 0).size() > 2u || fs::exists(dir / "jobs" / ids[0])) &&
           std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    EXPECT_THROW(jobs.get(ids[0]), NotFoundError);
    EXPECT_FALSE(fs::exists(dir / "jobs" / ids[0]));
    EXPECT_EQ(jobs.list(std::nullopt, 0).size(), 2u);
    EXPECT_NO_THROW(jobs.output(ids[2], "v.exr"));
  }
  {
    o.max_finished_jobs = 0;
    o.prune_grace_seconds = 600;  // just restored: as if clients had touched them now
    o.keep_finished_seconds = 1e-9;
    JobManager jobs(o);
    EXPECT_EQ(jobs.list(std::nullopt, 0).size(), 2u);
  }
  {
    o.prune_grace_seconds = 0;
    JobManager jobs(o);  // older than the age limit: pruned at start
    EXPECT_TRUE(jobs.list(std::nullopt, 0).empty());
    EXPECT_FALSE(fs::exists(dir / "jobs" / ids[2]));
  }
  fs::remove_all(dir);
}

// Flips `n` bytes in the middle of a file in place, as a bad disk or a careless hand would.
void flipBytes(const fs::path& path, int n) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  const auto size = std::streamoff(fs::file_size(path));
  for (int i = 0; i < n; ++i) {
    f.seekg(size / 2 + i);
    const char c = char(f.get() ^ 0x5a);
    f.seekp(size / 2 + i);
    f.put(c);
  }
}

// A stored asset that no longer hashes to its name is dropped (never handed to a job) and the
// same bytes uploaded again are stored again, not skipped as "already present".
TEST(AssetStore, CorruptAssetIsDroppedAndTheNextUploadStoresIt) {
  const fs::path dir = freshDir("assets");
  AssetStore store(dir.string(), 1 << 20);
  const std::string bytes(4096, 'x');
  const std::string sha = sha256Hex(bytes);
  auto upload = [&] {
    AssetStore::Writer w(store, sha, bytes.size());
    w.write(bytes.data(), bytes.size());
    return w.finish();
  };
  const std::string path = upload();
  EXPECT_EQ(store.find(sha), path);
  flipBytes(path, 16);
  EXPECT_EQ(store.find(sha), "");
  EXPECT_FALSE(fs::exists(path));
  EXPECT_EQ(store.corruptDropped(), 1u);
  EXPECT_EQ(upload(), path);
  EXPECT_EQ(store.find(sha), path);
  fs::remove_all(dir);
}

JobManagerOptions localOptions(const fs::path& dir) {
  JobManagerOptions o;
  o.state_dir = dir.string();
  o.worker_threads = 2;
  return o;
}

// A succeeded job of method single (its bake in the cache); "" when it did not succeed.
std::string bakedJob(JobManager& jobs) {
  SubmitInput in;
  in.shot_json = sphereShot(R"({"method": "single", "light_resolution": 8})");
  const std::string id = jobs.submit(in).id;
  return waitFinished(jobs, id).state == JobState::kSucceeded ? id : "";
}

// An output changed on disk after it was written is rebuilt from the cache, else refused with a
// clear reason instead of being streamed under its original checksum.
TEST(JobManager, DamagedOutputIsRebuiltFromTheCacheElseRefused) {
  const fs::path dir = freshDir("damaged");
  JobManager jobs(localOptions(dir));
  const std::string id = bakedJob(jobs);
  ASSERT_FALSE(id.empty());
  const OutputFile good = jobs.output(id, "v.exr");
  const std::string bytes = readWholeFile(good.path);
  flipBytes(good.path, 16);
  // The bake is in the cache: the view is rendered from it again, bit for bit, and served.
  const OutputFile rebuilt = jobs.output(id, "v.exr");
  EXPECT_EQ(readWholeFile(rebuilt.path), bytes);
  EXPECT_EQ(jobs.stats().outputs_corrupt, 0u);
  // Without it, a damaged output is refused, never streamed as if intact.
  fs::remove_all(dir / "cache" / "entries");
  flipBytes(good.path, 16);
  try {
    jobs.output(id, "v.exr");
    FAIL() << "a damaged output was served";
  } catch (const FailedPreconditionError& e) {
    EXPECT_NE(std::string(e.what()).find("damaged"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find(dir.string()), std::string::npos) << e.what();
  }
  EXPECT_EQ(jobs.stats().outputs_corrupt, 1u);
  fs::remove_all(dir);
}

// The same after a restart: a finished job keeps its submission, from which the shot is read
// again to rebuild (it was refused though the cache held everything: an outside probe).
TEST(JobManager, DamagedOutputOfAJobFromBeforeARestartIsRebuilt) {
  const fs::path dir = freshDir("damaged-restart");
  std::string id, bytes, path;
  {
    JobManager jobs(localOptions(dir));
    id = bakedJob(jobs);
    ASSERT_FALSE(id.empty());
    const OutputFile good = jobs.output(id, "v.exr");
    bytes = readWholeFile(good.path);
    path = good.path;
  }
  flipBytes(path, 16);
  JobManager restarted(localOptions(dir));
  EXPECT_EQ(readWholeFile(restarted.output(id, "v.exr").path), bytes);
  EXPECT_EQ(restarted.stats().outputs_corrupt, 0u);
  fs::remove_all(dir);
}

// Bit rot keeps a file's size and time, so a fetch (which rehashes only changed files) would
// not see it: the scrub rehashes everything, rebuilds outputs and drops assets.
TEST(JobManager, TheScrubFindsBitRotRebuildsOutputsAndDropsAssets) {
  const fs::path dir = freshDir("scrub");
  JobManager jobs(localOptions(dir));
  const std::string id = bakedJob(jobs);
  ASSERT_FALSE(id.empty());
  const std::string asset = "asset bytes";
  {
    AssetStore::Writer w(jobs.assets(), sha256Hex(asset), asset.size());
    w.write(asset.data(), asset.size());
    w.finish();
  }
  const std::string asset_path = jobs.assets().find(sha256Hex(asset));
  ASSERT_FALSE(asset_path.empty());
  const OutputFile out = jobs.output(id, "v.exr");
  const std::string bytes = readWholeFile(out.path);
  auto rot = [](const std::string& path) {
    const auto t = fs::last_write_time(path);
    flipBytes(path, 4);
    fs::last_write_time(path, t);
  };
  rot(out.path);
  rot(asset_path);
  EXPECT_EQ(readWholeFile(jobs.output(id, "v.exr").path), readWholeFile(out.path))
      << "unchanged size and time: a fetch does not rehash";
  const ScrubReport r = jobs.scrub();
  EXPECT_EQ(r.outputs_damaged, 1u);
  EXPECT_EQ(r.outputs_rebuilt, 1u);
  EXPECT_EQ(r.assets_checked, 1u);
  EXPECT_EQ(r.assets_dropped, 1u);
  EXPECT_EQ(readWholeFile(out.path), bytes);
  EXPECT_TRUE(jobs.assets().find(sha256Hex(asset)).empty());
  EXPECT_EQ(jobs.scrub().outputs_damaged, 0u);
  fs::remove_all(dir);
}

// A job whose record is corrupt is reported FAILED with the reason, not dropped silently; a
// folder without any record (a submit that crashed before it was acknowledged) is skipped.
TEST(JobStore, CorruptRecordIsReportedFailedNotDropped) {
  const fs::path dir = freshDir("corrupt-record");
  JobStore store((dir / "jobs").string());
  JobRecord good;
  good.id = newJobId();
  good.state = JobState::kSucceeded;
  store.save(good);
  const std::string broken = newJobId();
  fs::create_directories(store.jobDir(broken));
  writeFileAtomic((fs::path(store.jobDir(broken)) / "job.json").string(), "{\"id\": \"x\", trunc");
  fs::create_directories(store.jobDir(newJobId()));  // no record at all
  const std::vector<JobRecord> all = store.loadAll();
  ASSERT_EQ(all.size(), 2u);
  const JobRecord& b = all[0].id == broken ? all[0] : all[1];
  EXPECT_EQ(b.id, broken);
  EXPECT_EQ(b.state, JobState::kFailed);
  EXPECT_NE(b.error.find("could not read this job's record"), std::string::npos) << b.error;
  fs::remove_all(dir);
}

// A record whose id is not its folder's name (an outside probe edited a queued job's to
// "../../x": the restarted server wrote outside its state folder) is reported FAILED under the
// folder's name, like any unreadable record, and nothing is written outside the store.
TEST(JobStore, ARecordWhoseIdIsNotItsFolderIsUnreadable) {
  const fs::path dir = freshDir("record-id");
  JobStore store((dir / "jobs").string());
  JobRecord edited;
  edited.id = newJobId();
  edited.state = JobState::kQueued;
  store.save(edited);
  const std::string file = (fs::path(store.jobDir(edited.id)) / "job.json").string();
  const std::string escape = "x" + newJobId();  // beside the test's folder: dir/../escape
  for (const std::string& forged : {"../../" + escape, newJobId()}) {
    nlohmann::json j = nlohmann::json::parse(readWholeFile(file));
    j["id"] = forged;
    writeFileAtomic(file, j.dump());
    const std::vector<JobRecord> all = store.loadAll();
    ASSERT_EQ(all.size(), 1u) << forged;
    EXPECT_EQ(all[0].id, edited.id);
    EXPECT_EQ(all[0].state, JobState::kFailed);
    EXPECT_FALSE(store.load(edited.id).has_value()) << forged;
  }
  JobRecord outside;
  outside.id = "../../" + escape;
  EXPECT_THROW(store.save(outside), InternalError);
  EXPECT_FALSE(fs::exists(dir.parent_path() / escape));
  fs::remove_all(dir);
}

// A replica: its own state folder `name` under `dir`, and dir/shared shared with the others.
JobManagerOptions replicaOptions(const fs::path& dir, const std::string& name) {
  JobManagerOptions o;
  o.state_dir = (dir / name).string();
  o.shared_dir = (dir / "shared").string();
  o.worker_threads = 2;
  return o;
}

// Two servers (replicas) with their own state folders on one shared folder: a bake made by one
// is a cache hit on the other.
TEST(JobManager, ReplicasOnOneSharedFolderShareTheirBakes) {
  const fs::path dir = freshDir("replicas");
  JobManager a(replicaOptions(dir, "a")), b(replicaOptions(dir, "b"));
  SubmitInput in;
  in.shot_json = sphereShot(R"({"method": "single", "light_resolution": 8})");
  const JobRecord first = waitFinished(a, a.submit(in).id);
  ASSERT_EQ(first.state, JobState::kSucceeded);
  EXPECT_EQ(first.bakes_computed, 1);
  const JobRecord second = waitFinished(b, b.submit(in).id);
  ASSERT_EQ(second.state, JobState::kSucceeded);
  EXPECT_EQ(second.bakes_computed, 0);
  EXPECT_EQ(second.bakes_cached, 1);
  EXPECT_TRUE(fs::exists(dir / "shared" / "cache" / "entries"));
  EXPECT_FALSE(fs::exists(dir / "a" / "cache"));

  // Either replica answers for any job: status, events, outputs.
  const JobRecord seen = b.get(first.id);
  EXPECT_EQ(seen.state, JobState::kSucceeded);
  EXPECT_EQ(seen.bakes_computed, 1);
  const OutputFile here = a.output(first.id, "v.exr"), there = b.output(first.id, "v.exr");
  EXPECT_EQ(there.sha256, here.sha256);
  EXPECT_EQ(sha256File(there.path), here.sha256);
  JobRecord r;
  const std::vector<JobEvent> events = b.events(first.id, 0, std::chrono::milliseconds(0), &r);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state, JobState::kSucceeded);
  EXPECT_TRUE(b.events(first.id, events.back().seq, std::chrono::milliseconds(0), &r).empty());
  EXPECT_THROW(b.get("j0123456789abcdef"), NotFoundError);
  EXPECT_THROW(b.output(first.id, "nope.exr"), NotFoundError);
  // A published record is read from the shared folder, where anyone with access may edit it:
  // an output name that leaves the job's folder is not served (an outside probe fetched a file
  // outside the job by such a name through the other replica).
  const fs::path published = dir / "shared" / "jobs" / first.id / "job.json";
  ASSERT_TRUE(fs::exists(published));
  nlohmann::json record = nlohmann::json::parse(readWholeFile(published.string()));
  const std::string escape = "../outside.txt";
  const fs::path target = fs::path(there.path).parent_path() / escape;
  std::ofstream(target) << "secret\n";
  record["outputs"][0]["name"] = escape;
  record["outputs"][0]["size"] = fs::file_size(target);
  record["outputs"][0]["sha256"] = sha256File(target.string());
  std::ofstream(published) << record.dump();
  EXPECT_THROW(b.output(first.id, escape), FailedPreconditionError);
  fs::remove_all(dir);
}

// A job one replica runs is cancelled through another within a few seconds, and a damaged
// published output is refused there as on its own replica.
TEST(JobManager, AJobIsCancelledThroughAnotherReplica) {
  const fs::path dir = freshDir("replica_cancel");
  JobManagerOptions oa = replicaOptions(dir, "a"), ob = replicaOptions(dir, "b");
  oa.limits.max_samples = 1000000;  // minutes of work: it must still run when cancelled
  ob.limits.max_samples = oa.limits.max_samples;
  JobManager a(oa), b(ob);
  SubmitInput in;
  in.shot_json = sphereShot(R"({"method": "pathtrace", "samples": 1000000, "max_depth": 1000})");
  const std::string id = a.submit(in).id;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (b.get(id).state != JobState::kRunning && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_EQ(b.get(id).state, JobState::kRunning);
  const auto t0 = std::chrono::steady_clock::now();
  b.cancel(id);
  const JobRecord done = waitFinished(a, id);
  EXPECT_EQ(done.state, JobState::kCancelled);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
  for (int i = 0; i < 50 && !b.get(id).terminal(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(b.get(id).state, JobState::kCancelled);
  EXPECT_THROW(b.output(id, "v.exr"), FailedPreconditionError);
  fs::remove_all(dir);
}

TEST(JobManager, RunningJobFoundAfterACrashIsMarkedFailed) {
  const fs::path dir = freshDir("crash");
  {
    JobStore store((dir / "jobs").string());
    JobRecord r;
    r.id = newJobId();
    r.state = JobState::kRunning;
    store.save(r);
  }
  JobManagerOptions o;
  o.state_dir = dir.string();
  JobManager jobs(o);
  const std::vector<JobRecord> all = jobs.list(std::nullopt, 0);
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(all[0].state, JobState::kFailed);
  EXPECT_NE(all[0].error.find("interrupted"), std::string::npos);
  EXPECT_THROW(jobs.output(all[0].id, "x.exr"), std::exception);
  // A second manager on the same folder is refused.
  EXPECT_THROW(JobManager second(o), std::runtime_error);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace cloudbake

namespace cloudbake {
namespace {

// A view rendered from the cached bake of a nearby sun says so in its header too.
// A cache and a direction index in a fresh folder, and run options that use them.
struct CachedRuns {
  explicit CachedRuns(const std::string& name)
      : dir(freshDir(name)),
        cache((dir / "cache").string(), 0),
        directions((dir / "dirs").string()) {
    opt.cache = &cache;
    opt.directions = &directions;
  }
  ~CachedRuns() { fs::remove_all(dir); }
  fs::path dir;
  BakeCache cache;
  DirectionIndex directions;
  RunOptions opt;
};

TEST(RunShot, AViewFromANearbyBakeNamesTheSunThatLitIt) {
  CachedRuns runs("tolerance-bake");
  const fs::path& dir = runs.dir;
  RunOptions& opt = runs.opt;
  std::string shot = tinyShot();
  shot.replace(shot.find(R"("method": "pathtrace", "samples": 2, "seed": 3)"), 46,
               R"("method": "single", "light_resolution": 16)");
  shot.replace(shot.find(R"(, "vdb_voxel_size": 0.25)"), 24, "");
  opt.out_dir = (dir / "a").string();
  runShot(parse(shot), opt);
  EXPECT_EQ(readExr((dir / "a/front.exr").string()).attributes.count("cloudbake:lit_sun_direction"),
            0u);
  shot.replace(shot.find("\"direction\": [0, 0, 1]"), 22, "\"direction\": [0, 0.012, 1]");
  opt.sun_tolerance_deg = 1;
  opt.out_dir = (dir / "b").string();
  EXPECT_EQ(runShot(parse(shot), opt).views_reused_direction, 1);
  const auto attributes = readExr((dir / "b/front.exr").string()).attributes;
  EXPECT_EQ(attributes.at("cloudbake:lit_sun_direction"), "0 0 1");
  EXPECT_NEAR(std::stod(attributes.at("cloudbake:lit_sun_angle_deg")), 0.6875, 1e-3);
}

TEST(RunShot, SunDirectionToleranceReusesANearbyBakeOnlyWhenAsked) {
  CachedRuns runs("tolerance");
  const fs::path& dir = runs.dir;
  RunOptions& opt = runs.opt;
  opt.out_dir = (dir / "a").string();
  const RunResult a = runShot(parse(tinyShot()), opt);
  EXPECT_EQ(a.views_rendered, 1);
  std::string tilted = tinyShot();
  tilted.replace(tilted.find("\"direction\": [0, 0, 1]"), 22, "\"direction\": [0.01, 0, 1]");
  opt.out_dir = (dir / "b").string();
  const RunResult exact = runShot(parse(tilted), opt);  // tolerance 0: its own render
  EXPECT_EQ(exact.views_rendered, 1);
  std::string tilted2 = tinyShot();
  tilted2.replace(tilted2.find("\"direction\": [0, 0, 1]"), 22, "\"direction\": [0, 0.012, 1]");
  opt.sun_tolerance_deg = 1;  // 0.69 deg from [0,0,1], 0.89 deg from [0.01,0,1]
  opt.out_dir = (dir / "c").string();
  const RunResult near = runShot(parse(tilted2), opt);
  EXPECT_EQ(near.views_rendered, 0);
  EXPECT_EQ(near.views_reused_direction, 1);
  EXPECT_NEAR(near.reused_angle_deg, 0.6875, 1e-3);  // the closest one
  EXPECT_EQ(readExr((dir / "c/front.exr").string()).layers.at("").data,
            readExr((dir / "a/front.exr").string()).layers.at("").data);
  // Its header says which sun lit it, beside the shot's own (an outside probe found only the
  // shot's); a view lit from the shot's own direction says nothing more.
  const auto attributes = readExr((dir / "c/front.exr").string()).attributes;
  EXPECT_EQ(attributes.at("cloudbake:lit_sun_direction"), "0 0 1");
  EXPECT_NE(attributes.at("cloudbake:sun_direction"), "0 0 1");
  EXPECT_NEAR(std::stod(attributes.at("cloudbake:lit_sun_angle_deg")), 0.6875, 1e-3);
  EXPECT_EQ(readExr((dir / "a/front.exr").string()).attributes.count("cloudbake:lit_sun_direction"),
            0u);
  opt.sun_tolerance_deg = 0.5;  // too far now
  opt.out_dir = (dir / "d").string();
  EXPECT_EQ(runShot(parse(tilted2), opt).views_rendered, 1);
  EXPECT_NEAR(angleDeg({0, 0, 1}, {1, 0, 0}), 90, 1e-12);
  opt.sun_tolerance_deg = std::nan("");
  EXPECT_THROW(runShot(parse(tilted2), opt), InputError);
}

}  // namespace
}  // namespace cloudbake
