// The unbiased reference: a volumetric path tracer every faster method is measured against.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/io/image.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// Progress callback: fraction in [0,1]. Return false to cancel (the tracer then throws
/// Cancelled from its top-level loop within one tile's work).
using ProgressFn = std::function<bool(double fraction)>;

struct PathTracerOptions {
  int samples_per_pixel = 64;  ///< >= 1
  uint64_t seed = 1;           ///< results are identical for the same seed at any thread count
  /// Scattering events per path; paths are cut (not rouletted) beyond it. Russian roulette on
  /// the throughput ends absorbing paths unbiasedly, but in a white (albedo 1) medium the walk
  /// only ends by escaping: in optically huge media (extinction x size ~ 1e6) the escape-time
  /// tail is heavy, and the cap then loses a fraction ~ 1/sqrt(max_depth) of the multiply
  /// scattered light (< 1% at the default; see the Chandrasekhar test). Cost grows likewise.
  int max_depth = 100000;
  /// Probability of drawing the next direction from the phase function about the sun instead of
  /// about the travel direction (sun-directional importance sampling, core/transport/
  /// sun_guiding.h), in [0, 1); 0 is plain phase sampling; negative: autoSunGuiding(phase).
  double sun_guiding = -1;
  /// Most shadow rays towards the sun at one collision (prediction-based splitting and
  /// roulette, core/transport/shadow_splitting.h), 1..64; 1 turns splitting off (and the
  /// roulette, unless the transmittance predictor is on); negative: 8 where the transmittance
  /// predictor is on (decomposition tracking through a field with minorants), else
  /// autoSunSplitMax(phase).
  int sun_split_max = -1;
  /// Decomposition tracking for free paths and residual ratio tracking for shadow rays, against
  /// the tracking grid's per-cell minorants (core/transport/tracking.h); false: delta and ratio
  /// tracking, as version 2.
  bool decomposition_tracking = true;
  /// Voxels per tracking-grid cell edge for grid volumes: a power of two in 1..64; 0: chosen
  /// for the medium's extinction by the cost model of core/volume/tracking_grid.h, except that
  /// with decomposition_tracking off 0 keeps the density's own majorants (8^3-voxel blocks).
  int majorant_cell = 0;
  int threads = 0;     ///< 0: the caller's TBB arena / all hardware threads
  int tile_size = 16;  ///< pixels per tile side (work unit)
};

/// Render layers, all linear radiance in the units of the lights (W m^-2 sr^-1 for E in
/// W m^-2): `beauty` (RGBA; A = 1 - mean transmittance through the cloud along the pixel's
/// rays), and the parts it is the sum of: `sun`, `sky` (each: light scattered at least once
/// from that source), `single` and `multiple` (scattered exactly once / more than once, both
/// sources), plus what is seen directly behind the cloud (the sky through it), which is in
/// beauty only. beauty.rgb = sun + sky + background = single + multiple + background.
struct RenderLayers {
  Image beauty;      ///< 4 channels: everything the camera sees, and the coverage
  Image background;  ///< 3 channels: what is seen through the cloud (the sky times T)
  Image sun;         ///< 3 channels
  Image sky;         ///< 3 channels
  Image single;      ///< 3 channels
  Image multiple;    ///< 3 channels
  /// Pixels whose rays were traced: every pixel, but for a view from a bake's sparse film
  /// (core/bake/sparse_film.h), which interpolates the others.
  int64_t traced_pixels = 0;
};

/// Renders one view by path tracing. Throws InputError for invalid medium/camera/options.
RenderLayers renderPathTraced(const Medium& medium, const Sun& sun, const Sky& sky,
                              const Camera& camera, const PathTracerOptions& options,
                              const ProgressFn& progress = {});

}  // namespace cloudbake
