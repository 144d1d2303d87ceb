#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "core/error.h"
#include "core/volume/grid_volume.h"
#include "core/volume/sources.h"
#include "core/volume/vdb_transcode.h"
#include "tests/core/volume/volume_test_util.h"

namespace cloudbake {
namespace {

using testing::checkMajorants;
using testing::scratchDir;

std::string expectInputError(const VdbSourceOptions& o) {
  try {
    loadVdbVolume(o);
  } catch (const InputError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
    return "";
  }
  ADD_FAILURE() << "expected InputError for " << o.path;
  return "";
}

void writeGrids(const std::string& path, const openvdb::GridPtrVec& grids) {
  openvdb::io::File file(path);
  file.write(grids);
  file.close();
}

openvdb::FloatGrid::Ptr ballGrid(const std::string& name, float value) {
  auto grid = openvdb::FloatGrid::create(0.f);
  grid->setName(name);
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(0.1));
  auto acc = grid->getAccessor();
  for (int x = -6; x <= 6; ++x)
    for (int y = -6; y <= 6; ++y)
      for (int z = -6; z <= 6; ++z)
        if (x * x + y * y + z * z <= 36) acc.setValue(openvdb::Coord(x, y, z), value);
  return grid;
}

class VdbSourceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    openvdb::initialize();
    dir_ = scratchDir("vdb");
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string dir_;
};

TEST_F(VdbSourceTest, LoadsWrittenFogVolume) {
  const std::string path = dir_ + "/ball.vdb";
  writeGrids(path, {ballGrid("density", 0.75f), ballGrid("other", 2.f)});
  const auto field = loadVdbVolume({path, "density"});
  const auto* grid = dynamic_cast<const GridVolume*>(field.get());
  ASSERT_NE(grid, nullptr);
  EXPECT_FLOAT_EQ(grid->maxDensity(), 0.75f);
  EXPECT_NEAR(grid->lookup()->density(Vec3(0.05, 0, 0)), 0.75, 1e-6);
  EXPECT_NEAR(grid->voxelSize(), 0.1, 1e-12);
  const auto other = loadVdbVolume({path, "other"});
  EXPECT_FLOAT_EQ(other->maxDensity(), 2.f);
  checkMajorants(*field, 5000);
}

TEST_F(VdbSourceTest, MissingFileAndGarbageBytes) {
  std::string msg = expectInputError({dir_ + "/nope.vdb", "density"});
  EXPECT_NE(msg.find("nope.vdb"), std::string::npos) << msg;
  const std::string garbage = dir_ + "/garbage.vdb";
  testing::writeText(
      garbage, std::string("this is not an OpenVDB file at all\n") + std::string(1000, '\x7f'));
  msg = expectInputError({garbage, "density"});
  EXPECT_NE(msg.find("garbage.vdb"), std::string::npos) << msg;
  const std::string empty = dir_ + "/empty.vdb";
  testing::writeText(empty, "");
  expectInputError({empty, "density"});
  expectInputError({dir_, "density"});  // a directory
}

TEST_F(VdbSourceTest, TruncatedFilesFailCleanly) {
  const std::string path = dir_ + "/ball.vdb";
  writeGrids(path, {ballGrid("density", 1.f)});
  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 200u);
  const std::string cut = dir_ + "/cut.vdb";
  for (size_t len : {size_t{0}, size_t{4}, size_t{8}, size_t{16}, size_t{40}, size_t{100},
                     bytes.size() / 2, bytes.size() - 40, bytes.size() - 1}) {
    testing::writeText(cut, bytes.substr(0, len));
    const std::string msg = expectInputError({cut, "density"});
    EXPECT_NE(msg.find("cut.vdb"), std::string::npos) << len << ": " << msg;
  }
}

// transcodeVdb (what the server's child reader runs) keeps every grid, value and metadata, and
// refuses what loadVdbVolume refuses, naming the file.
TEST_F(VdbSourceTest, TranscodedFileHoldsTheSameGrids) {
  const std::string path = dir_ + "/ball.vdb", out = dir_ + "/ball.rewritten.vdb";
  writeGrids(path, {ballGrid("density", 0.75f), ballGrid("other", 2.f)});
  transcodeVdb(path, out);
  EXPECT_FALSE(std::filesystem::exists(out + ".tmp"));
  for (const char* name : {"density", "other"}) {
    const auto a = loadVdbVolume({path, name});
    const auto b = loadVdbVolume({out, name});
    EXPECT_EQ(a->maxDensity(), b->maxDensity()) << name;
    for (double x = -0.6; x <= 0.6; x += 0.037) {
      EXPECT_EQ(a->lookup()->density(Vec3(x, 0.01, -0.02)),
                b->lookup()->density(Vec3(x, 0.01, -0.02)))
          << name << " at " << x;
    }
  }
  const std::string cut = dir_ + "/cut.vdb";
  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  testing::writeText(cut, bytes.substr(0, bytes.size() / 2));
  try {
    transcodeVdb(cut, out);
    ADD_FAILURE() << "a truncated file was rewritten";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.vdb"), std::string::npos) << e.what();
  }
  EXPECT_THROW(transcodeVdb(dir_ + "/nope.vdb", out), InputError);
  EXPECT_THROW(transcodeVdb(path, dir_ + "/no/such/folder/x.vdb"), InputError);
}

TEST_F(VdbSourceTest, GridSelectionAndTypeErrors) {
  const std::string path = dir_ + "/grids.vdb";
  auto vec = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
  vec->setName("vel");
  vec->getAccessor().setValue(openvdb::Coord(0), openvdb::Vec3s(1, 2, 3));
  auto empty = openvdb::FloatGrid::create(0.f);
  empty->setName("empty");
  writeGrids(path, {ballGrid("smoke", 1.f), vec, empty});
  std::string msg = expectInputError({path, "density"});
  EXPECT_NE(msg.find("'smoke'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'vel'"), std::string::npos) << msg;
  msg = expectInputError({path, "vel"});
  EXPECT_NE(msg.find("float"), std::string::npos) << msg;
  msg = expectInputError({path, "empty"});
  EXPECT_NE(msg.find("empty"), std::string::npos) << msg;
}

TEST_F(VdbSourceTest, RejectsNanAndNegativeVoxelsNamingTheVoxel) {
  auto nan_grid = ballGrid("density", 1.f);
  nan_grid->getAccessor().setValue(openvdb::Coord(1, 2, 3), std::nanf(""));
  writeGrids(dir_ + "/nan.vdb", {nan_grid});
  std::string msg = expectInputError({dir_ + "/nan.vdb", "density"});
  EXPECT_NE(msg.find("(1, 2, 3)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("nan.vdb"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'density'"), std::string::npos) << msg;
  auto neg = ballGrid("density", 1.f);
  neg->getAccessor().setValue(openvdb::Coord(-4, 0, 0), -0.5f);
  writeGrids(dir_ + "/neg.vdb", {neg});
  msg = expectInputError({dir_ + "/neg.vdb", "density"});
  EXPECT_NE(msg.find("(-4, 0, 0)"), std::string::npos) << msg;
  auto inf_tile = ballGrid("density", 1.f);
  inf_tile->tree().addTile(1, openvdb::Coord(64, 0, 0), INFINITY, true);
  writeGrids(dir_ + "/inf.vdb", {inf_tile});
  expectInputError({dir_ + "/inf.vdb", "density"});
}

// The scale and voxel size (six doubles after the map's name) of a file's UniformScaleMap set to
// `value`, as a corrupt or hand-made file may hold them: OpenVDB refuses to build such a map in
// memory, but reads it from a file and only fails when it first inverts it.
void setFileScale(const std::string& path, double value) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  const std::string name = "UniformScaleMap";
  const size_t at = bytes.find(name);
  ASSERT_NE(at, std::string::npos);
  for (int k = 0; k < 6; ++k) {
    std::memcpy(&bytes[at + name.size() + 8 * size_t(k)], &value, sizeof value);
  }
  testing::writeText(path, bytes);
}

// An outside probe: a file's transform may be singular (a zero or tiny scale) or so large that
// the cloud's box is infinite. Both are the file's fault: an error naming it, not an internal one.
TEST_F(VdbSourceTest, RefusesADegenerateOrHugeTransformNamingTheFile) {
  for (const double scale : {0.0, 1e-7, 1e300, 1e15, std::nan("")}) {
    const std::string path = dir_ + "/scale.vdb";
    writeGrids(path, {ballGrid("density", 1.f)});
    setFileScale(path, scale);
    const std::string msg = expectInputError({path, "density"});
    EXPECT_NE(msg.find("scale.vdb: grid 'density': its "), std::string::npos) << scale << msg;
  }
  // A scale at which the cloud stays within +-1e15 loads.
  writeGrids(dir_ + "/big.vdb", {ballGrid("density", 1.f)});
  setFileScale(dir_ + "/big.vdb", 1e12);
  EXPECT_GT(loadVdbVolume({dir_ + "/big.vdb", "density"})->bounds().max.x, 6e12);
}

TEST_F(VdbSourceTest, LevelSetBecomesFogVolume) {
  auto sdf = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(1.0f, openvdb::Vec3f(0),
                                                                      0.05f, 3.0f);
  sdf->setName("surface");
  ASSERT_EQ(sdf->getGridClass(), openvdb::GRID_LEVEL_SET);
  writeGrids(dir_ + "/sphere.vdb", {sdf});
  const auto field = loadVdbVolume({dir_ + "/sphere.vdb", "surface"});
  auto lookup = field->lookup();
  EXPECT_NEAR(lookup->density(Vec3(0, 0, 0)), 1.0, 1e-6);
  EXPECT_NEAR(lookup->density(Vec3(0.5, 0.2, -0.3)), 1.0, 1e-6);
  EXPECT_EQ(lookup->density(Vec3(1.2, 0, 0)), 0.0);
  const Bounds3 b = field->bounds();
  EXPECT_NEAR(b.max.x, 1.0, 0.2);
  EXPECT_NEAR(b.min.z, -1.0, 0.2);
  checkMajorants(*field, 20000);
}

TEST(VdbSourceShared, LoadsWdasCloud) {
  const std::string path = testing::sharedData("wdas_cloud_sixteenth.vdb");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared asset absent: " << path;
  const auto t0 = std::chrono::steady_clock::now();
  const auto field = loadVdbVolume({path, "density"});
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto* grid = dynamic_cast<const GridVolume*>(field.get());
  ASSERT_NE(grid, nullptr);
  const Bounds3 b = grid->bounds();
  std::printf(
      "wdas_cloud_sixteenth: %.3f s, %llu active voxels, voxel %.4g, bounds [%g %g %g]-[%g %g %g], "
      "max %g, %s\n",
      secs, static_cast<unsigned long long>(grid->activeVoxelCount()), grid->voxelSize(), b.min.x,
      b.min.y, b.min.z, b.max.x, b.max.y, b.max.z, grid->maxDensity(), grid->describe().c_str());
  EXPECT_GT(grid->activeVoxelCount(), 100000u);
  EXPECT_GT(grid->maxDensity(), 0.0);
  EXPECT_LE(grid->maxDensity(), 10.0);
  for (int a = 0; a < 3; ++a) EXPECT_GT(b.extent()[a], 10 * grid->voxelSize());
  EXPECT_GT(checkMajorants(*grid, 200000), 1000);
  // Majorants are local: many empty cells, and most non-empty ones below the global maximum.
  const MajorantGrid& mg = grid->majorants();
  int empty = 0, below = 0, total = mg.nx() * mg.ny() * mg.nz();
  for (int z = 0; z < mg.nz(); ++z)
    for (int y = 0; y < mg.ny(); ++y)
      for (int x = 0; x < mg.nx(); ++x) {
        empty += mg.cell(x, y, z) == 0.f;
        below += mg.cell(x, y, z) > 0.f && mg.cell(x, y, z) < 0.9 * grid->maxDensity();
      }
  std::printf("majorant cells %dx%dx%d: %d empty, %d below 0.9 max\n", mg.nx(), mg.ny(), mg.nz(),
              empty, below);
  EXPECT_GT(empty, total / 10);
  EXPECT_GT(below, 0);
  std::string msg;
  try {
    loadVdbVolume({path, "temperature"});
  } catch (const InputError& e) {
    msg = e.what();
  }
  EXPECT_NE(msg.find("'density'"), std::string::npos) << msg;
  // Truncated copies of the real file.
  const std::string dir = scratchDir("wdas");
  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (size_t len : {size_t{300}, bytes.size() / 3, bytes.size() - 1000}) {
    testing::writeText(dir + "/cut.vdb", bytes.substr(0, len));
    EXPECT_THROW(loadVdbVolume({dir + "/cut.vdb", "density"}), InputError) << len;
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace cloudbake
