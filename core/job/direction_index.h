// Which sun directions have been baked for a family of otherwise identical bakes, so a request
// may reuse a bake whose light direction lies within a tolerance (off unless asked for).
#pragma once

#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "core/math/vec3.h"

namespace cloudbake {

/// Angle in degrees between two non-zero directions.
double angleDeg(const Vec3& a, const Vec3& b);

/// ROOT/<family>.json: the quantised directions baked for that family (ShotCacheKeys::family),
/// rewritten atomically on every addition. Entries can outlive their cache entries (eviction);
/// callers check the cache for each candidate. Thread safe.
class DirectionIndex {
 public:
  explicit DirectionIndex(std::string root);
  void add(const std::string& family, const Vec3& direction);
  /// Known directions of `family` within `tolerance_deg` of `direction`, closest first.
  std::vector<Vec3> near(const std::string& family, const Vec3& direction,
                         double tolerance_deg) const;

 private:
  std::vector<Vec3> loadLocked(const std::string& family) const;
  std::string root_;
  mutable std::mutex mutex_;
  mutable std::map<std::string, std::vector<Vec3>> memo_;
};

}  // namespace cloudbake
