#include "core/job/direction_index.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "common/json_limits.h"
#include "core/job/file_util.h"

namespace cloudbake {
namespace fs = std::filesystem;
using Json = nlohmann::json;

double angleDeg(const Vec3& a, const Vec3& b) {
  const double c = dot(a, b) / (length(a) * length(b));
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / kPi;
}

DirectionIndex::DirectionIndex(std::string root) : root_(std::move(root)) {
  fs::create_directories(root_);
}

std::vector<Vec3> DirectionIndex::loadLocked(const std::string& family) const {
  auto it = memo_.find(family);
  if (it != memo_.end()) return it->second;
  std::vector<Vec3> dirs;
  try {
    const std::string file = (fs::path(root_) / (family + ".json")).string();
    for (const Json& d : parseJsonLimited(readWholeFile(file), file)) {
      dirs.push_back({d.at(0).get<double>(), d.at(1).get<double>(), d.at(2).get<double>()});
    }
  } catch (const std::exception&) {
    dirs.clear();  // none yet, or unreadable: an index is only a hint
  }
  memo_[family] = dirs;
  return dirs;
}

void DirectionIndex::add(const std::string& family, const Vec3& direction) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<Vec3> dirs = loadLocked(family);
  for (const Vec3& d : dirs) {
    if (d.x == direction.x && d.y == direction.y && d.z == direction.z) return;
  }
  dirs.push_back(direction);
  Json j = Json::array();
  for (const Vec3& d : dirs) j.push_back({d.x, d.y, d.z});
  writeFileAtomic((fs::path(root_) / (family + ".json")).string(), j.dump());
  memo_[family] = dirs;
}

std::vector<Vec3> DirectionIndex::near(const std::string& family, const Vec3& direction,
                                       double tolerance_deg) const {
  std::vector<std::pair<double, Vec3>> found;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const Vec3& d : loadLocked(family)) {
      const double a = angleDeg(d, direction);
      if (a <= tolerance_deg) found.emplace_back(a, d);
    }
  }
  std::sort(found.begin(), found.end(),
            [](const auto& x, const auto& y) { return x.first < y.first; });
  std::vector<Vec3> out;
  for (const auto& f : found) out.push_back(f.second);
  return out;
}

}  // namespace cloudbake
