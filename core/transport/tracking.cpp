#include "core/transport/tracking.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cloudbake {
namespace {

// Exponential free path with rate sigma from one uniform; 1 - u is in (0, 1], so the log is finite.
inline double freePath(double sigma, Rng& rng) { return -std::log(1.0 - rng.uniform()) / sigma; }

// An exponential optical depth (mean 1), finite for the same reason.
inline double opticalDepth(Rng& rng) { return -std::log(1.0 - rng.uniform()); }

constexpr double kInf = std::numeric_limits<double>::infinity();
// Residual ratio tracking's roulette: below this estimate, survive with probability T / it.
constexpr double kRouletteBelow = 0.1;

// Russian roulette of a transmittance estimate: false when the walk ends (T set to 0).
inline bool rouletteTransmittance(double& T, Rng& rng) {
  if (T >= kRouletteBelow) return true;
  if (T <= 0 || !(rng.uniform() * kRouletteBelow < T)) {
    T = 0;
    return false;
  }
  T = kRouletteBelow;
  return true;
}

}  // namespace

Collision deltaTrack(const DensityField& field, DensityField::Lookup& lookup, double extinction,
                     const Ray& ray, double tmin, double tmax, Rng& rng) {
  return deltaTrack(field.majorants(), lookup, extinction, ray, tmin, tmax, rng);
}

Collision deltaTrack(const MajorantGrid& grid, DensityField::Lookup& lookup, double extinction,
                     const Ray& ray, double tmin, double tmax, Rng& rng) {
  Collision result;
  if (!(extinction > 0)) return result;
  grid.traverse(ray, tmin, tmax, [&](double t0, double t1, float majorant) {
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
  return ratioTrack(field.majorants(), lookup, extinction, ray, tmin, tmax, rng);
}

double ratioTrack(const MajorantGrid& grid, DensityField::Lookup& lookup, double extinction,
                  const Ray& ray, double tmin, double tmax, Rng& rng) {
  if (!(extinction > 0)) return 1.0;
  double T = 1.0;
  grid.traverse(ray, tmin, tmax, [&](double t0, double t1, float majorant) {
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

Collision decompositionTrack(const MajorantGrid& grid, DensityField::Lookup& lookup,
                             double extinction, const Ray& ray, double tmin, double tmax,
                             Rng& rng) {
  Collision result;
  if (!(extinction > 0)) return result;
  // Optical depths still to go to the next control collision and the next tentative residual
  // collision; both processes are memoryless, so what is left carries into the next cell.
  double tau_c = opticalDepth(rng), tau_r = opticalDepth(rng);
  grid.traverseBounds(ray, tmin, tmax, [&](double t0, double t1, float maj, float min) {
    const double sigma_c = extinction * double(min);
    const double sigma_r = extinction * (double(maj) - double(min));
    const double t_c = sigma_c > 0 ? t0 + tau_c / sigma_c : kInf;
    double t = t0;
    while (true) {
      const double t_r = sigma_r > 0 ? t + tau_r / sigma_r : kInf;
      if (t_c <= t_r && t_c < t1) {  // the control part collides first: real, no lookup
        result = {true, t_c, ray.at(t_c)};
        return false;
      }
      if (!(t_r < t1)) {
        tau_c = std::max(0.0, tau_c - sigma_c * (t1 - t0));
        tau_r = std::max(0.0, tau_r - sigma_r * (t1 - t));
        return true;
      }
      t = t_r;
      tau_r = opticalDepth(rng);
      const Vec3 p = ray.at(t);
      const double sigma_t = extinction * lookup.density(p);
      if (rng.uniform() * sigma_r < sigma_t - sigma_c) {
        result = {true, t, p};
        return false;
      }
    }
  });
  return result;
}

double residualRatioTrack(const MajorantGrid& grid, DensityField::Lookup& lookup, double extinction,
                          const Ray& ray, double tmin, double tmax, Rng& rng) {
  if (!(extinction > 0)) return 1.0;
  double T = 1.0;
  double tau_r = opticalDepth(rng);
  grid.traverseBounds(ray, tmin, tmax, [&](double t0, double t1, float maj, float min) {
    const double sigma_c = extinction * double(min);
    const double sigma_r = extinction * (double(maj) - double(min));
    if (sigma_r > 0) {
      double t = t0;
      while (true) {
        const double t_r = t + tau_r / sigma_r;
        if (!(t_r < t1)) {
          tau_r = std::max(0.0, tau_r - sigma_r * (t1 - t));
          break;
        }
        t = t_r;
        tau_r = opticalDepth(rng);
        const double sigma_t = extinction * lookup.density(ray.at(t));
        // Rounding can put a lookup a hair outside [min, max]: keep the factor in [0, 1].
        T *= std::clamp(1.0 - (sigma_t - sigma_c) / sigma_r, 0.0, 1.0);
        if (!rouletteTransmittance(T, rng)) return false;
      }
    }
    if (sigma_c > 0) {
      T *= std::exp(-sigma_c * (t1 - t0));
      if (!rouletteTransmittance(T, rng)) return false;
    }
    return true;
  });
  return T;
}

}  // namespace cloudbake
