#include "core/animation/basic_volumes.h"

#include <cmath>
#include <sstream>

#include "core/bake/bake_lattice.h"
#include "core/error.h"
#include "core/shot/scene_builder.h"

namespace cloudbake {

BasicVolumeDatabase buildBasicVolumes(const SequenceVolumeSpec& sequence, int resolution,
                                      const std::string& source,
                                      const std::function<bool(double)>& progress) {
  if (sequence.frames < 2) {
    throw InputError(source + ": /volume/sequence/frames: an endless animation needs at least 2 " +
                     "basic volumes, got " + std::to_string(sequence.frames));
  }
  // Every frame is built twice (bounds, then resampling) rather than all kept at once: the
  // database holds the dense lattices only.
  Bounds3 bounds;
  double voxel = 0;
  for (int i = 0; i < sequence.frames; ++i) {
    const DensityFieldPtr f = buildSequenceFrame(sequence, i, source);
    const Bounds3 b = f->bounds();
    bounds.expand(b.min);
    bounds.expand(b.max);
    if (!sequence.paths.empty()) {
      if (i == 0) voxel = f->featureSize();
      if (std::abs(f->featureSize() - voxel) > 1e-9 * voxel) {
        std::ostringstream os;
        os << source << ": /volume/sequence/paths/" << i << ": voxel size " << f->featureSize()
           << " differs from frame 0's " << voxel << " (basic volumes share one transform)";
        throw InputError(os.str());
      }
    }
    if (progress && !progress(0.5 * (i + 1) / sequence.frames)) throw Cancelled();
  }
  BasicVolumeDatabase db;
  for (int i = 0; i < sequence.frames; ++i) {
    const DensityFieldPtr f = buildSequenceFrame(sequence, i, source);
    BakedLight lattice = makeBakeLatticeOver(*f, bounds, resolution);
    if (i == 0) db.grid = lattice.grid;
    db.frames.push_back(std::move(lattice.density));
    if (progress && !progress(0.5 + 0.5 * (i + 1) / sequence.frames)) throw Cancelled();
  }
  return db;
}

}  // namespace cloudbake
