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
/// The same over the cells of `grid` (its minorants unused).
Collision deltaTrack(const MajorantGrid& grid, DensityField::Lookup& lookup, double extinction,
                     const Ray& ray, double tmin, double tmax, Rng& rng);

/// Ratio tracking (Cramer 1978; Novak et al. 2014): an unbiased estimate of the transmittance
/// T = exp(-integral of sigma_t) along `ray` over [tmin, tmax], the product of
/// (1 - sigma_t / sigma_maj) over tentative collisions. Once the running estimate falls below
/// 0.1 it is Russian-rouletted (survival 0.5, weight 2), which stays unbiased and ends walks
/// through thick media early; in a homogeneous cell the first tentative collision gives 0.
double ratioTrack(const DensityField& field, DensityField::Lookup& lookup, double extinction,
                  const Ray& ray, double tmin, double tmax, Rng& rng);
/// The same over the cells of `grid` (its minorants unused).
double ratioTrack(const MajorantGrid& grid, DensityField::Lookup& lookup, double extinction,
                  const Ray& ray, double tmin, double tmax, Rng& rng);

/// Decomposition tracking (Kutz et al. 2017): the medium is split per cell of `grid` into a
/// homogeneous control part sigma_c = extinction x minorant and a residual of at most
/// sigma_r = extinction x (majorant - minorant). Collisions of the control part are real and
/// need no lookup; tentative collisions of the residual part, at rate sigma_r, are real with
/// probability (sigma_t(x) - sigma_c) / sigma_r. The first of the two processes is distributed
/// exactly as delta tracking's collision, with sigma_r instead of sigma_maj lookups per unit
/// length. Optical depths carry across cells (one exponential draw per event, not per cell).
/// Without minorants it is delta tracking (another use of the random numbers).
Collision decompositionTrack(const MajorantGrid& grid, DensityField::Lookup& lookup,
                             double extinction, const Ray& ray, double tmin, double tmax, Rng& rng);

/// Residual ratio tracking (Novak et al. 2014) with the grid's minorants as control:
/// T = exp(-integral sigma_c) x the ratio-tracking estimate of the residual's transmittance,
/// whose tentative collisions (rate sigma_r) each multiply by 1 - (sigma_t(x) - sigma_c) /
/// sigma_r. Unbiased, with sigma_r instead of sigma_maj lookups per unit length. Once the
/// estimate falls below 0.1 it is Russian-rouletted with survival T / 0.1 (weight back to
/// 0.1), so walks through thick media end after a few optical depths.
double residualRatioTrack(const MajorantGrid& grid, DensityField::Lookup& lookup, double extinction,
                          const Ray& ray, double tmin, double tmax, Rng& rng);

}  // namespace cloudbake
