#include "core/volume/majorant_grid.h"

#include <gtest/gtest.h>

#include <vector>

namespace cloudbake {
namespace {

Bounds3 unitCube(double n) {
  Bounds3 b;
  b.min = Vec3(0, 0, 0);
  b.max = Vec3(n, n, n);
  return b;
}

TEST(MajorantGrid, TraversalCoversTheRayWithoutGapsInOrder) {
  std::vector<float> m(4 * 4 * 4);
  for (size_t i = 0; i < m.size(); ++i) m[i] = static_cast<float>(i);
  MajorantGrid g(unitCube(4), 4, 4, 4, m);
  const Ray ray{Vec3(-1, 0.3, 0.7), normalize(Vec3(1, 0.45, 0.3))};
  double t0, t1;
  ASSERT_TRUE(intersectBounds(g.bounds(), ray, 0, 1e30, &t0, &t1));
  double last = t0;
  int cells = 0;
  g.traverse(ray, 0, 1e30, [&](double a, double b, float maj) {
    EXPECT_NEAR(a, last, 1e-9);
    EXPECT_GT(b, a);
    // The majorant must be the one of the cell containing the segment's midpoint.
    const Vec3 mid = ray.at(0.5 * (a + b));
    const int x = static_cast<int>(mid.x), y = static_cast<int>(mid.y), z = static_cast<int>(mid.z);
    EXPECT_EQ(maj, g.cell(x, y, z));
    last = b;
    ++cells;
    return true;
  });
  EXPECT_NEAR(last, t1, 1e-9);
  EXPECT_GE(cells, 4);
}

TEST(MajorantGrid, AxisParallelRayAndEarlyStop) {
  MajorantGrid g(unitCube(2), 2, 2, 2, std::vector<float>(8, 1.f));
  int count = 0;
  const bool finished = g.traverse({Vec3(0.5, 0.5, 5), Vec3(0, 0, -1)}, 0, 1e30,
                                   [&](double, double, float) { return ++count < 1; });
  EXPECT_FALSE(finished);
  EXPECT_EQ(count, 1);
  count = 0;
  g.traverse({Vec3(0.5, 0.5, 5), Vec3(0, 0, -1)}, 0, 1e30, [&](double a, double b, float) {
    EXPECT_NEAR(b - a, 1.0, 1e-12);
    ++count;
    return true;
  });
  EXPECT_EQ(count, 2);
}

TEST(MajorantGrid, MissingRayVisitsNothing) {
  MajorantGrid g = MajorantGrid::uniform(unitCube(1), 3.f);
  int count = 0;
  g.traverse({Vec3(5, 5, 5), Vec3(0, 0, 1)}, 0, 1e30, [&](double, double, float) {
    ++count;
    return true;
  });
  EXPECT_EQ(count, 0);
}

// maxOver: the largest bound of the cells a box touches, faces included; 0 outside the grid.
TEST(MajorantGrid, MaxOverABoxTakesEveryCellItTouches) {
  Bounds3 b;
  b.min = Vec3(0.0);
  b.max = Vec3(4.0, 2.0, 2.0);
  std::vector<float> m(4 * 2 * 2, 0.f);
  m[(1 * 2 + 1) * 4 + 2] = 5.f;  // cell (2, 1, 1): x in [2, 3]
  m[0] = 1.f;                    // cell (0, 0, 0)
  const MajorantGrid grid(b, 4, 2, 2, m);
  auto box = [](Vec3 lo, Vec3 hi) {
    Bounds3 r;
    r.min = lo;
    r.max = hi;
    return r;
  };
  EXPECT_EQ(grid.maxOver(box(Vec3(2.2, 1.2, 1.2), Vec3(2.8, 1.8, 1.8))), 5.f);
  EXPECT_EQ(grid.maxOver(box(Vec3(1.5, 1.5, 1.5), Vec3(2.0, 1.9, 1.9))), 5.f);  // on its face
  EXPECT_EQ(grid.maxOver(box(Vec3(3.1, 0.1, 0.1), Vec3(3.9, 0.9, 0.9))), 0.f);
  EXPECT_EQ(grid.maxOver(box(Vec3(-1.0, -1.0, -1.0), Vec3(0.5, 0.5, 0.5))), 1.f);
  EXPECT_EQ(grid.maxOver(box(Vec3(5.0, 0.0, 0.0), Vec3(6.0, 1.0, 1.0))), 0.f);  // outside
  EXPECT_EQ(grid.maxOver(box(Vec3(-9.0), Vec3(9.0))), 5.f);
}

}  // namespace
}  // namespace cloudbake
