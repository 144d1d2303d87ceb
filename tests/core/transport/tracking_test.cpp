#include "core/transport/tracking.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/volume/analytic.h"
#include "tests/core/transport/test_util.h"

namespace cloudbake {
namespace {

using testing_util::LinearSlab;
using testing_util::Stats;

constexpr double kInf = 1e300;

// A ray from above the slab straight down through z in [0, 1].
const Ray kDown{Vec3(0.1, -0.2, 3), Vec3(0, 0, -1)};

TEST(Tracking, HomogeneousSlabTransmittanceIsExpMinusTau) {
  const BoxDensity slab(Vec3(-1e4, -1e4, 0), Vec3(1e4, 1e4, 1), 1.0);
  auto lookup = slab.lookup();
  for (double tau : {0.1, 2.0, 10.0}) {
    const double exact = std::exp(-tau);
    const int n = tau > 5 ? 2000000 : 200000;
    Rng rng(7, static_cast<uint64_t>(tau * 10));
    Stats ratio, delta;
    for (int i = 0; i < n; ++i) {
      ratio.add(ratioTrack(slab, *lookup, tau, kDown, 0, kInf, rng));
      delta.add(deltaTrack(slab, *lookup, tau, kDown, 0, kInf, rng).hit ? 0.0 : 1.0);
    }
    ASSERT_GT(ratio.stderror(), 0) << "tau " << tau;
    EXPECT_NEAR(ratio.mean(), exact, 4 * ratio.stderror()) << "ratio tracking, tau " << tau;
    EXPECT_NEAR(delta.mean(), exact, 4 * delta.stderror()) << "delta tracking, tau " << tau;
  }
}

TEST(Tracking, HeterogeneousSlabTransmittanceAndFreePathDistribution) {
  // density 0.2 + 3 z on 5 majorant cells: tau = extinction * 1.7.
  const LinearSlab slab(0.2, 3.0, 5);
  auto lookup = slab.lookup();
  const double extinction = 1.5;
  const double exact = std::exp(-extinction * slab.depth(1.0));
  const int n = 400000;
  Rng rng(11, 3);
  Stats ratio, delta;
  // P(first collision above height z) = 1 - exp(-extinction * (depth(1) - depth(z))).
  const double probes[] = {0.9, 0.6, 0.3};
  Stats above[3];
  for (int i = 0; i < n; ++i) {
    ratio.add(ratioTrack(slab, *lookup, extinction, kDown, 0, kInf, rng));
    const Collision c = deltaTrack(slab, *lookup, extinction, kDown, 0, kInf, rng);
    delta.add(c.hit ? 0.0 : 1.0);
    if (c.hit) {
      EXPECT_NEAR(c.p.z, kDown.at(c.t).z, 1e-12);
      ASSERT_GE(c.p.z, 0.0);
      ASSERT_LE(c.p.z, 1.0);
    }
    for (int k = 0; k < 3; ++k) above[k].add(c.hit && c.p.z > probes[k] ? 1.0 : 0.0);
  }
  EXPECT_NEAR(ratio.mean(), exact, 4 * ratio.stderror());
  EXPECT_NEAR(delta.mean(), exact, 4 * delta.stderror());
  // Ratio tracking must beat the binary delta-tracking estimator on variance.
  EXPECT_LT(ratio.variance(), delta.variance());
  for (int k = 0; k < 3; ++k) {
    const double p = 1 - std::exp(-extinction * (slab.depth(1.0) - slab.depth(probes[k])));
    EXPECT_NEAR(above[k].mean(), p, 4 * above[k].stderror()) << "z > " << probes[k];
  }
}

TEST(Tracking, IntervalLimitsAndEmptyMedium) {
  const BoxDensity slab(Vec3(-1, -1, 0), Vec3(1, 1, 1), 1.0);
  auto lookup = slab.lookup();
  Rng rng(3, 4);
  // A ray that misses the box is never attenuated.
  const Ray miss{Vec3(5, 5, 5), Vec3(0, 0, 1)};
  EXPECT_EQ(ratioTrack(slab, *lookup, 1e6, miss, 0, kInf, rng), 1.0);
  EXPECT_FALSE(deltaTrack(slab, *lookup, 1e6, miss, 0, kInf, rng).hit);
  // Zero extinction: transparent.
  EXPECT_EQ(ratioTrack(slab, *lookup, 0.0, kDown, 0, kInf, rng), 1.0);
  EXPECT_FALSE(deltaTrack(slab, *lookup, 0.0, kDown, 0, kInf, rng).hit);
  // tmax before the slab: transparent even at huge extinction.
  EXPECT_EQ(ratioTrack(slab, *lookup, 1e6, kDown, 0, 1.5, rng), 1.0);
  // Extinction 1e6 inside the interval: a collision within a few mean free paths of the entry.
  for (int i = 0; i < 1000; ++i) {
    const Collision c = deltaTrack(slab, *lookup, 1e6, kDown, 0, kInf, rng);
    ASSERT_TRUE(c.hit);
    EXPECT_LT(c.t - 2.0, 50e-6);
    EXPECT_EQ(ratioTrack(slab, *lookup, 1e6, kDown, 0, kInf, rng), 0.0);
  }
}

// Decomposition tracking and residual ratio tracking against the same exact answers as above,
// on the linear slab whose tracking grid carries minorants.
TEST(Tracking, DecompositionAndResidualRatioTrackingAreUnbiased) {
  const LinearSlab slab(0.2, 3.0, 5);
  const auto grid = slab.trackingGrid({});
  ASSERT_TRUE(grid->hasMinorants());
  auto lookup = slab.lookup();
  const double extinction = 1.5;
  const double exact = std::exp(-extinction * slab.depth(1.0));
  const int n = 400000;
  Rng rng(13, 5);
  Stats residual, ratio, decomposition;
  const double probes[] = {0.9, 0.6, 0.3};
  Stats above[3];
  for (int i = 0; i < n; ++i) {
    residual.add(residualRatioTrack(*grid, *lookup, extinction, kDown, 0, kInf, rng));
    ratio.add(ratioTrack(slab, *lookup, extinction, kDown, 0, kInf, rng));
    const Collision c = decompositionTrack(*grid, *lookup, extinction, kDown, 0, kInf, rng);
    decomposition.add(c.hit ? 0.0 : 1.0);
    if (c.hit) {
      ASSERT_GE(c.p.z, 0.0);
      ASSERT_LE(c.p.z, 1.0);
    }
    for (int k = 0; k < 3; ++k) above[k].add(c.hit && c.p.z > probes[k] ? 1.0 : 0.0);
  }
  EXPECT_NEAR(residual.mean(), exact, 4 * residual.stderror());
  EXPECT_NEAR(decomposition.mean(), exact, 4 * decomposition.stderror());
  // The control part is exact, so the residual estimate is less noisy than plain ratio tracking.
  EXPECT_LT(residual.variance(), 0.5 * ratio.variance());
  for (int k = 0; k < 3; ++k) {
    const double p = 1 - std::exp(-extinction * (slab.depth(1.0) - slab.depth(probes[k])));
    EXPECT_NEAR(above[k].mean(), p, 4 * above[k].stderror()) << "z > " << probes[k];
  }
}

// A ray starting inside the slab and stopped before leaving it: [0, tmax] of a ray from z = 0.7
// down to z = 0.2, across cells with and without their full length.
TEST(Tracking, DecompositionOverAPartialInterval) {
  const LinearSlab slab(0.2, 3.0, 5);
  const auto grid = slab.trackingGrid({});
  auto lookup = slab.lookup();
  const double extinction = 2.0;
  const Ray inside{Vec3(0.1, -0.2, 0.7), Vec3(0, 0, -1)};
  const double exact = std::exp(-extinction * (slab.depth(0.7) - slab.depth(0.2)));
  Rng rng(21, 4);
  Stats residual, decomposition;
  for (int i = 0; i < 400000; ++i) {
    residual.add(residualRatioTrack(*grid, *lookup, extinction, inside, 0, 0.5, rng));
    const Collision c = decompositionTrack(*grid, *lookup, extinction, inside, 0, 0.5, rng);
    decomposition.add(c.hit ? 0.0 : 1.0);
    if (c.hit) {
      ASSERT_LE(c.t, 0.5);
      ASSERT_GE(c.t, 0.0);
    }
  }
  EXPECT_NEAR(residual.mean(), exact, 4 * residual.stderror());
  EXPECT_NEAR(decomposition.mean(), exact, 4 * decomposition.stderror());
}

// In a homogeneous box the minorant is the density: transmittance needs no random numbers above
// the roulette threshold, and free paths are exactly exponential.
TEST(Tracking, DecompositionInAHomogeneousBoxIsAnalytic) {
  const BoxDensity slab(Vec3(-1e4, -1e4, 0), Vec3(1e4, 1e4, 1), 1.0);
  const auto grid = slab.trackingGrid({});
  auto lookup = slab.lookup();
  Rng rng(17, 2);
  EXPECT_NEAR(residualRatioTrack(*grid, *lookup, 2.0, kDown, 0, kInf, rng), std::exp(-2.0), 1e-12);
  Stats deep, below;
  for (int i = 0; i < 400000; ++i) {
    deep.add(residualRatioTrack(*grid, *lookup, 10.0, kDown, 0, kInf, rng));
    const Collision c = decompositionTrack(*grid, *lookup, 2.0, kDown, 0, kInf, rng);
    below.add(c.hit && c.p.z < 0.5 ? 1.0 : 0.0);
  }
  EXPECT_NEAR(deep.mean(), std::exp(-10.0), 4 * deep.stderror());
  EXPECT_GT(deep.stderror(), 0);
  EXPECT_NEAR(below.mean(), std::exp(-1.0) - std::exp(-2.0), 4 * below.stderror());
  // Missing the medium, or no extinction: transparent.
  const Ray miss{Vec3(5e4, 5, 5), Vec3(0, 0, 1)};
  EXPECT_EQ(residualRatioTrack(*grid, *lookup, 1e6, miss, 0, kInf, rng), 1.0);
  EXPECT_FALSE(decompositionTrack(*grid, *lookup, 1e6, miss, 0, kInf, rng).hit);
  EXPECT_EQ(residualRatioTrack(*grid, *lookup, 0.0, kDown, 0, kInf, rng), 1.0);
  EXPECT_FALSE(decompositionTrack(*grid, *lookup, 0.0, kDown, 0, kInf, rng).hit);
}

}  // namespace
}  // namespace cloudbake
