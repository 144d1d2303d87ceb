// The database of basic volumes (seed 002): every frame of an animated volume on one lattice.
#pragma once

#include <functional>
#include <string>

#include "core/animation/video_texture.h"
#include "core/bake/bake_grid.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// The frames of a sequence as dense densities on one lattice, in time order.
struct BasicVolumeDatabase {
  BakeGrid grid;
  BasicVolumes frames;
};

/// An animated volume as buildBasicVolumes reads it: `count` frames, each built on demand.
struct VolumeFrames {
  int count = 0;
  /// Frame `frame`, 0 <= frame < count. Called twice a frame (bounds first, then resampling),
  /// so that only the dense lattices are ever held, not every frame's field at once.
  std::function<DensityFieldPtr(int frame)> build;
  /// The frames are voxel grids (files): they must share one voxel size, since the database is
  /// one lattice with one transform. Procedural frames have no voxels of their own.
  bool same_voxel_size = false;
  /// Names frame `frame` in errors ("shot.json: /volume/sequence/paths/2"); empty: "frame N".
  std::function<std::string(int frame)> name;
};

/// Builds every frame and resamples each onto one lattice covering the union of their bounds,
/// `resolution` voxels along its longest side (core/bake/bake_lattice.h). InputError for fewer
/// than 2 frames, and naming the frame when voxel sizes that must agree differ.
/// `progress(fraction)` returning false cancels (Cancelled).
BasicVolumeDatabase buildBasicVolumes(const VolumeFrames& frames, int resolution,
                                      const std::function<bool(double)>& progress = {});

}  // namespace cloudbake
