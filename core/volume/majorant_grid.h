// Coarse grid of density upper bounds, for delta/ratio tracking and empty-space skipping.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "core/math/vec3.h"

namespace cloudbake {

/// A dense, coarse grid over a world-space box; each cell stores an upper bound of the density
/// anywhere inside it (including the footprint of trilinear interpolation). Tracking with one
/// majorant per cell instead of one global majorant keeps the number of null collisions low in
/// clouds whose density varies a lot (Kutz et al. 2017; pbrt-v4's DDAMajorantIterator).
///
/// A grid may also carry a lower bound (minorant) per cell: decomposition and residual ratio
/// tracking (core/transport/tracking.h) treat the minorant part of the density analytically and
/// look the density up only for the residual, max - min.
///
/// Parameters: `bounds` (world units), `res` cells per axis (>= 1 each), `maxima` in x-fastest
/// order (size res.x*res.y*res.z), density units (multiply by extinction for sigma_t_maj);
/// `minima` empty (no minorants: 0 everywhere) or of the same size, 0 <= min <= max per cell.
class MajorantGrid {
 public:
  MajorantGrid() = default;
  MajorantGrid(const Bounds3& bounds, int nx, int ny, int nz, std::vector<float> maxima,
               std::vector<float> minima = {});
  /// A single cell covering `bounds` with the given bound (analytic media).
  static MajorantGrid uniform(const Bounds3& bounds, float majorant);

  const Bounds3& bounds() const { return bounds_; }
  int nx() const { return nx_; }
  int ny() const { return ny_; }
  int nz() const { return nz_; }
  float cell(int x, int y, int z) const { return maxima_[index(x, y, z)]; }
  float maxValue() const { return max_value_; }
  /// The largest bound of the cells that `box` overlaps (cells on its faces included); 0 where
  /// it lies outside bounds() (the trackers take no density there either).
  float maxOver(const Bounds3& box) const;
  bool hasMinorants() const { return !minima_.empty(); }
  float minorant(int x, int y, int z) const {
    return minima_.empty() ? 0.f : minima_[index(x, y, z)];
  }

  /// Walks the cells that `ray` (unit direction) crosses within [tmin, tmax], in order, calling
  /// fn(t0, t1, majorant) for each non-empty overlap; stops early when fn returns false.
  /// Returns false if fn stopped the walk.
  template <typename Fn>
  bool traverse(const Ray& ray, double tmin, double tmax, Fn&& fn) const {
    return walkCells(ray, tmin, tmax,
                     [&](double t0, double t1, size_t i) { return fn(t0, t1, maxima_[i]); });
  }

  /// As traverse(), calling fn(t0, t1, majorant, minorant) (minorant 0 without minorants).
  template <typename Fn>
  bool traverseBounds(const Ray& ray, double tmin, double tmax, Fn&& fn) const {
    return walkCells(ray, tmin, tmax, [&](double t0, double t1, size_t i) {
      return fn(t0, t1, maxima_[i], minima_.empty() ? 0.f : minima_[i]);
    });
  }

 private:
  // The 3D DDA (Amanatides & Woo 1987) behind both traversals: fn(t0, t1, cell index).
  template <typename Fn>
  bool walkCells(const Ray& ray, double tmin, double tmax, Fn&& fn) const;

  size_t index(int x, int y, int z) const { return (static_cast<size_t>(z) * ny_ + y) * nx_ + x; }
  Bounds3 bounds_;
  int nx_ = 0, ny_ = 0, nz_ = 0;
  std::vector<float> maxima_;
  std::vector<float> minima_;
  float max_value_ = 0;
};

template <typename Fn>
bool MajorantGrid::walkCells(const Ray& ray, double tmin, double tmax, Fn&& fn) const {
  if (maxima_.empty()) return true;
  double t0, t1;
  if (!intersectBounds(bounds_, ray, tmin, tmax, &t0, &t1)) return true;
  const Vec3 ext = bounds_.extent();
  const int res[3] = {nx_, ny_, nz_};
  double cell_size[3];
  int ic[3], step[3], stop[3];
  double t_next[3], dt[3];
  const Vec3 p = ray.at(t0);
  for (int a = 0; a < 3; ++a) {
    cell_size[a] = ext[a] > 0 ? ext[a] / res[a] : 1.0;
    const double rel = ext[a] > 0 ? (p[a] - bounds_.min[a]) / cell_size[a] : 0.0;
    int c = static_cast<int>(std::floor(rel));
    c = c < 0 ? 0 : (c >= res[a] ? res[a] - 1 : c);
    ic[a] = c;
    if (ray.d[a] > 0) {
      step[a] = 1;
      stop[a] = res[a];
      t_next[a] = t0 + (bounds_.min[a] + (c + 1) * cell_size[a] - p[a]) / ray.d[a];
      dt[a] = cell_size[a] / ray.d[a];
    } else if (ray.d[a] < 0) {
      step[a] = -1;
      stop[a] = -1;
      t_next[a] = t0 + (bounds_.min[a] + c * cell_size[a] - p[a]) / ray.d[a];
      dt[a] = -cell_size[a] / ray.d[a];
    } else {
      step[a] = 0;
      stop[a] = -2;
      t_next[a] = INFINITY;
      dt[a] = INFINITY;
    }
  }
  double t = t0;
  while (t < t1) {
    int axis = 0;
    if (t_next[1] < t_next[axis]) axis = 1;
    if (t_next[2] < t_next[axis]) axis = 2;
    const double t_end = t_next[axis] < t1 ? t_next[axis] : t1;
    if (t_end > t) {
      if (!fn(t, t_end, index(ic[0], ic[1], ic[2]))) return false;
    }
    t = t_end;
    ic[axis] += step[axis];
    if (ic[axis] == stop[axis]) break;
    t_next[axis] += dt[axis];
  }
  return true;
}

}  // namespace cloudbake
