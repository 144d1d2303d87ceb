#include "core/volume/analytic.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace cloudbake {
namespace {

TEST(BoxDensity, InsideAndOutside) {
  BoxDensity box(Vec3(-1, -1, 0), Vec3(1, 1, 2), 0.5);
  auto lookup = box.lookup();
  EXPECT_EQ(lookup->density(Vec3(0, 0, 1)), 0.5);
  EXPECT_EQ(lookup->density(Vec3(0, 0, 2.01)), 0.0);
  EXPECT_EQ(box.maxDensity(), 0.5);
  EXPECT_EQ(box.majorants().maxValue(), 0.5f);
}

TEST(BoxDensity, RejectsBadInput) {
  EXPECT_THROW(BoxDensity(Vec3(1, 0, 0), Vec3(0, 1, 1), 1), InputError);
  EXPECT_THROW(BoxDensity(Vec3(0, 0, 0), Vec3(1, 1, 1), -1), InputError);
  EXPECT_THROW(BoxDensity(Vec3(0, 0, 0), Vec3(1, 1, 1), std::nan("")), InputError);
}

TEST(SphereDensity, InsideAndOutsideAndBadInput) {
  SphereDensity s(Vec3(1, 2, 3), 2, 1.5);
  auto lookup = s.lookup();
  EXPECT_EQ(lookup->density(Vec3(1, 2, 4.9)), 1.5);
  EXPECT_EQ(lookup->density(Vec3(2.5, 3.5, 3)), 0.0);
  EXPECT_THROW(SphereDensity(Vec3(0, 0, 0), 0, 1), InputError);
  EXPECT_THROW(SphereDensity(Vec3(0, 0, 0), 1, INFINITY), InputError);
}

}  // namespace
}  // namespace cloudbake

namespace cloudbake {
namespace {

// The support interval is the ray's chord: density is zero outside it and the full density
// just inside it, from inside, from outside and for a miss; the default (a box) clips to the
// bounds.
TEST(SphereDensity, SupportIntervalIsTheChord) {
  const SphereDensity s(Vec3(1, 2, 3), 2, 1.5);
  auto lookup = s.lookup();
  double t0 = 0, t1 = 0;
  ASSERT_TRUE(s.supportInterval(Ray{Vec3(1, 2, -5), Vec3(0, 0, 1)}, 0, 1e30, &t0, &t1));
  EXPECT_NEAR(t0, 6, 1e-6);
  EXPECT_NEAR(t1, 10, 1e-6);
  ASSERT_TRUE(s.supportInterval(Ray{Vec3(1, 2, 3), Vec3(1, 0, 0)}, 0, 1e30, &t0, &t1));
  EXPECT_EQ(t0, 0);
  EXPECT_NEAR(t1, 2, 1e-6);
  ASSERT_TRUE(s.supportInterval(Ray{Vec3(1, 2, 3), Vec3(1, 0, 0)}, 0, 0.5, &t0, &t1));
  EXPECT_EQ(t1, 0.5);
  EXPECT_FALSE(s.supportInterval(Ray{Vec3(4, 2, -5), Vec3(0, 0, 1)}, 0, 1e30, &t0, &t1));
  EXPECT_FALSE(s.supportInterval(Ray{Vec3(1, 2, 6), Vec3(0, 0, 1)}, 0, 1e30, &t0, &t1));
  // Random chords: full density just inside each end, none just outside.
  const Vec3 d = normalize(Vec3(0.9, -0.2, 5));
  const Ray ray{Vec3(0.5, 2.5, -2), d};
  ASSERT_TRUE(s.supportInterval(ray, 0, 1e30, &t0, &t1));
  EXPECT_EQ(lookup->density(ray.o + d * (t0 + 1e-6)), 1.5);
  EXPECT_EQ(lookup->density(ray.o + d * (t1 - 1e-6)), 1.5);
  EXPECT_EQ(lookup->density(ray.o + d * (t0 - 1e-6)), 0.0);
  EXPECT_EQ(lookup->density(ray.o + d * (t1 + 1e-6)), 0.0);
  const BoxDensity box(Vec3(0, 0, 0), Vec3(1, 1, 1), 1);
  ASSERT_TRUE(box.supportInterval(Ray{Vec3(0.5, 0.5, -1), Vec3(0, 0, 1)}, 0, 1e30, &t0, &t1));
  EXPECT_NEAR(t0, 1, 1e-12);
  EXPECT_NEAR(t1, 2, 1e-12);
}

TEST(SphereDensity, MajorantsBoundTheSphereAndSkipEmptyCorners) {
  SphereDensity s(Vec3(0.5, -1, 2), 1.5, 3.0);
  const MajorantGrid& m = s.majorants();
  // Corner cells of the bounding box lie outside the sphere: majorant 0 there.
  EXPECT_EQ(m.cell(0, 0, 0), 0.f);
  EXPECT_EQ(m.cell(m.nx() - 1, m.ny() - 1, m.nz() - 1), 0.f);
  // Every point inside the sphere lies in a cell whose majorant covers its density.
  auto lookup = s.lookup();
  const Bounds3 b = m.bounds();
  const Vec3 e = b.extent();
  for (int i = 0; i < 20000; ++i) {
    const Vec3 u(std::fmod(i * 0.6180339887, 1.0), std::fmod(i * 0.7548776662, 1.0),
                 std::fmod(i * 0.5698402910, 1.0));
    const Vec3 p = b.min + e * u;
    const int x = std::min(m.nx() - 1, static_cast<int>(u.x * m.nx()));
    const int y = std::min(m.ny() - 1, static_cast<int>(u.y * m.ny()));
    const int z = std::min(m.nz() - 1, static_cast<int>(u.z * m.nz()));
    ASSERT_GE(m.cell(x, y, z), lookup->density(p)) << "at " << p.x << "," << p.y << "," << p.z;
  }
}

}  // namespace
}  // namespace cloudbake
