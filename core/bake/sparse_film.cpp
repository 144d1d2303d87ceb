#include "core/bake/sparse_film.h"

#include <algorithm>
#include <cmath>

namespace cloudbake {

int sparseFilmSpacing(double pixel_footprint, double voxel_size, int max_spacing) {
  int s = 1;
  if (!(pixel_footprint > 0) || !std::isfinite(pixel_footprint)) return s;
  while (2 * s <= std::min(max_spacing, kMaxFilmSpacing) && 2 * s * pixel_footprint <= voxel_size) {
    s *= 2;
  }
  return s;
}

namespace {

double floorOf(int k, const FilmTolerance& tol) {
  return k == 3 ? tol.alpha_floor : tol.light_floor;
}

// Whether the second difference at b, between a at distance h1 before it and c at h2 after,
// exceeds the tolerance: 2 (h1 c - (h1 + h2) b + h2 a) / (h1 + h2), the plain a - 2b + c for an
// even spacing, which a peak between traced pixels shows and their range may not.
bool curved(const FilmPixel& a, const FilmPixel& b, const FilmPixel& c, double h1, double h2,
            const FilmTolerance& tol) {
  for (int k = 0; k < kFilmFloats; ++k) {
    if (!judgedFloat(k)) continue;
    const double d = 2 * (h1 * c.v[k] - (h1 + h2) * b.v[k] + h2 * a.v[k]) / (h1 + h2);
    const double m = std::max({std::fabs(a.v[k]), std::fabs(b.v[k]), std::fabs(c.v[k])});
    if (std::fabs(d) > tol.curvature * (m + floorOf(k, tol))) return true;
  }
  return false;
}

}  // namespace

std::vector<uint8_t> filmCellsToTrace(const std::vector<FilmPixel>& grid,
                                      const std::vector<int>& xs, const std::vector<int>& ys,
                                      const FilmTolerance& tol) {
  const int nx = int(xs.size()), ny = int(ys.size());
  if (nx < 2 || ny < 2) return {};
  if (nx < 3 || ny < 3) return std::vector<uint8_t>(size_t(nx - 1) * (ny - 1), 1);
  auto at = [&](int i, int j) -> const FilmPixel& { return grid[size_t(j) * nx + i]; };
  // Grid pixels with a second difference over the tolerance along x or y.
  std::vector<uint8_t> bent(size_t(nx) * ny, 0);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      bool b = false;
      if (i > 0 && i < nx - 1) {
        b = curved(at(i - 1, j), at(i, j), at(i + 1, j), xs[i] - xs[i - 1], xs[i + 1] - xs[i], tol);
      }
      if (!b && j > 0 && j < ny - 1) {
        b = curved(at(i, j - 1), at(i, j), at(i, j + 1), ys[j] - ys[j - 1], ys[j + 1] - ys[j], tol);
      }
      bent[size_t(j) * nx + i] = b;
    }
  }
  std::vector<uint8_t> trace(size_t(nx - 1) * (ny - 1), 0);
  for (int j = 0; j + 1 < ny; ++j) {
    for (int i = 0; i + 1 < nx; ++i) {
      trace[size_t(j) * (nx - 1) + i] = bent[size_t(j) * nx + i] || bent[size_t(j) * nx + i + 1] ||
                                        bent[size_t(j + 1) * nx + i] ||
                                        bent[size_t(j + 1) * nx + i + 1];
    }
  }
  return trace;
}

FilmPixel interpolateFilm(const FilmPixel& c00, const FilmPixel& c10, const FilmPixel& c01,
                          const FilmPixel& c11, double fx, double fy) {
  FilmPixel out;
  const float ax = float(fx), ay = float(fy);
  for (int k = 0; k < kFilmFloats; ++k) {
    const float lo = c00.v[k] + ax * (c10.v[k] - c00.v[k]);
    const float hi = c01.v[k] + ax * (c11.v[k] - c01.v[k]);
    out.v[k] = lo + ay * (hi - lo);
  }
  return out;
}

}  // namespace cloudbake
