// In-memory cache of built density fields, so resubmitting a shot (another view, another sun
// colour) does not parse and voxelise its volume again.
#pragma once

#include <cstdint>
#include <functional>
#include <future>
#include <list>
#include <map>
#include <mutex>
#include <string>

#include "core/volume/density_field.h"

namespace cloudbake {

/// Keeps the `capacity` most recently used fields by volume key (ShotCacheKeys::volume). A
/// field is immutable once built, so sharing the pointer across jobs is safe. Identical
/// concurrent builds share one (single flight); a failed build is not remembered.
class VolumeCache {
 public:
  explicit VolumeCache(size_t capacity = 8) : capacity_(capacity) {}
  DensityFieldPtr getOrBuild(const std::string& key, const std::function<DensityFieldPtr()>& build,
                             bool* was_cached = nullptr);
  uint64_t builds() const;
  uint64_t hits() const;

 private:
  size_t capacity_;
  mutable std::mutex mutex_;
  std::list<std::string> lru_;  // front = most recent
  std::map<std::string, std::shared_future<DensityFieldPtr>> fields_;
  uint64_t builds_ = 0, hits_ = 0;
};

}  // namespace cloudbake
