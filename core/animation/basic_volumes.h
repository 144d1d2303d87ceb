// The database of basic volumes (seed 002): every frame of an animated volume on one lattice.
#pragma once

#include <functional>
#include <string>

#include "core/animation/video_texture.h"
#include "core/bake/bake_grid.h"
#include "core/shot/shot.h"

namespace cloudbake {

/// The frames of a sequence as dense densities on one lattice, in time order.
struct BasicVolumeDatabase {
  BakeGrid grid;
  BasicVolumes frames;
};

/// Builds every frame of `sequence` (VDB files, or the procedural cloud at successive times;
/// core/shot/scene_builder.h) and resamples each onto one lattice covering the union of their
/// bounds, `resolution` voxels along its longest side (core/bake/bake_lattice.h). VDB frames
/// must share one voxel size: InputError naming the frame otherwise, as for fewer than 2 frames.
/// `progress(fraction)` returning false cancels (Cancelled).
BasicVolumeDatabase buildBasicVolumes(const SequenceVolumeSpec& sequence, int resolution,
                                      const std::string& source = "shot.json",
                                      const std::function<bool(double)>& progress = {});

}  // namespace cloudbake
