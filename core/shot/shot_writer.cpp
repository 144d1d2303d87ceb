// Canonical JSON form of a ShotSpec (the cache key text and the round-trip form).
#include <nlohmann/json.hpp>
#include <type_traits>

#include "core/shot/shot_parser.h"

namespace cloudbake {
namespace {
using Json = nlohmann::json;

// -0.0 and 0.0 parse to equal specs; write both as 0 so they hash the same.
double canon(double v) { return v == 0.0 ? 0.0 : v; }
Json vec(const Vec3& v) { return Json::array({canon(v.x), canon(v.y), canon(v.z)}); }

Json proceduralJson(const ProceduralVolumeSpec& p) {
  const PerlinCloudOptions& c = p.perlin;
  return {{"type", p.type},
          {"seed", c.seed},
          {"center", vec(c.center)},
          {"size", vec(c.size)},
          {"resolution", c.resolution},
          {"cover", canon(c.cover)},
          {"sharpness", c.sharpness},
          {"density", canon(c.density)},
          {"octaves", c.octaves},
          {"frequency", c.frequency},
          {"persistence", c.persistence}};
}

// With the cloud time only when it is not 0, so static clouds keep their canonical form.
Json proceduralJsonWithTime(const ProceduralVolumeSpec& p) {
  Json j = proceduralJson(p);
  if (p.perlin.time != 0) j["time"] = p.perlin.time;
  return j;
}

Json volumeJson(const VolumeSpec& volume) {
  return std::visit(
      [](const auto& v) -> Json {
        using T = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<T, BoxVolumeSpec>) {
          return {
              {"box", {{"min", vec(v.min)}, {"max", vec(v.max)}, {"density", canon(v.density)}}}};
        } else if constexpr (std::is_same_v<T, SphereVolumeSpec>) {
          return {
              {"sphere",
               {{"center", vec(v.center)}, {"radius", v.radius}, {"density", canon(v.density)}}}};
        } else if constexpr (std::is_same_v<T, VdbVolumeSpec>) {
          return {{"vdb", {{"path", v.path}, {"grid", v.grid}}}};
        } else if constexpr (std::is_same_v<T, MeshVolumeSpec>) {
          Json m = {{"path", v.path}, {"density", canon(v.density)}};
          if (v.resolution > 0) {
            m["resolution"] = v.resolution;
          } else {
            m["voxel_size"] = v.voxel_size;
          }
          if (v.noise_enabled) {
            m["noise"] = {{"frequency", v.noise.frequency},
                          {"octaves", v.noise.octaves},
                          {"persistence", v.noise.persistence},
                          {"amount", canon(v.noise.amount)},
                          {"seed", v.noise.seed}};
          }
          return {{"mesh", m}};
        } else if constexpr (std::is_same_v<T, ProceduralVolumeSpec>) {
          return {{"procedural", proceduralJsonWithTime(v)}};
        } else {
          Json s = {{"frames", v.frames}};
          if (v.procedural) {
            s["procedural"] = proceduralJsonWithTime(*v.procedural);
            s["time_step"] = v.time_step;
          } else {
            s["paths"] = v.paths;
            s["grid"] = v.grid;
          }
          return {{"sequence", s}};
        }
      },
      volume);
}

Json phaseTypeJson(const PhaseSpec& p) {
  switch (p.type) {
    case PhaseSpec::Type::kIsotropic:
      return {{"type", "isotropic"}};
    case PhaseSpec::Type::kHenyeyGreenstein:
      return {{"type", "hg"}, {"g", canon(p.g)}};
    case PhaseSpec::Type::kMieApprox:
      return {{"type", "mie_approx"}, {"diameter_um", p.diameter_um}};
    case PhaseSpec::Type::kMie:
      return {{"type", "mie"},
              {"effective_radius_um", p.effective_radius_um},
              {"effective_variance", p.effective_variance}};
  }
  return {};
}

Json phaseJson(const PhaseSpec& p) {
  Json j = phaseTypeJson(p);
  j["mie_ratio"] = p.mie_ratio;
  return j;
}

Json skyJson(const Sky& s) {
  switch (s.type) {
    case Sky::Type::kConstant:
      return {{"radiance", vec(s.radiance)}};
    case Sky::Type::kGradient:
      return {{"zenith", vec(s.zenith)}, {"horizon", vec(s.horizon)}, {"ground", vec(s.ground)}};
    case Sky::Type::kMap:
      return {{"map", s.map_path}, {"scale", canon(s.map_scale)}};
  }
  return {};
}

Json viewJson(const Camera& c) {
  Json cam = {{"position", vec(c.position)}, {"look_at", vec(c.look_at)}, {"up", vec(c.up)}};
  if (c.type == Camera::Type::kPerspective) {
    cam["type"] = "perspective";
    cam["fov_deg"] = c.fov_deg;
  } else {
    cam["type"] = "orthographic";
    cam["width"] = c.width;
  }
  return {{"name", c.name}, {"camera", cam}, {"resolution", {c.width_px, c.height_px}}};
}

}  // namespace

std::string serializeShot(const ShotSpec& shot, const SerializeOptions& options) {
  Json j;
  j["version"] = shot.version;
  if (options.name) j["name"] = shot.name;
  j["volume"] = volumeJson(shot.volume);
  j["medium"] = {{"extinction", canon(shot.medium.extinction)},
                 {"albedo", vec(shot.medium.albedo)},
                 {"phase", phaseJson(shot.medium.phase)}};
  Json lighting = {{"sky", skyJson(shot.lighting.sky)}};
  if (shot.lighting.has_sun) {
    lighting["sun"] = {{"direction", vec(shot.lighting.sun.direction)},
                       {"irradiance", vec(shot.lighting.sun.irradiance)}};
  }
  j["lighting"] = lighting;
  Json bake = Json::object();
  for (const auto& [key, value] : shot.bake.knobs.explicitValues()) {
    std::visit(
        [&, k = key](const auto& v) {
          if constexpr (!std::is_same_v<std::decay_t<decltype(v)>, std::monostate>) bake[k] = v;
        },
        value);
  }
  bake["method"] = shot.bake.method;
  bake["samples"] = shot.bake.samples;
  bake["seed"] = shot.bake.seed;
  j["bake"] = bake;
  if (options.views) {
    j["views"] = Json::array();
    for (const Camera& c : shot.views) j["views"].push_back(viewJson(c));
  }
  if (options.outputs) {
    j["outputs"] = {{"exr", shot.outputs.exr}, {"vdb", shot.outputs.vdb}};
    if (shot.outputs.exr) {
      j["outputs"]["exr_compression"] = shot.outputs.exr_compression;
      j["outputs"]["exr_layers"] = shot.outputs.exr_layers;
    }
    if (shot.outputs.vdb_voxel_size > 0)
      j["outputs"]["vdb_voxel_size"] = shot.outputs.vdb_voxel_size;
  }
  return j.dump();
}

}  // namespace cloudbake
