#include "core/shot/scene_builder.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>

#include "core/io/exr_io.h"
#include "core/shot/shot_parser.h"
#include "tests/core/shot/shot_test_util.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;
using testing::kDesignSlab;

const fs::path kData = fs::path(CLOUDBAKE_SHARED_DIR) / "data";

TEST(SceneBuilder, BuildsTheDesignSlab) {
  const Scene s = buildScene(parseShot(kDesignSlab, ""));
  ASSERT_NE(s.medium.density, nullptr);
  const Bounds3 b = s.medium.density->bounds();
  EXPECT_EQ(b.min, Vec3(-50, -50, 0));
  EXPECT_EQ(b.max, Vec3(50, 50, 1));
  EXPECT_EQ(s.medium.density->maxDensity(), 1.0);
  EXPECT_EQ(s.medium.density->lookup()->density(Vec3(0, 0, 0.5)), 1.0);
  EXPECT_EQ(s.medium.extinction, 2.0);
  EXPECT_EQ(s.medium.albedo, Rgb(0.9, 0.9, 0.9));
  ASSERT_NE(s.medium.phase, nullptr);
  EXPECT_NEAR(s.medium.phase->meanCosine().x, 0.75, 1e-6);
  EXPECT_EQ(s.sun.direction, Vec3(0, 0, 1));
  EXPECT_EQ(s.sun.irradiance, Rgb(3.14159, 3.14159, 3.14159));
  EXPECT_EQ(s.sky.type, Sky::Type::kConstant);
  ASSERT_EQ(s.cameras.size(), 1u);
  EXPECT_EQ(s.cameras[0].name, "nadir");
  EXPECT_EQ(s.cameras[0].width_px, 32);
}

TEST(SceneBuilder, SphereProceduralAndNoSun) {
  json j = json::parse(kDesignSlab);
  j["volume"] = {{"sphere", {{"center", {1, 2, 3}}, {"radius", 0.5}, {"density", 3}}}};
  j["lighting"].erase("sun");
  j["medium"]["phase"] = {{"type", "isotropic"}, {"mie_ratio", 0.5}};
  Scene s = buildScene(parseShot(j.dump(), ""));
  EXPECT_EQ(s.medium.density->lookup()->density(Vec3(1, 2, 3.4)), 3.0);
  EXPECT_EQ(s.medium.density->lookup()->density(Vec3(1, 2, 3.6)), 0.0);
  EXPECT_EQ(s.sun.irradiance, Rgb(0, 0, 0));
  EXPECT_NEAR(s.medium.phase->eval(0.3).x, 1.0 / (4.0 * kPi), 1e-9);

  j["volume"] = {{"procedural", {{"type", "perlin_cloud"}, {"resolution", 24}, {"seed", 5}}}};
  s = buildScene(parseShot(j.dump(), ""));
  const Bounds3 b = s.medium.density->bounds();
  EXPECT_GE(b.min.x, -1.0 - 1e-9);
  EXPECT_LE(b.max.z, 1.0 + 1e-9);
  EXPECT_GT(s.medium.density->maxDensity(), 0.0);
}

TEST(SceneBuilder, SequencesAreBuiltFrameByFrame) {
  json j = json::parse(kDesignSlab);
  j["volume"] = {{"sequence", {{"procedural", {{"type", "perlin_cloud"}}}, {"frames", 3}}}};
  const ShotSpec shot = parseShot(j.dump(), "");
  try {
    buildScene(shot);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shot.json: /volume/sequence: "), std::string::npos);
  }
  const auto& seq = std::get<SequenceVolumeSpec>(shot.volume);
  EXPECT_THROW(buildSequenceFrame(seq, 3), InputError);
  // Procedural frames: the cloud at time procedural.time + i * time_step, inside one box; frames
  // differ from each other, and more for a larger step.
  const DensityFieldPtr f0 = buildSequenceFrame(seq, 0), f1 = buildSequenceFrame(seq, 1),
                        f2 = buildSequenceFrame(seq, 2);
  for (const DensityFieldPtr& f : {f0, f1, f2}) {
    EXPECT_GE(f->bounds().min.x, -1.0 - 1e-9);
    EXPECT_LE(f->bounds().max.z, 1.0 + 1e-9);
  }
  auto difference = [](const DensityField& a, const DensityField& b) {
    auto la = a.lookup(), lb = b.lookup();
    double d = 0;
    for (int i = 0; i < 2000; ++i) {
      const Vec3 p(-0.9 + 1.8 * ((i * 37) % 100) / 100.0, -0.9 + 1.8 * ((i * 61) % 100) / 100.0,
                   0.1 + 0.8 * ((i * 13) % 100) / 100.0);
      d += std::abs(la->density(p) - lb->density(p));
    }
    return d;
  };
  const double d01 = difference(*f0, *f1), d02 = difference(*f0, *f2);
  EXPECT_GT(d01, 0);
  EXPECT_GT(d02, d01);
  // Time 0 is the static cloud.
  json still = json::parse(kDesignSlab);
  still["volume"] = {{"procedural", {{"type", "perlin_cloud"}}}};
  EXPECT_EQ(difference(*f0, *buildScene(parseShot(still.dump(), "")).medium.density), 0.0);
  json bad = j;
  bad["volume"]["sequence"]["paths"] = {"a.vdb"};
  bad["volume"]["sequence"].erase("procedural");
  bad["volume"]["sequence"]["time_step"] = 0.5;
  EXPECT_THROW(parseShot(bad.dump(), ""), InputError);
}

TEST(SceneBuilder, AssetErrorsNameTheField) {
  testing::TempDir dir;
  dir.write("fake.vdb", "not a vdb file");
  dir.write("fake.ply", "ply\nformat ascii 1.0\nelement vertex 9999\nend_header\n1 2\n");
  json j = json::parse(kDesignSlab);
  j["volume"] = {{"vdb", {{"path", "fake.vdb"}}}};
  try {
    buildScene(parseShot(j.dump(), dir.path().string()));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shot.json: /volume/vdb: "), std::string::npos)
        << e.what();
  }
  j["volume"] = {{"mesh", {{"path", "fake.ply"}, {"resolution", 16}}}};
  try {
    buildScene(parseShot(j.dump(), dir.path().string()));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shot.json: /volume/mesh: "), std::string::npos)
        << e.what();
  }
}

// A builder's refusal of one key names that key's pointer (an outside probe read
// "/volume/sequence/procedural: perlin_cloud.cover: ..." and "/volume/mesh: ... mesh.voxel_size").
TEST(SceneBuilder, ABuildersRefusalNamesTheKeysPointer) {
  testing::TempDir dir;
  dir.write("tet.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n");
  json j = json::parse(kDesignSlab);
  const auto error = [&] {
    try {
      const ShotSpec shot = parseShot(j.dump(), dir.path().string());
      if (const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume)) {
        buildSequenceFrame(*seq, 0, "shot.json");
      } else {
        buildScene(shot, "shot.json");
      }
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const json cloud = {{"type", "perlin_cloud"}, {"resolution", 12}, {"cover", 1}};
  j["volume"] = {{"procedural", cloud}};
  EXPECT_EQ(error(), "shot.json: /volume/procedural/cover: 1 leaves no cloud at all (lower it)");
  j["volume"] = {{"sequence", {{"frames", 2}, {"procedural", cloud}}}};
  EXPECT_EQ(error(),
            "shot.json: /volume/sequence/procedural/cover: 1 leaves no cloud at all (lower it)");
  j["volume"] = {{"mesh", {{"path", "tet.obj"}, {"voxel_size", 1e-4}}}};
  const std::string mesh = error();
  EXPECT_EQ(mesh.find("shot.json: /volume/mesh/voxel_size: "), 0u) << mesh;
  EXPECT_NE(mesh.find("tet.obj: 1e-04 needs"), std::string::npos) << mesh;
}

// A sky map is read and checked as the scene is built, before any bake: a bad pixel was found
// only when the first view rendered, after the bake.
TEST(SceneBuilder, ABadSkyMapIsRefusedAsTheSceneIsBuilt) {
  testing::TempDir dir;
  Image map(8, 4, 3);
  map.at(5, 0)[1] = std::numeric_limits<float>::quiet_NaN();
  writeExr((dir.path() / "sky.exr").string(), {{"", map}});
  json j = json::parse(kDesignSlab);
  j["lighting"]["sky"] = {{"map", "sky.exr"}};
  try {
    buildScene(parseShot(j.dump(), dir.path().string()));
    FAIL() << "a NaN pixel must be refused";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shot.json: /lighting/sky/map: "), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("pixel (5, 0)"), std::string::npos) << e.what();
  }
  map.at(5, 0)[1] = 0.5f;
  writeExr((dir.path() / "sky.exr").string(), {{"", map}});
  EXPECT_EQ(buildScene(parseShot(j.dump(), dir.path().string())).sky.type, Sky::Type::kMap);
}

TEST(SceneBuilder, SharedAssets) {
  if (!fs::exists(kData / "wdas_cloud_sixteenth.vdb")) {
    GTEST_SKIP() << "shared assets absent (" << kData << ")";
  }
  json j = json::parse(kDesignSlab);
  j["volume"] = {
      {"vdb", {{"path", (kData / "wdas_cloud_sixteenth.vdb").string()}, {"grid", "dens"}}}};
  try {
    buildScene(parseShot(j.dump(), ""));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/volume/vdb: "), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("'dens'"), std::string::npos) << e.what();
  }
  j["volume"]["vdb"]["grid"] = "density";
  EXPECT_GT(buildScene(parseShot(j.dump(), "")).medium.density->maxDensity(), 0.0);
  // 10^12 voxels: the budget of a mesh given by voxel size is checked when the mesh loads.
  j["volume"] = {{"mesh", {{"path", (kData / "bun_zipper.ply").string()}, {"voxel_size", 1e-6}}}};
  try {
    buildScene(parseShot(j.dump(), ""));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shot.json: /volume/mesh/voxel_size: "), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("voxels"), std::string::npos) << e.what();
  }
  // Frame 1 of a two-frame sequence of the same file.
  j["volume"] = {{"sequence",
                  {{"paths",
                    {(kData / "wdas_cloud_sixteenth.vdb").string(),
                     (kData / "wdas_cloud_sixteenth.vdb").string()}}}}};
  const ShotSpec shot = parseShot(j.dump(), "");
  EXPECT_GT(buildSequenceFrame(std::get<SequenceVolumeSpec>(shot.volume), 1)->maxDensity(), 0.0);
}

}  // namespace
}  // namespace cloudbake
