// Method `precomputed`: endless cloud animation (Iwasaki, Nishino and Dobashi 2011, "Real-time
// rendering of endless cloud animation"). Per basic volume, independent of the light: optical-
// depth SH and clustered voxel-to-sample transfers; per frame: the blend of two basic volumes
// on a video-texture walk, lit from those precomputes, rendered as an EXR frame sequence.
#pragma once

#include <string>

#include "core/animation/precomputed.h"
#include "core/animation/video_texture.h"
#include "core/bake/render_from_bake.h"
#include "core/methods/method.h"

namespace cloudbake {

const BakeMethod& precomputedMethod();

/// The `bake` knobs of a method-precomputed shot with their defaults (docs/shot-format.md).
struct PrecomputedShotOptions {
  int light_resolution = 64;  ///< lattice voxels along the longest side
  PrecomputeOptions precompute;
  FrameLightOptions frame;
  VideoTextureOptions walk;
  int frames = 1;         ///< output frames; default: the database's size
  int basic_volumes = 1;  ///< the sequence's frames (1 for a static volume)
};
PrecomputedShotOptions precomputedOptions(const ShotSpec& shot);

/// The render options of a frame's views: the shot's, with the step a whole voxel of the frame's
/// lattice where the shot leaves it out (see docs/methods.md, "An eighth step").
BakeRenderOptions frameRenderOptions(const ShotSpec& shot, const BakedLight& frame, int threads);

/// Output names of frame `f`: "<stem>.<ffff>" (4 digits at least, as DCC frame sequences).
std::string frameStem(const std::string& stem, int frame);

}  // namespace cloudbake
