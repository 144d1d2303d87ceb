// Order-4 real SH and the per-voxel optical depth to the sky they store (seed 002, section 2).
#include "core/animation/optical_depth_sh.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>

#include "core/bake/bake_lattice.h"
#include "core/error.h"
#include "core/volume/analytic.h"

namespace cloudbake {
namespace {

TEST(SphericalHarmonics, AreOrthonormal) {
  const std::vector<Vec3> dirs = sphereDirections(40000);
  double gram[kShCoefficients][kShCoefficients] = {};
  for (const Vec3& w : dirs) {
    const auto y = shBasis(w);
    for (int i = 0; i < kShCoefficients; ++i)
      for (int j = 0; j < kShCoefficients; ++j) gram[i][j] += y[size_t(i)] * y[size_t(j)];
  }
  for (int i = 0; i < kShCoefficients; ++i)
    for (int j = 0; j < kShCoefficients; ++j) {
      EXPECT_NEAR(gram[i][j] * 4 * kPi / double(dirs.size()), i == j ? 1.0 : 0.0, 2e-3)
          << i << " " << j;
    }
}

TEST(OpticalDepth, SweepsMatchRayMarchesThroughASphere) {
  const SphereDensity sphere(Vec3(0.0), 1.0, 1.0);
  const BakedLight lattice = makeBakeLattice(sphere, 32);
  const BakeGrid& g = lattice.grid;
  const double ext = 2.0;
  for (const Vec3& w : {Vec3(0, 0, 1), Vec3(-1, 0, 0), normalize(Vec3(1, 2, -0.5)),
                        normalize(Vec3(-0.3, 0.4, 0.9))}) {
    const std::vector<float> tau = sweepOpticalDepth(g, lattice.density, ext, w);
    double worst = 0;
    for (int k = 8; k < g.nz - 8; k += 4)
      for (int j = 8; j < g.ny - 8; j += 4)
        for (int i = 8; i < g.nx - 8; i += 4) {
          const Vec3 p = g.center(i, j, k);
          const double t =
              marchTransmittance(g, lattice.density.data(), ext, p, w, 0.01 * g.voxel_size);
          const double ref = -std::log(std::max(t, 1e-30));
          worst = std::max(worst, std::abs(tau[g.index(i, j, k)] - ref) / (ref + 0.1));
        }
    // Bilinear reads of the upstream slice smooth tau over about a voxel.
    EXPECT_LT(worst, 0.05) << w.x << " " << w.y << " " << w.z;
  }
}

TEST(OpticalDepth, ShProjectionOfASphere) {
  const SphereDensity sphere(Vec3(0.0), 1.0, 1.0);
  const BakedLight lattice = makeBakeLattice(sphere, 24);
  const BakeGrid& g = lattice.grid;
  const double ext = 1.5;
  std::vector<ShCoefficients> one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = projectOpticalDepth(g, lattice.density, ext, 64);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = projectOpticalDepth(g, lattice.density, ext, 64);
  }
  ASSERT_EQ(one.size(), g.voxelCount());
  for (size_t v = 0; v < one.size(); v += 97) EXPECT_EQ(one[v], two[v]);
  // At the centre tau is the same in every direction: only the constant term.
  const int m = g.nx / 2;
  const ShCoefficients& c = one[g.index(m, m, m)];
  const double tau_centre = ext * 1.0;
  EXPECT_NEAR(c[0] / std::sqrt(4 * kPi), tau_centre, 0.06 * tau_centre);
  for (int i = 1; i < kShCoefficients; ++i) EXPECT_LT(std::abs(c[size_t(i)]), 0.05 * c[0]) << i;
  // Off centre the projection follows the directional optical depth (a smooth function).
  const int i0 = m + g.nx / 4;
  const ShCoefficients& off = one[g.index(i0, m, m)];
  double err = 0, norm = 0;
  for (const Vec3& w : sphereDirections(200)) {
    const double t = marchTransmittance(g, lattice.density.data(), ext, g.center(i0, m, m), w,
                                        0.05 * g.voxel_size);
    const double ref = -std::log(t);
    err += (shEvaluate(off, w) - ref) * (shEvaluate(off, w) - ref);
    norm += ref * ref;
  }
  EXPECT_LT(std::sqrt(err / norm), 0.1);
  EXPECT_THROW(projectOpticalDepth(g, lattice.density, ext, 8), InputError);
  EXPECT_THROW(projectOpticalDepth(g, lattice.density, ext, 64, [](double) { return false; }),
               Cancelled);
}

}  // namespace
}  // namespace cloudbake
