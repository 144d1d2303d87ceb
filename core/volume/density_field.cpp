#include "core/volume/density_field.h"

#include <algorithm>

#include "core/error.h"

namespace cloudbake {

MajorantGrid::MajorantGrid(const Bounds3& bounds, int nx, int ny, int nz, std::vector<float> maxima)
    : bounds_(bounds), nx_(nx), ny_(ny), nz_(nz), maxima_(std::move(maxima)) {
  if (nx < 1 || ny < 1 || nz < 1 ||
      maxima_.size() != static_cast<size_t>(nx) * static_cast<size_t>(ny) * nz) {
    throw std::invalid_argument("MajorantGrid: resolution does not match the maxima array");
  }
  if (bounds.empty()) throw std::invalid_argument("MajorantGrid: empty bounds");
  max_value_ = maxima_.empty() ? 0.f : *std::max_element(maxima_.begin(), maxima_.end());
}

MajorantGrid MajorantGrid::uniform(const Bounds3& bounds, float majorant) {
  return MajorantGrid(bounds, 1, 1, 1, {majorant});
}

}  // namespace cloudbake
