#include "core/transport/tracking.h"

#include <cmath>

namespace cloudbake {
namespace {

// Exponential free path with rate sigma from one uniform; 1 - u is in (0, 1], so the log is finite.
inline double freePath(double sigma, Rng& rng) { return -std::log(1.0 - rng.uniform()) / sigma; }

}  // namespace

Collision deltaTrack(const DensityField& field, DensityField::Lookup& lookup, double extinction,
                     const Ray& ray, double tmin, double tmax, Rng& rng) {
  Collision result;
  if (!(extinction > 0)) return result;
  field.majorants().traverse(ray, tmin, tmax, [&](double t0, double t1, float majorant) {
    const double sigma_maj = extinction * static_cast<double>(majorant);
    if (!(sigma_maj > 0)) return true;  // empty cell: skip it
    double t = t0;
    while (true) {
      t += freePath(sigma_maj, rng);
      if (!(t < t1)) return true;  // memoryless: restart in the next cell from its entry
      const Vec3 p = ray.at(t);
      const double sigma_t = extinction * lookup.density(p);
      if (rng.uniform() * sigma_maj < sigma_t) {
        result.hit = true;
        result.t = t;
        result.p = p;
        return false;
      }
    }
  });
  return result;
}

double ratioTrack(const DensityField& field, DensityField::Lookup& lookup, double extinction,
                  const Ray& ray, double tmin, double tmax, Rng& rng) {
  if (!(extinction > 0)) return 1.0;
  double T = 1.0;
  field.majorants().traverse(ray, tmin, tmax, [&](double t0, double t1, float majorant) {
    const double sigma_maj = extinction * static_cast<double>(majorant);
    if (!(sigma_maj > 0)) return true;
    double t = t0;
    while (true) {
      t += freePath(sigma_maj, rng);
      if (!(t < t1)) return true;
      const double sigma_t = extinction * lookup.density(ray.at(t));
      // A density above the majorant would make this negative; clamp to keep T in [0, 1].
      T *= std::max(0.0, 1.0 - sigma_t / sigma_maj);
      if (T < 0.1) {
        if (T <= 0 || rng.uniform() < 0.5) {
          T = 0;
          return false;
        }
        T *= 2.0;
      }
    }
  });
  return T;
}

}  // namespace cloudbake
