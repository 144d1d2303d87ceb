// Analytic density fields with exact boundaries, used to verify transport against theory.
#pragma once

#include "core/volume/density_field.h"

namespace cloudbake {

/// Homogeneous axis-aligned box (a slab when wide and thin). Parameters: min, max corners in
/// world units (min < max on every axis), density >= 0. Exact: no voxelisation blur, so a slab's
/// direct transmittance is exactly exp(-extinction * density * thickness). Its tracking grid's
/// minorant equals its majorant, so decomposition tracking needs no lookups inside it.
class BoxDensity final : public DensityField {
 public:
  BoxDensity(const Vec3& min, const Vec3& max, double density);
  Bounds3 bounds() const override { return box_; }
  double maxDensity() const override { return density_; }
  std::unique_ptr<Lookup> lookup() const override;
  const MajorantGrid& majorants() const override { return majorants_; }
  std::shared_ptr<const MajorantGrid> trackingGrid(
      const TrackingGridRequest& /*request*/) const override {
    return tracking_;
  }
  double featureSize() const override;
  std::string describe() const override;
  /// The density times the share of `cell` inside the box.
  std::optional<double> cellMean(const Bounds3& cell) const override;

 private:
  Bounds3 box_;
  double density_;
  MajorantGrid majorants_;
  std::shared_ptr<const MajorantGrid> tracking_;
};

/// Homogeneous sphere. Parameters: center (world), radius > 0 (world units), density >= 0.
class SphereDensity final : public DensityField {
 public:
  SphereDensity(const Vec3& center, double radius, double density);
  Bounds3 bounds() const override;
  double maxDensity() const override { return density_; }
  std::unique_ptr<Lookup> lookup() const override;
  const MajorantGrid& majorants() const override { return majorants_; }
  /// The ray's chord through the sphere.
  bool supportInterval(const Ray& ray, double tmin, double tmax, double* t0,
                       double* t1) const override;
  double featureSize() const override { return radius_ / 32.0; }
  std::string describe() const override;

 private:
  Vec3 center_;
  double radius_, density_;
  MajorantGrid majorants_;
};

}  // namespace cloudbake
