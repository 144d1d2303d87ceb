#include "core/job/cache_key.h"

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <tuple>

#include "core/job/sha256.h"
#include "core/methods/common.h"
#include "core/methods/registry.h"
#include "core/methods/versions.h"
#include "core/shot/shot_parser.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
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
// A file stands in a key for its content and for how it is read: readers choose the format by
// the name's extension (a mesh's .obj or .ply), so the same bytes under another extension are
// another input (PLY bytes named m.obj fail to read, and must not hit the cache of m.ply).
void replaceFilesByHashes(Json& j) {
  if (j.is_object() || j.is_array()) {
    for (auto& child : j) replaceFilesByHashes(child);
  } else if (j.is_string()) {
    const std::string s = j.get<std::string>();
    if (!s.empty() && s[0] == '/') {
      const std::string hash = fileHashMemo(s);
      std::string ext = fs::path(s).extension().string();
      std::transform(ext.begin(), ext.end(), ext.begin(),
                     [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
      if (!hash.empty()) j = "sha256:" + hash + " read as '" + ext + "'";
    }
  }
}

std::string keyOf(const char* kind, const Json& material) {
  return sha256Hex(std::string("cloudbake/") + kind + "\n" + material.dump());
}

Json directionJson(const Vec3& direction) {
  const Vec3 d = quantiseDirection(direction);
  return {d.x, d.y, d.z};
}

// A key whose material lacks only the sun direction.
std::string keyAt(const char* kind, const std::string& material, const Vec3& direction) {
  Json m = Json::parse(material);
  m["sun_direction"] = directionJson(direction);
  return keyOf(kind, m);
}

}  // namespace

std::string algorithmSalt(const MethodInfo& info) {
  return info.name + "/" + std::to_string(info.version) + " " + sharedVersionSalt();
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
  const BakeMethod& method = methodOf(shot);
  const std::string salt = algorithmSalt(method.info());

  ShotCacheKeys keys;
  keys.volume = keyOf("volume", {{"volume", canonical["volume"]}, {"version", kVolumeVersion}});

  const Sky& sky = shot.lighting.sky;
  const bool sky_black = sky.type == Sky::Type::kConstant && sky.radiance.x == 0 &&
                         sky.radiance.y == 0 && sky.radiance.z == 0;
  const Rgb& e = shot.lighting.sun.irradiance;
  keys.sun_scaled = shot.lighting.has_sun && sky_black && (e.x > 0 || e.y > 0 || e.z > 0);

  // The whole computation without the sun direction: the family of bakes that differ only in
  // it (tolerance reuse), then the bake itself.
  const Json bake = {{"volume", keys.volume},
                     {"medium", canonical["medium"]},
                     {"sky", canonical["lighting"]["sky"]},
                     {"bake", canonical["bake"]},
                     {"algorithm", salt}};
  keys.bake_material = bake.dump();
  keys.family = keyOf("family", bake);
  if (shot.lighting.has_sun) {
    keys.bake = keyAt("bake", keys.bake_material, shot.lighting.sun.direction);
  } else {
    Json b = bake;
    b["sun_direction"] = nullptr;
    keys.bake = keyOf("bake", b);
  }

  // The shot name and method are in bake.vdb's metadata, so they are part of its key.
  keys.vdb = keyOf("vdb", {{"volume", keys.volume},
                           {"voxel_size", canonical["outputs"].value("vdb_voxel_size", 0.0)},
                           {"shot", shot.name},
                           {"algorithm", salt}});

  const Json parts = method.keyMaterial(shot, canonical);
  if (parts.contains("light")) {
    Json light = parts["light"];
    light["volume"] = keys.volume;
    light["algorithm"] = salt;
    keys.light_material = light.dump();
    keys.light_family = keyOf("light-family", light);
    keys.light = keyAt("light", keys.light_material, sunDirection(shot));
  }
  if (parts.contains("precompute")) {
    Json pre = parts["precompute"];
    pre["volume"] = keys.volume;
    pre["algorithm"] = salt;
    keys.precompute = keyOf("precompute", pre);
    // The database's parts, which farm tasks compute apart (RunScope); a whole run never
    // stores them.
    if (const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume)) {
      keys.precompute_layout = keyOf("precompute-layout", pre);
      for (int i = 0; i < seq->frames; ++i) {
        pre["basic_volume"] = i;
        keys.precompute_basic.push_back(keyOf("precompute-basic", pre));
      }
    }
  }

  for (const Json& view : canonical["views"]) {
    Json v = {{"camera", view["camera"]}, {"resolution", view["resolution"]}};
    if (!keys.sun_scaled && shot.lighting.has_sun) {
      v["sun_irradiance"] = canonical["lighting"]["sun"]["irradiance"];
    }
    keys.view_materials.push_back(v.dump());
    v["bake"] = keys.bake;
    keys.views.push_back(keyOf("view", v));
  }
  return keys;
}

std::string lightKeyAt(const ShotCacheKeys& keys, const Vec3& direction) {
  return keys.light_material.empty() ? "" : keyAt("light", keys.light_material, direction);
}

std::string viewKeyAt(const ShotCacheKeys& keys, size_t view, const Vec3& direction) {
  Json v = Json::parse(keys.view_materials.at(view));
  v["bake"] = keyAt("bake", keys.bake_material, direction);
  return keyOf("view", v);
}

}  // namespace cloudbake
