// Small statistics and scene helpers shared by the transport tests.
#pragma once

#include <cmath>
#include <memory>
#include <vector>

#include "core/io/image.h"
#include "core/transport/scene.h"
#include "core/volume/density_field.h"

namespace cloudbake {
namespace testing_util {

/// Running mean and standard error of i.i.d. samples.
struct Stats {
  double n = 0, sum = 0, sum2 = 0;
  void add(double x) {
    n += 1;
    sum += x;
    sum2 += x * x;
  }
  double mean() const { return sum / n; }
  double variance() const { return n > 1 ? std::max(0.0, (sum2 - sum * sum / n) / (n - 1)) : 0; }
  double stderror() const { return std::sqrt(variance() / n); }
};

/// A px x px perspective camera 4 units in front of the test media (centred at z = 0.5),
/// looking along +y with +z up.
inline Camera perspectiveCamera(int px, double fov_deg = 35) {
  Camera cam;
  cam.name = "test";
  cam.type = Camera::Type::kPerspective;
  cam.position = Vec3(0, -4, 0.5);
  cam.look_at = Vec3(0, 0, 0.5);
  cam.up = Vec3(0, 0, 1);
  cam.fov_deg = fov_deg;
  cam.width_px = cam.height_px = px;
  return cam;
}

/// Stats over one channel of every pixel of an image (pixels are independent estimates).
inline Stats pixelStats(const Image& im, int channel, double scale = 1.0) {
  Stats s;
  for (int y = 0; y < im.height; ++y) {
    for (int x = 0; x < im.width; ++x) s.add(scale * im.at(x, y)[channel]);
  }
  return s;
}

/// Heterogeneous test medium: density a + b z inside a box spanning z in [0, 1], with a majorant
/// grid of `cells` layers along z (exercises multi-cell traversal). Optical depth of the full
/// height is extinction * (a + b / 2).
class LinearSlab final : public DensityField {
 public:
  LinearSlab(double a, double b, int cells, double half_width = 1e4) : a_(a), b_(b) {
    box_.min = Vec3(-half_width, -half_width, 0);
    box_.max = Vec3(half_width, half_width, 1);
    std::vector<float> m(cells);
    for (int i = 0; i < cells; ++i) {
      const double z0 = double(i) / cells, z1 = double(i + 1) / cells;
      m[i] = static_cast<float>(std::max(a + b * z0, a + b * z1)) * 1.0001f;
    }
    grid_ = MajorantGrid(box_, 1, 1, cells, m);
    std::vector<float> lo(cells);
    for (int i = 0; i < cells; ++i) {
      const double z0 = double(i) / cells, z1 = double(i + 1) / cells;
      lo[i] = static_cast<float>(std::min(a + b * z0, a + b * z1)) * 0.9999f;
    }
    tracking_ = std::make_shared<const MajorantGrid>(box_, 1, 1, cells, m, lo);
  }
  /// With minorants: the density's exact minimum per cell (less 0.01 %).
  std::shared_ptr<const MajorantGrid> trackingGrid(const TrackingGridRequest&) const override {
    return tracking_;
  }
  Bounds3 bounds() const override { return box_; }
  double maxDensity() const override { return grid_.maxValue(); }
  std::unique_ptr<Lookup> lookup() const override { return std::make_unique<L>(this); }
  const MajorantGrid& majorants() const override { return grid_; }
  double featureSize() const override { return 0.01; }
  std::string describe() const override { return "linear slab"; }
  /// Optical depth (density integral) from z = 0 to z (clamped to the slab).
  double depth(double z) const {
    z = std::clamp(z, 0.0, 1.0);
    return a_ * z + 0.5 * b_ * z * z;
  }

 private:
  struct L final : Lookup {
    explicit L(const LinearSlab* s) : s(s) {}
    double density(const Vec3& p) override {
      return s->box_.contains(p) ? s->a_ + s->b_ * p.z : 0.0;
    }
    const LinearSlab* s;
  };
  double a_, b_;
  Bounds3 box_;
  MajorantGrid grid_;
  std::shared_ptr<const MajorantGrid> tracking_;
};

}  // namespace testing_util
}  // namespace cloudbake
