#include "core/animation/basic_volumes.h"

#include <cmath>
#include <sstream>

#include "core/bake/bake_lattice.h"
#include "core/error.h"

namespace cloudbake {
namespace {

std::string frameName(const VolumeFrames& frames, int i) {
  return frames.name ? frames.name(i) : "frame " + std::to_string(i);
}

}  // namespace

BasicVolumeDatabase buildBasicVolumes(const VolumeFrames& frames, int resolution,
                                      const std::function<bool(double)>& progress) {
  if (frames.count < 2) {
    throw InputError("basic volumes: an endless animation needs at least 2, got " +
                     std::to_string(frames.count));
  }
  // Every frame is built twice (bounds, then resampling) rather than all kept at once: the
  // database holds the dense lattices only.
  Bounds3 bounds;
  double voxel = 0;
  for (int i = 0; i < frames.count; ++i) {
    const DensityFieldPtr f = frames.build(i);
    const Bounds3 b = f->bounds();
    bounds.expand(b.min);
    bounds.expand(b.max);
    if (frames.same_voxel_size) {
      if (i == 0) voxel = f->featureSize();
      if (std::abs(f->featureSize() - voxel) > 1e-9 * voxel) {
        std::ostringstream os;
        os << frameName(frames, i) << ": voxel size " << f->featureSize()
           << " differs from frame 0's " << voxel << " (basic volumes share one transform)";
        throw InputError(os.str());
      }
    }
    if (progress && !progress(0.5 * (i + 1) / frames.count)) throw Cancelled();
  }
  BasicVolumeDatabase db;
  for (int i = 0; i < frames.count; ++i) {
    const DensityFieldPtr f = frames.build(i);
    BakedLight lattice = makeBakeLatticeOver(*f, bounds, resolution);
    if (i == 0) db.grid = lattice.grid;
    db.frames.push_back(std::move(lattice.density));
    if (progress && !progress(0.5 + 0.5 * (i + 1) / frames.count)) throw Cancelled();
  }
  return db;
}

}  // namespace cloudbake
