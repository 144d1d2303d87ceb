// A small in-memory LRU cache of immutable built objects, shared by the jobs of one server
// (density fields: VolumeCache; phase functions: PhaseCache).
#pragma once

#include <cstdint>
#include <exception>
#include <functional>
#include <future>
#include <list>
#include <map>
#include <mutex>
#include <string>

#include "core/error.h"

namespace cloudbake {

/// Keeps the `capacity` most recently used values by key. Values are immutable once built
/// (shared pointers to const objects), so sharing them across jobs is safe. Identical
/// concurrent builds share one (single flight); a failed build is not remembered.
template <class T>
class MemoryCache {
 public:
  explicit MemoryCache(size_t capacity = 8) : capacity_(capacity) {}

  T getOrBuild(const std::string& key, const std::function<T()>& build, bool* was_cached = nullptr);
  /// True when `key` is held (built or being built).
  bool contains(const std::string& key) const {
    std::lock_guard<std::mutex> lock(mutex_);
    return values_.count(key) > 0;
  }
  uint64_t builds() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return builds_;
  }
  uint64_t hits() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return hits_;
  }

 private:
  T getOrBuildOnce(const std::string& key, const std::function<T()>& build, bool* was_cached,
                   bool* is_leader);
  size_t capacity_;
  mutable std::mutex mutex_;
  std::list<std::string> lru_;  // front = most recent
  std::map<std::string, std::shared_future<T>> values_;
  uint64_t builds_ = 0, hits_ = 0;
};

// Implementation.

template <class T>
T MemoryCache<T>::getOrBuild(const std::string& key, const std::function<T()>& build,
                             bool* was_cached) {
  // The leader's cancellation is its own request's: a waiter then builds (or waits) afresh.
  for (;;) {
    bool leader = false;
    try {
      return getOrBuildOnce(key, build, was_cached, &leader);
    } catch (const Cancelled&) {
      if (leader) throw;
    }
  }
}

template <class T>
T MemoryCache<T>::getOrBuildOnce(const std::string& key, const std::function<T()>& build,
                                 bool* was_cached, bool* is_leader) {
  std::promise<T> promise;
  std::shared_future<T> future;
  bool& leader = *is_leader;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = values_.find(key);
    if (it != values_.end()) {
      future = it->second;
      lru_.remove(key);
      lru_.push_front(key);
      ++hits_;
    } else {
      future = promise.get_future().share();
      values_[key] = future;
      lru_.push_front(key);
      leader = true;
      ++builds_;
      while (capacity_ > 0 && lru_.size() > capacity_) {
        values_.erase(lru_.back());
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
      auto it = values_.find(key);
      if (it != values_.end()) {
        values_.erase(it);
        lru_.remove(key);
      }
    }
  }
  return future.get();
}

}  // namespace cloudbake
