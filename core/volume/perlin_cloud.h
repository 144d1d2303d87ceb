// The procedural Perlin-noise cloud of seed 004 (makePerlinCloud in sources.h) and its maths.
//
// Construction (after Hugo Elias, "Clouds", and seed 004's cloud generator): inside the box
// (options.center, options.size) voxels of size h = max(size) / resolution hold
//   v       = envelope(r) * 2 * fbm01(q)          q = (p - box_min) / max(size) * frequency
//   c       = max(v - cover, 0)                   (cloud cover)
//   density = options.density * (1 - sharpness^(255 c))   (Elias's exponential, 8-bit units)
// where r is the ellipsoidal radius of p with semi-axes size/2 - 1.5 h, and
// envelope(r) = max(0, 1 - r^2). The envelope is exactly 0 for r >= 1, so the outermost layer
// of voxels is always empty: the cloud never touches the grid boundary. The noise breaks the
// ellipsoid's edge into puffs; the result depends only on the options (seed included).
#pragma once

#include "core/volume/noise.h"
#include "core/volume/sources.h"

namespace cloudbake {

/// Envelope of the ellipsoidal radius r (1 on the ellipsoid surface): max(0, 1 - r^2).
double cloudEnvelope(double r);

/// Elias's cover/sharpness mapping of a shaped noise value v (about [0, 2]) to density in
/// [0, 1): 1 - sharpness^(255 * max(v - cover, 0)).
double eliasCloudDensity(double v, double cover, double sharpness);

/// fbm01 (noise.h) at cloud time `time`: each octave drifts by (1 + octave/2) noise cells per
/// unit time in its own direction; equal to fbm01 at time 0.
double evolvingFbm01(const PerlinNoise& noise, const Vec3& q, int octaves, double persistence,
                     double time);

/// Throws InputError naming the first invalid option ("perlin_cloud.<field>: ...").
void validatePerlinCloudOptions(const PerlinCloudOptions& options);

}  // namespace cloudbake
