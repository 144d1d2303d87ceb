#include "core/bake/sun_transmittance.h"

#include <cmath>

#include "core/error.h"
#include "core/math/parallel.h"

namespace cloudbake {

void computeSunTransmittance(BakedLight& bake, const Vec3& sun_dir, double extinction,
                             const BakeProgressFn& progress) {
  const BakeGrid& g = bake.grid;
  if (!(std::abs(length(sun_dir) - 1) < 1e-6)) {
    throw InputError("sun direction: must be a unit vector");
  }
  BakeChannel& t = bake.add(bake_grids::kSunTransmittance, 1);
  const float* rho = bake.density.data();
  const std::vector<uint8_t> support = densitySupport(g, bake.density);
  const double step = 0.5 * g.voxel_size;
  const TransmittanceMarcher march(g, rho, extinction);
  ParallelOptions slices;  // one slice per chunk: cancellation within about a second
  if (progress) {
    slices.cancelled = [&](double f) { return !progress(f, "sun transmittance"); };
  }
  slices.cancelled_message = "bake cancelled while computing the sun transmittance";
  parallelFor(
      0, g.nz,
      [&](int k) {
        for (int j = 0; j < g.ny; ++j) {
          for (int i = 0; i < g.nx; ++i) {
            if (!support[g.index(i, j, k)]) continue;
            t.data[g.index(i, j, k)] = float(march(g.center(i, j, k), sun_dir, step));
          }
        }
      },
      slices);
}

}  // namespace cloudbake
