#include "core/volume/noise.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/math/rng.h"

namespace cloudbake {
namespace {

double fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }
double lerp(double t, double a, double b) { return a + t * (b - a); }

// Dot product with one of the 12 cube-edge gradients (Perlin 2002).
double grad(int hash, double x, double y, double z) {
  const int h = hash & 15;
  const double u = h < 8 ? x : y;
  const double v = h < 4 ? y : (h == 12 || h == 14 ? x : z);
  return ((h & 1) ? -u : u) + ((h & 2) ? -v : v);
}

}  // namespace

PerlinNoise::PerlinNoise(uint64_t seed) {
  Rng rng(mixBits(seed), mixBits(seed, 0x5eed));
  for (int i = 0; i < 256; ++i) perm_[i] = static_cast<uint8_t>(i);
  for (int i = 255; i > 0; --i) {
    const int j = static_cast<int>(rng.nextU32() % static_cast<uint32_t>(i + 1));
    std::swap(perm_[i], perm_[j]);
  }
  for (int i = 0; i < 256; ++i) perm_[256 + i] = perm_[i];
}

double PerlinNoise::noise(const Vec3& p) const {
  const double fx = std::floor(p.x), fy = std::floor(p.y), fz = std::floor(p.z);
  const int X = static_cast<int>(static_cast<int64_t>(fx) & 255);
  const int Y = static_cast<int>(static_cast<int64_t>(fy) & 255);
  const int Z = static_cast<int>(static_cast<int64_t>(fz) & 255);
  const double x = p.x - fx, y = p.y - fy, z = p.z - fz;
  const double u = fade(x), v = fade(y), w = fade(z);
  const int A = perm_[X] + Y, AA = perm_[A] + Z, AB = perm_[A + 1] + Z;
  const int B = perm_[X + 1] + Y, BA = perm_[B] + Z, BB = perm_[B + 1] + Z;
  return lerp(
      w,
      lerp(v, lerp(u, grad(perm_[AA], x, y, z), grad(perm_[BA], x - 1, y, z)),
           lerp(u, grad(perm_[AB], x, y - 1, z), grad(perm_[BB], x - 1, y - 1, z))),
      lerp(
          v, lerp(u, grad(perm_[AA + 1], x, y, z - 1), grad(perm_[BA + 1], x - 1, y, z - 1)),
          lerp(u, grad(perm_[AB + 1], x, y - 1, z - 1), grad(perm_[BB + 1], x - 1, y - 1, z - 1))));
}

double PerlinNoise::fbm(const Vec3& p, int octaves, double persistence) const {
  double sum = 0, amplitude = 1, norm = 0, scale = 1;
  for (int o = 0; o < octaves; ++o) {
    // Offset each octave so lattice zeros of different octaves do not line up.
    sum += amplitude * noise(p * scale + Vec3(17.31 * o, 5.77 * o, 11.13 * o));
    norm += amplitude;
    amplitude *= persistence;
    scale *= 2;
  }
  return norm > 0 ? sum / norm : 0.0;
}

double fbm01(const PerlinNoise& noise, const Vec3& p, int octaves, double persistence) {
  return std::clamp(0.5 + 0.5 * noise.fbm(p, octaves, persistence), 0.0, 1.0);
}

void validateNoiseOptions(const NoiseOptions& o, const std::string& prefix) {
  auto fail = [&](const char* field, const char* rule, double got) {
    std::ostringstream os;
    os << prefix << field << ": must be " << rule << ", got " << got;
    throw InputError(os.str());
  };
  if (!std::isfinite(o.frequency) || o.frequency <= 0 || o.frequency > 1e6)
    fail("frequency", "finite and in (0, 1e6]", o.frequency);
  if (o.octaves < 1 || o.octaves > 12) fail("octaves", "in [1, 12]", o.octaves);
  if (!(o.persistence > 0 && o.persistence <= 1)) fail("persistence", "in (0, 1]", o.persistence);
  if (!(o.amount >= 0 && o.amount <= 1)) fail("amount", "in [0, 1]", o.amount);
}

}  // namespace cloudbake
