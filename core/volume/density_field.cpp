#include "core/volume/density_field.h"

#include <algorithm>

#include "core/error.h"

namespace cloudbake {

MajorantGrid::MajorantGrid(const Bounds3& bounds, int nx, int ny, int nz, std::vector<float> maxima,
                           std::vector<float> minima)
    : bounds_(bounds),
      nx_(nx),
      ny_(ny),
      nz_(nz),
      maxima_(std::move(maxima)),
      minima_(std::move(minima)) {
  if (nx < 1 || ny < 1 || nz < 1 ||
      maxima_.size() != static_cast<size_t>(nx) * static_cast<size_t>(ny) * nz) {
    throw std::invalid_argument("MajorantGrid: resolution does not match the maxima array");
  }
  if (bounds.empty()) throw std::invalid_argument("MajorantGrid: empty bounds");
  if (!minima_.empty()) {
    if (minima_.size() != maxima_.size()) {
      throw std::invalid_argument("MajorantGrid: minima and maxima differ in size");
    }
    for (size_t i = 0; i < minima_.size(); ++i) {
      if (!(minima_[i] >= 0.f && minima_[i] <= maxima_[i])) {
        throw std::invalid_argument("MajorantGrid: a minorant is not in [0, majorant]");
      }
    }
  }
  max_value_ = maxima_.empty() ? 0.f : *std::max_element(maxima_.begin(), maxima_.end());
}

std::shared_ptr<const MajorantGrid> DensityField::trackingGrid(
    const TrackingGridRequest& /*request*/) const {
  return nonOwning(majorants());
}

MajorantGrid MajorantGrid::uniform(const Bounds3& bounds, float majorant) {
  return MajorantGrid(bounds, 1, 1, 1, {majorant});
}

float MajorantGrid::maxOver(const Bounds3& box) const {
  if (maxima_.empty()) return 0.f;
  const int res[3] = {nx_, ny_, nz_};
  int lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    if (box.max[a] < bounds_.min[a] || box.min[a] > bounds_.max[a]) return 0.f;
    const double ext = bounds_.max[a] - bounds_.min[a];
    if (!(ext > 0)) {
      lo[a] = 0;
      hi[a] = res[a] - 1;
      continue;
    }
    const double cell = ext / res[a];
    lo[a] = int(std::clamp(std::floor((box.min[a] - bounds_.min[a]) / cell), 0.0, res[a] - 1.0));
    hi[a] = int(std::clamp(std::floor((box.max[a] - bounds_.min[a]) / cell), 0.0, res[a] - 1.0));
  }
  float m = 0.f;
  for (int z = lo[2]; z <= hi[2]; ++z) {
    for (int y = lo[1]; y <= hi[1]; ++y) {
      for (int x = lo[0]; x <= hi[0]; ++x) m = std::max(m, maxima_[index(x, y, z)]);
    }
  }
  return m;
}

}  // namespace cloudbake
