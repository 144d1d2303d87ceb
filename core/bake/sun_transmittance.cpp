#include "core/bake/sun_transmittance.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>

#include "core/error.h"

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
  std::atomic<bool> cancelled{false};
  std::atomic<int> slices_done{0};
  // Slices in small batches so progress (and cancellation) is reported about every second even
  // for large lattices; the per-voxel results do not depend on the batching.
  const int batch = 4;
  for (int k0 = 0; k0 < g.nz && !cancelled; k0 += batch) {
    const int k1 = std::min(g.nz, k0 + batch);
    tbb::parallel_for(tbb::blocked_range<int>(k0, k1), [&](const tbb::blocked_range<int>& r) {
      for (int k = r.begin(); k != r.end(); ++k) {
        for (int j = 0; j < g.ny; ++j) {
          for (int i = 0; i < g.nx; ++i) {
            if (!support[g.index(i, j, k)]) continue;
            t.data[g.index(i, j, k)] =
                float(marchTransmittance(g, rho, extinction, g.center(i, j, k), sun_dir, step));
          }
        }
      }
      slices_done += int(r.size());
    });
    if (progress && !progress(double(slices_done) / g.nz, "sun transmittance")) cancelled = true;
  }
  if (cancelled) throw Cancelled("bake cancelled while computing the sun transmittance");
}

}  // namespace cloudbake
