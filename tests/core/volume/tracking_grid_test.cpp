#include "core/volume/tracking_grid.h"

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/math/rng.h"
#include "core/volume/openvdb_grid.h"

namespace cloudbake {
namespace {

struct Dense {
  int n[3];
  std::vector<float> v;
  float at(int x, int y, int z) const {
    if (x >= n[0] || y >= n[1] || z >= n[2]) return 0.f;
    return std::max(0.f, v[(size_t(z) * n[1] + y) * n[0] + x]);
  }
  DenseView view() const {
    DenseView d;
    d.values = v.data();
    for (int a = 0; a < 3; ++a) d.n[a] = n[a];
    return d;
  }
};

// Random values with zeros and negatives (lookups clamp those to 0).
Dense randomDense(int nx, int ny, int nz, uint64_t seed) {
  Dense d{{nx, ny, nz}, {}};
  Rng rng(seed);
  d.v.resize(size_t(nx) * ny * nz);
  for (float& x : d.v) {
    const double u = rng.uniform();
    x = u < 0.1 ? 0.f : u < 0.15 ? -0.5f : float(2 * rng.uniform());
  }
  return d;
}

size_t cellIndex(const CellBounds& b, int x, int y, int z) {
  return (size_t(z) * b.n[1] + y) * b.n[0] + x;
}

TEST(TrackingGrid, CellsBoundEveryTrilinearLookupExactly) {
  const Dense d = randomDense(7, 6, 5, 3);
  const CellBounds b = trilinearCellBounds(d.view());
  ASSERT_EQ(b.n[0], 6);
  ASSERT_EQ(b.n[2], 4);
  Rng rng(5);
  int at_min = 0;
  for (int s = 0; s < 20000; ++s) {
    const double p[3] = {rng.uniform() * 6, rng.uniform() * 5, rng.uniform() * 4};
    int i[3];
    double f[3];
    for (int a = 0; a < 3; ++a) {
      i[a] = int(p[a]);
      f[a] = p[a] - i[a];
    }
    double v = 0;
    for (int c = 0; c < 8; ++c) {
      const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
      v += d.at(i[0] + dx, i[1] + dy, i[2] + dz) * (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) *
           (dz ? f[2] : 1 - f[2]);
    }
    const size_t k = cellIndex(b, i[0], i[1], i[2]);
    ASSERT_LE(v, b.maxima[k] * (1 + 1e-6));
    ASSERT_GE(v, b.minima[k] * (1 - 1e-6));
    if (b.minima[k] > 0) ++at_min;
  }
  EXPECT_GT(at_min, 0) << "the test must see non-zero minorants";
}

TEST(TrackingGrid, CoarseLevelsEqualTheBoundsOfTheirVoxels) {
  const Dense d = randomDense(11, 9, 6, 7);
  CellBounds b = trilinearCellBounds(d.view());
  for (int level = 0; level < 2; ++level) {
    b = coarsenCellBounds(b);
    const int m = b.m;
    ASSERT_EQ(m, 2 << level);
    for (int z = 0; z < b.n[2]; ++z)
      for (int y = 0; y < b.n[1]; ++y)
        for (int x = 0; x < b.n[0]; ++x) {
          float hi = 0, lo = 1e30f;
          for (int k = 0; k <= m; ++k)
            for (int j = 0; j <= m; ++j)
              for (int i = 0; i <= m; ++i) {
                const float v = d.at(x * m + i, y * m + j, z * m + k);
                hi = std::max(hi, v);
                lo = std::min(lo, v);
              }
          const size_t c = cellIndex(b, x, y, z);
          ASSERT_EQ(b.maxima[c], hi) << "m " << m << " cell " << x << "," << y << "," << z;
          ASSERT_EQ(b.minima[c], lo) << "m " << m << " cell " << x << "," << y << "," << z;
        }
  }
}

TEST(TrackingGrid, ThickMediaGetFineCellsThinOnesCoarse) {
  // A smooth blob: fine cells bound it tightly, so a thick medium pays for their crossings.
  Dense d{{65, 65, 65}, {}};
  d.v.resize(size_t(65) * 65 * 65);
  for (int z = 0; z < 65; ++z)
    for (int y = 0; y < 65; ++y)
      for (int x = 0; x < 65; ++x) {
        const double r2 =
            ((x - 32.) * (x - 32.) + (y - 32.) * (y - 32.) + (z - 32.) * (z - 32.)) / (24. * 24.);
        d.v[(size_t(z) * 65 + y) * 65 + x] = float(std::max(0.0, 1 - r2));
      }
  const std::vector<CellBounds> levels = cellBoundsLevels(d.view(), int64_t(1) << 21);
  ASSERT_EQ(levels.front().m, 1);
  ASSERT_EQ(levels.back().m, 64);
  const int thick = levels[cheapestLevel(levels, 20.0)].m;
  const int medium = levels[cheapestLevel(levels, 0.5)].m;
  const int thin = levels[cheapestLevel(levels, 1e-6)].m;
  EXPECT_LE(thick, 2);
  EXPECT_LT(thick, medium);
  EXPECT_LT(medium, thin);
  EXPECT_EQ(thin, 64);
  // The cost falls with the residual: at a fixed cell size, thicker is dearer.
  EXPECT_LT(trackingCost(levels[2], 0.1, {}), trackingCost(levels[2], 1.0, {}));
  // A cap on cells drops the finest levels.
  const std::vector<CellBounds> capped = cellBoundsLevels(d.view(), 40 * 40 * 40);
  EXPECT_EQ(capped.front().m, 2);
}

// GridVolume's tracking grid, with a mirrored axis: every lookup lies within its cell's bounds.
TEST(TrackingGrid, GridVolumeLookupsLieWithinTheirCells) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.f);
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  m.preScale(openvdb::Vec3d(0.25));
  m(0, 0) = -0.25;  // mirrored x
  m.setTranslation(openvdb::Vec3d(1, 2, 3));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  Rng rng(9);
  auto acc = grid->getAccessor();
  for (int z = -3; z < 14; ++z)
    for (int y = 0; y < 10; ++y)
      for (int x = 2; x < 21; ++x) acc.setValue(openvdb::Coord(x, y, z), float(rng.uniform()));
  const auto vol = makeGridVolume(grid, "test");
  for (int cell : {1, 2, 8}) {
    const auto tg = vol->trackingGrid({1.0, cell});
    ASSERT_TRUE(tg->hasMinorants());
    const Bounds3 b = tg->bounds();
    for (int a = 0; a < 3; ++a) {
      EXPECT_LE(b.min[a], vol->bounds().min[a] + 1e-9);
      EXPECT_GE(b.max[a], vol->bounds().max[a] - 1e-9);
    }
    auto lookup = vol->lookup();
    const int n[3] = {tg->nx(), tg->ny(), tg->nz()};
    int inside = 0;
    for (int s = 0; s < 20000; ++s) {
      int c[3];
      Vec3 p;
      for (int a = 0; a < 3; ++a) {
        c[a] = std::min(n[a] - 1, int(rng.uniform() * n[a]));
        p[a] = b.min[a] + (c[a] + rng.uniform()) * b.extent()[a] / n[a];
      }
      const double d = lookup->density(p);
      ASSERT_LE(d, tg->cell(c[0], c[1], c[2]) * (1 + 1e-6) + 1e-7) << "cell " << cell;
      ASSERT_GE(d, tg->minorant(c[0], c[1], c[2]) * (1 - 1e-6) - 1e-7) << "cell " << cell;
      if (tg->minorant(c[0], c[1], c[2]) > 0) ++inside;
    }
    // (Cells of 8 voxels all touch the grid's zero border: their minorants are 0.)
    if (cell < 8) {
      EXPECT_GT(inside, 100) << "cell " << cell;
    }
  }
  // Thick media get finer cells than thin ones, and the grid is cached per cell size.
  const auto thick = vol->trackingGrid({1e3, 0}), thin = vol->trackingGrid({1e-6, 0});
  EXPECT_LT(thick->bounds().extent().x / thick->nx(), thin->bounds().extent().x / thin->nx());
  EXPECT_EQ(vol->trackingGrid({1.0, 2}).get(), vol->trackingGrid({1.0, 2}).get());
}

}  // namespace
}  // namespace cloudbake
