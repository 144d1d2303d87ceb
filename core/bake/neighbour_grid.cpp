#include "core/bake/neighbour_grid.h"

namespace cloudbake {

PointGrid::PointGrid(const std::vector<Vec3>& points, double cell_size) {
  Bounds3 box;
  for (const Vec3& p : points) box.expand(p);
  if (points.empty()) box.expand(Vec3(0.0));
  const Vec3 extent = box.extent();
  // At most ~2 cells per point (and 2^24 in all): beyond that cells are mostly empty and only
  // cost memory; a larger cell still finds every neighbour (queries span several cells).
  const double cells_max = std::min(2.0 * double(points.size()) + 8.0, double(1 << 24));
  const double volume =
      std::max(extent.x, 1e-300) * std::max(extent.y, 1e-300) * std::max(extent.z, 1e-300);
  double cell = cell_size > 0 && std::isfinite(cell_size) ? cell_size : 1.0;
  cell = std::max(cell, maxComponent(extent) * 1e-6);
  for (int guard = 0; guard < 200; ++guard) {
    const double cells = std::ceil(std::max(extent.x, 1e-300) / cell + 1) *
                         std::ceil(std::max(extent.y, 1e-300) / cell + 1) *
                         std::ceil(std::max(extent.z, 1e-300) / cell + 1);
    if (cells <= cells_max) break;
    cell = std::max(cell * 1.25, std::cbrt(volume / cells_max));
  }
  cell_ = cell;
  origin_ = box.min;
  nx_ = int(extent.x / cell) + 1;
  ny_ = int(extent.y / cell) + 1;
  nz_ = int(extent.z / cell) + 1;
  const size_t ncells = size_t(nx_) * size_t(ny_) * size_t(nz_);
  std::vector<uint32_t> cell_of(points.size());
  start_.assign(ncells + 1, 0);
  for (size_t i = 0; i < points.size(); ++i) {
    const Vec3 c = (points[i] - origin_) / cell_;
    const size_t id =
        (size_t(clampCell(c.z, nz_)) * size_t(ny_) + size_t(clampCell(c.y, ny_))) * size_t(nx_) +
        size_t(clampCell(c.x, nx_));
    cell_of[i] = uint32_t(id);
    ++start_[id + 1];
  }
  for (size_t c = 0; c < ncells; ++c) start_[c + 1] += start_[c];
  std::vector<uint32_t> fill(start_.begin(), start_.end() - 1);
  order_.resize(points.size());
  sorted_.resize(points.size());
  for (size_t i = 0; i < points.size(); ++i) {  // stable: index order within a cell
    const uint32_t s = fill[cell_of[i]]++;
    order_[s] = uint32_t(i);
    sorted_[s] = points[i];
  }
}

double estimateMeanNeighbours(const PointGrid& grid, const std::vector<Vec3>& points, double radius,
                              int samples, double stop_above) {
  const size_t n = points.size();
  if (n == 0) return 0;
  const size_t s = std::min(n, size_t(std::max(samples, 1)));
  uint64_t total = 0;
  for (size_t t = 0; t < s; ++t) {
    const size_t i = (2 * t + 1) * n / (2 * s);
    grid.forEachWithin(points[i], radius, [&](uint32_t src, double) {
      if (src != i) ++total;
    });
    if (double(total) > stop_above * double(s)) return double(total) / double(t + 1);
  }
  return double(total) / double(s);
}

}  // namespace cloudbake
