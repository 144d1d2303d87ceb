// Resampling a shot's density field onto the dense lattice a bake computes on.
#pragma once

#include <cstdint>
#include <string>

#include "core/bake/baked_light.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// Default lattice resolution (voxels along the longest side of the density's bounds).
constexpr int kDefaultLightResolution = 128;
/// Largest lattice a bake may allocate (voxels, margin included): 2^25 (a few hundred MB with
/// every pointcloud grid).
constexpr uint64_t kMaxBakeVoxels = uint64_t(1) << 25;

/// How a lattice takes its values from the field.
enum class LatticeSampling {
  /// Each voxel the mean density over its volume (the field supersampled 2x2x2 per voxel, or
  /// more when the field's feature size is smaller than the voxel, up to 4x4x4): keeps optical
  /// depths right where the lattice is coarser than the field, but its trilinear reconstruction
  /// blurs the field by about a voxel.
  kBoxMean,
  /// Where the field has a SampleLattice (a grid's voxel centres) and `resolution` is at least
  /// 4/5 of the field's own voxels along the longest side (n, its active voxels' extent): a
  /// lattice of spacing s / m aligned with it, m = floor(resolution / n + 1/5) (so at most 1.25x
  /// the voxels per axis asked for), each voxel the field's value at its centre, so trilinear
  /// lookups of the lattice equal the field's own, unless that lattice holds more than
  /// (resolution + 4)^3 voxels (the (resolution + 2)^3 the servers' limits count, and a voxel
  /// per face for the grid's footprint). Otherwise as kBoxMean.
  kFieldAligned,
};

/// A BakedLight with only `density` filled: a lattice of cubic voxels covering field.bounds()
/// with `resolution` voxels along its longest side plus one empty voxel of margin on every face
/// (so trilinear lookups fall to zero outside the cloud), sampled as `sampling` says; with
/// kFieldAligned where it applies, the grid's own voxel centres (or 1/m of them) over its
/// footprint, whose outermost voxels are zeros. resolution in [8, 1024]; InputError naming
/// "light_resolution" otherwise, or when the lattice would exceed kMaxBakeVoxels. Parallel over z
/// slices with one density lookup per thread; deterministic.
BakedLight makeBakeLattice(const DensityField& field, int resolution,
                           LatticeSampling sampling = LatticeSampling::kBoxMean);

/// How far from the origin, in its own voxels, a lattice may reach.
constexpr double kMaxLatticeOffsetVoxels = 4e9;

/// The geometry alone of such a lattice over world `bounds` (`what` describes the volume in
/// errors, `knob` names the resolution's field): InputError as makeBakeLattice.
BakeGrid bakeLatticeGeometry(const Bounds3& bounds, int resolution, const std::string& what,
                             const char* knob = "light_resolution");

/// The same, box means, over explicit world `bounds` instead of the field's own (e.g. the union of
/// the frames of an animation, so every frame lands on one lattice).
BakedLight makeBakeLatticeOver(const DensityField& field, const Bounds3& bounds, int resolution);

}  // namespace cloudbake
