#include "core/bake/bake_grid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/bake/phase_lut.h"
#include "core/phase/henyey_greenstein.h"

namespace cloudbake {
namespace {

BakeGrid lattice(int n, double h) {
  BakeGrid g;
  g.origin = Vec3(0.0);
  g.voxel_size = h;
  g.nx = g.ny = g.nz = n;
  return g;
}

TEST(BakeGrid, TrilinearReproducesALinearField) {
  const BakeGrid g = lattice(6, 0.5);
  std::vector<float> v(g.voxelCount());
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 6; ++j)
      for (int i = 0; i < 6; ++i) {
        const Vec3 c = g.center(i, j, k);
        v[g.index(i, j, k)] = float(1 + c.x + 2 * c.y - c.z);
      }
  for (const Vec3 p : {Vec3(0.3, 0.7, 1.1), Vec3(2.49, 0.01, 1.99), Vec3(1.25, 1.25, 1.25)}) {
    EXPECT_NEAR(sampleTrilinear(g, v.data(), p), 1 + p.x + 2 * p.y - p.z, 1e-5);
  }
  // Outside the lattice: zero background, fading over the last half voxel.
  EXPECT_EQ(sampleTrilinear(g, v.data(), Vec3(-0.6, 1, 1)), 0.f);
  EXPECT_EQ(sampleTrilinear(g, v.data(), Vec3(1, 1, 1e30)), 0.f);
  EXPECT_EQ(sampleTrilinear(g, v.data(), Vec3(std::nan(""), 1, 1)), 0.f);
  EXPECT_NEAR(sampleTrilinear(g, v.data(), Vec3(-0.25, 0, 0)), 0.5 * 1.0, 1e-6);
}

// A coarse voxel's mean of a fine lattice's voxels is their mean weighted by overlap: a ramp
// along x averages to its value at the coarse voxel's centre, wherever the voxels' edges fall,
// and a coarse voxel reaching past the fine lattice counts what lies outside as 0.
TEST(BakeGrid, BoxMeanWeightsTheFineVoxelsByTheirOverlap) {
  BakeGrid fine;
  fine.origin = Vec3(0.05, 0.05, 0.05);
  fine.voxel_size = 0.1;
  fine.nx = fine.ny = fine.nz = 12;  // [0, 1.2]^3
  std::vector<float> ramp(fine.voxelCount());
  for (int k = 0; k < 12; ++k)
    for (int j = 0; j < 12; ++j)
      for (int i = 0; i < 12; ++i) ramp[fine.index(i, j, k)] = float(fine.center(i, j, k).x);
  BakeGrid coarse;
  coarse.origin = Vec3(0.2, 0.2, 0.2);
  coarse.voxel_size = 0.4;
  coarse.nx = coarse.ny = coarse.nz = 3;  // [0, 1.2]^3: edges between fine voxels
  std::vector<float> m = boxMean(fine, ramp.data(), coarse);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(m[coarse.index(i, 1, 2)], coarse.center(i, 1, 2).x, 1e-6);
  coarse.origin = Vec3(0.15, 0.15, 0.15);
  coarse.voxel_size = 0.3;
  coarse.nx = coarse.ny = coarse.nz = 4;  // [0, 1.2]^3: edges through the middle of fine voxels
  m = boxMean(fine, ramp.data(), coarse);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(m[coarse.index(i, 2, 1)], coarse.center(i, 2, 1).x, 1e-6);
  const std::vector<float> ones(fine.voxelCount(), 1.f);
  coarse.origin = Vec3(1.2, 0.2, 0.2);  // [1.0, 1.4] along x: half outside
  coarse.voxel_size = 0.4;
  coarse.nx = 1;
  coarse.ny = coarse.nz = 1;
  EXPECT_NEAR(boxMean(fine, ones.data(), coarse)[0], 0.5, 1e-6);
}

TEST(BakeGrid, MarchedTransmittanceOfAHomogeneousBlock) {
  const BakeGrid g = lattice(20, 0.1);
  std::vector<float> d(g.voxelCount(), 0.f);
  for (int k = 0; k < 20; ++k)
    for (int j = 0; j < 20; ++j)
      for (int i = 0; i < 20; ++i) d[g.index(i, j, k)] = 2.f;
  // From the centre along +x: the trilinear density is 2 up to the last voxel centre (x = 1.9),
  // then falls linearly towards the zero background, to 1 at the lattice face (x = 1.95).
  const Vec3 p(0.95, 0.95, 0.95);
  const double tau = 3.0 * (2 * (1.9 - 0.95) + 0.5 * (2 + 1) * 0.05);
  EXPECT_NEAR(marchTransmittance(g, d.data(), 3.0, p, Vec3(1, 0, 0), 0.01), std::exp(-tau), 1e-6);
  EXPECT_EQ(marchTransmittance(g, d.data(), 0.0, p, Vec3(1, 0, 0), 0.01), 1.0);
  EXPECT_EQ(marchTransmittance(g, d.data(), 1e6, p, Vec3(0, 0, 1), 0.01), 0.0);
  // A point outside, looking away: nothing in the way.
  EXPECT_EQ(marchTransmittance(g, d.data(), 3.0, Vec3(5, 5, 5), Vec3(1, 0, 0), 0.01), 1.0);
}

// The marcher for many rays returns marchTransmittance's values bit for bit: through empty
// blocks it skips, across the lattice's faces and corners, and along the axes.
TEST(BakeGrid, TransmittanceMarcherEqualsTheMarchBitForBit) {
  BakeGrid g = lattice(37, 0.1);
  g.ny = 29;
  g.nz = 23;
  g.origin = Vec3(-1.3, 0.2, -0.7);
  std::vector<float> rho(g.voxelCount(), 0.f);
  uint64_t state = 12345;
  auto uniform = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return double(state >> 11) * 0x1.0p-53;
  };
  // Two blobs with empty space between them and a slab touching one face.
  for (int k = 0; k < g.nz; ++k) {
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) {
        const bool blob = (i - 8) * (i - 8) + (j - 9) * (j - 9) + (k - 6) * (k - 6) < 30 ||
                          (i - 28) * (i - 28) + (j - 20) * (j - 20) + (k - 15) * (k - 15) < 20;
        if (blob || i == g.nx - 1) rho[g.index(i, j, k)] = float(0.2 + uniform());
      }
    }
  }
  const double extinction = 7;
  const TransmittanceMarcher march(g, rho.data(), extinction);
  int nonzero = 0, partial = 0;
  for (int r = 0; r < 4000; ++r) {
    const Vec3 p = g.origin + Vec3(uniform() * (g.nx + 2) - 1.5, uniform() * (g.ny + 2) - 1.5,
                                   uniform() * (g.nz + 2) - 1.5) *
                                  g.voxel_size;
    Vec3 d(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
    if (r % 10 == 0) d = Vec3(r % 20 ? 1.0 : -1.0, 0, 0);  // along an axis
    d = normalize(d);
    const double step = g.voxel_size * (r % 3 ? 0.5 : 0.37);
    const double want = marchTransmittance(g, rho.data(), extinction, p, d, step);
    ASSERT_EQ(march(p, d, step), want) << "ray " << r;
    ASSERT_EQ(march.density(p), sampleTrilinear(g, rho.data(), p)) << "ray " << r;
    nonzero += want < 1;
    partial += want > 0 && want < 1;
  }
  EXPECT_GT(nonzero, 1000);  // the rays do cross density, and partly
  EXPECT_GT(partial, 500);
}

TEST(PhaseLut, MatchesTheFunctionItTabulates) {
  const HenyeyGreensteinPhase hg(0.9);
  const PhaseLut lut(hg);
  for (double c : {-1.0, -0.5, 0.0, 0.5, 0.9, 0.99, 0.999, 1.0}) {
    EXPECT_NEAR(lut.eval(c).x / hg.eval(c).x, 1.0, 2e-3) << c;
  }
  EXPECT_TRUE(std::isfinite(lut.eval(1.5).x));
}

// Either peak is resolved: the table integrates to 1 over the sphere (by a midpoint rule in
// theta, independent of the table's own nodes) for strongly forward and backward phases. A table
// uniform in sin(theta / 2) alone gave 4x for HG -0.99.
TEST(PhaseLut, ResolvesTheForwardAndTheBackwardPeak) {
  for (const double g : {-0.999, -0.99, -0.9, 0.9, 0.99, 0.999}) {
    const HenyeyGreensteinPhase hg(g);
    const PhaseLut lut(hg);
    constexpr int kSteps = 400000;
    double integral = 0;
    for (int k = 0; k < kSteps; ++k) {
      const double theta = (k + 0.5) * kPi / kSteps;
      integral += lut.eval(std::cos(theta)).x * 2 * kPi * std::sin(theta) * kPi / kSteps;
    }
    EXPECT_NEAR(integral, 1.0, 0.01) << "g = " << g;
    EXPECT_NEAR(lut.eval(-1).x / hg.eval(-1).x, 1.0, 1e-6) << g;
    EXPECT_NEAR(lut.eval(1).x / hg.eval(1).x, 1.0, 1e-6) << g;
  }
  const PhaseLut lut(HenyeyGreensteinPhase(0.5), 64);
  EXPECT_EQ(lut.nodes(), 129);
  EXPECT_DOUBLE_EQ(lut.nodeCosine(0), 1.0);
  EXPECT_NEAR(lut.nodeCosine(64), 0.0, 1e-15);
  EXPECT_DOUBLE_EQ(lut.nodeCosine(128), -1.0);
}

}  // namespace
}  // namespace cloudbake
