// Runs `cloudbake render` on real shot files and checks exit codes, messages and outputs.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>
#include <thread>

#include "core/io/exr_io.h"
#include "core/io/vdb_io.h"
#include "core/volume/analytic.h"
#include "tests/tiny_volume.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const fs::path kExamples = fs::path(CLOUDBAKE_SOURCE_DIR) / "examples";

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

struct CliResult {
  int rc = -1;
  std::string out, err;
};

class RenderCli : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device rd;
    dir_ = fs::temp_directory_path() /
           ("cloudbake_cli_test_" + std::to_string(rd()) + std::to_string(rd()));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  // Runs cloudbake with `args` (already shell-quoted where needed), after `prefix` (such as
  // "timeout 20 ").
  CliResult run(const std::string& args, const std::string& prefix = "") {
    const fs::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
    const std::string cmd = prefix + "'" + CLOUDBAKE_EXE + "' " + args + " > '" + out.string() +
                            "' 2> '" + err.string() + "'";
    const int status = std::system(cmd.c_str());
    CliResult r;
    r.rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
  }
  fs::path writeShot(const std::string& name, const json& j) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << j.dump(2);
    return p;
  }
  static json slab() { return json::parse(slurp(kExamples / "slab.json")); }
  // Renders the slab's view at `side` x `side` pixels, 1 sample, into dir_: its EXR's path.
  std::string renderSmallSlab(int side) {
    json j = slab();
    j["views"][0]["resolution"] = {side, side};
    j["bake"]["samples"] = 1;
    const CliResult r = run("render '" + writeShot("small.json", j).string() + "' --out '" +
                            dir_.string() + "' --quiet");
    EXPECT_EQ(r.rc, 0) << r.err;
    return (dir_ / (j["views"][0]["name"].get<std::string>() + ".exr")).string();
  }
  fs::path dir_;
};

double mean(const Image& im, int c) {
  double s = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x) s += im.at(x, y)[c];
  return s / (double(im.width) * im.height);
}

TEST_F(RenderCli, RendersTheDesignSlabWithAllLayers) {
  const fs::path out = dir_ / "out";
  const CliResult r = run("render '" + (kExamples / "slab.json").string() + "' --out '" +
                          out.string() + "' --samples 32 --threads 2");
  ASSERT_EQ(r.rc, 0) << r.err;
  const fs::path exr = out / "nadir.exr";
  ASSERT_TRUE(fs::exists(exr));
  EXPECT_EQ(r.out, exr.string() + "\n");  // stdout lists exactly the written files
  EXPECT_NE(r.err.find("view 'nadir'"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("100%"), std::string::npos) << r.err;

  const ExrContents c = readExr(exr.string());
  EXPECT_EQ(c.width, 32);
  EXPECT_EQ(c.height, 32);
  for (const char* layer : {"", "sun", "sky", "single", "multiple"}) {
    EXPECT_EQ(c.layers.count(layer), 1u) << "layer '" << layer << "'";
  }
  const Image& beauty = c.layers.at("");
  ASSERT_EQ(beauty.channels, 4);
  for (float v : beauty.data) ASSERT_TRUE(std::isfinite(v));
  // Black sky: all light comes from the sun, and beauty = single + multiple (no background).
  for (int ch = 0; ch < 3; ++ch) {
    const double b = mean(beauty, ch);
    EXPECT_GT(b, 0.01);
    EXPECT_LT(b, 1.0);  // a slab under E = pi cannot reflect more than L = 1 on average
    EXPECT_NEAR(mean(c.layers.at("sun"), ch), b, 1e-5 * b);
    EXPECT_NEAR(mean(c.layers.at("single"), ch) + mean(c.layers.at("multiple"), ch), b, 1e-4 * b);
    EXPECT_EQ(mean(c.layers.at("sky"), ch), 0.0);
  }
  EXPECT_EQ(c.attributes.at("cloudbake:view"), "nadir");
  EXPECT_EQ(c.attributes.at("cloudbake:samples"), "32");
}

TEST_F(RenderCli, EveryExampleRendersAtOneSample) {
  const bool have_shared = fs::exists(fs::path(CLOUDBAKE_SHARED_DIR) / "data");
  int rendered = 0;
  for (const auto& e : fs::directory_iterator(kExamples)) {
    if (e.path().extension() != ".json") continue;
    const std::string text = slurp(e.path());
    if (!have_shared && text.find("shared/data") != std::string::npos) continue;
    SCOPED_TRACE(e.path().string());
    const fs::path out = dir_ / e.path().stem();
    const CliResult r =
        run("render '" + e.path().string() + "' --out '" + out.string() + "' --samples 1 --quiet");
    ASSERT_EQ(r.rc, 0) << r.err;
    const json shot = json::parse(text);
    // Method precomputed writes a frame sequence: check its first frame.
    const bool frames = shot["bake"].value("method", "") == "precomputed";
    for (const json& view : shot["views"]) {
      const fs::path exr =
          out / (view["name"].get<std::string>() + (frames ? ".0000.exr" : ".exr"));
      ASSERT_TRUE(fs::exists(exr)) << exr;
      const ExrContents c = readExr(exr.string());
      EXPECT_EQ(c.width, view["resolution"][0].get<int>());
      double sum = 0;
      for (float v : c.layers.at("").data) {
        ASSERT_TRUE(std::isfinite(v));
        sum += v;
      }
      EXPECT_GT(sum, 0.0) << "an example renders something";
    }
    ++rendered;
  }
  EXPECT_GE(rendered, 2);
  if (!have_shared) GTEST_SKIP() << "examples using " << CLOUDBAKE_SHARED_DIR << " were skipped";
}

TEST_F(RenderCli, SameSeedSameImageAtAnyThreadCount) {
  ASSERT_EQ(run("render '" + (kExamples / "slab.json").string() + "' --out '" +
                (dir_ / "a").string() + "' --samples 8 --threads 1 --quiet")
                .rc,
            0);
  const CliResult r = run("render '" + (kExamples / "slab.json").string() + "' --out '" +
                          (dir_ / "b").string() + "' --samples 8 --threads 2 --quiet");
  ASSERT_EQ(r.rc, 0);
  EXPECT_EQ(r.err, "");  // --quiet
  EXPECT_EQ(readExr((dir_ / "a/nadir.exr").string()).layers.at("").data,
            readExr((dir_ / "b/nadir.exr").string()).layers.at("").data);
}

TEST_F(RenderCli, WritesVdbAndPngWhenAsked) {
  json j = slab();
  j["volume"]["box"] = {{"min", {-1, -1, 0}}, {"max", {1, 1, 0.5}}, {"density", 2.0}};
  j["outputs"] = {{"exr", true}, {"vdb", true}, {"vdb_voxel_size", 0.1}};
  const fs::path shot = writeShot("small.json", j);
  const CliResult r = run("render '" + shot.string() + "' --out '" + (dir_ / "o").string() +
                          "' --samples 2 --png --quiet");
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "o/nadir.png"));
  ASSERT_TRUE(fs::exists(dir_ / "o/bake.vdb"));
  EXPECT_NE(r.out.find((dir_ / "o/bake.vdb").string()), std::string::npos);
  VdbFileReader vdb((dir_ / "o/bake.vdb").string());
  ASSERT_FALSE(vdb.grids().empty());
  EXPECT_EQ(vdb.grids()[0].name, "density");
  EXPECT_NEAR(vdb.floatAt("density", Vec3(0.05, 0.05, 0.25)), 2.0, 1e-6);
  EXPECT_EQ(vdb.floatAt("density", Vec3(0.05, 0.05, 0.75)), 0.0);
}

TEST_F(RenderCli, StatsJsonHasCountersStepsAndPeakMemory) {
  json j = slab();
  j["bake"] = {{"method", "single"}, {"light_resolution", 12}};
  const fs::path shot = writeShot("stats.json", j);
  const fs::path stats = dir_ / "stats.out.json";
  const CliResult r = run("render '" + shot.string() + "' --out '" + (dir_ / "o").string() +
                          "' --quiet --stats-json '" + stats.string() + "'");
  ASSERT_EQ(r.rc, 0) << r.err;
  const json s = json::parse(slurp(stats));
  EXPECT_EQ(s.at("method"), "single");
  EXPECT_EQ(s.at("counters").at("bakes_computed"), 1);
  EXPECT_EQ(s.at("counters").at("views_from_bake"), 1);
  EXPECT_GT(s.at("peak_rss_mib").get<double>(), 1.0);
  std::set<std::string> kinds;
  double sum = 0;
  for (const json& step : s.at("steps")) {
    kinds.insert(step.at("step").get<std::string>());
    EXPECT_GE(step.at("seconds").get<double>(), 0.0);
    sum += step.at("seconds").get<double>();
    if (step.at("step") == "view") {  // writing the EXR is a part of the view's seconds
      EXPECT_GT(step.at("write").get<double>(), 0.0);
      EXPECT_LE(step.at("write").get<double>(), step.at("seconds").get<double>());
      EXPECT_GT(step.at("traced").get<double>(), 0.0);  // a view from the bake: its film
      EXPECT_LE(step.at("traced").get<double>(), 1.0);
    }
  }
  EXPECT_EQ(kinds, (std::set<std::string>{"volume", "bake", "view"}));
  EXPECT_LE(sum, s.at("seconds").get<double>() + 1e-6);  // steps are parts of the run
  // An unwritable path is a clear error naming the flag, not a success without the file.
  const CliResult bad =
      run("render '" + shot.string() + "' --out '" + (dir_ / "o").string() +
          "' --quiet --stats-json '" + (dir_ / "no/such/dir/s.json").string() + "'");
  EXPECT_EQ(bad.rc, 2) << bad.err;
  EXPECT_NE(bad.err.find("--stats-json"), std::string::npos) << bad.err;
}

TEST_F(RenderCli, BadShotExitsWith2AndNamesTheField) {
  json j = slab();
  j["medium"]["albedo"] = 1.5;
  const CliResult r = run("render '" + writeShot("bad.json", j).string() + "' --out '" +
                          (dir_ / "o").string() + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("bad.json: /medium/albedo: must be in [0, 1], got 1.5"), std::string::npos)
      << r.err;
  EXPECT_EQ(r.out, "");
  EXPECT_FALSE(fs::exists(dir_ / "o/nadir.exr"));
}

// A folder the run cannot write in is refused before the render, not at its first file. /proc's
// folders refuse new files even to root (the tests run as root, whom modes do not stop), and
// one that is a regular file cannot be a folder.
TEST_F(RenderCli, AnOutputFolderThatCannotBeWrittenIsRefusedBeforeTheRender) {
  std::ofstream(dir_ / "file") << "x";
  for (const std::string& out : {std::string("/proc/self"), (dir_ / "file").string()}) {
    const CliResult r =
        run("render '" + writeShot("s.json", slab()).string() + "' --out '" + out + "'");
    EXPECT_EQ(r.rc, 2) << out;
    EXPECT_NE(r.err.find("out: cannot"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("path trace"), std::string::npos) << "rendered first: " << r.err;
  }
  // A folder it can write in keeps no trace of the check.
  ASSERT_EQ(run("render '" + writeShot("s.json", slab()).string() + "' --out '" +
                (dir_ / "o").string() + "' --quiet")
                .rc,
            0);
  for (const auto& e : fs::directory_iterator(dir_ / "o")) {
    EXPECT_EQ(e.path().filename().string().find(".cloudbake-write-test"), std::string::npos);
  }
}

TEST_F(RenderCli, MalformedJsonAndBadArgumentsExitWith2) {
  std::ofstream(dir_ / "broken.json") << "{\"version\": 1,";
  CliResult r =
      run("render '" + (dir_ / "broken.json").string() + "' --out '" + dir_.string() + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("invalid JSON"), std::string::npos) << r.err;
  for (const char* samples : {"0", "-1", "1000001"}) {  // -1 was once "not given", so ignored
    r = run("render '" + (kExamples / "slab.json").string() + "' --out '" + dir_.string() +
            "' --samples=" + samples);
    EXPECT_EQ(r.rc, 2) << samples;
    EXPECT_NE(r.err.find("--samples: must be in [1, 1000000], got " + std::string(samples)),
              std::string::npos)
        << r.err;
  }
  r = run("render '" + (kExamples / "slab.json").string() + "'");  // no --out
  EXPECT_EQ(r.rc, 2);
}

TEST_F(RenderCli, MissingFilesExitWith3) {
  CliResult r = run("render '" + (dir_ / "nope.json").string() + "' --out '" + dir_.string() + "'");
  EXPECT_EQ(r.rc, 3);
  EXPECT_NE(r.err.find("nope.json: file not found"), std::string::npos) << r.err;
  json j = slab();
  j["volume"] = {{"vdb", {{"path", "missing.vdb"}}}};
  r = run("render '" + writeShot("vdb.json", j).string() + "' --out '" + dir_.string() + "'");
  EXPECT_EQ(r.rc, 3);
  EXPECT_NE(r.err.find("/volume/vdb/path: file not found"), std::string::npos) << r.err;
}

// Method auto's dry run says what it chose and writes nothing; a tolerance no method meets
// within the limits is an input error naming /bake/tolerance.
TEST_F(RenderCli, AutoDryRunSaysWhatItChose) {
  json j = slab();
  j["bake"] = {{"method", "auto"}, {"tolerance", 0.2}};
  const fs::path out = dir_ / "auto-out";
  CliResult r = run("render '" + writeShot("auto.json", j).string() + "' --out '" + out.string() +
                    "' --dry-run --quiet");
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("auto: chose "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("predicted error"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(out / "view.exr"));
  j["bake"] = {{"method", "auto"}, {"tolerance", 1e-6}};
  r = run("render '" + writeShot("auto2.json", j).string() + "' --out '" + out.string() +
          "' --dry-run --quiet");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("/bake/tolerance: no method is predicted to meet"), std::string::npos)
      << r.err;
}

TEST_F(RenderCli, AssetErrorsFoundWhileBuildingNameTheField) {
  // A file that exists but is not a VDB passes the parser and fails in the volume loader.
  std::ofstream(dir_ / "fake.vdb") << "not a vdb";
  json j = slab();
  j["volume"] = {{"vdb", {{"path", "fake.vdb"}}}};
  const CliResult r =
      run("render '" + writeShot("fake.json", j).string() + "' --out '" + dir_.string() + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("fake.json: /volume/vdb: "), std::string::npos) << r.err;
}

// Work too large for the machine is refused before anything runs, naming the field: the
// limit is half of the physical memory in floats by default, and --max-voxels sets it.
TEST_F(RenderCli, WorkTooLargeForTheMemoryIsRefusedBeforeItRuns) {
  json j = slab();
  j["volume"] = {{"sphere", {{"center", {0, 0, 0}}, {"radius", 1}, {"density", 1}}}};
  // About 3 x 10^10 floats of tallies (120 GB) on a lattice of 322^3 voxels, under the bake
  // lattices' own limit of 2^25 voxels (which the parser checks over a sphere's bounds).
  j["bake"] = {{"method", "photon"}, {"photons", 1000},        {"order", 8},
               {"zonal_order", 64},  {"light_resolution", 16}, {"tally_resolution", 320}};
  const std::string shot = writeShot("huge.json", j).string();
  CliResult r = run("render '" + shot + "' --out '" + (dir_ / "huge").string() + "' --quiet");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("huge.json: /bake/tally_resolution: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("(--max-voxels)"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "huge"));
  // A small shot under an explicit limit its lattice exceeds; 0 lifts the limit.
  j["bake"] = {{"method", "single"}, {"light_resolution", 16}};
  const std::string small = writeShot("small.json", j).string();
  r = run("render '" + small + "' --out '" + (dir_ / "s").string() + "' --quiet --max-voxels 1000");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("/bake/light_resolution: "), std::string::npos) << r.err;
  r = run("render '" + small + "' --out '" + (dir_ / "s").string() + "' --quiet --max-voxels 0");
  EXPECT_EQ(r.rc, 0) << r.err;
  // -1 too: it once stood for the default inside, and passed.
  for (const char* bad : {"-5", "-1"}) {
    r = run("render '" + small + "' --out '" + (dir_ / "s").string() + "' --max-voxels " + bad);
    EXPECT_EQ(r.rc, 2) << bad;
    EXPECT_NE(r.err.find("--max-voxels: must be at least 0"), std::string::npos) << r.err;
  }
}

// A views' step far under the lattice's voxel is refused as the bake starts, before its work,
// which it would otherwise have waited for (4M photons here).
TEST_F(RenderCli, AStepFarUnderTheVoxelIsRefusedBeforeTheBake) {
  json j = slab();
  j["volume"] = {{"sphere", {{"center", {0, 0, 0}}, {"radius", 1}, {"density", 1}}}};
  j["views"][0]["resolution"] = {8, 8};
  for (const char* method : {"single", "pointcloud", "photon"}) {
    j["bake"] = {{"method", method}, {"light_resolution", 16}, {"step", 1e-300}};
    if (std::string(method) == "photon") j["bake"]["photons"] = 4000000;
    const CliResult r = run("render '" + writeShot("step.json", j).string() + "' --out '" +
                            (dir_ / "step").string() + "'");
    EXPECT_EQ(r.rc, 2) << method;
    EXPECT_NE(r.err.find("step.json: /bake/step: must be at least 1e-4 voxel"), std::string::npos)
        << r.err;
    // (No stage of the bake reported: "slab: bake: lattice", ...)
    EXPECT_EQ(r.err.find("slab: bake: "), std::string::npos) << method << ": " << r.err;
  }
}

// A step over four lattice voxels would put no sample inside a lone block of cloud, which then
// vanished from the view with success (an outside probe: a sphere 16 voxels across, step 5
// world units); refused naming the field, before the bake where it is far over.
TEST_F(RenderCli, AStepOverFourVoxelsIsRefused) {
  json j = slab();
  j["volume"] = {{"sphere", {{"center", {0, 0, 0}}, {"radius", 1}, {"density", 1}}}};
  j["views"][0]["resolution"] = {8, 8};
  for (const char* method : {"single", "pointcloud", "photon", "precomputed"}) {
    for (double step : {5.0, 0.6}) {  // the lattice's voxel is 0.125 world units
      j["bake"] = {{"method", method}, {"light_resolution", 16}, {"step", step}};
      const CliResult r = run("render '" + writeShot("step.json", j).string() + "' --out '" +
                              (dir_ / "step").string() + "'");
      EXPECT_EQ(r.rc, 2) << method << " " << step;
      EXPECT_NE(r.err.find("step.json: /bake/step: must be at most 4 lattice voxels"),
                std::string::npos)
          << r.err;
      if (step > 1) {
        EXPECT_EQ(r.err.find("slab: bake: "), std::string::npos) << method << ": " << r.err;
      }
    }
    j["bake"]["step"] = 0.5;  // four voxels: allowed
    const CliResult ok = run("render '" + writeShot("step.json", j).string() + "' --out '" +
                             (dir_ / "step").string() + "' --quiet");
    EXPECT_EQ(ok.rc, 0) << method << ": " << ok.err;
  }
}

// A run that fails at its first frame writes no animation.json naming frames it never wrote.
TEST_F(RenderCli, AFailedAnimationLeavesNoWalk) {
  json j = slab();
  j["volume"] = {{"sphere", {{"center", {0, 0, 0}}, {"radius", 1}, {"density", 1}}}};
  j["views"][0]["resolution"] = {8, 8};
  // A march step far under the lattice's voxel: refused when the first frame renders.
  j["bake"] = {{"method", "precomputed"}, {"light_resolution", 8}, {"step", 1e-300}};
  const fs::path out = dir_ / "anim";
  const CliResult r =
      run("render '" + writeShot("anim.json", j).string() + "' --out '" + out.string() + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("/bake/step: "), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out / "animation.json"));
}

// A VDB file that leads OpenVDB's reader past its buffers (tests/data/fuzz) is read in a child
// process by default, as the server reads it: the command fails as bad input naming the file,
// and does not crash.
TEST_F(RenderCli, ACorruptVdbIsAnErrorNotACrash) {
  const std::string bad =
      std::string(CLOUDBAKE_SOURCE_DIR) + "/tests/data/fuzz/vdb_blosc_abort.vdb";
  json j = slab();
  j["volume"] = {{"vdb", {{"path", bad}}}};
  CliResult r = run("render '" + writeShot("bad.json", j).string() + "' --out '" +
                    (dir_ / "bad").string() + "' --quiet");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("bad.json: /volume/vdb: " + bad + ": not a readable OpenVDB file"),
            std::string::npos)
      << r.err;
  r = run("bake-slice '" + bad + "' --grid density --png '" + (dir_ / "x.png").string() + "'");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find(bad + ": not a readable OpenVDB file"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "x.png"));
}

// A tiny pointcloud bake, inspected with bake-slice and compared with compare.
TEST_F(RenderCli, BakeSliceAndCompareInspectABake) {
  json j = slab();
  j["volume"] = {{"sphere", {{"center", {0, 0, 0}}, {"radius", 1}, {"density", 1}}}};
  j["bake"] = {{"method", "pointcloud"}, {"points", 1024}, {"passes", 3}, {"light_resolution", 16}};
  j["views"][0]["camera"]["position"] = {0, 0, 5};
  j["views"][0]["resolution"] = {16, 16};
  j["outputs"] = {{"exr", true}, {"vdb", true}};
  const fs::path out = dir_ / "pc";
  CliResult r =
      run("render '" + writeShot("pc.json", j).string() + "' --out '" + out.string() + "' --quiet");
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string bake = (out / "bake.vdb").string();
  r = run("bake-slice '" + bake + "' --grid mie_ratio --axis y --png '" +
          (dir_ / "r.png").string() + "'");
  ASSERT_EQ(r.rc, 0) << r.err;
  const json slice = json::parse(r.out);
  EXPECT_GE(slice.at("min").get<double>(), 0.0);
  EXPECT_LE(slice.at("max").get<double>(), 1.0);
  // The lattice: 16 voxels along the sphere's diameter of 2, plus a voxel of margin each side.
  const auto lattice = slice.at("lattice").get<std::vector<int>>();
  ASSERT_EQ(lattice.size(), 3u);
  EXPECT_EQ(*std::max_element(lattice.begin(), lattice.end()), 18);
  const double voxel = slice.at("voxel_size").get<double>();
  EXPECT_GE(16 * voxel, 2.0 - 1e-9);
  EXPECT_LE(16 * voxel, 2.0 + 2 * voxel);
  EXPECT_GT(fs::file_size(dir_ / "r.png"), 100u);
  EXPECT_EQ(slurp(dir_ / "r.png").substr(1, 3), "PNG");
  r = run("bake-slice '" + bake + "' --grid Co --axis z --at 0.1 --png '" +
          (dir_ / "co.png").string() + "'");
  EXPECT_EQ(r.rc, 0) << r.err;
  r = run("bake-slice '" + bake + "' --grid colour --png '" + (dir_ / "x.png").string() + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--grid: 'colour' is not in"), std::string::npos) << r.err;
  r = run("bake-slice '" + bake + "' --grid density --at 99 --png '" + (dir_ / "x.png").string() +
          "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--at"), std::string::npos) << r.err;
  r = run("bake-slice '" + (dir_ / "none.vdb").string() + "' --grid density --png '" +
          (dir_ / "x.png").string() + "'");
  EXPECT_EQ(r.rc, 3);
  r = run("bake-slice '" + dir_.string() + "' --grid density --png '" + (dir_ / "x.png").string() +
          "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("not a file"), std::string::npos) << r.err;
  // Numbers that are not finite, or a range whose width is not, are refused, not used.
  for (const std::string flags : {"--at nan", "--at inf", "--range 0,inf", "--range nan,1",
                                  "--range 0,1,2", "--range -1e308,1e308", "--range 1,1"}) {
    r = run("bake-slice '" + bake + "' --grid density " + flags + " --png '" +
            (dir_ / "x.png").string() + "'");
    EXPECT_EQ(r.rc, 2) << flags;
    EXPECT_NE(r.err.find(flags.substr(0, flags.find(' '))), std::string::npos) << r.err;
  }
  r = run("bake-slice '" + bake + "' --grid density --at 1e300 --png '" +
          (dir_ / "x.png").string() + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--at: 1e+300 is outside"), std::string::npos) << r.err;

  // compare: a view against itself is exact; against a brighter copy it is not.
  const std::string view = (out / "nadir.exr").string();
  r = run("compare '" + view + "' '" + view + "' --json");
  ASSERT_EQ(r.rc, 0) << r.err;
  const json same = json::parse(r.out);
  EXPECT_EQ(same.at("beauty").at("rel_rmse").get<double>(), 0.0);
  EXPECT_GT(same.at("multiple").at("mean").get<double>(), 0.0);
  j["lighting"]["sun"]["irradiance"] = {6.28318, 6.28318, 6.28318};  // twice as bright
  const fs::path out2 = dir_ / "pc2";
  r = run("render '" + writeShot("pc2.json", j).string() + "' --out '" + out2.string() +
          "' --quiet");
  ASSERT_EQ(r.rc, 0) << r.err;
  r = run("compare '" + (out2 / "nadir.exr").string() + "' '" + view + "' --json");
  ASSERT_EQ(r.rc, 0) << r.err;
  const json twice = json::parse(r.out);
  EXPECT_NEAR(twice.at("sun").at("mean").get<double>(),
              2 * twice.at("sun").at("reference_mean").get<double>(), 1e-6);
  // Per channel too, averaging to the layer's mean; a sun brighter in red alone shows in red
  // alone (the layer's mean had hidden one channel's error behind the others').
  const json& ch = twice.at("sun").at("channel_means");
  const json& ch_ref = twice.at("sun").at("reference_channel_means");
  ASSERT_EQ(ch.size(), 3u);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(ch[c].get<double>(), 2 * ch_ref[c].get<double>(), 1e-6) << c;
  }
  EXPECT_NEAR((ch[0].get<double>() + ch[1].get<double>() + ch[2].get<double>()) / 3,
              twice.at("sun").at("mean").get<double>(), 1e-6);
  j["lighting"]["sun"]["irradiance"] = {6.28318, 3.14159, 3.14159};
  const fs::path red = dir_ / "red";
  r = run("render '" + writeShot("red.json", j).string() + "' --out '" + red.string() +
          "' --quiet");
  ASSERT_EQ(r.rc, 0) << r.err;
  r = run("compare '" + (red / "nadir.exr").string() + "' '" + view + "' --json");
  ASSERT_EQ(r.rc, 0) << r.err;
  const json reds = json::parse(r.out).at("sun");
  EXPECT_NEAR(reds.at("channel_means")[0].get<double>(),
              2 * reds.at("reference_channel_means")[0].get<double>(), 1e-6);
  EXPECT_NEAR(reds.at("channel_means")[1].get<double>(),
              reds.at("reference_channel_means")[1].get<double>(), 1e-6);
  j["lighting"]["sun"]["irradiance"] = {6.28318, 6.28318, 6.28318};
  // x = 2r: RMSE = sqrt(mean(r^2)), so rel. RMSE = sqrt(mean(r^2)) / mean(r).
  const Image ref = readExr(view).layers.at("sun");
  double s1 = 0, s2 = 0;
  for (float v : ref.data) {
    s1 += v;
    s2 += double(v) * v;
  }
  EXPECT_NEAR(twice.at("sun").at("rel_rmse").get<double>(),
              std::sqrt(s2 / double(ref.data.size())) / (s1 / double(ref.data.size())), 1e-4);
  // scattered = sun + sky; the cloud mask drops the dark background, so the cloud's mean rises.
  EXPECT_NEAR(twice.at("scattered").at("reference_mean").get<double>(),
              twice.at("sun").at("reference_mean").get<double>() +
                  twice.at("sky").at("reference_mean").get<double>(),
              1e-6);
  r = run("compare '" + (out2 / "nadir.exr").string() + "' '" + view +
          "' --json --cloud-alpha 0.3");
  ASSERT_EQ(r.rc, 0) << r.err;
  const json cloud = json::parse(r.out);
  EXPECT_GT(cloud.at("scattered").at("reference_mean").get<double>(),
            1.2 * twice.at("scattered").at("reference_mean").get<double>());
  EXPECT_NEAR(cloud.at("sun").at("mean").get<double>(),
              2 * cloud.at("sun").at("reference_mean").get<double>(), 1e-6);
  r = run("compare '" + (out2 / "nadir.exr").string() + "' '" + view +
          "' --json --cloud-alpha 0.3 --mask-from '" + view + "'");
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("sun"), cloud.at("sun"));
  r = run("compare '" + view + "' '" + view + "' --mask-from '" + view + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--mask-from: needs --cloud-alpha"), std::string::npos) << r.err;
  // The sphere's alpha peaks at 1 - exp(-2): no pixel reaches 0.99.
  r = run("compare '" + view + "' '" + view + "' --cloud-alpha 0.99");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--cloud-alpha: no pixel"), std::string::npos) << r.err;
  // A missing file is "not found" (exit 3, docs/cli.md), as everywhere else.
  r = run("compare '" + view + "' '" + (dir_ / "none.exr").string() + "'");
  EXPECT_EQ(r.rc, 3);
  EXPECT_NE(r.err.find("none.exr: file not found"), std::string::npos) << r.err;
  // A non-finite pixel is named in the file that has it, and nothing reaches stdout.
  std::vector<ExrLayer> layers;
  for (auto& [name, image] : readExr(view).layers) layers.push_back({name, image});
  for (ExrLayer& l : layers) {
    if (l.name == "sun") l.image.data[0] = std::numeric_limits<float>::quiet_NaN();
  }
  const std::string nan_exr = (dir_ / "nan.exr").string();
  writeExr(nan_exr, layers);
  for (const bool nan_is_ref : {true, false}) {
    r = run("compare '" + (nan_is_ref ? view : nan_exr) + "' '" + (nan_is_ref ? nan_exr : view) +
            "'");
    EXPECT_EQ(r.rc, 2);
    // ('scattered', sun + sky, is compared before 'sun'.)
    EXPECT_NE(r.err.find("nan.exr layer 'scattered': non-finite pixel at (0, 0)"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(r.out, "");
  }
  r = run("preview '" + nan_exr + "' --layer sun --out '" + (dir_ / "nan.png").string() + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("non-finite pixel at (0, 0)"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "nan.png"));
}

// Previews of any EXR: the beauty by default, any layer by name, a clear error for a layer the
// file lacks (listing what it has) and exit 3 for a missing file.
TEST_F(RenderCli, PreviewWritesAPngOfAnyLayer) {
  const std::string exr = renderSmallSlab(8);
  CliResult r = run("preview '" + exr + "' --out '" + (dir_ / "b.png").string() + "'");
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("layer"), "beauty");
  EXPECT_GT(fs::file_size(dir_ / "b.png"), 50u);
  r = run("preview '" + exr + "' --layer sun --exposure 3 --out '" + (dir_ / "s.png").string() +
          "'");
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(json::parse(r.out).at("exposure"), 3.0);
  r = run("preview '" + exr + "' --layer nope --out '" + (dir_ / "n.png").string() + "'");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--layer: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("it has: cloud, background, beauty"), std::string::npos) << r.err;
  r = run("preview '" + (dir_ / "none.exr").string() + "' --out x.png");
  EXPECT_EQ(r.rc, 3);
}

// An outside probe: a huge refractive index made `mie` ask for a vector of 1e11 terms (an
// internal error), and `preview --exposure nan` fell back to auto exposure with exit 0.
TEST_F(RenderCli, OutOfRangeArgumentsExitWith2NamingTheOption) {
  for (const char* m : {"1e10,0", "1.33,1e300", "1e300,0"}) {
    const CliResult r = run(std::string("mie --x 10 --m ") + m);
    EXPECT_EQ(r.rc, 2) << m << r.err;
    EXPECT_NE(r.err.find("--m: refractive index must have |m| <= 1000"), std::string::npos)
        << r.err;
  }
  CliResult r = run("mie --x 1e5 --m 100,0");  // |m| x beyond what the recurrence holds
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--m: |m| x must be at most"), std::string::npos) << r.err;
  r = run("mie --x 1e-9 --m 1.33");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--x: size parameter must be in"), std::string::npos) << r.err;
  ASSERT_EQ(run("mie --x 10 --m 1.33,0").rc, 0);

  const std::string exr = renderSmallSlab(4);
  for (const char* exposure : {"nan", "inf", "1e300"}) {
    r = run("preview '" + exr + "' --exposure " + exposure + " --out '" +
            (dir_ / "e.png").string() + "'");
    EXPECT_EQ(r.rc, 2) << exposure << r.out;
    EXPECT_NE(r.err.find("--exposure"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "e.png")) << exposure;
  }
}

// An outside probe: a FIFO given as an input blocked compare and preview, and run-task read
// /dev/zero until the kernel killed it. Inputs are regular files, checked before they are read.
TEST_F(RenderCli, InputsThatAreNotRegularFilesAreRefusedBeforeTheyAreRead) {
  const std::string fifo = (dir_ / "fifo").string();
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const std::string exr = renderSmallSlab(4);
  for (const std::string& args :
       {"compare '" + exr + "' '" + fifo + "'", "compare '" + fifo + "' '" + exr + "'",
        "preview '" + fifo + "' --out '" + (dir_ / "p.png").string() + "'",
        "run-task '" + fifo + "' gather --check --cache-dir '" + (dir_ / "c").string() +
            "' --out '" + (dir_ / "o").string() + "'",
        std::string("run-task /dev/zero gather --check --cache-dir '") + (dir_ / "c").string() +
            "' --out '" + (dir_ / "o").string() + "'"}) {
    const CliResult r = run(args, "timeout 20 ");  // a regression blocks: 124, not a hang
    EXPECT_EQ(r.rc, 2) << args << ": " << r.err;
    EXPECT_NE(r.err.find("not a regular file"), std::string::npos) << args << ": " << r.err;
  }
}

// A mistyped subcommand is named, with the nearest command (CLI11 said "A subcommand is
// required").
// What an outside probe found: a result printed into a full disk exited 0 with an empty file;
// the farm's and the transcoder's missing files were exit 2, not 3; a phase table on a full disk
// left an empty file and blamed the input (exit 2, not 4).
TEST_F(RenderCli, FullDisksAndMissingFilesHaveTheirOwnExitCodes) {
  if (fs::exists("/dev/full")) {
    const std::string cmd = std::string("'") + CLOUDBAKE_EXE + "' methods --json > /dev/full 2> '" +
                            (dir_ / "err.txt").string() + "'";
    const int status = std::system(cmd.c_str());
    EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 4);
    EXPECT_NE(slurp(dir_ / "err.txt").find("cannot write to standard output"), std::string::npos);
  }
  CliResult r = run("transcode-vdb '" + (dir_ / "none.vdb").string() + "' '" +
                    (dir_ / "out.vdb").string() + "'");
  EXPECT_EQ(r.rc, 3) << r.err;
  r = run("run-task '" + (dir_ / "none.json").string() + "' layout --cache-dir '" +
          (dir_ / "c").string() + "' --out '" + (dir_ / "o").string() + "'");
  EXPECT_EQ(r.rc, 3) << r.err;
  r = run("phase hg:g=0.5 --out '" + (dir_ / "no/such/folder.csv").string() + "'");
  EXPECT_EQ(r.rc, 2) << r.err;
  testing::TinyVolume volume((dir_ / "tiny").string(), 1);
  if (!volume.ok()) GTEST_SKIP() << volume.why();
  // 100000 rows of about 80 bytes: more than the volume holds.
  const fs::path csv = fs::path(volume.dir()) / "phase.csv";
  r = run("phase hg:g=0.5 --samples 100000 --out '" + csv.string() + "'");
  EXPECT_EQ(r.rc, 4) << r.err;
  EXPECT_FALSE(fs::exists(csv));
}

// An outside probe: a --cache-dir the task cannot write in was an internal error (exit 1), after
// the task had written its files. It is bad input naming the flag, before any work.
TEST_F(RenderCli, ATaskRefusesACacheFolderItCannotWriteIn) {
  json j = slab();
  j["bake"] = {{"method", "single"}, {"light_resolution", 16}};
  j["views"][0]["resolution"] = {8, 8};
  const std::string shot = writeShot("farm.json", j).string();
  const fs::path plan = dir_ / "plan.json";
  CliResult r = run("plan '" + shot + "' --json");
  ASSERT_EQ(r.rc, 0) << r.err;
  std::ofstream(plan) << r.out;
  // /proc/self exists, and not even root can make a file in it.
  for (const char* task : {"bake", "render.000"}) {
    r = run("run-task '" + plan.string() + "' " + task + " --cache-dir /proc/self --out '" +
            (dir_ / "o").string() + "'");
    EXPECT_EQ(r.rc, 2) << task << ": " << r.err;
    EXPECT_NE(r.err.find("--cache-dir: cannot create folder '/proc/self/cache'"), std::string::npos)
        << r.err;
    EXPECT_TRUE(!fs::exists(dir_ / "o") || fs::is_empty(dir_ / "o")) << task;
  }
}

// A relative RMSE against a reference without light is undefined: null, not 0 (which read as a
// perfect match of any image).
TEST_F(RenderCli, CompareAgainstADarkReferenceSaysTheErrorIsUndefined) {
  json j = slab();
  j["volume"] = {{"sphere", {{"center", {0, 0, 0}}, {"radius", 1}, {"density", 1}}}};
  j["bake"] = {{"method", "single"}, {"light_resolution", 16}};
  j["views"][0]["resolution"] = {8, 8};
  const fs::path lit = dir_ / "lit", dark = dir_ / "dark";
  CliResult r = run("render '" + writeShot("lit.json", j).string() + "' --out '" + lit.string() +
                    "' --quiet");
  ASSERT_EQ(r.rc, 0) << r.err;
  j["lighting"] = {{"sun", {{"direction", {0, 0, 1}}, {"irradiance", {0, 0, 0}}}}};
  r = run("render '" + writeShot("dark.json", j).string() + "' --out '" + dark.string() +
          "' --quiet");
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string view = j["views"][0]["name"].get<std::string>() + ".exr";
  r = run("compare '" + (lit / view).string() + "' '" + (dark / view).string() + "' --json");
  ASSERT_EQ(r.rc, 0) << r.err;
  const json c = json::parse(r.out);
  EXPECT_TRUE(c.at("sun").at("rel_rmse").is_null()) << r.out;
  EXPECT_GT(c.at("sun").at("rmse").get<double>(), 0) << r.out;
  r = run("compare '" + (dark / view).string() + "' '" + (dark / view).string() + "' --json");
  EXPECT_EQ(json::parse(r.out).at("sun").at("rel_rmse"), 0.0) << r.out;
  r = run("compare '" + (lit / view).string() + "' '" + (lit / view).string() +
          "' --cloud-alpha nan");
  EXPECT_EQ(r.rc, 2) << r.err;
}

// Voxels finer than OpenVDB's transforms allow are refused naming the field, not an internal
// error from inside OpenVDB.
TEST_F(RenderCli, VoxelsTooSmallForOpenVdbAreRefusedNamingTheField) {
  json j = slab();
  j["volume"] = {
      {"procedural", {{"type", "perlin_cloud"}, {"resolution", 16}, {"size", {1e-5, 1e-5, 1e-5}}}}};
  CliResult r = run("render '" + writeShot("tiny.json", j).string() + "' --out '" +
                    (dir_ / "t").string() + "' --dry-run");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("/volume/procedural/size"), std::string::npos) << r.err;
  // A mesh of no extent, refused by the voxel budget's check before the scene is built: the
  // message names the field there too (it named only the mesh file).
  const fs::path obj = dir_ / "point.obj";
  std::ofstream(obj) << "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n";
  j["volume"] = {{"mesh", {{"path", obj.string()}, {"resolution", 16}}}};
  r = run("render '" + writeShot("point.json", j).string() + "' --out '" + (dir_ / "p").string() +
          "' --quiet");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("point.json: /volume/mesh: "), std::string::npos) << r.err;
}

// A frame of a sequence denser than tracking resolves is refused as a static VDB is, naming
// /medium/extinction and the frame (an outside probe: it rendered, its multiple layer 0).
TEST_F(RenderCli, ASequenceFrameTooDenseForTheExtinctionIsRefused) {
  const std::string light = (dir_ / "light.vdb").string(), heavy = (dir_ / "heavy.vdb").string();
  VdbWriteOptions o;
  o.voxel_size = 0.25;
  writeVdb(light, BoxDensity(Vec3(-1.0), Vec3(1.0), 1.0), o);
  writeVdb(heavy, BoxDensity(Vec3(-1.0), Vec3(1.0), 1e12), o);
  json j = slab();
  j["volume"] = {{"sequence", {{"paths", {light, heavy}}}}};
  j["medium"]["extinction"] = 100;
  j["bake"] = {{"method", "precomputed"},
               {"light_resolution", 12},
               {"sample_points", 128},
               {"transfer_resolution", 6}};
  j["views"][0]["resolution"] = {8, 8};
  const CliResult r = run("render '" + writeShot("seq.json", j).string() + "' --out '" +
                          (dir_ / "seq").string() + "' --quiet");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("/medium/extinction"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("/volume/sequence/paths/1"), std::string::npos) << r.err;
}

// SIGINT (Ctrl-C) or SIGTERM (a farm's scancel) cancels the run: it stops within about a second
// with exit code 6 and leaves none of its outputs (it was killed where it stood before, and could
// leave a view's temporary file). The render would take minutes: a million paths a pixel.
TEST_F(RenderCli, AnInterruptCancelsTheRunAndLeavesNoOutputs) {
  json shot = slab();
  shot["views"].push_back(shot["views"][0]);
  shot["views"][1]["name"] = "second";
  const fs::path path = writeShot("long.json", shot);
  // The third: SIGTERM twice at once, as `timeout` sends it (to the process, then its group);
  // the second had ended the process where it stood, its files left behind (an outside probe).
  for (const auto& [signal, times] : {std::pair{SIGINT, 1}, {SIGTERM, 1}, {SIGTERM, 2}}) {
    const std::string name = std::to_string(signal) + "x" + std::to_string(times);
    const fs::path out = dir_ / ("out" + name), err = dir_ / ("err" + name + ".txt");
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      if (!std::freopen(err.c_str(), "w", stderr)) _exit(127);
      execl(CLOUDBAKE_EXE, "cloudbake", "render", path.c_str(), "--out", out.c_str(), "--threads",
            "1", "--samples", "1000000", static_cast<char*>(nullptr));
      _exit(127);
    }
    // Once the first view is being rendered.
    for (int i = 0; i < 600 && slurp(err).find("0%") == std::string::npos; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    for (int k = 0; k < times; ++k) {
      // Apart, or the kernel merges the two into one pending signal.
      if (k > 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
      ASSERT_EQ(kill(pid, signal), 0);
    }
    const auto t0 = std::chrono::steady_clock::now();
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ASSERT_TRUE(WIFEXITED(status)) << "signal " << signal << " killed it";
    EXPECT_EQ(WEXITSTATUS(status), 6) << slurp(err);
    EXPECT_LT(seconds, 10.0);  // a bound far above the second it takes, far below the run
    const std::string said = std::string("cloudbake: cancelled: interrupted by ") +
                             (signal == SIGINT ? "SIGINT" : "SIGTERM");
    EXPECT_NE(slurp(err).find(said), std::string::npos) << slurp(err);
    EXPECT_TRUE(!fs::exists(out) || fs::is_empty(out)) << "files left in " << out;
  }
}

TEST_F(RenderCli, MistypedCommandIsNamedWithTheNearestOne) {
  CliResult r = run("rendr '" + (kExamples / "slab.json").string() + "' --out x");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("unknown command 'rendr' (did you mean 'render'?)"), std::string::npos)
      << r.err;
  r = run("frobnicate");
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("unknown command 'frobnicate'; commands: mie, phase, render"),
            std::string::npos)
      << r.err;
}

}  // namespace
}  // namespace cloudbake
