#include "core/shot/shot_parser.h"

#include <gtest/gtest.h>

#include <functional>
#include <nlohmann/json.hpp>

#include "core/bake/pointcloud_bake.h"
#include "core/transport/path_tracer.h"
#include "tests/core/shot/shot_test_util.h"

namespace cloudbake {
namespace {
using nlohmann::json;
using testing::kDesignSlab;
using testing::TempDir;

TEST(ShotParser, DesignExampleParsesToExpectedValues) {
  const ShotSpec s = parseShot(kDesignSlab, "");
  EXPECT_EQ(s.version, 1);
  EXPECT_EQ(s.name, "slab");
  const auto* box = std::get_if<BoxVolumeSpec>(&s.volume);
  ASSERT_NE(box, nullptr);
  EXPECT_EQ(box->min, Vec3(-50, -50, 0));
  EXPECT_EQ(box->max, Vec3(50, 50, 1));
  EXPECT_EQ(box->density, 1.0);
  EXPECT_EQ(s.medium.extinction, 2.0);
  EXPECT_EQ(s.medium.albedo, Rgb(0.9, 0.9, 0.9));
  EXPECT_EQ(s.medium.phase.type, PhaseSpec::Type::kHenyeyGreenstein);
  EXPECT_EQ(s.medium.phase.g, 0.75);
  EXPECT_EQ(s.medium.phase.mie_ratio, 1.0);
  ASSERT_TRUE(s.lighting.has_sun);
  EXPECT_EQ(s.lighting.sun.direction, Vec3(0, 0, 1));
  EXPECT_EQ(s.lighting.sun.irradiance, Rgb(3.14159, 3.14159, 3.14159));
  EXPECT_EQ(s.lighting.sky.type, Sky::Type::kConstant);
  EXPECT_EQ(s.lighting.sky.radiance, Rgb(0, 0, 0));
  EXPECT_EQ(s.bake.method, "pathtrace");
  EXPECT_EQ(s.bake.samples, 256);
  EXPECT_EQ(s.bake.seed, 1u);
  EXPECT_EQ(s.bake.knobs.integer("max_depth"), PathTracerOptions{}.max_depth);
  EXPECT_TRUE(s.bake.knobs.explicitValues().empty());
  ASSERT_EQ(s.views.size(), 1u);
  const Camera& c = s.views[0];
  EXPECT_EQ(c.name, "nadir");
  EXPECT_EQ(c.type, Camera::Type::kOrthographic);
  EXPECT_EQ(c.position, Vec3(0, 0, 10));
  EXPECT_EQ(c.look_at, Vec3(0, 0, 0));
  EXPECT_EQ(c.up, Vec3(0, 1, 0));
  EXPECT_EQ(c.width, 2.0);
  EXPECT_EQ(c.width_px, 32);
  EXPECT_EQ(c.height_px, 32);
  EXPECT_TRUE(s.outputs.exr);
  EXPECT_FALSE(s.outputs.vdb);
}

TEST(ShotParser, DefaultsAndNormalisation) {
  json j = json::parse(kDesignSlab);
  j.erase("bake");
  j.erase("outputs");
  j.erase("name");
  j["medium"] = {{"extinction", 1.5}, {"albedo", {0.5, 0.75, 1.0}}};
  j["lighting"] = {{"sun", {{"direction", {3, 0, 4}}, {"irradiance", {1, 2, 3}}}}};
  j["views"][0]["camera"] = {
      {"type", "perspective"}, {"position", {0, -5, 1}}, {"look_at", {0, 0, 0.5}}};
  const ShotSpec s = parseShot(j.dump(), "");
  EXPECT_EQ(s.name, "shot");
  EXPECT_EQ(s.medium.albedo, Rgb(0.5, 0.75, 1.0));
  EXPECT_EQ(s.medium.phase.type, PhaseSpec::Type::kIsotropic);
  EXPECT_NEAR(s.lighting.sun.direction.x, 0.6, 1e-15);
  EXPECT_NEAR(s.lighting.sun.direction.z, 0.8, 1e-15);
  EXPECT_EQ(s.lighting.sky.radiance, Rgb(0, 0, 0));
  EXPECT_EQ(s.bake.method, "pathtrace");
  EXPECT_EQ(s.bake.samples, 64);
  EXPECT_EQ(s.views[0].type, Camera::Type::kPerspective);
  EXPECT_EQ(s.views[0].fov_deg, 40.0);
  EXPECT_EQ(s.views[0].up, Vec3(0, 0, 1));
  EXPECT_TRUE(s.outputs.exr);
  EXPECT_FALSE(s.outputs.vdb);
}

TEST(ShotParser, OtherVolumesSkyFormsAndMethodKnobs) {
  TempDir dir;
  dir.write("assets/cloud.vdb", "x");
  dir.write("assets/bunny.ply", "x");
  dir.write("assets/sky.exr", "x");
  json j = json::parse(kDesignSlab);
  j["volume"] = {{"mesh",
                  {{"path", "assets/bunny.ply"},
                   {"resolution", 64},
                   {"density", 2},
                   {"noise", {{"octaves", 3}, {"amount", 0.25}}}}}};
  j["lighting"]["sky"] = {{"map", "assets/sky.exr"}, {"scale", 0.5}};
  j["bake"] = {{"method", "pointcloud"}, {"points", 4096}, {"rule", "paper"}, {"samples", 4}};
  ShotSpec s = parseShot(j.dump(), dir.path().string());
  const auto* mesh = std::get_if<MeshVolumeSpec>(&s.volume);
  ASSERT_NE(mesh, nullptr);
  EXPECT_EQ(mesh->path, std::filesystem::weakly_canonical(dir.path() / "assets/bunny.ply"));
  EXPECT_EQ(mesh->resolution, 64);
  EXPECT_EQ(mesh->voxel_size, 0.0);
  EXPECT_TRUE(mesh->noise_enabled);
  EXPECT_EQ(mesh->noise.octaves, 3);
  EXPECT_EQ(mesh->noise.amount, 0.25);
  EXPECT_EQ(mesh->noise.frequency, NoiseOptions().frequency);
  EXPECT_EQ(s.lighting.sky.type, Sky::Type::kMap);
  EXPECT_EQ(s.lighting.sky.map_scale, 0.5);
  EXPECT_EQ(s.bake.method, "pointcloud");
  EXPECT_EQ(s.bake.knobs.integer("points"), 4096);
  EXPECT_EQ(s.bake.knobs.choice("rule"), "paper");
  EXPECT_EQ(s.bake.knobs.integer("passes"), PointcloudOptions{}.passes);  // a default
  EXPECT_FALSE(s.bake.knobs.has("radius"));                               // derived when absent

  j["volume"] = {{"sequence", {{"paths", {"assets/cloud.vdb", "assets/cloud.vdb"}}}}};
  j["lighting"]["sky"] = {{"zenith", {0.1, 0.2, 0.4}}, {"horizon", {0.3, 0.3, 0.3}}};
  j["bake"] = {{"method", "auto"}, {"tolerance", 0.02}};
  s = parseShot(j.dump(), dir.path().string());
  const auto* seq = std::get_if<SequenceVolumeSpec>(&s.volume);
  ASSERT_NE(seq, nullptr);
  EXPECT_EQ(seq->frames, 2);
  EXPECT_EQ(seq->paths.size(), 2u);
  EXPECT_EQ(s.lighting.sky.type, Sky::Type::kGradient);
  EXPECT_EQ(s.lighting.sky.ground, Rgb(0, 0, 0));
  EXPECT_EQ(s.bake.knobs.number("tolerance"), 0.02);

  j["volume"] = {{"procedural", {{"type", "perlin_cloud"}, {"seed", 7}, {"resolution", 32}}}};
  s = parseShot(j.dump(), dir.path().string());
  const auto* proc = std::get_if<ProceduralVolumeSpec>(&s.volume);
  ASSERT_NE(proc, nullptr);
  EXPECT_EQ(proc->perlin.seed, 7u);
  EXPECT_EQ(proc->perlin.center, Vec3(0, 0, 0.5));  // DESIGN.md: fills [-1,1]^2 x [0,1]
  EXPECT_EQ(proc->perlin.size, Vec3(2, 2, 1));
}

TEST(ShotParser, ASerializedSunDirectionParsesBackBitForBit) {
  // Farm tasks re-read the planned shot: a direction normalised twice can move its last bit
  // (and the render with it). These directions each did before the fix.
  for (const auto& d : {Vec3(0.5, 0.2, 1), Vec3(0.3, 0.2, 1), Vec3(0.9, 0.3, 0.25)}) {
    json j = json::parse(kDesignSlab);
    j["lighting"]["sun"]["direction"] = {d.x, d.y, d.z};
    const ShotSpec a = parseShot(j.dump(), "");
    const ShotSpec b = parseShot(serializeShot(a), "");
    EXPECT_EQ(a.lighting.sun.direction.x, b.lighting.sun.direction.x);
    EXPECT_EQ(a.lighting.sun.direction.y, b.lighting.sun.direction.y);
    EXPECT_EQ(a.lighting.sun.direction.z, b.lighting.sun.direction.z);
    EXPECT_NEAR(length(b.lighting.sun.direction), 1.0, 1e-15);
  }
}

TEST(ShotParser, CanonicalFormRoundTripsAndIgnoresSpelling) {
  const ShotSpec a = parseShot(kDesignSlab, "");
  const std::string text = serializeShot(a);
  const ShotSpec b = parseShot(text, "");
  EXPECT_EQ(serializeShot(b), text);
  // Same shot, spelled differently: key order, 0.9 vs [0.9, 0.9, 0.9], unnormalised direction,
  // -0 vs 0, explicit defaults.
  json j = json::parse(kDesignSlab);
  j["medium"]["albedo"] = {0.9, 0.9, 0.9};
  j["lighting"]["sun"]["direction"] = {-0.0, 0, 7};
  j["outputs"] = {{"vdb", false}};
  j["medium"]["phase"]["mie_ratio"] = 1;
  EXPECT_EQ(serializeShot(parseShot(j.dump(2), "")), text);
  // Something that matters changes the text.
  j["bake"]["seed"] = 2;
  EXPECT_NE(serializeShot(parseShot(j.dump(), "")), text);
  // Views and outputs can be left out of a key.
  SerializeOptions key;
  key.views = key.outputs = key.name = false;
  j = json::parse(kDesignSlab);
  j["views"][0]["resolution"] = {64, 64};
  j["name"] = "other";
  EXPECT_EQ(serializeShot(parseShot(j.dump(), ""), key), serializeShot(a, key));
  EXPECT_EQ(json::parse(serializeShot(a, key)).count("views"), 0u);
}

// The canonical text is a cache key: changing it invalidates every cached bake, so it is pinned.
TEST(ShotParser, CanonicalFormOfTheDesignExampleIsPinned) {
  EXPECT_EQ(serializeShot(parseShot(kDesignSlab, "")),
            R"({"bake":{"method":"pathtrace","samples":256,"seed":1},)"
            R"("lighting":{"sky":{"radiance":[0.0,0.0,0.0]},)"
            R"("sun":{"direction":[0.0,0.0,1.0],"irradiance":[3.14159,3.14159,3.14159]}},)"
            R"("medium":{"albedo":[0.9,0.9,0.9],"extinction":2.0,)"
            R"("phase":{"g":0.75,"mie_ratio":1.0,"type":"hg"}},"name":"slab",)"
            R"("outputs":{"exr":true,"exr_compression":"zip","exr_layers":["cloud","background",)"
            R"("beauty","sun","sky","single","multiple"],"vdb":false},"version":1,)"
            R"("views":[{"camera":{"look_at":[0.0,0.0,0.0],"position":[0.0,0.0,10.0],)"
            R"("type":"orthographic","up":[0.0,1.0,0.0],"width":2.0},"name":"nadir",)"
            R"("resolution":[32,32]}],)"
            R"("volume":{"box":{"density":1.0,"max":[50.0,50.0,1.0],"min":[-50.0,-50.0,0.0]}}})");
}

TEST(ShotParser, EveryVariantRoundTripsThroughTheCanonicalForm) {
  TempDir dir;
  dir.write("a.vdb", "x");
  dir.write("b.obj", "x");
  dir.write("sky.exr", "x");
  const std::vector<std::function<void(json&)>> variants = {
      [](json& j) {
        j["volume"] = {{"sphere", {{"center", {1, 2, 3}}, {"radius", 2}, {"density", 0.5}}}};
        j["outputs"] = {{"vdb", true}, {"vdb_voxel_size", 0.25}, {"exr_compression", "piz"}};
      },
      [](json& j) {
        j["outputs"]["exr_layers"] = {"multiple", "cloud"};
      },
      [](json& j) {
        j["volume"] = {{"vdb", {{"path", "a.vdb"}, {"grid", "smoke"}}}};
      },
      [](json& j) {
        j["volume"] = {
            {"mesh", {{"path", "b.obj"}, {"voxel_size", 0.01}, {"noise", json::object()}}}};
      },
      [](json& j) {
        j["volume"] = {{"mesh", {{"path", "b.obj"}, {"resolution", 100}}}};
      },
      [](json& j) {
        j["volume"] = {{"procedural",
                        {{"type", "perlin_cloud"},
                         {"size", {4, 4, 1}},
                         {"cover", 0.2},
                         {"seed", 18446744073709551615ull}}}};
      },
      [](json& j) {
        j["volume"] = {{"sequence", {{"paths", {"a.vdb", "a.vdb", "a.vdb"}}}}};
      },
      [](json& j) {
        j["volume"] = {{"sequence", {{"procedural", {{"type", "perlin_cloud"}}}, {"frames", 9}}}};
      },
      [](json& j) {
        j["lighting"]["sky"] = {{"map", "sky.exr"}, {"scale", 2}};
      },
      [](json& j) {
        j["lighting"] = {
            {"sky", {{"zenith", {1, 2, 3}}, {"horizon", {4, 5, 6}}, {"ground", {0, 0, 1}}}}};
      },
      [](json& j) {
        j["medium"]["phase"] = {{"type", "mie"},
                                {"effective_radius_um", 8},
                                {"effective_variance", 0.2},
                                {"mie_ratio", 0.3}};
      },
      [](json& j) {
        j["medium"]["phase"] = {{"type", "mie_approx"}, {"diameter_um", 12.5}};
      },
      [](json& j) {
        j["bake"] = {{"method", "precomputed"},
                     {"sample_points", 512},
                     {"transfer_resolution", 16},
                     {"cut_error", 0.002},
                     {"iterations", 3},
                     {"tolerance", 0.01},
                     {"frames", 4},
                     {"light_resolution", 32},
                     {"step", 0.1}};
      },
      [](json& j) {
        j["bake"] = {{"method", "single"}, {"step", 0.05}, {"light_resolution", 64}};
      },
      [](json& j) {
        j["bake"] = {{"method", "pointcloud"}, {"points", 4096},        {"passes", 5},
                     {"radius", 0.3},          {"rule", "paper"},       {"output_mapping", true},
                     {"tolerance", 0.05},      {"light_resolution", 48}};
      },
      [](json& j) {
        j["views"].push_back({{"name", "persp.v2"},
                              {"camera",
                               {{"type", "perspective"},
                                {"fov_deg", 60},
                                {"position", {1, 1, 1}},
                                {"look_at", {0, 0, 0}}}},
                              {"resolution", {320, 200}}});
      },
      [](json& j) {
        j["views"] = json::array();
        j["outputs"] = {{"exr", false}, {"vdb", true}, {"vdb_voxel_size", 0.25}};
      },
  };
  for (size_t i = 0; i < variants.size(); ++i) {
    SCOPED_TRACE("variant " + std::to_string(i));
    json j = json::parse(kDesignSlab);
    variants[i](j);
    const std::string text = serializeShot(parseShot(j.dump(), dir.path().string()));
    EXPECT_EQ(serializeShot(parseShot(text, "/nonexistent-base")), text);
    EXPECT_NE(text, serializeShot(parseShot(kDesignSlab, "")));
  }
}

TEST(ShotParser, ReadsFilesAndResolvesPathsAgainstTheirFolder) {
  TempDir dir;
  dir.write("data/cloud.vdb", "x");
  json j = json::parse(kDesignSlab);
  j["volume"] = {{"vdb", {{"path", "../data/cloud.vdb"}}}};
  const auto shot_path = dir.write("shots/a.json", j.dump());
  ParseOptions options;
  options.allowed_roots = {dir.path().string()};
  const ShotSpec s = parseShotFile(shot_path.string(), options);
  EXPECT_EQ(std::get<VdbVolumeSpec>(s.volume).path,
            std::filesystem::weakly_canonical(dir.path() / "data/cloud.vdb").string());
  EXPECT_EQ(std::get<VdbVolumeSpec>(s.volume).grid, "density");
  EXPECT_THROW(parseShotFile((dir.path() / "nope.json").string()), MissingFileError);
  try {
    parseShotFile((dir.path() / "shots").string());
    FAIL() << "a folder must not parse";
  } catch (const MissingFileError&) {
    FAIL() << "a folder exists; not a missing-file error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos);
  }
  // Error messages start with the path of the shot file.
  const auto bad = dir.write("shots/bad.json", R"({"version": 1, "volume": 3})");
  try {
    parseShotFile(bad.string());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(bad.string() + ": /volume: ", 0), 0u) << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Bad input: each case must throw InputError whose message names the JSON pointer.

struct BadCase {
  const char* what;
  std::function<void(json&)> mutate;  // applied to the DESIGN.md example (unless raw is set)
  const char* expected;               // substring of the message: "<pointer>: <words>"
  const char* raw = nullptr;          // replaces the whole text
  bool missing_file = false;          // expect MissingFileError specifically
};

class BadShots : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_.write("root/cloud.vdb", "x");
    dir_.write("root/bunny.ply", "x");
    dir_.write("outside.vdb", "x");
    std::filesystem::create_symlink(dir_.path() / "outside.vdb", dir_.path() / "root/link.vdb");
  }
  void check(const BadCase& c) {
    SCOPED_TRACE(c.what);
    std::string text;
    if (c.raw) {
      text = c.raw;
    } else {
      json j = json::parse(kDesignSlab);
      c.mutate(j);
      text = j.dump();
    }
    ParseOptions options;
    options.allowed_roots = {(dir_.path() / "root").string()};
    try {
      parseShot(text, (dir_.path() / "root").string(), options);
      ADD_FAILURE() << "no error for: " << c.what;
    } catch (const MissingFileError& e) {
      EXPECT_TRUE(c.missing_file) << e.what();
      EXPECT_NE(std::string(e.what()).find(c.expected), std::string::npos) << e.what();
    } catch (const InputError& e) {
      EXPECT_FALSE(c.missing_file) << e.what();
      const std::string msg = e.what();
      EXPECT_EQ(msg.rfind("shot.json: ", 0), 0u) << msg;
      EXPECT_NE(msg.find(c.expected), std::string::npos)
          << "expected '" << c.expected << "' in: " << msg;
    }
  }
  TempDir dir_;
};

json box() { return {{"box", {{"min", {0, 0, 0}}, {"max", {1, 1, 1}}}}}; }

TEST_F(BadShots, EachNamesTheOffendingField) {
  const std::vector<BadCase> cases = {
      {"malformed JSON", nullptr, "/: invalid JSON", R"({"version": 1, "volume": )"},
      {"not an object", nullptr, "/: a shot must be a JSON object", "[1, 2]"},
      {"duplicate key inside an array", nullptr, "/views/1/camera/type: duplicate key",
       R"({"version": 1, "views": [{"name": "a"}, {"camera": {"type": 1, "type": 2}}]})"},
      {"hostile nesting", nullptr,
       "/name/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0/0: nested deeper than 32 "
       "levels",
       R"({"version": 1, "name": [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]})"},
      {"duplicate key", nullptr, "/medium/extinction: duplicate key",
       R"({"version": 1, "medium": {"extinction": 1, "extinction": 2}})"},
      {"missing version", [](json& j) { j.erase("version"); }, "/version: missing"},
      // Numbers read back as written: not "got 1" for an albedo a hair above 1.
      {"albedo a hair above 1", [](json& j) { j["medium"]["albedo"] = 1.0000000000000002; },
       "/medium/albedo: must be in [0, 1], got 1.0000000000000002"},
      {"tiny extinction below 0", [](json& j) { j["medium"]["extinction"] = -1e-300; },
       "got -1e-300"},
      {"version 2", [](json& j) { j["version"] = 2; },
       "/version: unsupported shot format version 2"},
      {"version as string", [](json& j) { j["version"] = "1"; }, "/version: must be the number 1"},
      {"unknown top-level key", [](json& j) { j["colour"] = 1; }, "/colour: unknown key"},
      {"unknown key in phase", [](json& j) { j["medium"]["phase"]["gg"] = 0.5; },
       "/medium/phase/gg: unknown key for phase type 'hg' (allowed: type, g, mie_ratio)"},
      {"misspelt phase type key",
       [](json& j) {
         j["medium"]["phase"] = {{"tpye", "hg"}};
       },
       "/medium/phase/tpye: unknown key"},
      {"unknown key in camera", [](json& j) { j["views"][0]["camera"]["fov_deg"] = 30; },
       "/views/0/camera/fov_deg: unknown key for an orthographic camera"},
      {"unknown key in box", [](json& j) { j["volume"]["box"]["size"] = 1; },
       "/volume/box/size: unknown key"},
      {"unknown volume source",
       [](json& j) {
         j["volume"] = {{"cube", 1}};
       },
       "/volume/cube: unknown key"},
      {"two volume sources",
       [](json& j) {
         j["volume"]["sphere"] = {{"center", {0, 0, 0}}, {"radius", 1}};
       },
       "/volume/sphere: a volume has exactly one source"},
      {"no volume source", [](json& j) { j["volume"] = json::object(); },
       "/volume: needs exactly one"},
      {"missing medium", [](json& j) { j.erase("medium"); }, "/medium: missing (required)"},
      {"wrong type (string for number)", [](json& j) { j["medium"]["extinction"] = "two"; },
       "/medium/extinction: must be a number, got a string"},
      {"wrong type (object for array)", [](json& j) { j["volume"]["box"]["min"] = json::object(); },
       "/volume/box/min: must be an array of 3 numbers"},
      {"NaN string", [](json& j) { j["medium"]["albedo"] = "NaN"; },
       "/medium/albedo: must be a finite number; got the string 'NaN'"},
      {"-Infinity string", [](json& j) { j["lighting"]["sun"]["irradiance"][1] = "-Infinity"; },
       "/lighting/sun/irradiance/1: must be a finite number"},
      {"number overflowing double", nullptr,
       "/: invalid JSON: number overflow parsing '1e999' (after key \"extinction\", line 2, "
       "column 36)",
       R"({"version": 1, "volume": {"box": {"min": [0,0,0], "max": [1,1,1]}},
          "medium": {"extinction": 1e999}})"},
      {"negative extinction", [](json& j) { j["medium"]["extinction"] = -1; },
       "/medium/extinction: must be in [0, 1e+06]"},
      {"negative density", [](json& j) { j["volume"]["box"]["density"] = -0.5; },
       "/volume/box/density: must be in [0,"},
      {"box max below min", [](json& j) { j["volume"]["box"]["max"][2] = -1; },
       "/volume/box/max/2: must be greater than min"},
      {"negative voxel size",
       [](json& j) {
         j["volume"] = {{"mesh", {{"path", "bunny.ply"}, {"voxel_size", -0.1}}}};
       },
       "/volume/mesh/voxel_size: must be in (0,"},
      {"mesh with both voxel_size and resolution",
       [](json& j) {
         j["volume"] = {{"mesh", {{"path", "bunny.ply"}, {"voxel_size", 0.1}, {"resolution", 64}}}};
       },
       "/volume/mesh/resolution: give either voxel_size or resolution"},
      {"mesh resolution too large",
       [](json& j) {
         j["volume"] = {{"mesh", {{"path", "bunny.ply"}, {"resolution", 100000}}}};
       },
       "/volume/mesh/resolution: must be an integer in [1, 1022]"},
      {"10^12 voxels in the VDB output",
       [](json& j) {
         j["outputs"] = {{"vdb", true}, {"vdb_voxel_size", 0.001}};
       },
       "/outputs/vdb_voxel_size: gives 1e+13 voxels"},
      {"vdb voxel wider than the volume",
       [](json& j) {
         j["outputs"] = {{"vdb", true}, {"vdb_voxel_size", 1e12}};
       },
       "/outputs/vdb_voxel_size: is 1e+12, wider than the volume's thinnest side"},
      {"vdb output of a box without voxel size", [](json& j) { j["outputs"]["vdb"] = true; },
       "/outputs/vdb_voxel_size: missing"},
      {"procedural resolution too large",
       [](json& j) {
         j["volume"] = {{"procedural", {{"type", "perlin_cloud"}, {"resolution", 1000000}}}};
       },
       "/volume/procedural/resolution: must be an integer in [8, 1024]"},
      {"unknown procedural type",
       [](json& j) {
         j["volume"] = {{"procedural", {{"type", "cumulus"}}}};
       },
       "/volume/procedural/type: unknown procedural type 'cumulus'"},
      {"zero-size image",
       [](json& j) {
         j["views"][0]["resolution"] = {0, 32};
       },
       "/views/0/resolution/0: must be an integer in [1, 16384]"},
      {"huge image",
       [](json& j) {
         j["views"][0]["resolution"] = {16384, 16384};
       },
       "/views/0/resolution: 16384x16384 is more than 67108864 pixels"},
      {"resolution not a pair", [](json& j) { j["views"][0]["resolution"] = {32}; },
       "/views/0/resolution: must be [width, height]"},
      {"fractional samples", [](json& j) { j["bake"]["samples"] = 1.5; },
       "/bake/samples: must be an integer, got 1.5"},
      {"too many samples", [](json& j) { j["bake"]["samples"] = 1e7; },
       "/bake/samples: must be an integer in [1, 1000000]"},
      {"negative seed", [](json& j) { j["bake"]["seed"] = -3; },
       "/bake/seed: must be a non-negative"},
      {"unknown method", [](json& j) { j["bake"]["method"] = "magic"; },
       "/bake/method: unknown method 'magic'"},
      {"knob of another method", [](json& j) { j["bake"]["points"] = 100; },
       "/bake/points: unknown key for method 'pathtrace'"},
      {"bad knob value",
       [](json& j) {
         j["bake"] = {{"method", "pointcloud"}, {"rule", "exact"}};
       },
       "/bake/rule: must be 'normalized' or 'paper'"},
      {"auto without tolerance",
       [](json& j) {
         j["bake"] = {{"method", "auto"}};
       },
       "/bake/tolerance: missing (required)"},
      // A tolerance is a relative error below 1: 0, 1 and NaN are refused (issue 13).
      {"auto tolerance 1",
       [](json& j) {
         j["bake"] = {{"method", "auto"}, {"tolerance", 1}};
       },
       "/bake/tolerance: must be in (0, 1), got 1"},
      {"auto tolerance 0",
       [](json& j) {
         j["bake"] = {{"method", "auto"}, {"tolerance", 0}};
       },
       "/bake/tolerance: must be in (0, 1), got 0"},
      {"auto tolerance NaN",
       [](json& j) {
         j["bake"] = {{"method", "auto"}, {"tolerance", "NaN"}};
       },
       "/bake/tolerance: must be a finite number"},
      // auto chooses the samples: a number in the shot would be ignored.
      {"auto with samples",
       [](json& j) {
         j["bake"] = {{"method", "auto"}, {"tolerance", 0.1}, {"samples", 5}};
       },
       "/bake/samples: method 'auto' chooses the samples with the method"},
      {"unknown phase type",
       [](json& j) {
         j["medium"]["phase"] = {{"type", "rayleigh"}};
       },
       "/medium/phase/type: unknown phase type 'rayleigh'"},
      {"parameter of another phase type", [](json& j) { j["medium"]["phase"]["diameter_um"] = 20; },
       "/medium/phase/diameter_um: unknown key for phase type 'hg'"},
      {"albedo 1.5", [](json& j) { j["medium"]["albedo"] = 1.5; },
       "/medium/albedo: must be in [0, 1], got 1.5"},
      {"albedo triple out of range",
       [](json& j) {
         j["medium"]["albedo"] = {0.5, -0.1, 0.5};
       },
       "/medium/albedo/1: must be in [0, 1]"},
      {"g = 1", [](json& j) { j["medium"]["phase"]["g"] = 1; },
       "/medium/phase/g: must be in [-0.999999, 0.999999], got 1"},
      // Past double precision's resolution of the peak: the path tracer's pixels were NaN.
      {"g = 1 - 1e-9", [](json& j) { j["medium"]["phase"]["g"] = 0.999999999; },
       "/medium/phase/g: must be in [-0.999999, 0.999999], got 0.999999999"},
      {"g = -1 + 1e-7", [](json& j) { j["medium"]["phase"]["g"] = -0.9999999; },
       "/medium/phase/g: must be in [-0.999999, 0.999999]"},
      {"hg without g", [](json& j) { j["medium"]["phase"].erase("g"); },
       "/medium/phase/g: missing (required)"},
      {"mie variance out of range",
       [](json& j) {
         j["medium"]["phase"] = {
             {"type", "mie"}, {"effective_radius_um", 10}, {"effective_variance", 0.5}};
       },
       "/medium/phase/effective_variance: must be in [0.01, 0.5)"},
      {"zero sun direction",
       [](json& j) {
         j["lighting"]["sun"]["direction"] = {0, 0, 0};
       },
       "/lighting/sun/direction: must be a non-zero vector"},
      {"no light at all", [](json& j) { j["lighting"] = json::object(); },
       "/lighting: needs a sun, a sky, or both"},
      {"sky with two forms",
       [](json& j) {
         j["lighting"]["sky"]["zenith"] = {1, 1, 1};
       },
       "/lighting/sky/zenith: unknown key beside 'radiance'"},
      {"duplicate view names", [](json& j) { j["views"].push_back(j["views"][0]); },
       "/views/1/name: duplicate view name 'nadir'"},
      {"view name with '/'", [](json& j) { j["views"][0]["name"] = "a/b"; },
       "/views/0/name: 'a/b' is not a safe file name"},
      {"view named bake", [](json& j) { j["views"][0]["name"] = "bake"; },
       "/views/0/name: 'bake' is reserved"},
      {"no views while writing EXR", [](json& j) { j["views"] = json::array(); },
       "/views: needs at least one view"},
      {"camera up parallel to view",
       [](json& j) {
         j["views"][0]["camera"]["up"] = {0, 0, 2};
       },
       "/views/0/camera/up: must not be parallel"},
      {"camera beyond the world's coordinates",
       [](json& j) {
         j["views"][0]["camera"]["position"] = {0, -1e160, 0};
       },
       "/views/0/camera/position/1: must be within +-1e+15 world units, got -1e+160"},
      {"box beyond the world's coordinates",
       [](json& j) {
         j["volume"] = {{"box", {{"min", {2e15, -1, -1}}, {"max", {2e15 + 1e10, 1, 1}}}}};
       },
       "/volume/box/min/0: must be within +-1e+15 world units"},
      {"sphere beyond the world's coordinates",
       [](json& j) {
         j["volume"] = {{"sphere", {{"center", {1e40, 0, 0}}, {"radius", 1}}}};
       },
       "/volume/sphere/center/0: must be within +-1e+15 world units"},
      {"sphere far from the origin for its size",
       [](json& j) {
         j["volume"] = {{"sphere", {{"center", {0, -2e6, 0}}, {"radius", 1}}}};
       },
       "/volume/sphere/center: lies 2e+06 world units from the origin, more than 1e+06 times its "
       "radius (1)"},
      {"procedural cloud far from the origin for its size",
       [](json& j) {
         j["volume"] = {{"procedural",
                         {{"type", "perlin_cloud"}, {"center", {0, 0, 5e6}}, {"size", {2, 4, 1}}}}};
       },
       "/volume/procedural/center: lies 5e+06 world units from the origin, more than 1e+06 times "
       "its largest size (4)"},
      {"camera at its target",
       [](json& j) {
         j["views"][0]["camera"]["look_at"] = {0, 0, 10};
       },
       "/views/0/camera/look_at: must differ from position"},
      {"unknown camera type", [](json& j) { j["views"][0]["camera"]["type"] = "fisheye"; },
       "/views/0/camera/type: unknown camera type 'fisheye'"},
      {"path escaping the allowed root via ../",
       [](json& j) {
         j["volume"] = {{"vdb", {{"path", "../outside.vdb"}}}};
       },
       "/volume/vdb/path: path '../outside.vdb' is outside the allowed folders"},
      {"path escaping the allowed root via a symlink",
       [](json& j) {
         j["volume"] = {{"vdb", {{"path", "link.vdb"}}}};
       },
       "/volume/vdb/path: path 'link.vdb' is outside the allowed folders"},
      {"missing vdb file",
       [](json& j) {
         j["volume"] = {{"vdb", {{"path", "nope.vdb"}}}};
       },
       "/volume/vdb/path: file not found", nullptr, true},
      {"missing mesh file",
       [](json& j) {
         j["volume"] = {{"mesh", {{"path", "nope.obj"}, {"resolution", 32}}}};
       },
       "/volume/mesh/path: file not found", nullptr, true},
      {"missing sequence frame",
       [](json& j) {
         j["volume"] = {{"sequence", {{"paths", {"cloud.vdb", "f2.vdb"}}}}};
       },
       "/volume/sequence/paths/1: file not found", nullptr, true},
      {"0 frames in a sequence",
       [](json& j) {
         j["volume"] = {{"sequence", {{"procedural", {{"type", "perlin_cloud"}}}, {"frames", 0}}}};
       },
       "/volume/sequence/frames: must be an integer in [2, 100000]"},
      // Only precomputed renders a sequence, and it needs two basic volumes: one frame was
      // accepted here and by a dry run, then failed as the job ran (an outside probe).
      {"1 frame in a sequence",
       [](json& j) {
         j["volume"] = {{"sequence", {{"procedural", {{"type", "perlin_cloud"}}}, {"frames", 1}}}};
       },
       "/volume/sequence/frames: must be an integer in [2, 100000], got 1"},
      {"1 path in a sequence",
       [](json& j) {
         j["volume"] = {{"sequence", {{"paths", {"cloud.vdb"}}}}};
       },
       "/volume/sequence/paths: must list at least 2 files"},
      {"dissolve longer than the database",
       [](json& j) {
         j["volume"] = {{"sequence", {{"procedural", {{"type", "perlin_cloud"}}}, {"frames", 5}}}};
         j["bake"] = {{"method", "precomputed"}, {"dissolve", 4}};
       },
       "/bake/dissolve: 4 frames of cross-dissolve do not fit a database of 5 basic volumes"},
      {"walk knob on a static volume",
       [](json& j) {
         j["bake"] = {{"method", "precomputed"}, {"sigma", 0.1}};
       },
       "/bake/sigma: applies to animated volumes only"},
      {"sigma 0",
       [](json& j) {
         j["bake"] = {{"method", "precomputed"}, {"sigma", 0}};
       },
       "/bake/sigma: must be"},
      {"future cost on a static volume",
       [](json& j) {
         j["bake"] = {{"method", "precomputed"}, {"future_cost", 0.5}};
       },
       "/bake/future_cost: applies to animated volumes only"},
      {"future cost of 1 (the costs would not converge)",
       [](json& j) {
         j["volume"] = {{"sequence", {{"procedural", {{"type", "perlin_cloud"}}}, {"frames", 5}}}};
         j["bake"] = {{"method", "precomputed"}, {"future_cost", 1}};
       },
       "/bake/future_cost: must be in [0, 0.999]"},
      {"0 output frames",
       [](json& j) {
         j["bake"] = {{"method", "precomputed"}, {"frames", 0}};
       },
       "/bake/frames: must be an integer in [1, 1000000]"},
      {"0 sample points (K = 0)",
       [](json& j) {
         j["bake"] = {{"method", "precomputed"}, {"sample_points", 0}};
       },
       "/bake/sample_points: must be an integer in [1, 1048576]"},
      {"a knob of another method",
       [](json& j) {
         j["bake"] = {{"method", "precomputed"}, {"points", 100}};
       },
       "/bake/points"},
      {"frames disagreeing with paths",
       [](json& j) {
         j["volume"] = {{"sequence", {{"paths", {"cloud.vdb", "cloud.vdb"}}, {"frames", 3}}}};
       },
       "/volume/sequence/frames: is 3 but paths lists 2 files"},
      {"vdb_voxel_size for a grid volume",
       [](json& j) {
         j["volume"] = {{"vdb", {{"path", "cloud.vdb"}}}};
         j["outputs"]["vdb_voxel_size"] = 0.1;
       },
       "/outputs/vdb_voxel_size: only applies to box and sphere volumes"},
      {"output flag not a boolean", [](json& j) { j["outputs"]["exr"] = "yes"; },
       "/outputs/exr: must be true or false"},
      {"a lossy or unknown EXR compression",
       [](json& j) { j["outputs"]["exr_compression"] = "dwaa"; },
       "/outputs/exr_compression: unknown EXR compression 'dwaa' (known: none, rle, zips, zip, "
       "piz; lossless only)"},
      // A value's control characters are escaped where the message quotes it: a NUL would
      // have cut the message short, an escape sequence reached the terminal.
      {"an EXR compression with control characters",
       [](json& j) { j["outputs"]["exr_compression"] = std::string("zip\0\x1b[31m", 9); },
       "/outputs/exr_compression: unknown EXR compression 'zip\\x00\\x1B[31m' (known: none, rle"},
      {"an EXR compression that is not a string",
       [](json& j) { j["outputs"]["exr_compression"] = 3; },
       "/outputs/exr_compression: must be a string"},
      {"an EXR compression without EXR outputs",
       [](json& j) {
         j["outputs"]["exr"] = false;
         j["outputs"]["exr_compression"] = "piz";
       },
       "/outputs/exr_compression: applies only when /outputs/exr is true"},
      {"EXR layers not an array", [](json& j) { j["outputs"]["exr_layers"] = "beauty"; },
       "/outputs/exr_layers: must be an array of layer names (known: cloud, background, beauty, "
       "sun, sky, single, multiple), got a string"},
      {"no EXR layer", [](json& j) { j["outputs"]["exr_layers"] = json::array(); },
       "/outputs/exr_layers: must name at least one layer"},
      {"an unknown EXR layer",
       [](json& j) {
         j["outputs"]["exr_layers"] = {"sun", "Beauty"};
       },
       "/outputs/exr_layers/1: unknown layer 'Beauty' (known: cloud,"},
      {"an EXR layer twice",
       [](json& j) {
         j["outputs"]["exr_layers"] = {"sun", "sky", "sun"};
       },
       "/outputs/exr_layers/2: layer 'sun' is listed twice"},
      {"an EXR layer that is not a string", [](json& j) { j["outputs"]["exr_layers"] = {1}; },
       "/outputs/exr_layers/0: must be a string"},
      {"EXR layers without EXR outputs",
       [](json& j) {
         j["outputs"]["exr"] = false;
         j["outputs"]["exr_layers"] = {"sun"};
       },
       "/outputs/exr_layers: applies only when /outputs/exr is true"},
      {"no output at all",
       [](json& j) {
         j["outputs"]["exr"] = false;
         j["outputs"]["vdb"] = false;
       },
       "/outputs: asks for nothing: exr and vdb are both false"},
      // An outside probe's findings: each was refused late, or blamed on the wrong field.
      {"a denormal extinction", [](json& j) { j["medium"]["extinction"] = 1e-320; },
       "/medium/extinction: must be 0 or at least 1e-30 (the grids hold densities as floats), "
       "got "},
      {"a denormal box density", [](json& j) { j["volume"]["box"]["density"] = 1e-35; },
       "/volume/box/density: must be 0 or at least 1e-30"},
      {"a denormal procedural density",
       [](json& j) {
         j["volume"] = {{"procedural", {{"type", "perlin_cloud"}, {"density", 1e-320}}}};
       },
       "/volume/procedural/density: must be at least 1e-30"},
      {"a procedural size beyond 1e9",
       [](json& j) {
         j["volume"] = {{"procedural", {{"type", "perlin_cloud"}, {"size", {1e12, 2, 1}}}}};
       },
       "/volume/procedural/size/0: must be in (0, 1e+09], got 1e+12"},
      {"a procedural cloud too thin for its resolution",
       [](json& j) {
         j["volume"] = {
             {"procedural", {{"type", "perlin_cloud"}, {"size", {2, 2, 0.1}}, {"resolution", 8}}}};
       },
       "/volume/procedural/size: must be at least 6 voxels along every axis at resolution 8"},
      {"a sequence whose last frame's time is beyond 1e6",
       [](json& j) {
         j["volume"] = {
             {"sequence",
              {{"procedural", {{"type", "perlin_cloud"}, {"time", 1e6}}}, {"frames", 3}}}};
         j["bake"] = {{"method", "precomputed"}};
       },
       "/volume/sequence/time_step: puts the last frame's time at 1000000.2"},
      {"more rays per pixel than a view from a bake takes",
       [](json& j) {
         j["bake"] = {{"method", "single"}, {"samples", 1025}};
       },
       "/bake/samples: must be an integer in [1, 1024], got 1025"},
      {"shot name with a space", [](json& j) { j["name"] = "my shot"; }, "/name: must be 1 to 128"},
      {"box of the wrong shape",
       [](json& j) {
         j["volume"] = box();
         j["volume"]["box"]["min"] = {0, 0};
       },
       "/volume/box/min: must be an array of 3 numbers [x, y, z], got an array of 2"},
  };
  ASSERT_GE(cases.size(), 25u);
  for (const BadCase& c : cases) check(c);
}

// A direction is a direction at any scale: neither huge components (their length overflows) nor
// tiny ones (it underflows) make it a zero vector.
TEST(ShotParser, HugeAndTinyDirectionsAreDirections) {
  for (const json& d : {json{1e200, 1e200, 1e200}, json{1e-300, 0, 0}, json{-1e308, 0, 1e308}}) {
    json j = json::parse(kDesignSlab);
    j["lighting"]["sun"]["direction"] = d;
    const ShotSpec shot = parseShot(j.dump(), "");
    EXPECT_NEAR(length(shot.lighting.sun.direction), 1.0, 1e-12) << d;
  }
  json j = json::parse(kDesignSlab);
  j["lighting"]["sun"]["direction"] = {0, 0, 0};
  EXPECT_THROW(parseShot(j.dump(), ""), InputError);
}

TEST(ShotParser, AllowedRootsAcceptPathsInside) {
  TempDir dir;
  dir.write("root/sub/cloud.vdb", "x");
  json j = json::parse(kDesignSlab);
  j["volume"] = {{"vdb", {{"path", "sub/../sub/cloud.vdb"}, {"grid", "density"}}}};
  ParseOptions options;
  options.allowed_roots = {(dir.path() / "elsewhere").string(), (dir.path() / "root/").string()};
  EXPECT_NO_THROW(parseShot(j.dump(), (dir.path() / "root").string(), options));
  // Without the existence check (re-reading canonical shots), a missing file is fine.
  j["volume"]["vdb"]["path"] = "gone.vdb";
  options.check_files_exist = false;
  EXPECT_NO_THROW(parseShot(j.dump(), (dir.path() / "root").string(), options));
}

}  // namespace
}  // namespace cloudbake
