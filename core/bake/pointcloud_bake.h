// Method `pointcloud` (Reimschuessel 2011, seed 000): light scattered between points inside the
// cloud, pass by pass, with a Mie/isotropic ratio per point; splatted to grids for rendering.
#pragma once

#include <cstdint>
#include <string>

#include "core/bake/bake_progress.h"
#include "core/bake/baked_light.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// Knobs of method `pointcloud` (shot keys beside "method": "pointcloud").
struct PointcloudOptions {
  int points = 65536;       ///< points inside the volume, [64, 2^24]; the quality knob
  int passes = 32;          ///< maximum scattering passes, [1, 1000]
  double radius = 0;        ///< neighbourhood cut-off, world units; 0: 3x the mean point spacing
  double tolerance = 0.01;  ///< stop when a pass changes Co by less than this (relative), (0, 1]
  enum class Rule { kNormalized, kPaper };
  Rule rule = Rule::kNormalized;
  bool output_mapping = false;  ///< apply seed 000's Eq. 2 (Co = 1 - exp(-Ci)); paper rule only
  int light_resolution = 128;   ///< lattice resolution, as SingleBakeOptions
  double step = 0;              ///< view ray-march step; 0: half a lattice voxel
  bool sky = true;              ///< also bake sky_visibility
  /// Add the geometric tail of the orders after the last pass (normalised rule); false shows
  /// exactly the orders computed, e.g. for a pass-by-pass sequence (seed 000's Figure 9).
  bool tail = true;
  uint64_t seed = 1;  ///< point jitter; same seed, same bake at any thread count
};

/// What a pointcloud bake did, also recorded in the bake's metadata.
struct PointcloudStats {
  int points = 0;
  int passes_run = 0;
  double radius = 0;               ///< the cut-off used, world units
  double mean_neighbours = 0;      ///< points within the cut-off, per point
  uint64_t pair_interactions = 0;  ///< source-destination transfers evaluated, all passes
  double last_relative_change = 0;
  double seconds_points = 0, seconds_neighbours = 0, seconds_passes = 0, seconds_splat = 0;
};

/// Bakes `medium` (density, extinction, albedo, phase) for a sun in direction `sun_dir`: the
/// lattice, sun_transmittance and sky_visibility as method `single`, then the point cloud and
/// its scattering passes, splatted into Co, light_dir, mie_ratio and Cd (docs/methods.md has
/// the two transfer rules and their derivation). InputError naming the knob for an unusable
/// radius (larger than the volume's diagonal, or more neighbour pairs than fit in memory) or an
/// empty volume; Cancelled on request.
BakedLight bakePointcloud(const Medium& medium, const Vec3& sun_dir,
                          const PointcloudOptions& options, const BakeProgressFn& progress = {},
                          PointcloudStats* stats = nullptr);

}  // namespace cloudbake
