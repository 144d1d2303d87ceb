// A density field stored in a sparse OpenVDB float grid (the public header stays OpenVDB-free).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/volume/density_field.h"

namespace cloudbake {

/// Density sampled from a sparse OpenVDB FloatGrid (Museth 2013) with trilinear interpolation
/// between voxel centres (openvdb::tools::BoxSampler). The grid's index-to-world transform must
/// be linear with uniform scale (rotation and translation allowed); voxel values are unitless
/// densities >= 0, zero in inactive voxels (the grid background is 0).
///
/// Majorants: one cell per block of 8^3 voxels (16^3, 32^3, ... for huge grids, so that there
/// are at most kMaxMajorantCells cells), each the maximum over the block's voxels dilated by one
/// voxel, so any trilinear lookup inside the cell is bounded by it.
///
/// The grid is shared and immutable: copies of a GridVolume share it, and lookups hold their
/// own OpenVDB ValueAccessor (one per thread). Build one with makeGridVolume() from
/// core/volume/openvdb_grid.h (sources, voxelize) or load one with loadVdbVolume().
class GridVolume final : public DensityField {
 public:
  struct Impl;
  static constexpr int64_t kMaxMajorantCells = 128 * 128 * 128;

  explicit GridVolume(std::shared_ptr<const Impl> impl);
  ~GridVolume() override;

  Bounds3 bounds() const override;
  double maxDensity() const override;
  std::unique_ptr<Lookup> lookup() const override;
  const MajorantGrid& majorants() const override;
  /// For grids with a dense copy and no rotation: cells of 1, 2, 4, ... 64 voxels aligned with
  /// the voxel centres, each with the exact maximum and minimum of trilinear lookups inside it
  /// (core/volume/tracking_grid.h), the cell size the requested one (rounded to a power of two,
  /// at most kMaxMajorantCells cells) or the cheapest by the cost model for the extinction.
  /// Other grids: majorants(), without minorants.
  std::shared_ptr<const MajorantGrid> trackingGrid(
      const TrackingGridRequest& request) const override;
  /// The voxel centres, for grids without rotation (mirrored axes allowed); none otherwise.
  std::optional<SampleLattice> sampleLattice() const override;
  double featureSize() const override { return voxelSize(); }
  std::string describe() const override;

  /// Edge length of one voxel in world units.
  double voxelSize() const;
  /// Number of active voxels (and active tile voxels) in the grid.
  uint64_t activeVoxelCount() const;
  /// Name of the grid (e.g. "density").
  const std::string& gridName() const;
  /// Voxels per majorant cell along each axis (8, 16, ...).
  int majorantBlockSize() const;
  /// Inclusive index-space box of the active voxels (min.xyz, max.xyz), for reports.
  void activeIndexBox(int min[3], int max[3]) const;

  const Impl& impl() const { return *impl_; }

 private:
  std::shared_ptr<const Impl> impl_;
};

}  // namespace cloudbake
