#include "core/bake/bake_lattice.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/bake/bake_grid.h"
#include "core/error.h"
#include "core/math/rng.h"
#include "core/volume/analytic.h"
#include "core/volume/sources.h"

namespace cloudbake {
namespace {

// A lumpy grid: a sphere with a density ramp, voxelised at `voxel` (centres at multiples of it).
DensityFieldPtr lumpyGrid(double voxel) {
  const SphereDensity sphere(Vec3(0.13, -0.07, 0.21), 1.0, 2.0);
  return voxelize(sphere, voxel);
}

// The largest difference between the lattice's trilinear lookups and the field's own, over
// random points of the field's bounds grown by a voxel.
double maxLookupDifference(const BakedLight& bake, const DensityField& field) {
  Rng rng(7);
  auto lookup = field.lookup();
  const Bounds3 b = field.bounds();
  const Vec3 lo = b.min - Vec3(bake.grid.voxel_size);
  const Vec3 ext = b.extent() + Vec3(2 * bake.grid.voxel_size);
  double worst = 0;
  for (int n = 0; n < 20000; ++n) {
    const Vec3 p = lo + Vec3(rng.uniform() * ext.x, rng.uniform() * ext.y, rng.uniform() * ext.z);
    const double d = sampleTrilinear(bake.grid, bake.density.data(), p);
    worst = std::max(worst, std::abs(d - lookup->density(p)));
  }
  return worst;
}

// A lattice aligned with a grid's voxel centres, at its spacing or an integer fraction of it,
// reads what the grid reads everywhere; the box means at the same resolution blur it.
TEST(BakeLattice, AlignedLatticeReproducesTheGridsLookups) {
  const double voxel = 0.05;
  const DensityFieldPtr grid = lumpyGrid(voxel);
  // Its own voxels along the longest side (the bounds hold one more, the trilinear footprint).
  const int own = int(std::round(maxComponent(grid->bounds().extent()) / voxel)) - 1;
  for (int m : {1, 2, 3}) {
    const int resolution = own * m;
    const BakedLight aligned = makeBakeLattice(*grid, resolution, LatticeSampling::kFieldAligned);
    EXPECT_NEAR(aligned.grid.voxel_size, voxel / m, 1e-12) << "m = " << m;
    EXPECT_LT(maxLookupDifference(aligned, *grid), 1e-5) << "m = " << m;
    // The test can fail: box means of the same lattice are a voxel's blur away.
    const BakedLight box = makeBakeLattice(*grid, resolution, LatticeSampling::kBoxMean);
    EXPECT_GT(maxLookupDifference(box, *grid), 0.05) << "m = " << m;
  }
}

// A request of the grid's own voxels or between two spacings takes the coarser (about as many
// voxels as asked); a request clearly coarser than the grid, a lattice over (resolution + 4)^3
// voxels (what the servers' limits count, and the footprint), or a field with no sample lattice
// keeps the box means.
TEST(BakeLattice, AlignedLatticeIsAboutTheRequestAndFallsBackToBoxMeans) {
  const double voxel = 0.05;
  // An elongated cloud, as clouds are (a cube's lattice a little finer than asked would hold
  // more than the cube of the request).
  const DensityFieldPtr grid = voxelize(BoxDensity(Vec3(-1, -0.5, 0), Vec3(1, 0.5, 0.8), 1), voxel);
  const int own = int(std::round(maxComponent(grid->bounds().extent()) / voxel)) - 1;
  // A request a little short of the grid's own (a mesh voxelised at 128 holds 129) snaps to it.
  for (int resolution : {(own * 4 + 4) / 5, own - 1, own, own * 3 / 2, own * 7 / 4}) {
    const BakedLight aligned = makeBakeLattice(*grid, resolution, LatticeSampling::kFieldAligned);
    EXPECT_NEAR(aligned.grid.voxel_size, voxel, 1e-12) << resolution;
    EXPECT_LE(double(aligned.grid.voxelCount()), std::pow(resolution + 4.0, 3)) << resolution;
  }
  auto staysBoxMeans = [](const DensityField& field, int resolution) {
    const BakedLight kept = makeBakeLattice(field, resolution, LatticeSampling::kFieldAligned);
    const BakedLight box = makeBakeLattice(field, resolution);
    EXPECT_EQ(kept.grid.voxel_size, box.grid.voxel_size) << resolution;
    EXPECT_EQ(kept.density, box.density) << resolution;
  };
  for (int resolution : {own / 2, own * 3 / 4}) staysBoxMeans(*grid, resolution);
  // A cube-shaped grid asked for a little less than its own voxels: its own would exceed the
  // cube of the request.
  const DensityFieldPtr cube = lumpyGrid(voxel);
  const int cube_own = int(std::round(maxComponent(cube->bounds().extent()) / voxel)) - 1;
  staysBoxMeans(*cube, cube_own * 9 / 10);
  // One voxel: its footprint is two voxels wide, and its 64-fold lattice would hold 8x the
  // voxels of the request.
  staysBoxMeans(*voxelize(SphereDensity(Vec3(0.0), 0.01, 1.0), voxel), 64);
  const SphereDensity analytic(Vec3(0.0), 1.0, 1.0);
  EXPECT_FALSE(analytic.sampleLattice());
  EXPECT_EQ(makeBakeLattice(analytic, 40, LatticeSampling::kFieldAligned).density,
            makeBakeLattice(analytic, 40).density);
}

// A lattice whose corners lie more than kMaxLatticeOffsetVoxels of its voxels from the origin is
// refused (world coordinates there keep no digits of a voxel); one just within is built.
// A box's voxels hold its exact share of each voxel, so a box thinner than the samples of a box
// mean keeps its optical depth: sampled, one under a quarter voxel thick vanished (every lattice
// method rendered no cloud) and thicker ones aliased (an outside probe's sweep).
TEST(BakeLattice, ABoxKeepsItsOpticalDepthAtAnyThickness) {
  for (double thickness : {1e-6, 0.002, 0.0049, 0.008, 0.013, 0.02, 0.05, 0.3}) {
    SCOPED_TRACE(thickness);
    const double z0 = 0.0123;  // the faces cut the voxels anywhere
    const BoxDensity box(Vec3(-1, -1, z0), Vec3(1, 1, z0 + thickness), 1 / thickness);
    const BakedLight bake = makeBakeLattice(box, 64);
    const BakeGrid& g = bake.grid;
    // Each column through the box's interior sums to its optical depth per unit extinction, 1.
    for (const auto& [i, j] : {std::pair{g.nx / 2, g.ny / 2}, std::pair{5, g.ny - 6}}) {
      double column = 0;
      for (int k = 0; k < g.nz; ++k) column += bake.density[g.index(i, j, k)] * g.voxel_size;
      EXPECT_NEAR(column, 1.0, 1e-5);
    }
    // The whole lattice holds the box's mass (its edge voxels by their shares too).
    double mass = 0;
    for (float d : bake.density) mass += d;
    mass *= std::pow(g.voxel_size, 3);
    EXPECT_NEAR(mass, 4.0, 4e-5);
  }
}

TEST(BakeLattice, AVolumeTooFarFromTheOriginForItsVoxelsIsRefused) {
  Bounds3 close;
  close.expand(Vec3(1e3, 0, 0));
  close.expand(Vec3(1e3 + 1, 1, 1));
  const BakeGrid g = bakeLatticeGeometry(close, 64, "near");
  EXPECT_EQ(g.nx, 66);
  Bounds3 far;
  far.expand(Vec3(0, 0, 1e12));
  far.expand(Vec3(1, 1, 1e12 + 1));
  std::string message = "no error";
  try {
    bakeLatticeGeometry(far, 64, "far");
  } catch (const InputError& e) {
    message = e.what();
  }
  EXPECT_EQ(message.rfind("volume: 'far' reaches 1e+12 world units from the origin", 0), 0u)
      << message;
}

}  // namespace
}  // namespace cloudbake
