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

}  // namespace cloudbake
