#include "core/io/vdb_io.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <vector>

#include "core/error.h"
#include "core/math/rng.h"
#include "core/volume/analytic.h"
#include "core/volume/grid_volume.h"
#include "core/volume/sources.h"
#include "core/volume/vdb_header_check.h"
#include "tests/tiny_volume.h"

namespace cloudbake {
namespace {

class VdbIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = (std::filesystem::temp_directory_path() /
            ("cloudbake_vdb_io_test_" + std::to_string(::getpid())))
               .string();
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string dir_;
};

TEST_F(VdbIoTest, RoundTripsDensityExtraGridsAndMetadata) {
  PerlinCloudOptions cloud;
  cloud.resolution = 32;
  const auto field = makePerlinCloud(cloud);
  VdbWriteOptions o;
  o.float_grids.push_back({"height", [](const Vec3& p) { return static_cast<float>(p.z + 1); }});
  o.vec3_grids.push_back({"Cd", [](const Vec3& p) { return Vec3(p.x, 2.0, p.z); }});
  o.file_metadata["creator"] = "cloudbake test";
  o.grid_metadata["units"] = "metres";
  const std::string path = dir_ + "/cloud.vdb";
  writeVdb(path, *field, o);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));

  const VdbFileReader reader(path);
  EXPECT_EQ(reader.fileMetadata().at("creator"), "cloudbake test");
  EXPECT_EQ(reader.fileMetadata().at("cloudbake:version"), CLOUDBAKE_VERSION);
  ASSERT_EQ(reader.grids().size(), 3u);
  // Grid order in the file is OpenVDB's choice; look them up by name.
  auto grid = [&](const std::string& name) {
    for (const auto& info : reader.grids())
      if (info.name == name) return info;
    ADD_FAILURE() << "no grid " << name;
    return VdbGridInfo{};
  };
  const VdbGridInfo g[3] = {grid("density"), grid("height"), grid("Cd")};
  const uint64_t active = dynamic_cast<const GridVolume&>(*field).activeVoxelCount();
  EXPECT_EQ(g[0].name, "density");
  EXPECT_EQ(g[0].value_type, "float");
  EXPECT_EQ(g[0].grid_class, "fog volume");
  EXPECT_EQ(g[0].active_voxels, active);
  EXPECT_EQ(g[0].metadata.at("units"), "metres");
  EXPECT_EQ(g[1].name, "height");
  EXPECT_EQ(g[1].active_voxels, active);
  EXPECT_EQ(g[2].name, "Cd");
  EXPECT_EQ(g[2].value_type, "vec3s");
  EXPECT_EQ(g[2].vector_type, "invariant");
  EXPECT_EQ(g[2].active_voxels, active);
  EXPECT_NEAR(g[2].voxel_size, dynamic_cast<const GridVolume&>(*field).voxelSize(), 1e-12);

  // Values at voxel centres survive; the density reloads as the same field.
  const auto reloaded = loadVdbVolume({path, "density"});
  auto a = field->lookup(), b = reloaded->lookup();
  Rng rng(1);
  int checked = 0;
  for (int i = 0; i < 2000; ++i) {
    const Vec3 p(rng.uniform() * 2 - 1, rng.uniform() * 2 - 1, rng.uniform());
    EXPECT_EQ(a->density(p), b->density(p));
    const float d = reader.floatAt("density", p);
    if (d > 0) {
      ++checked;
      EXPECT_NEAR(reader.floatAt("height", p), p.z + 1, 0.04);
      const Vec3 cd = reader.vec3At("Cd", p);
      EXPECT_NEAR(cd.x, p.x, 0.04);
      EXPECT_EQ(cd.y, 2.0);
    }
  }
  EXPECT_GT(checked, 100);
  EXPECT_THROW(reader.floatAt("nope", Vec3(0)), InputError);
  EXPECT_THROW(reader.floatAt("Cd", Vec3(0)), InputError);
}

TEST_F(VdbIoTest, VoxelizesAnalyticFieldsAndOverwritesAtomically) {
  const BoxDensity box(Vec3(0.01, 0.01, 0.01), Vec3(0.99, 0.49, 0.29), 3.0);
  const std::string path = dir_ + "/box.vdb";
  VdbWriteOptions o;
  EXPECT_THROW(writeVdb(path, box, o), InputError);  // no voxel size for a non-grid field
  o.voxel_size = 0.1;
  writeVdb(path, box, o);
  writeVdb(path, box, o);  // overwrite in place
  const VdbFileReader reader(path);
  ASSERT_EQ(reader.grids().size(), 1u);
  EXPECT_EQ(reader.grids()[0].active_voxels, 9u * 4u * 2u);  // centres at multiples of 0.1
  EXPECT_EQ(reader.floatAt("density", Vec3(0.5, 0.2, 0.1)), 3.0f);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
}

TEST_F(VdbIoTest, ErrorsNameThePath) {
  const SphereDensity sphere(Vec3(0), 1.0, 1.0);
  VdbWriteOptions o;
  o.voxel_size = 0.25;
  const std::string bad = dir_ + "/no/such/dir/x.vdb";
  try {
    writeVdb(bad, sphere, o);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
  }
  o.float_grids.push_back({"density", [](const Vec3&) { return 1.f; }});
  EXPECT_THROW(writeVdb(dir_ + "/y.vdb", sphere, o), InputError);
  o.float_grids = {{"", [](const Vec3&) { return 1.f; }}};
  EXPECT_THROW(writeVdb(dir_ + "/y.vdb", sphere, o), InputError);
  EXPECT_THROW(VdbFileReader(dir_ + "/missing.vdb"), InputError);
  // A truncated file is reported, not half-read.
  const std::string good = dir_ + "/good.vdb";
  o.float_grids.clear();
  writeVdb(good, sphere, o);
  const auto size = std::filesystem::file_size(good);
  std::filesystem::resize_file(good, size - 10);
  EXPECT_THROW(VdbFileReader{good}, InputError);
}

// A full disk: the write fails with StorageFullError (a message naming no path, the path kept
// for the log) and leaves neither the file nor its temporary; it used to leave 0-byte files.
TEST_F(VdbIoTest, FullDiskThrowsStorageFullAndLeavesNoFile) {
  testing::TinyVolume volume(dir_ + "/tiny", 1);
  if (!volume.ok()) GTEST_SKIP() << volume.why();
  PerlinCloudOptions cloud;
  cloud.resolution = 128;
  cloud.cover = 0.1;  // mostly cloud: many active voxels
  const auto field = makePerlinCloud(cloud);
  const std::string path = volume.dir() + "/cloud.vdb";
  try {
    writeVdb(path, *field, {});
    FAIL() << "wrote " << std::filesystem::file_size(path) << " bytes into 1 MiB";
  } catch (const StorageFullError& e) {
    EXPECT_STREQ(e.what(), "no space left on the server's cache volume");
    EXPECT_NE(e.detail().find(path), std::string::npos) << e.detail();
  }
  EXPECT_FALSE(std::filesystem::exists(path));
  for (const auto& f : std::filesystem::directory_iterator(dir_)) {
    EXPECT_EQ(f.path().string().rfind(path + ".tmp", 0), std::string::npos) << f.path();
  }
  // The space is free again: a small file writes and reads back.
  cloud.resolution = 16;
  writeVdb(path, *makePerlinCloud(cloud), {});
  EXPECT_EQ(VdbFileReader(path).grids().size(), 1u);
}

// A corrupt length in the header (here the first metadata name's, set to 4 GB - 8) is refused
// by the pre-check naming the path, before OpenVDB would allocate what it declares.
TEST_F(VdbIoTest, CorruptHeaderLengthIsRefusedBeforeOpenVdbAllocates) {
  PerlinCloudOptions cloud;
  cloud.resolution = 16;
  const std::string path = dir_ + "/header.vdb";
  VdbWriteOptions o;
  o.file_metadata["creator"] = "cloudbake test";
  writeVdb(path, *makePerlinCloud(cloud), o);
  EXPECT_NO_THROW(checkVdbHeader(path));
  {
    // magic 8, version 4, library version 8, offsets flag 1, UUID 36; then the metadata count
    // (4) and the first name's length.
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(8 + 4 + 8 + 1 + 36 + 4);
    const unsigned char huge[4] = {0xf8, 0xff, 0xff, 0xff};
    f.write(reinterpret_cast<const char*>(huge), 4);
  }
  for (auto read : std::vector<std::function<void()>>{[&] { checkVdbHeader(path); },
                                                      [&] { VdbFileReader{path}; },
                                                      [&] {
                                                        loadVdbVolume({path, "density"});
                                                      }}) {
    try {
      read();
      ADD_FAILURE() << "a corrupt header was read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("more than the file holds"), std::string::npos)
          << e.what();
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
}

// Writes a small Perlin cloud to `path`, checks that its header passes, and returns its bytes.
std::string writeSmallCloud(const std::string& path) {
  PerlinCloudOptions cloud;
  cloud.resolution = 16;
  writeVdb(path, *makePerlinCloud(cloud), {});
  EXPECT_NO_THROW(checkVdbHeader(path));
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// A grid's delayed-load metadata (OpenVDB's own, in every file it writes) declares its buffers'
// sizes inside its value; OpenVDB allocates them before reading (a fuzzing finding: a mask
// declared 4 GB long in a 67-byte value). Each corrupt size is refused, the file intact is not.
TEST_F(VdbIoTest, CorruptDelayedLoadBufferIsRefusedBeforeOpenVdbAllocates) {
  const std::string path = dir_ + "/delayed.vdb";
  const std::string bytes = writeSmallCloud(path);
  EXPECT_NO_THROW(loadVdbVolume({path, "density"}));
  // The type name, then the value's size (4), the leaf count (4) and the mask buffer's size (4).
  const std::string type = "__delayedload";
  const size_t at = bytes.find(type);
  ASSERT_NE(at, std::string::npos);
  const size_t count_at = at + type.size() + 4;
  struct Patch {
    size_t offset;
    uint32_t value;
  };
  for (const Patch& patch :
       {Patch{count_at, 0xffffffffu}, Patch{count_at + 4, 0xffffffffu}, Patch{count_at + 4, 3u}}) {
    const std::string corrupt = dir_ + "/delayed_corrupt.vdb";
    {
      std::string copy = bytes;
      for (int i = 0; i < 4; ++i) copy[patch.offset + i] = char((patch.value >> (8 * i)) & 0xff);
      std::ofstream out(corrupt, std::ios::binary);
      out.write(copy.data(), std::streamsize(copy.size()));
    }
    for (auto read : std::vector<std::function<void()>>{[&] { checkVdbHeader(corrupt); },
                                                        [&] {
                                                          loadVdbVolume({corrupt, "density"});
                                                        }}) {
      try {
        read();
        ADD_FAILURE() << "a corrupt delayed-load value was read (patch at " << patch.offset << ")";
      } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("delayed-load"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(corrupt), std::string::npos) << e.what();
      }
    }
  }
}

// The same inside a grid: its own metadata, which OpenVDB reads before the tree (a fuzzing
// finding: a name declared 1.7 GB long was allocated before anything failed).
TEST_F(VdbIoTest, CorruptGridMetadataLengthIsRefusedBeforeOpenVdbAllocates) {
  const std::string path = dir_ + "/grid_meta.vdb";
  const std::string bytes = writeSmallCloud(path);
  // After the grid type: the instance parent's length (4), the data, block and end offsets
  // (24), the grid's compression flags (4), its metadata count (4), then the first name's length.
  const std::string type = "Tree_float_5_4_3";
  const size_t at = bytes.find(type);
  ASSERT_NE(at, std::string::npos);
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(at + type.size() + 4 + 24 + 4 + 4));
    const unsigned char huge[4] = {0x00, 0x00, 0x00, 0x65};
    f.write(reinterpret_cast<const char*>(huge), 4);
  }
  for (auto read : std::vector<std::function<void()>>{[&] { checkVdbHeader(path); },
                                                      [&] {
                                                        loadVdbVolume({path, "density"});
                                                      }}) {
    try {
      read();
      ADD_FAILURE() << "a corrupt grid header was read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("more than the file holds"), std::string::npos)
          << e.what();
    }
  }
}

}  // namespace
}  // namespace cloudbake
