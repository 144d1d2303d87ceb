#include "core/bake/sparse_film.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

namespace cloudbake {
namespace {

std::vector<int> line(int n, int spacing) {
  std::vector<int> xs;
  for (int i = 0; i < n; ++i) xs.push_back(i * spacing);
  return xs;
}

// A grid of traced pixels whose every float is f(x, y).
template <typename F>
std::vector<FilmPixel> gridOf(const std::vector<int>& xs, const std::vector<int>& ys, F f) {
  std::vector<FilmPixel> g(xs.size() * ys.size());
  for (size_t j = 0; j < ys.size(); ++j) {
    for (size_t i = 0; i < xs.size(); ++i) {
      for (float& v : g[j * xs.size() + i].v) v = float(f(xs[i], ys[j]));
    }
  }
  return g;
}

int count(const std::vector<uint8_t>& flags) {
  int n = 0;
  for (uint8_t f : flags) n += f;
  return n;
}

TEST(SparseFilm, SpacingIsThePixelsAVoxelCoversAtItsWidest) {
  EXPECT_EQ(sparseFilmSpacing(0.004, 0.0156, 4), 2);   // 3.9 pixels a voxel
  EXPECT_EQ(sparseFilmSpacing(0.0039, 0.0156, 4), 4);  // 4 pixels a voxel
  EXPECT_EQ(sparseFilmSpacing(0.0039, 0.0156, 3), 2);  // 3 reads as 2
  EXPECT_EQ(sparseFilmSpacing(0.0039, 0.0156, 1), 1);
  EXPECT_EQ(sparseFilmSpacing(0.001, 0.0156, 8), kMaxFilmSpacing);
  EXPECT_EQ(sparseFilmSpacing(0.009, 0.0156, 4), 1);  // a voxel under two pixels
  EXPECT_EQ(sparseFilmSpacing(0.0, 0.0156, 4), 1);
  EXPECT_EQ(sparseFilmSpacing(std::nan(""), 0.0156, 4), 1);
  EXPECT_EQ(sparseFilmSpacing(std::numeric_limits<double>::infinity(), 0.0156, 4), 1);
}

TEST(SparseFilm, ARampIsInterpolatedHoweverSteep) {
  const std::vector<int> xs = line(6, 4), ys = line(5, 4);
  FilmTolerance tol;
  // Bilinear data: interpolation is exact, so no cell is traced.
  const auto g =
      gridOf(xs, ys, [](int x, int y) { return 0.01 + 3.0 * x + 0.5 * y + 0.01 * x * y; });
  const std::vector<uint8_t> cells = filmCellsToTrace(g, xs, ys, tol);
  ASSERT_EQ(cells.size(), size_t(5 * 4));
  EXPECT_EQ(count(cells), 0);
  const FilmPixel p = interpolateFilm(g[0], g[1], g[6], g[7], 0.25, 0.75);
  const double want = 0.01 + 3.0 * 1 + 0.5 * 3 + 0.01 * 1 * 3;
  for (float v : p.v) EXPECT_NEAR(v, want, 1e-5);
}

TEST(SparseFilm, APeakOrAnEdgeBetweenTracedPixelsTracesTheCellsBesideIt) {
  const std::vector<int> xs = line(7, 2), ys = line(7, 2);
  FilmTolerance tol;
  // One traced pixel 20 % above a flat film bends, and so do its four neighbours (0.2 against
  // a tolerance of 0.12): the 12 cells with one of them as a corner are traced.
  auto peak = gridOf(xs, ys, [](int x, int y) { return x == 6 && y == 6 ? 1.2 : 1.0; });
  std::vector<uint8_t> cells = filmCellsToTrace(peak, xs, ys, tol);
  EXPECT_EQ(count(cells), 12);
  EXPECT_TRUE(cells[2 * 6 + 2]);
  EXPECT_FALSE(cells[0]);
  // 5 % is under the tolerance of 10 % on the second difference: interpolated.
  auto faint = gridOf(xs, ys, [](int x, int y) { return x == 6 && y == 6 ? 1.05 : 1.0; });
  EXPECT_EQ(count(filmCellsToTrace(faint, xs, ys, tol)), 0);
  // A silhouette between columns 4 and 6: the cells on both sides of it, on every row.
  auto edge = gridOf(xs, ys, [](int x, int) { return x <= 4 ? 0.0 : 1.0; });
  cells = filmCellsToTrace(edge, xs, ys, tol);
  for (int j = 0; j < 6; ++j) {
    for (int i = 0; i < 6; ++i) EXPECT_EQ(bool(cells[size_t(j) * 6 + i]), i >= 1 && i <= 3) << i;
  }
}

TEST(SparseFilm, TheSkyBehindTheCloudIsNotJudged) {
  const std::vector<int> xs = line(5, 2), ys = line(5, 2);
  // A sky map's line through one traced pixel: beauty and background peak, nothing else does.
  auto g = gridOf(xs, ys, [](int, int) { return 1.0; });
  for (int k = 0; k < kFilmFloats; ++k) {
    if (!judgedFloat(k)) g[2 * 5 + 2].v[k] = 10.f;
  }
  EXPECT_EQ(count(filmCellsToTrace(g, xs, ys, FilmTolerance{})), 0);
  // The same peak in alpha or in a light layer is traced.
  for (int k : {3, 7, 13, 18}) {
    auto h = gridOf(xs, ys, [](int, int) { return 1.0; });
    h[2 * 5 + 2].v[k] = 10.f;
    EXPECT_GT(count(filmCellsToTrace(h, xs, ys, FilmTolerance{})), 0) << k;
  }
}

TEST(SparseFilm, FaintLightAndAGridWithoutSecondDifferences) {
  const std::vector<int> xs = line(5, 2), ys = line(5, 2);
  FilmTolerance tol;
  tol.light_floor = 1.0;
  tol.alpha_floor = 100.0;
  // Light far under its floor bends by 100 % of itself and is still interpolated.
  auto faint = gridOf(xs, ys, [](int x, int y) { return x == 4 && y == 4 ? 0.02 : 0.01; });
  EXPECT_EQ(count(filmCellsToTrace(faint, xs, ys, tol)), 0);
  // Two traced columns: nothing to bend against along x, so every cell is traced.
  const std::vector<int> two = line(2, 2);
  auto flat = gridOf(two, ys, [](int, int) { return 1.0; });
  EXPECT_EQ(count(filmCellsToTrace(flat, two, ys, FilmTolerance{})), 4);
  EXPECT_TRUE(filmCellsToTrace(gridOf(line(1, 2), ys, [](int, int) { return 1.0; }), line(1, 2), ys,
                               FilmTolerance{})
                  .empty());
}

TEST(SparseFilm, InterpolationStaysWithinItsCorners) {
  FilmPixel a, b, c, d;
  for (int k = 0; k < kFilmFloats; ++k) {
    a.v[k] = 0.f;
    b.v[k] = 1.f;
    c.v[k] = 3e-8f;
    d.v[k] = 0.999999f;
  }
  for (double fx : {0.0, 0.1, 0.5, 0.9, 1.0}) {
    for (double fy : {0.0, 0.3, 1.0}) {
      const FilmPixel p = interpolateFilm(a, b, c, d, fx, fy);
      for (float v : p.v) {
        EXPECT_GE(v, 0.f);
        EXPECT_LE(v, 1.f);
      }
    }
  }
}

}  // namespace
}  // namespace cloudbake
