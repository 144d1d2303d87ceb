// The density-field interface the transport and bake code read clouds through.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "core/math/vec3.h"
#include "core/volume/majorant_grid.h"

namespace cloudbake {

/// What DensityField::trackingGrid() is asked for.
struct TrackingGridRequest {
  /// sigma_t per unit density per world unit: a thick medium favours fine cells (fewer density
  /// lookups), a thin one coarse cells (fewer cell crossings).
  double extinction = 1;
  /// Voxels per cell edge (grids); 0: chosen by the cost model (core/volume/tracking_grid.h).
  int cell_voxels = 0;
};

/// An axis-aligned cubic lattice of sample points (`origin` is one of them, `spacing` apart, in
/// world units) on which the field is exactly the trilinear interpolant of its values: a grid's
/// voxel centres. A lattice aligned with it whose spacing is spacing / m (m = 1, 2, ...) is one
/// too, since each of its cells lies inside one of the field's, where the field is trilinear.
struct SampleLattice {
  Vec3 origin;
  double spacing = 0;
};

/// A scalar density field in world space (unitless density; the medium's `extinction` turns it
/// into sigma_t per world unit). Zero outside bounds(). Implementations: analytic box/sphere
/// (exact, for verification) and GridVolume (sparse OpenVDB FloatGrid, trilinear lookups).
///
/// Thread-safety: the field itself is immutable and shared; lookups go through a per-thread
/// Lookup object (OpenVDB accessors cache tree nodes and must not be shared between threads).
class DensityField {
 public:
  /// Per-thread density lookup.
  class Lookup {
   public:
    virtual ~Lookup() = default;
    /// Density at world position `p` (>= 0, finite).
    virtual double density(const Vec3& p) = 0;
  };

  virtual ~DensityField() = default;

  /// World-space box outside which density is exactly zero.
  virtual Bounds3 bounds() const = 0;
  /// Upper bound of density anywhere.
  virtual double maxDensity() const = 0;
  /// A new lookup object, to be used by one thread at a time.
  virtual std::unique_ptr<Lookup> lookup() const = 0;
  /// Per-region density upper bounds for tracking and empty-space skipping.
  virtual const MajorantGrid& majorants() const = 0;
  /// Bounds for tracking a medium of the requested extinction, with per-cell minorants where the
  /// field can give them (decomposition and residual ratio tracking). The default is
  /// majorants() (no minorants), owned by the field: the pointer must not outlive it.
  virtual std::shared_ptr<const MajorantGrid> trackingGrid(
      const TrackingGridRequest& request) const;
  /// A non-owning shared pointer to `grid` (which must outlive it).
  static std::shared_ptr<const MajorantGrid> nonOwning(const MajorantGrid& grid) {
    return std::shared_ptr<const MajorantGrid>(std::shared_ptr<const MajorantGrid>(), &grid);
  }
  /// The part [t0, t1] of `ray`'s [tmin, tmax] outside which the density is exactly zero (one
  /// interval: a convex support); false when the ray misses it. The default clips to bounds();
  /// analytic shapes clip to themselves, so trackers take no null collisions in the empty
  /// corners of majorant cells they straddle (a sphere of extinction 1e6 cost a path tracer
  /// about 5e5 of them per escaping path, 2 ms).
  virtual bool supportInterval(const Ray& ray, double tmin, double tmax, double* t0,
                               double* t1) const {
    return intersectBounds(bounds(), ray, tmin, tmax, t0, t1);
  }
  /// The lattice of samples the field interpolates, when it has one (SampleLattice); none by
  /// default.
  virtual std::optional<SampleLattice> sampleLattice() const { return std::nullopt; }
  /// The field's mean over the box `cell` where it knows it in closed form (a homogeneous box:
  /// its share of the cell), so a lattice keeps features thinner than its samples' spacing;
  /// none by default (a lattice samples the field).
  virtual std::optional<double> cellMean(const Bounds3& /*cell*/) const { return std::nullopt; }
  /// Characteristic feature size in world units (voxel size for grids; for analytic shapes a
  /// small fraction of their extent). Ray marchers use it to choose step lengths.
  virtual double featureSize() const = 0;
  /// e.g. "box [..]-[..] density 1" or "vdb 'density' 412x300x500 voxels of 0.5".
  virtual std::string describe() const = 0;
};

using DensityFieldPtr = std::shared_ptr<const DensityField>;

}  // namespace cloudbake
