#include "core/volume/analytic.h"

#include <gtest/gtest.h>

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
