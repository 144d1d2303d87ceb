#include "core/job/cache_key.h"

#include <sys/stat.h>

#include <cmath>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <tuple>

#include "core/animation/precomputed_io.h"
#include "core/job/sha256.h"
#include "core/shot/shot_parser.h"

namespace cloudbake {
namespace {
using Json = nlohmann::json;

// Hashing a large VDB on every submit would dominate small jobs, so hashes are memoised by
// (path, size, mtime): a file rewritten in place gets a new mtime and is hashed again.
std::string fileHashMemo(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return {};
  if (!S_ISREG(st.st_mode)) return {};
  using MemoKey = std::tuple<std::string, long long, long long, long long>;
  static std::mutex mutex;
  static std::map<MemoKey, std::string> memo;
  const MemoKey key{path, static_cast<long long>(st.st_size),
                    static_cast<long long>(st.st_mtim.tv_sec),
                    static_cast<long long>(st.st_mtim.tv_nsec)};
  {
    std::lock_guard<std::mutex> lock(mutex);
    auto it = memo.find(key);
    if (it != memo.end()) return it->second;
  }
  const std::string hash = sha256File(path);
  std::lock_guard<std::mutex> lock(mutex);
  if (memo.size() > 4096) memo.clear();
  memo[key] = hash;
  return hash;
}

// Paths in a canonical shot are absolute: replace each that names a regular file by the hash of
// its content, so the key follows the bytes, not where they were uploaded to.
void replaceFilesByHashes(Json& j) {
  if (j.is_object() || j.is_array()) {
    for (auto& child : j) replaceFilesByHashes(child);
  } else if (j.is_string()) {
    const std::string s = j.get<std::string>();
    if (!s.empty() && s[0] == '/') {
      const std::string hash = fileHashMemo(s);
      if (!hash.empty()) j = "sha256:" + hash;
    }
  }
}

std::string keyOf(const char* kind, const Json& material) {
  return sha256Hex(std::string("cloudbake/") + CLOUDBAKE_VERSION + "/" + kind + "\n" +
                   material.dump());
}

}  // namespace

bool bakesLight(const ShotSpec& shot) {
  return shot.bake.method == BakeSpec::Method::kSingle ||
         shot.bake.method == BakeSpec::Method::kPointcloud;
}

bool needsSky(const ShotSpec& shot) {
  const Sky& sky = shot.lighting.sky;
  switch (sky.type) {
    case Sky::Type::kConstant:
      return maxComponent(sky.radiance) > 0;
    case Sky::Type::kGradient:
      return maxComponent(sky.zenith) > 0 || maxComponent(sky.horizon) > 0 ||
             maxComponent(sky.ground) > 0;
    case Sky::Type::kMap:
      return sky.map_scale > 0;  // a map of zeros still bakes visibility: cheap and harmless
  }
  return true;
}

Vec3 quantiseDirection(const Vec3& direction) {
  const double len = length(direction);
  const Vec3 d = len > 0 ? direction / len : direction;
  auto q = [](double v) {
    const double r = std::round(v / kSunDirectionQuantum) * kSunDirectionQuantum;
    return r == 0 ? 0.0 : r;  // no -0 in keys
  };
  return {q(d.x), q(d.y), q(d.z)};
}

ShotCacheKeys computeCacheKeys(const ShotSpec& shot) {
  SerializeOptions so;
  so.name = false;
  so.outputs = true;
  so.views = true;
  Json canonical = Json::parse(serializeShot(shot, so));
  replaceFilesByHashes(canonical);

  ShotCacheKeys keys;
  keys.volume = keyOf("volume", canonical["volume"]);

  const Sky& sky = shot.lighting.sky;
  const bool sky_black = sky.type == Sky::Type::kConstant && sky.radiance.x == 0 &&
                         sky.radiance.y == 0 && sky.radiance.z == 0;
  const Rgb& e = shot.lighting.sun.irradiance;
  keys.sun_scaled = shot.lighting.has_sun && sky_black && (e.x > 0 || e.y > 0 || e.z > 0);

  Json bake;
  bake["volume"] = keys.volume;
  bake["medium"] = canonical["medium"];
  bake["sky"] = canonical["lighting"]["sky"];
  keys.family = keyOf("family", bake);
  if (shot.lighting.has_sun) {
    const Vec3 d = quantiseDirection(shot.lighting.sun.direction);
    bake["sun_direction"] = {d.x, d.y, d.z};
  } else {
    bake["sun_direction"] = nullptr;
  }
  bake["bake"] = canonical["bake"];
  keys.bake = keyOf("bake", bake);

  Json vdb = {{"volume", keys.volume},
              {"voxel_size", canonical["outputs"].value("vdb_voxel_size", 0.0)}};
  keys.vdb = keyOf("vdb", vdb);

  if (bakesLight(shot)) {
    Json light;
    light["volume"] = keys.volume;
    if (shot.bake.method == BakeSpec::Method::kSingle) {
      light["extinction"] = canonical["medium"]["extinction"];
    } else {
      light["medium"] = canonical["medium"];
      light["seed"] = shot.bake.seed;
    }
    light["sky"] = needsSky(shot);
    light["method"] = methodName(shot.bake.method);
    Json knobs = Json::parse(shot.bake.options_json);
    knobs.erase("step");
    light["knobs"] = knobs;
    keys.light_family = keyOf("light-family", light);
    const Vec3 d =
        quantiseDirection(shot.lighting.has_sun ? shot.lighting.sun.direction : Vec3(0, 0, 1));
    light["sun_direction"] = {d.x, d.y, d.z};
    keys.light = keyOf("light", light);
  }

  if (shot.bake.method == BakeSpec::Method::kPrecomputed) {
    const Json knobs = Json::parse(shot.bake.options_json);
    Json pre;
    pre["volume"] = keys.volume;
    pre["extinction"] = canonical["medium"]["extinction"];
    pre["seed"] = shot.bake.seed;
    pre["file_version"] = kPrecomputedFileVersion;
    for (const char* k :
         {"light_resolution", "sample_points", "transfer_resolution", "cut_error"}) {
      pre[k] = knobs.contains(k) ? knobs[k] : Json(nullptr);
    }
    keys.precompute = keyOf("precompute", pre);
  }

  for (const Json& view : canonical["views"]) {
    Json v = {{"bake", keys.bake}, {"camera", view["camera"]}, {"resolution", view["resolution"]}};
    if (!keys.sun_scaled && shot.lighting.has_sun) {
      v["sun_irradiance"] = canonical["lighting"]["sun"]["irradiance"];
    }
    keys.views.push_back(keyOf("view", v));
  }
  return keys;
}

}  // namespace cloudbake
