#include "core/job/volume_cache.h"

#include <algorithm>
#include <exception>

namespace cloudbake {

DensityFieldPtr VolumeCache::getOrBuild(const std::string& key,
                                        const std::function<DensityFieldPtr()>& build,
                                        bool* was_cached) {
  std::promise<DensityFieldPtr> promise;
  std::shared_future<DensityFieldPtr> future;
  bool leader = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = fields_.find(key);
    if (it != fields_.end()) {
      future = it->second;
      lru_.remove(key);
      lru_.push_front(key);
      ++hits_;
    } else {
      future = promise.get_future().share();
      fields_[key] = future;
      lru_.push_front(key);
      leader = true;
      ++builds_;
      while (capacity_ > 0 && lru_.size() > capacity_) {
        fields_.erase(lru_.back());
        lru_.pop_back();
      }
    }
  }
  if (was_cached) *was_cached = !leader;
  if (leader) {
    try {
      promise.set_value(build());
    } catch (...) {
      promise.set_exception(std::current_exception());
      std::lock_guard<std::mutex> lock(mutex_);
      auto it = fields_.find(key);
      if (it != fields_.end()) {
        fields_.erase(it);
        lru_.remove(key);
      }
    }
  }
  return future.get();
}

uint64_t VolumeCache::builds() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return builds_;
}

uint64_t VolumeCache::hits() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return hits_;
}

}  // namespace cloudbake
