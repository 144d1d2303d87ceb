#include "core/volume/grid_volume.h"

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <cmath>
#include <optional>

#include "core/error.h"
#include "core/volume/analytic.h"
#include "core/volume/openvdb_grid.h"
#include "core/volume/sources.h"
#include "tests/core/volume/volume_test_util.h"

namespace cloudbake {
namespace {

using testing::checkMajorants;

TEST(Voxelize, BoxBecomesGridWithSameDensityInside) {
  const BoxDensity box(Vec3(-0.31, 0.11, 0.21), Vec3(0.51, 0.41, 1.11), 2.5);
  const auto field = voxelize(box, 0.05);
  const auto* grid = dynamic_cast<const GridVolume*>(field.get());
  ASSERT_NE(grid, nullptr);
  EXPECT_DOUBLE_EQ(grid->featureSize(), 0.05);
  EXPECT_DOUBLE_EQ(grid->voxelSize(), 0.05);
  EXPECT_FLOAT_EQ(grid->maxDensity(), 2.5);
  // Voxel centres at multiples of 0.05 within the box: x -6..10, y 3..8, z 5..22.
  EXPECT_EQ(grid->activeVoxelCount(), 17u * 6u * 18u);
  auto lookup = grid->lookup();
  EXPECT_NEAR(lookup->density(Vec3(0.1, 0.25, 0.6)), 2.5, 1e-6);
  EXPECT_EQ(lookup->density(Vec3(2, 2, 2)), 0.0);
  const Bounds3 b = grid->bounds();
  EXPECT_NEAR(b.min.x, -0.35, 1e-9);  // first centre -0.3, minus one voxel of footprint
  EXPECT_NEAR(b.max.z, 1.15, 1e-9);
  EXPECT_GT(checkMajorants(*grid, 20000), 1000);
  EXPECT_NE(grid->describe().find("vdb 'density'"), std::string::npos);
}

TEST(Voxelize, RejectsBadVoxelSizeAndTooManyVoxels) {
  const SphereDensity sphere(Vec3(0, 0, 0), 1.0, 1.0);
  EXPECT_THROW(voxelize(sphere, 0.0), InputError);
  EXPECT_THROW(voxelize(sphere, -1.0), InputError);
  EXPECT_THROW(voxelize(sphere, std::nan("")), InputError);
  try {
    voxelize(sphere, 1e-4);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("limit"), std::string::npos) << e.what();
  }
  EXPECT_THROW(voxelize(sphere, 0.1, 1000), InputError);
}

TEST(GridVolume, TrilinearMatchesHandComputedValue) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.f);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
  auto acc = grid->getAccessor();
  acc.setValue(openvdb::Coord(0, 0, 0), 1.f);
  acc.setValue(openvdb::Coord(1, 0, 0), 3.f);
  acc.setValue(openvdb::Coord(0, 1, 0), 5.f);
  grid->setName("density");
  const auto vol = makeGridVolume(grid, "test");
  auto lookup = vol->lookup();
  // World (0.25, 0, 0) = index (0.5, 0, 0): halfway between 1 and 3.
  EXPECT_NEAR(lookup->density(Vec3(0.25, 0, 0)), 2.0, 1e-6);
  // Index (0.5, 0.5, 0): (1 + 3 + 5 + 0) / 4.
  EXPECT_NEAR(lookup->density(Vec3(0.25, 0.25, 0)), 2.25, 1e-6);
  EXPECT_NEAR(lookup->density(Vec3(0, 0, 0.25)), 0.5, 1e-6);
  EXPECT_EQ(lookup->density(Vec3(-0.5, 0, 0)), 0.0);
  EXPECT_FLOAT_EQ(vol->maxDensity(), 5.f);
  EXPECT_EQ(vol->activeVoxelCount(), 3u);
  const Bounds3 b = vol->bounds();
  EXPECT_DOUBLE_EQ(b.min.x, -0.5);
  EXPECT_DOUBLE_EQ(b.max.x, 1.0);
  checkMajorants(*vol, 5000);
  // Tight: only the cells of block 0 and its lower neighbours (whose one-voxel dilation
  // reaches the voxels on block 0's lower faces) are non-zero, none above 5.
  const MajorantGrid& mg = vol->majorants();
  int nonzero = 0;
  for (int z = 0; z < mg.nz(); ++z)
    for (int y = 0; y < mg.ny(); ++y)
      for (int x = 0; x < mg.nx(); ++x) {
        nonzero += mg.cell(x, y, z) != 0.f;
        EXPECT_LE(mg.cell(x, y, z), 5.f);
      }
  EXPECT_GE(nonzero, 1);
  EXPECT_LE(nonzero, 8);
  EXPECT_EQ(mg.maxValue(), 5.f);
}

// Random sparse grid with a few dense blobs and an active tile; majorants must bound every
// trilinear lookup, for an axis-aligned, a mirrored and a rotated transform.
openvdb::FloatGrid::Ptr randomGrid(const openvdb::math::Transform::Ptr& xform) {
  auto grid = openvdb::FloatGrid::create(0.f);
  grid->setTransform(xform);
  auto acc = grid->getAccessor();
  Rng rng(3);
  for (int i = 0; i < 4000; ++i) {
    const openvdb::Coord c(static_cast<int>(rng.uniform() * 40) - 20,
                           static_cast<int>(rng.uniform() * 30) - 5,
                           static_cast<int>(rng.uniform() * 50) - 10);
    acc.setValue(c, static_cast<float>(rng.uniform() * rng.uniform() * 10));
  }
  grid->tree().addTile(1, openvdb::Coord(32, 32, 32), 4.f, true);
  grid->setName("density");
  return grid;
}

// A translated, a mirrored (voxels of 0.1) and a rotated transform (voxels of 0.2).
struct TestTransforms {
  openvdb::math::Transform::Ptr aligned, mirrored, rotated;
};
TestTransforms testTransforms() {
  TestTransforms t;
  t.aligned = openvdb::math::Transform::createLinearTransform(0.1);
  t.aligned->postTranslate(openvdb::Vec3d(1.0, -2.0, 0.5));
  t.mirrored = openvdb::math::Transform::createLinearTransform(0.1);
  t.mirrored->postScale(openvdb::Vec3d(-1.0, 1.0, -1.0));
  t.rotated = openvdb::math::Transform::createLinearTransform(0.2);
  t.rotated->postRotate(0.5, openvdb::math::Y_AXIS);
  t.rotated->postRotate(0.3, openvdb::math::Z_AXIS);
  return t;
}

TEST(GridVolume, MajorantsBoundTrilinearLookupsForAllTransforms) {
  openvdb::initialize();
  const auto [aligned, mirrored, rotated] = testTransforms();
  for (const auto& xform : {aligned, mirrored, rotated}) {
    const auto vol = makeGridVolume(randomGrid(xform), "test");
    EXPECT_GT(checkMajorants(*vol, 200000), 5000);
    EXPECT_EQ(vol->majorantBlockSize(), 8);
    EXPECT_NEAR(vol->featureSize(), xform == rotated ? 0.2 : 0.1, 1e-12);
  }
}

// The voxel centres are the sample lattice of a grid without rotation: lookups there return the
// voxel's value; a rotated grid has none.
TEST(GridVolume, SampleLatticeIsTheVoxelCentres) {
  openvdb::initialize();
  const auto [translated, mirrored, rotated] = testTransforms();
  for (const auto& xform : {translated, mirrored}) {
    const auto vol = makeGridVolume(randomGrid(xform), "test");
    const std::optional<SampleLattice> lat = vol->sampleLattice();
    ASSERT_TRUE(lat);
    EXPECT_NEAR(lat->spacing, 0.1, 1e-12);
    const auto grid = openvdbGrid(*vol);
    const auto acc = grid->getConstAccessor();
    auto lookup = vol->lookup();
    int nonzero = 0;
    for (int x = -20; x < 20; ++x) {
      for (int z = -10; z < 40; ++z) {
        const openvdb::Vec3d w = xform->indexToWorld(openvdb::Coord(x, 3, z));
        const Vec3 q(w.x(), w.y(), w.z());
        // Every voxel centre is a point of the lattice.
        for (int a = 0; a < 3; ++a) {
          const double steps = (q[a] - lat->origin[a]) / lat->spacing;
          EXPECT_NEAR(steps, std::round(steps), 1e-6);
        }
        const float v = acc.getValue(openvdb::Coord(x, 3, z));
        EXPECT_NEAR(lookup->density(q), v, 1e-5 * (1 + v));
        nonzero += v > 0;
      }
    }
    EXPECT_GT(nonzero, 0);
  }
  EXPECT_FALSE(makeGridVolume(randomGrid(rotated), "test")->sampleLattice());
}

// Lookups read a dense copy of small grids; they must return the tree's own trilinear value, bit
// for bit, everywhere in the bounds (the copy's edges included), for every transform.
TEST(GridVolume, DenseLookupsAreTheTreesOwnBits) {
  openvdb::initialize();
  auto aligned = openvdb::math::Transform::createLinearTransform(0.1);
  aligned->postTranslate(openvdb::Vec3d(1.0, -2.0, 0.5));
  auto rotated = openvdb::math::Transform::createLinearTransform(0.2);
  rotated->postRotate(0.5, openvdb::math::Y_AXIS);
  for (const auto& xform : {aligned, rotated}) {
    const auto vol = makeGridVolume(randomGrid(xform), "test");
    ASSERT_FALSE(vol->impl().dense.empty());
    const auto grid = openvdbGrid(*vol);
    const auto acc = grid->getConstAccessor();
    auto lookup = vol->lookup();
    const Bounds3 b = vol->bounds();
    Rng rng(17);
    int nonzero = 0;
    for (int i = 0; i < 200000; ++i) {
      const Vec3 p(b.min.x + rng.uniform() * (b.max.x - b.min.x),
                   b.min.y + rng.uniform() * (b.max.y - b.min.y),
                   b.min.z + rng.uniform() * (b.max.z - b.min.z));
      const auto& m = vol->impl().world_to_index;  // the lookup's own map, so idx is the same
      const openvdb::Vec3d idx(p.x * m[0][0] + p.y * m[1][0] + p.z * m[2][0] + m[3][0],
                               p.x * m[0][1] + p.y * m[1][1] + p.z * m[2][1] + m[3][1],
                               p.x * m[0][2] + p.y * m[1][2] + p.z * m[2][2] + m[3][2]);
      const float tree = openvdb::tools::BoxSampler::sample(acc, idx);
      const double d = lookup->density(p);
      ASSERT_EQ(d, tree > 0.f ? double(tree) : 0.0) << p.x << " " << p.y << " " << p.z;
      nonzero += d > 0;
    }
    EXPECT_GT(nonzero, 1000);
  }
  // A grid whose active box is too large for a dense copy keeps reading the tree.
  auto sparse = openvdb::FloatGrid::create(0.f);
  sparse->getAccessor().setValue(openvdb::Coord(0), 1.f);
  sparse->getAccessor().setValue(openvdb::Coord(400), 2.f);
  const auto far = makeGridVolume(sparse, "test");
  EXPECT_TRUE(far->impl().dense.empty());
  EXPECT_FLOAT_EQ(static_cast<float>(far->lookup()->density(Vec3(400))), 2.f);
}

TEST(GridVolume, RejectsNonUniformScaleAndNonZeroBackground) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.f);
  grid->getAccessor().setValue(openvdb::Coord(0), 1.f);
  auto stretched = openvdb::math::Transform::createLinearTransform(0.1);
  stretched->postScale(openvdb::Vec3d(1, 2, 1));
  grid->setTransform(stretched);
  EXPECT_THROW(makeGridVolume(grid, "test"), InputError);
  auto bg = openvdb::FloatGrid::create(1.f);
  bg->getAccessor().setValue(openvdb::Coord(0), 2.f);
  EXPECT_THROW(makeGridVolume(bg, "test"), InputError);
  EXPECT_THROW(makeGridVolume(openvdb::FloatGrid::create(0.f), "test"), InputError);
}

TEST(GridVolume, InactiveValuesAreIgnored) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.f);
  auto acc = grid->getAccessor();
  acc.setValue(openvdb::Coord(0), 1.f);
  acc.setValueOff(openvdb::Coord(1, 0, 0), 100.f);  // stale inactive value
  const auto vol = makeGridVolume(grid, "test");
  EXPECT_FLOAT_EQ(vol->maxDensity(), 1.f);
  EXPECT_NEAR(vol->lookup()->density(Vec3(0.5, 0, 0)), 0.5, 1e-6);
}

TEST(GridVolume, HugeGridsGetCoarserMajorantCells) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.f);
  // Two voxels 3000 apart on every axis: 375^3 blocks of 8 > 128^3 cells, so cells grow.
  grid->getAccessor().setValue(openvdb::Coord(0), 1.f);
  grid->getAccessor().setValue(openvdb::Coord(3000), 2.f);
  const auto vol = makeGridVolume(grid, "test");
  EXPECT_EQ(vol->majorantBlockSize(), 32);
  const MajorantGrid& mg = vol->majorants();
  EXPECT_LE(static_cast<int64_t>(mg.nx()) * mg.ny() * mg.nz(), GridVolume::kMaxMajorantCells);
  checkMajorants(*vol, 2000);
  auto lookup = vol->lookup();
  EXPECT_FLOAT_EQ(static_cast<float>(lookup->density(Vec3(3000))), 2.f);
  // Far-apart voxels must not allocate per-block arrays spanning the gap.
  auto sparse = openvdb::FloatGrid::create(0.f);
  sparse->getAccessor().setValue(openvdb::Coord(-1000000, 5, 5), 1.f);
  sparse->getAccessor().setValue(openvdb::Coord(1000000, 2000000, -3000000), 3.f);
  sparse->tree().addTile(2, openvdb::Coord(4096 * 3), 0.5f, true);  // a 128^3 tile
  const auto far = makeGridVolume(sparse, "test");
  EXPECT_FLOAT_EQ(far->maxDensity(), 3.f);
  const MajorantGrid& fm = far->majorants();
  EXPECT_LE(static_cast<int64_t>(fm.nx()) * fm.ny() * fm.nz(), GridVolume::kMaxMajorantCells);
  checkMajorants(*far, 2000);
  EXPECT_FLOAT_EQ(static_cast<float>(far->lookup()->density(Vec3(4096 * 3 + 5))), 0.5f);
}

}  // namespace
}  // namespace cloudbake
