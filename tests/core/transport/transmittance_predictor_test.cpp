#include "core/transport/transmittance_predictor.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/math/rng.h"
#include "core/volume/analytic.h"

namespace cloudbake {
namespace {

// Distance from p inside the box to its boundary along unit d.
double exitDistance(const Bounds3& b, const Vec3& p, const Vec3& d) {
  double t = 1e300;
  for (int a = 0; a < 3; ++a) {
    if (d[a] > 0) t = std::min(t, (b.max[a] - p[a]) / d[a]);
    if (d[a] < 0) t = std::min(t, (b.min[a] - p[a]) / d[a]);
  }
  return t;
}

// In a homogeneous box the minorant is exact, so every prediction bounds the true transmittance
// from above, and deep points are predicted dark.
TEST(TransmittancePredictor, BoundsAHomogeneousBoxFromAbove) {
  const BoxDensity box(Vec3(0, 0, 0), Vec3(4, 2, 3), 1.0);
  const double extinction = 6;
  const Vec3 sun = normalize(Vec3(0.3, 0.5, 0.8));
  const TransmittancePredictor pred(*box.trackingGrid({extinction, 0}), extinction, &sun, true, 8);
  ASSERT_TRUE(pred.active());
  const Bounds3 b = box.bounds();
  const Vec3 axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  Rng rng(3);
  for (int i = 0; i < 5000; ++i) {
    const Vec3 p(4 * rng.uniform(), 2 * rng.uniform(), 3 * rng.uniform());
    const double t_sun = std::exp(-extinction * exitDistance(b, p, sun));
    ASSERT_GE(pred.sun(p), t_sun * (1 - 1e-5));
    for (const Vec3& d : axes) {
      ASSERT_GE(pred.sky(p), std::exp(-extinction * exitDistance(b, p, d)) * (1 - 1e-5));
    }
  }
  EXPECT_LT(pred.sun(Vec3(2, 1, 1.5)), 1e-2);
  EXPECT_LT(pred.sky(Vec3(2, 1, 1.5)), 0.1);
  EXPECT_EQ(pred.sun(Vec3(10, 10, 10)), 1.0);  // outside: nothing in the way
}

// Deep inside a huge optical depth the prediction is tiny but never 0: a 0 would roulette away,
// always, the events the light does reach where the prediction is wrong.
TEST(TransmittancePredictor, NeverPredictsZero) {
  const BoxDensity box(Vec3(0, 0, 0), Vec3(4, 2, 3), 1.0);
  const Vec3 sun(0, 0, 1);
  const TransmittancePredictor pred(*box.trackingGrid({1e4, 0}), 1e4, &sun, true, 8);
  EXPECT_GT(pred.sun(Vec3(2, 1, 1.5)), 0.0);
  EXPECT_LT(pred.sun(Vec3(2, 1, 1.5)), 1e-20);
  EXPECT_GT(pred.sky(Vec3(2, 1, 1.5)), 0.0);
}

TEST(TransmittancePredictor, WithoutMinorantsPredictsOne) {
  const SphereDensity sphere(Vec3(0, 0, 0), 1, 5);
  const Vec3 sun(0, 0, 1);
  const TransmittancePredictor pred(*sphere.trackingGrid({1.0, 0}), 1.0, &sun, true);
  EXPECT_FALSE(pred.active());
  EXPECT_EQ(pred.sun(Vec3(0, 0, 0)), 1.0);
  EXPECT_EQ(pred.sky(Vec3(0, 0, 0)), 1.0);
  // No light asked for: inactive too.
  const BoxDensity box(Vec3(0, 0, 0), Vec3(1, 1, 1), 1.0);
  EXPECT_FALSE(TransmittancePredictor(*box.trackingGrid({}), 1.0, nullptr, false).active());
}

}  // namespace
}  // namespace cloudbake
