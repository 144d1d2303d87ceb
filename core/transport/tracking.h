// Free-path sampling and transmittance estimation in a heterogeneous medium.
#pragma once

#include "core/math/rng.h"
#include "core/math/vec3.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// Result of delta tracking: the first real collision along a ray, if any.
struct Collision {
  bool hit = false;  ///< false: the ray left the medium (or reached tmax) without colliding
  double t = 0;      ///< ray parameter of the collision (world units for a unit direction)
  Vec3 p;            ///< collision position
};

/// Delta (Woodcock) tracking (Woodcock et al. 1965; Kutz et al. 2017) over the segments of
/// field.majorants().traverse(): within each cell sigma_maj = extinction * cell majorant; tentative
/// collisions are accepted as real with probability sigma_t(x) / sigma_maj. The returned
/// collision is distributed exactly as the first real collision (density sigma_t T), and
/// `hit == false` has probability T(tmin, tmax), so the indicator is an unbiased transmittance
/// estimate. `ray.d` must be unit length; `lookup` belongs to the calling thread.
Collision deltaTrack(const DensityField& field, DensityField::Lookup& lookup, double extinction,
                     const Ray& ray, double tmin, double tmax, Rng& rng);

/// Ratio tracking (Cramer 1978; Novak et al. 2014): an unbiased estimate of the transmittance
/// T = exp(-integral of sigma_t) along `ray` over [tmin, tmax], the product of
/// (1 - sigma_t / sigma_maj) over tentative collisions. Once the running estimate falls below
/// 0.1 it is Russian-rouletted (survival 0.5, weight 2), which stays unbiased and ends walks
/// through thick media early; in a homogeneous cell the first tentative collision gives 0.
double ratioTrack(const DensityField& field, DensityField::Lookup& lookup, double extinction,
                  const Ray& ray, double tmin, double tmax, Rng& rng);

}  // namespace cloudbake
