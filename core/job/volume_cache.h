// In-memory cache of built density fields, so resubmitting a shot (another view, another sun
// colour) does not parse and voxelise its volume again.
#pragma once

#include "core/job/memory_cache.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// Keeps the `capacity` most recently used fields by volume key (ShotCacheKeys::volume); see
/// MemoryCache.
class VolumeCache : public MemoryCache<DensityFieldPtr> {
 public:
  using MemoryCache<DensityFieldPtr>::MemoryCache;
};

}  // namespace cloudbake
