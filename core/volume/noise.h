// Gradient noise and fractal sums used by the procedural cloud and mesh density modulation.
#pragma once

#include <cstdint>
#include <string>

#include "core/math/vec3.h"
#include "core/volume/sources.h"

namespace cloudbake {

/// Improved Perlin gradient noise (Perlin 2002, "Improving Noise"): quintic fade, 12 edge
/// gradients, period 256 per axis. The permutation table is shuffled (Fisher-Yates with PCG32)
/// from `seed`, so different seeds give independent noise and equal seeds equal noise on any
/// machine. Values lie in about [-1, 1]; noise is 0 at integer lattice points.
class PerlinNoise {
 public:
  explicit PerlinNoise(uint64_t seed = 0);
  /// Noise at p (lattice units).
  double noise(const Vec3& p) const;
  /// Fractal Brownian motion (Musgrave): sum over `octaves` of persistence^o * noise(p * 2^o),
  /// normalised by the sum of amplitudes so the result stays in about [-1, 1].
  double fbm(const Vec3& p, int octaves, double persistence) const;

 private:
  uint8_t perm_[512];
};

/// Maps fBm to [0, 1] (0.5 + 0.5 * fbm, clamped).
double fbm01(const PerlinNoise& noise, const Vec3& p, int octaves, double persistence);

/// Throws InputError naming `prefix` + field when a NoiseOptions value is out of range:
/// frequency finite > 0, octaves 1..12, persistence (0, 1], amount [0, 1].
void validateNoiseOptions(const NoiseOptions& options, const std::string& prefix);

}  // namespace cloudbake
