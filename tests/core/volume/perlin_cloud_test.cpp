#include "core/volume/perlin_cloud.h"

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <atomic>
#include <chrono>
#include <cmath>

#include "core/error.h"
#include "core/volume/grid_volume.h"
#include "core/volume/noise.h"
#include "core/volume/openvdb_grid.h"
#include "tests/core/volume/volume_test_util.h"

namespace cloudbake {
namespace {

TEST(PerlinNoise, DeterministicPerSeedZeroOnLatticeAndBounded) {
  const PerlinNoise a(5), b(5), c(6);
  Rng rng(1);
  double max_abs = 0, diff = 0, sum = 0;
  for (int i = 0; i < 20000; ++i) {
    const Vec3 p(rng.uniform() * 50 - 25, rng.uniform() * 50 - 25, rng.uniform() * 50 - 25);
    const double n = a.noise(p);
    EXPECT_EQ(n, b.noise(p));
    diff += std::abs(n - c.noise(p));
    max_abs = std::max(max_abs, std::abs(n));
    sum += n;
  }
  EXPECT_LE(max_abs, 1.05);
  EXPECT_GT(max_abs, 0.5);
  EXPECT_GT(diff / 20000, 0.1) << "different seeds must give different noise";
  EXPECT_LT(std::abs(sum / 20000), 0.05) << "noise should be zero-mean";
  EXPECT_EQ(a.noise(Vec3(3, -7, 12)), 0.0);
  // Continuity: tiny steps change the value only a little.
  EXPECT_NEAR(a.noise(Vec3(0.3, 0.4, 0.5)), a.noise(Vec3(0.3 + 1e-6, 0.4, 0.5)), 1e-5);
}

TEST(PerlinNoise, FbmIsNormalisedAndValidated) {
  const PerlinNoise noise(9);
  Rng rng(2);
  for (int i = 0; i < 5000; ++i) {
    const Vec3 p(rng.uniform() * 10, rng.uniform() * 10, rng.uniform() * 10);
    const double f = noise.fbm(p, 6, 0.5);
    EXPECT_LE(std::abs(f), 1.05);
    const double f01 = fbm01(noise, p, 6, 0.5);
    EXPECT_GE(f01, 0.0);
    EXPECT_LE(f01, 1.0);
  }
  EXPECT_EQ(noise.fbm(Vec3(0.3, 0.2, 0.1), 1, 0.5), noise.noise(Vec3(0.3, 0.2, 0.1)));
  NoiseOptions o;
  EXPECT_NO_THROW(validateNoiseOptions(o, "mesh.noise."));
  o.octaves = 13;
  EXPECT_THROW(validateNoiseOptions(o, "mesh.noise."), InputError);
  o = {};
  o.persistence = 0;
  EXPECT_THROW(validateNoiseOptions(o, "mesh.noise."), InputError);
  o = {};
  o.frequency = std::nan("");
  EXPECT_THROW(validateNoiseOptions(o, "mesh.noise."), InputError);
  o = {};
  o.amount = 1.5;
  try {
    validateNoiseOptions(o, "mesh.noise.");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "mesh.noise.amount: must be in [0, 1], got 1.5");
  }
}

TEST(PerlinCloud, EliasMappingAndEnvelope) {
  EXPECT_EQ(eliasCloudDensity(0.3, 0.45, 0.9), 0.0);
  EXPECT_EQ(eliasCloudDensity(0.45, 0.45, 0.9), 0.0);
  EXPECT_NEAR(eliasCloudDensity(0.46, 0.45, 0.9), 1 - std::pow(0.9, 2.55), 1e-12);
  EXPECT_GT(eliasCloudDensity(1.0, 0.45, 0.9), 0.999);
  // Softer (higher) sharpness gives lower density for the same excess.
  EXPECT_LT(eliasCloudDensity(0.47, 0.45, 0.99), eliasCloudDensity(0.47, 0.45, 0.9));
  EXPECT_EQ(cloudEnvelope(0), 1.0);
  EXPECT_EQ(cloudEnvelope(1), 0.0);
  EXPECT_EQ(cloudEnvelope(1.5), 0.0);
  EXPECT_NEAR(cloudEnvelope(0.5), 0.75, 1e-12);
}

std::string perlinError(const PerlinCloudOptions& o) {
  try {
    makePerlinCloud(o);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

// As for meshes: a stop that fires ends the cloud's evaluation with Cancelled.
TEST(PerlinCloud, AStopPredicateCancelsTheEvaluation) {
  PerlinCloudOptions o;
  o.resolution = 256;
  std::atomic<int> polls{0};
  EXPECT_THROW(makePerlinCloud(o, [&] { return ++polls > 1; }), Cancelled);
  EXPECT_GE(polls.load(), 2);
}

TEST(PerlinCloud, ValidatesEveryOption) {
  PerlinCloudOptions o;
  o.resolution = 5;
  EXPECT_EQ(perlinError(o), "perlin_cloud.resolution: must be in [8, 1024], got 5");
  o = {};
  o.resolution = 2000;
  EXPECT_NE(perlinError(o).find("perlin_cloud.resolution"), std::string::npos);
  o = {};
  o.cover = -0.1;
  EXPECT_NE(perlinError(o).find("perlin_cloud.cover"), std::string::npos);
  o = {};
  o.sharpness = 1.0;
  EXPECT_NE(perlinError(o).find("perlin_cloud.sharpness"), std::string::npos);
  o = {};
  o.density = std::nan("");
  EXPECT_NE(perlinError(o).find("perlin_cloud.density"), std::string::npos);
  o = {};
  o.octaves = 0;
  EXPECT_NE(perlinError(o).find("perlin_cloud.octaves"), std::string::npos);
  o = {};
  o.frequency = -1;
  EXPECT_NE(perlinError(o).find("perlin_cloud.frequency"), std::string::npos);
  o = {};
  o.persistence = 1.5;
  EXPECT_NE(perlinError(o).find("perlin_cloud.persistence"), std::string::npos);
  o = {};
  o.size = Vec3(2, 2, -1);
  EXPECT_NE(perlinError(o).find("perlin_cloud.size"), std::string::npos);
  o = {};
  o.size = Vec3(2, 2, 0.01);  // less than 6 voxels thick at resolution 128
  EXPECT_NE(perlinError(o).find("perlin_cloud.size"), std::string::npos);
  o = {};
  o.center = Vec3(INFINITY, 0, 0);
  EXPECT_NE(perlinError(o).find("perlin_cloud.center"), std::string::npos);
  o = {};
  o.cover = 1.0;  // the highest cover still leaves the densest cores
  EXPECT_EQ(perlinError(o), "no error");
}

TEST(PerlinCloud, DefaultCloudFillsBoxDeterministicallyAndNeverTouchesBoundary) {
  PerlinCloudOptions o;
  o.resolution = 64;
  const auto t0 = std::chrono::steady_clock::now();
  const auto field = makePerlinCloud(o);
  std::printf("perlin cloud 64^3: %.3f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  const auto* grid = dynamic_cast<const GridVolume*>(field.get());
  ASSERT_NE(grid, nullptr);
  const Bounds3 b = grid->bounds();
  EXPECT_GE(b.min.x, -1.0);
  EXPECT_GE(b.min.y, -1.0);
  EXPECT_GE(b.min.z, 0.0);
  EXPECT_LE(b.max.x, 1.0);
  EXPECT_LE(b.max.y, 1.0);
  EXPECT_LE(b.max.z, 1.0);
  EXPECT_NEAR(grid->voxelSize(), 2.0 / 64, 1e-12);
  // Voxels 0..63 in x, y and 0..31 in z: the outermost layer must stay empty.
  int lo[3], hi[3];
  grid->activeIndexBox(lo, hi);
  const int dims[3] = {64, 64, 32};
  for (int a = 0; a < 3; ++a) {
    EXPECT_GE(lo[a], 1) << a;
    EXPECT_LE(hi[a], dims[a] - 2) << a;
  }
  // A substantial, but not box-filling, cloud with full-density cores.
  const double filled = static_cast<double>(grid->activeVoxelCount()) / (64.0 * 64 * 32);
  EXPECT_GT(filled, 0.1);
  EXPECT_LT(filled, 0.6);
  EXPECT_GT(grid->maxDensity(), 0.99);
  EXPECT_LE(grid->maxDensity(), 1.0);
  EXPECT_GT(field->lookup()->density(Vec3(0, 0, 0.5)), 0.5) << "the core should be cloud";
  testing::checkMajorants(*field, 50000);

  const auto again = makePerlinCloud(o);
  o.seed = 2;
  const auto other = makePerlinCloud(o);
  auto la = field->lookup(), lb = again->lookup(), lc = other->lookup();
  Rng rng(4);
  int differ = 0;
  for (int i = 0; i < 5000; ++i) {
    const Vec3 p(rng.uniform() * 2 - 1, rng.uniform() * 2 - 1, rng.uniform());
    EXPECT_EQ(la->density(p), lb->density(p));
    differ += la->density(p) != lc->density(p);
  }
  EXPECT_GT(differ, 500);
}

TEST(PerlinCloud, CoverDensityAndPlacementOptionsAct) {
  PerlinCloudOptions o;
  o.resolution = 32;
  o.center = Vec3(10, -5, 3);
  o.size = Vec3(4, 3, 2);
  o.density = 3.0;
  const auto a = makePerlinCloud(o);
  const Bounds3 b = a->bounds();
  EXPECT_GE(b.min.x, 8.0);
  EXPECT_LE(b.max.x, 12.0);
  EXPECT_GE(b.min.z, 2.0);
  EXPECT_LE(b.max.z, 4.0);
  EXPECT_NEAR(a->maxDensity(), 3.0, 0.01);
  o.cover = 0.7;
  const auto thinner = makePerlinCloud(o);
  EXPECT_LT(dynamic_cast<const GridVolume&>(*thinner).activeVoxelCount(),
            dynamic_cast<const GridVolume&>(*a).activeVoxelCount());
}

// Same grid, voxel for voxel, whatever the number of threads.
TEST(PerlinCloud, IndependentOfThreadCount) {
  PerlinCloudOptions o;
  o.resolution = 48;
  o.seed = 77;
  DensityFieldPtr one;
  {
    tbb::global_control single(tbb::global_control::max_allowed_parallelism, 1);
    one = makePerlinCloud(o);
  }
  const auto many = makePerlinCloud(o);
  const auto a = openvdbGrid(dynamic_cast<const GridVolume&>(*one));
  const auto b = openvdbGrid(dynamic_cast<const GridVolume&>(*many));
  ASSERT_TRUE(a->tree().hasSameTopology(b->tree()));
  auto acc = b->getConstAccessor();
  for (auto it = a->cbeginValueOn(); it; ++it) ASSERT_EQ(*it, acc.getValue(it.getCoord()));
}

}  // namespace
}  // namespace cloudbake
