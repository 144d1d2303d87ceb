#include "core/bake/single_bake.h"

#include <chrono>
#include <cmath>
#include <string>

#include "core/bake/bake_lattice.h"
#include "core/bake/sky_visibility.h"
#include "core/bake/sun_transmittance.h"
#include "core/error.h"
#include "core/format.h"

namespace cloudbake {

BakedLight bakeSingle(const Medium& medium, const Vec3& sun_dir, const SingleBakeOptions& options,
                      const BakeProgressFn& progress) {
  if (!medium.density) throw InputError("medium: no density field");
  if (!std::isfinite(medium.extinction) || medium.extinction < 0) {
    throw InputError("medium.extinction: must be finite and >= 0, got " + str(medium.extinction));
  }
  if (!isFinite(sun_dir) || std::abs(length(sun_dir) - 1) > 1e-6) {
    throw InputError("lighting.sun.direction: must be a unit vector");
  }
  if (!(options.step >= 0) || !std::isfinite(options.step)) {
    throw InputError("step: must be finite and >= 0 (0: half a lattice voxel), got " +
                     str(options.step));
  }
  using Clock = std::chrono::steady_clock;
  // Stage weights for the overall fraction: the sky sweeps cost about as much as the sun march.
  const double w_sun = options.sky ? 0.5 : 0.9;
  auto stage = [&](double lo, double span) -> BakeProgressFn {
    return [&, lo, span](double f, const std::string& name) {
      return !progress || progress(lo + span * f, name);
    };
  };
  if (progress && !progress(0, "lattice")) throw Cancelled("bake cancelled");
  auto t0 = Clock::now();
  BakedLight bake =
      makeBakeLattice(*medium.density, options.light_resolution, LatticeSampling::kFieldAligned);
  bake.metadata["cloudbake:seconds_lattice"] = str(secondsSince(t0));
  bake.method = "single";
  bake.sun_direction = sun_dir;
  t0 = Clock::now();
  computeSunTransmittance(bake, sun_dir, medium.extinction, stage(0.1, w_sun));
  bake.metadata["cloudbake:seconds_sun_transmittance"] = str(secondsSince(t0));
  if (options.sky) {
    t0 = Clock::now();
    computeSkyVisibility(bake, medium.extinction, stage(0.1 + w_sun, 0.9 - w_sun), true);
    bake.metadata["cloudbake:seconds_sky_visibility"] = str(secondsSince(t0));
  }
  // Cd: the isotropic preview (grey: direct sun only, since single models no multiple scattering).
  bake.addMeanRadiance();
  bake.metadata["cloudbake:extinction"] = str(medium.extinction);
  bake.metadata["cloudbake:sky"] = options.sky ? "baked" : "skipped (black sky)";
  bake.trimToSupport();
  if (progress && !progress(1, "done")) throw Cancelled("bake cancelled");
  return bake;
}

}  // namespace cloudbake
