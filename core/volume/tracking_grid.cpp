#include "core/volume/tracking_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/math/parallel.h"

namespace cloudbake {
namespace {

int cellsFor(int voxels, int m) { return std::max(1, (voxels - 1 + m - 1) / m); }

}  // namespace

CellBounds trilinearCellBounds(const DenseView& dense) {
  CellBounds b;
  b.m = 1;
  for (int a = 0; a < 3; ++a) b.n[a] = cellsFor(dense.n[a], 1);
  const size_t count = size_t(b.n[0]) * b.n[1] * b.n[2];
  b.maxima.assign(count, 0.f);
  b.minima.assign(count, 0.f);
  auto value = [&](int x, int y, int z) {
    if (x >= dense.n[0] || y >= dense.n[1] || z >= dense.n[2]) return 0.f;
    const float v = dense.values[(size_t(z) * dense.n[1] + y) * dense.n[0] + x];
    return v > 0.f ? v : 0.f;
  };
  parallelFor(0, b.n[2], [&](size_t z) {
    for (int y = 0; y < b.n[1]; ++y)
      for (int x = 0; x < b.n[0]; ++x) {
        float hi = 0.f, lo = std::numeric_limits<float>::infinity();
        for (int c = 0; c < 8; ++c) {
          const float v = value(x + (c & 1), y + ((c >> 1) & 1), int(z) + ((c >> 2) & 1));
          hi = std::max(hi, v);
          lo = std::min(lo, v);
        }
        const size_t i = (z * b.n[1] + y) * b.n[0] + x;
        b.maxima[i] = hi;
        b.minima[i] = lo;
      }
  });
  return b;
}

CellBounds coarsenCellBounds(const CellBounds& fine) {
  CellBounds b;
  b.m = fine.m * 2;
  for (int a = 0; a < 3; ++a) b.n[a] = (fine.n[a] + 1) / 2;
  const size_t count = size_t(b.n[0]) * b.n[1] * b.n[2];
  b.maxima.assign(count, 0.f);
  b.minima.assign(count, 0.f);
  parallelFor(0, b.n[2], [&](size_t z) {
    for (int y = 0; y < b.n[1]; ++y)
      for (int x = 0; x < b.n[0]; ++x) {
        float hi = 0.f, lo = std::numeric_limits<float>::infinity();
        for (int c = 0; c < 8; ++c) {
          const int fx = 2 * x + (c & 1), fy = 2 * y + ((c >> 1) & 1),
                    fz = 2 * int(z) + ((c >> 2) & 1);
          // A child beyond the fine grid lies outside the dense box: all zero.
          if (fx >= fine.n[0] || fy >= fine.n[1] || fz >= fine.n[2]) {
            lo = 0.f;
            continue;
          }
          const size_t j = (size_t(fz) * fine.n[1] + fy) * fine.n[0] + fx;
          hi = std::max(hi, fine.maxima[j]);
          lo = std::min(lo, fine.minima[j]);
        }
        const size_t i = (z * b.n[1] + y) * b.n[0] + x;
        b.maxima[i] = hi;
        b.minima[i] = lo;
      }
  });
  return b;
}

double trackingCost(const CellBounds& b, double sigma_per_voxel, const TrackingCostModel& model) {
  if (b.size() == 0) return 0;
  double residual = 0;
  for (size_t i = 0; i < b.size(); ++i) residual += double(b.maxima[i]) - double(b.minima[i]);
  residual /= double(b.size());
  return 1.5 * model.crossing_cost / b.m + sigma_per_voxel * residual;
}

std::vector<CellBounds> cellBoundsLevels(const DenseView& dense, int64_t max_cells, int max_m) {
  std::vector<CellBounds> levels;
  CellBounds level = trilinearCellBounds(dense);
  while (true) {
    const int64_t cells = int64_t(level.n[0]) * level.n[1] * level.n[2];
    const bool last = level.m * 2 > max_m;
    CellBounds next;
    if (!last) next = coarsenCellBounds(level);
    if (cells <= max_cells || last) levels.push_back(std::move(level));
    if (last) break;
    level = std::move(next);
  }
  return levels;
}

size_t cheapestLevel(const std::vector<CellBounds>& levels, double sigma_per_voxel,
                     const TrackingCostModel& model) {
  size_t best = 0;
  double best_cost = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < levels.size(); ++i) {
    const double c = trackingCost(levels[i], sigma_per_voxel, model);
    if (c <= best_cost) {
      best = i;
      best_cost = c;
    }
  }
  return best;
}

}  // namespace cloudbake
