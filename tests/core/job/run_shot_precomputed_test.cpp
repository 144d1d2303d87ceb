// runShot with method precomputed: an endless animation of a procedural sequence written as an
// EXR frame sequence and per-frame VDBs, the precompute reused from the cache for new lighting
// and more frames, a static volume as a one-volume database, cancellation and bad input.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <tuple>

#include "core/bake/baked_light_vdb.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/job/bake_cache.h"
#include "core/job/cache_key.h"
#include "core/job/run_shot.h"
#include "core/job/volume_limits.h"
#include "core/methods/precomputed.h"
#include "core/methods/single.h"
#include "core/shot/shot_parser.h"
#include "tests/core/job/job_test_util.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

// A procedural cloud evolving over 6 basic volumes, sun and a sky, one small view.
std::string animated(const std::string& knobs, const std::string& sun = "[1, 1, 1]",
                     const std::string& volume = "") {
  const std::string vol =
      volume.empty() ? R"({"sequence": {"procedural": {"type": "perlin_cloud", "size": [2, 2, 1],
                          "resolution": 24, "seed": 3}, "frames": 6, "time_step": 0.05}})"
                     : volume;
  return R"({"version": 1, "name": "anim", "volume": )" + vol + R"(,
    "medium": {"extinction": 6, "albedo": 0.95, "phase": {"type": "hg", "g": 0.5}},
    "lighting": {"sun": {"direction": [0.3, 0.2, 1], "irradiance": )" +
         sun + R"(}, "sky": {"radiance": [0.1, 0.15, 0.3]}},
    "bake": {"method": "precomputed", "light_resolution": 20, "sample_points": 512,
             "transfer_resolution": 10)" +
         knobs + R"(},
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 2],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 3}, "resolution": [16, 12]}],
    "outputs": {"exr": true, "vdb": true}})";
}

ShotSpec parse(const std::string& text) { return parseShot(text, ""); }

TEST(RunShotPrecomputed, WritesAFrameSequenceAndReusesThePrecompute) {
  const fs::path dir = freshDir("precomputed");
  BakeCache cache((dir / "cache").string(), 0);
  RunOptions opt;
  opt.out_dir = (dir / "a").string();
  opt.cache = &cache;
  const RunResult r = runShot(parse(animated(R"(, "frames": 4, "dissolve": 2)")), opt);
  EXPECT_EQ(r.bakes_computed, 1);
  EXPECT_EQ(r.views_from_bake, 4);
  for (int f = 0; f < 4; ++f) {
    const std::string exr = (dir / "a" / frameStem("v", f)).string() + ".exr";
    ASSERT_TRUE(fs::exists(exr)) << exr;
    const ExrContents c = readExr(exr);
    EXPECT_EQ(c.attributes.at("cloudbake:frame"), std::to_string(f));
    EXPECT_GT(sumOf(c.layers.at("single"), 1), 0);
    EXPECT_GT(sumOf(c.layers.at("multiple"), 1), 0);
    EXPECT_GT(sumOf(c.layers.at("sky"), 2), 0);
    const BakedLight light = readBakedLight((dir / "a" / frameStem("bake", f)).string() + ".vdb");
    EXPECT_EQ(light.method, "precomputed");
    EXPECT_NE(light.find(bake_grids::skyTransmittanceSh(15)), nullptr);
  }
  std::ifstream walk_file(dir / "a" / "animation.json");
  const nlohmann::json walk = nlohmann::json::parse(walk_file);
  EXPECT_EQ(walk["basic_volumes"], 6);
  EXPECT_EQ(walk["frames"].size(), 4u);

  // Another sun colour, a sky and more frames: the precompute comes from the cache, and the
  // images scale with the sun (the sun layer is linear in its irradiance).
  opt.out_dir = (dir / "b").string();
  const RunResult again =
      runShot(parse(animated(R"(, "frames": 5, "dissolve": 2)", "[2, 2, 2]")), opt);
  EXPECT_EQ(again.bakes_computed, 0);
  EXPECT_EQ(again.bakes_cached, 1);
  EXPECT_EQ(again.views_from_bake, 5);
  const double sun_a = sumOf(readExr((dir / "a" / "v.0002.exr").string()).layers.at("sun"), 0);
  const double sun_b = sumOf(readExr((dir / "b" / "v.0002.exr").string()).layers.at("sun"), 0);
  EXPECT_NEAR(sun_b / sun_a, 2.0, 1e-4);
  fs::remove_all(dir);
}

// An endless walk shows its blends again: each is lit and rendered once, and a repeat's views
// hold the pixels of that frame rendered alone (a farm task of one frame, which finds no
// earlier frame of its blend).
TEST(RunShotPrecomputed, ARepeatedBlendIsLitAndRenderedOnce) {
  const fs::path dir = freshDir("precomputed_repeat");
  BakeCache cache((dir / "cache").string(), 0);
  RunOptions opt;
  opt.cache = &cache;
  opt.out_dir = (dir / "all").string();
  const ShotSpec shot = parse(animated(R"(, "frames": 24, "dissolve": 2)"));
  const RunResult r = runShot(shot, opt);
  std::ifstream walk_file(dir / "all" / "animation.json");
  const nlohmann::json walk = nlohmann::json::parse(walk_file);
  ASSERT_EQ(walk["frames"].size(), 24u);
  std::map<std::tuple<int, int, double>, int> first;
  int repeat = -1;
  for (int f = 0; f < 24; ++f) {
    const auto& fr = walk["frames"][size_t(f)];
    const auto key = std::make_tuple(fr["a"].get<int>(), fr["b"].get<int>(), fr["w"].get<double>());
    if (!first.emplace(key, f).second && repeat < 0) repeat = f;
  }
  ASSERT_GE(repeat, 0) << "24 frames of 6 volumes repeat some blend";
  int lit = 0, replayed = 0;
  for (const StepTime& s : r.steps) {
    if (s.step == "light" && !s.values.count("repeated")) ++lit;
    if (s.step == "view" && s.values.at("repeated") == 1) ++replayed;
  }
  EXPECT_EQ(lit, int(first.size()));
  EXPECT_EQ(replayed, 24 - int(first.size()));
  EXPECT_EQ(r.views_from_bake, 24);

  opt.out_dir = (dir / "one").string();
  opt.scope.part = RunScope::Part::kRender;
  opt.scope.begin = repeat;
  opt.scope.end = repeat + 1;
  runShot(shot, opt);
  const std::string name = frameStem("v", repeat) + ".exr";
  const ExrContents all = readExr((dir / "all" / name).string());
  const ExrContents one = readExr((dir / "one" / name).string());
  EXPECT_EQ(all.attributes.at("cloudbake:frame"), std::to_string(repeat));
  ASSERT_EQ(all.layers.size(), one.layers.size());
  for (const auto& [layer, image] : one.layers) {
    EXPECT_EQ(all.layers.at(layer).data, image.data) << layer;
  }
  fs::remove_all(dir);
}

TEST(RunShotPrecomputed, ThirtyBasicVolumesWalkEndlessly) {
  // The issue's database size for tests: 30 basic volumes, 60 frames of endless animation.
  const fs::path dir = freshDir("precomputed_30");
  RunOptions opt;
  opt.out_dir = dir.string();
  const std::string shot = R"({"version": 1, "name": "thirty",
    "volume": {"sequence": {"procedural": {"type": "perlin_cloud", "size": [2, 2, 1],
               "resolution": 12, "seed": 9}, "frames": 30, "time_step": 0.03}},
    "medium": {"extinction": 6, "albedo": 0.95, "phase": {"type": "isotropic"}},
    "lighting": {"sun": {"direction": [0, 0.3, 1], "irradiance": [1, 1, 1]}},
    "bake": {"method": "precomputed", "light_resolution": 12, "sample_points": 128,
             "transfer_resolution": 6, "frames": 60, "dissolve": 3},
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 1],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 3}, "resolution": [8, 8]}],
    "outputs": {"exr": true, "vdb": false}})";
  const RunResult r = runShot(parse(shot), opt);
  EXPECT_EQ(r.views_from_bake, 60);
  std::ifstream walk_file(dir / "animation.json");
  const nlohmann::json walk = nlohmann::json::parse(walk_file);
  ASSERT_EQ(walk["frames"].size(), 60u);
  int jumps = 0;
  for (size_t f = 0; f < 60; ++f) {
    const auto& fr = walk["frames"][f];
    EXPECT_GE(fr["a"].get<int>(), 0);
    EXPECT_LT(fr["b"].get<int>(), 30);
    if (fr["w"].get<double>() < 1) ++jumps;
    EXPECT_TRUE(fs::exists(dir / (frameStem("v", int(f)) + ".exr")));
  }
  EXPECT_GT(jumps, 0) << "60 frames of 30 volumes cannot play without a jump";
  fs::remove_all(dir);
}

// A static volume is one basic volume, every frame the same image and the walk all of it; an
// empty one too, rendering the background (an outside probe: it wrote no walk, in a run nor in a
// farm's gather).
TEST(RunShotPrecomputed, AStaticVolumeIsOneBasicVolume) {
  for (const char* density : {"1", "0"}) {
    SCOPED_TRACE(density);
    const fs::path dir = freshDir("precomputed_static");
    RunOptions opt;
    opt.out_dir = dir.string();
    const std::string sphere =
        std::string(R"({"sphere": {"center": [0, 0, 0], "radius": 1, "density": )") + density +
        "}}";
    const RunResult r = runShot(parse(animated(R"(, "frames": 3)", "[1, 1, 1]", sphere)), opt);
    EXPECT_EQ(r.views_from_bake, 3);
    const Image a = readExr((dir / "v.0000.exr").string()).layers.at("");
    const Image b = readExr((dir / "v.0002.exr").string()).layers.at("");
    EXPECT_EQ(a.data, b.data);
    std::ifstream walk_file(dir / "animation.json");
    ASSERT_TRUE(walk_file.good());
    const nlohmann::json walk = nlohmann::json::parse(walk_file);
    EXPECT_EQ(walk["basic_volumes"], 1);
    ASSERT_EQ(walk["frames"].size(), 3u);
    for (const auto& f : walk["frames"]) {
      EXPECT_EQ(f["a"], 0);
      EXPECT_EQ(f["b"], 0);
      EXPECT_EQ(f["w"], 1.0);
    }
    fs::remove_all(dir);
  }
}

TEST(RunShotPrecomputed, CancelsAndRefusesBadInput) {
  const fs::path dir = freshDir("precomputed_bad");
  RunOptions opt;
  opt.out_dir = dir.string();
  int calls = 0;
  opt.progress = [&](const RunProgress&) { return ++calls < 5; };
  EXPECT_THROW(runShot(parse(animated("")), opt), Cancelled);
  opt.progress = {};
  // A database of one basic volume cannot animate: the error names the frame count (a shot
  // says so as it is read, BadShots; a ShotSpec built otherwise, here).
  try {
    ShotSpec one = parse(animated(""));
    std::get<SequenceVolumeSpec>(one.volume).frames = 1;
    runShot(one, opt);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/volume/sequence/frames: an endless animation needs at "
                                         "least 2 basic volumes"),
              std::string::npos)
        << e.what();
  }
  // Other methods refuse a sequence by name.
  ShotSpec s = parse(animated(""));
  s.bake.method = "single";
  s.bake.knobs = defaultKnobValues(singleMethod().info().knobs);
  try {
    checkRunnable(s, "shot.json");
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/volume/sequence"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

// Every file of a folder, by name, with its bytes.
std::map<std::string, std::string> folderBytes(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    std::ifstream in(e.path(), std::ios::binary);
    out[e.path().filename().string()] =
        std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  return out;
}

// A re-render into the folder of an earlier complete run (other lighting, so other pixels) that
// is cancelled midway, or fails, leaves the earlier run as it was: its frames and the
// animation.json that lists them. One that finishes replaces them and leaves nothing hidden.
TEST(RunShotPrecomputed, AnInterruptedReRenderLeavesTheEarlierRunAsItWas) {
  const fs::path dir = freshDir("precomputed_rerender");
  RunOptions opt;
  opt.out_dir = dir.string();
  opt.png = true;
  runShot(parse(animated(R"(, "frames": 6, "dissolve": 2)")), opt);
  const std::map<std::string, std::string> before = folderBytes(dir);
  ASSERT_EQ(before.count("animation.json"), 1u);
  ASSERT_EQ(before.count("v.0005.exr"), 1u);
  ASSERT_EQ(before.count("v.0005.png"), 1u);

  const ShotSpec other = parse(animated(R"(, "frames": 6, "dissolve": 2)", "[2, 1, 0.5]"));
  // Cancelled once it has written over a few earlier files (kept aside under hidden names).
  size_t replaced = 0;
  opt.progress = [&](const RunProgress&) {
    replaced = 0;
    for (const auto& e : fs::directory_iterator(dir)) {
      replaced += e.path().filename().string().find(".replaced.") != std::string::npos;
    }
    return replaced < 3;
  };
  EXPECT_THROW(runShot(other, opt), Cancelled);
  EXPECT_GE(replaced, 3u) << "the cancel must come after frames were written over";
  EXPECT_EQ(folderBytes(dir), before);
  // Cancelled after its last file, as it reports that it is done: still cancelled, still put
  // back (a late signal gave exit 6 over a finished run whose earlier files were deleted).
  opt.progress = [&](const RunProgress& p) { return p.stage != "done"; };
  EXPECT_THROW(runShot(other, opt), Cancelled);
  EXPECT_EQ(folderBytes(dir), before);

  // Finished: every frame replaced, and none of the earlier files is kept.
  opt.progress = {};
  runShot(other, opt);
  const std::map<std::string, std::string> after = folderBytes(dir);
  EXPECT_EQ(after.size(), before.size());
  for (const auto& [name, bytes] : after) {
    EXPECT_NE(name[0], '.') << name;
    if (name.find(".exr") != std::string::npos) {
      EXPECT_NE(bytes, before.at(name)) << name;
    }
  }
  fs::remove_all(dir);
}

TEST(RunShotPrecomputed, TheDatabaseCountsAgainstTheServersVoxelLimit) {
  // 6 basic volumes of (20 + 2)^3 voxels, 17 floats each: 1086096 voxel-equivalents.
  const ShotSpec s = parse(animated(""));
  EXPECT_NO_THROW(checkShotVoxels(s, 1100000, "shot.json"));
  try {
    checkShotVoxels(s, 1000000, "shot.json");
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/bake/light_resolution: a database of 6 basic volume(s)"),
              std::string::npos)
        << e.what();
  }
  // The walk's two tables of frames^2 doubles count too: 100000 basic volumes hold 4e10 floats
  // there, more than their database's 1.8e10.
  const ShotSpec many = parse(animated("", "[1, 1, 1]", R"({"sequence": {"procedural":
      {"type": "perlin_cloud", "size": [2, 2, 1], "resolution": 24}, "frames": 100000}})"));
  try {
    checkShotVoxels(many, 20000000000, "shot.json");
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/volume/sequence/frames: the walk over 100000 basic "
                                         "volumes holds two tables"),
              std::string::npos)
        << e.what();
  }
}

TEST(RunShotPrecomputed, PrecomputeKeyIgnoresLightingAndFrames) {
  const ShotCacheKeys a = computeCacheKeys(parse(animated(R"(, "frames": 4)")));
  const ShotCacheKeys b =
      computeCacheKeys(parse(animated(R"(, "frames": 9, "sigma": 0.2)", "[3, 1, 1]")));
  const ShotCacheKeys c = computeCacheKeys(parse(animated(R"(, "cut_error": 0.002)")));
  EXPECT_FALSE(a.precompute.empty());
  EXPECT_EQ(a.precompute, b.precompute);
  EXPECT_NE(a.precompute, c.precompute);
}

}  // namespace
}  // namespace cloudbake
