#include "core/job/bake_methods.h"

#include <nlohmann/json.hpp>

#include <cstdio>

#include "core/error.h"
#include "core/job/cache_key.h"
#include "core/job/run_outputs.h"

namespace cloudbake {
namespace {
using Json = nlohmann::json;

Json knobsOf(const ShotSpec& shot) {
  Json j = Json::parse(shot.bake.options_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) throw InputError("/bake: method knobs are not a JSON object");
  return j;
}

}  // namespace

SingleBakeOptions singleBakeOptions(const ShotSpec& shot) {
  const Json k = knobsOf(shot);
  SingleBakeOptions o;
  o.light_resolution = k.value("light_resolution", o.light_resolution);
  o.step = k.value("step", o.step);
  o.sky = needsSky(shot);
  return o;
}

PointcloudOptions pointcloudOptions(const ShotSpec& shot) {
  const Json k = knobsOf(shot);
  PointcloudOptions o;
  o.points = k.value("points", o.points);
  o.passes = k.value("passes", o.passes);
  o.radius = k.value("radius", o.radius);
  o.tolerance = k.value("tolerance", o.tolerance);
  o.rule = k.value("rule", std::string("normalized")) == "paper" ? PointcloudOptions::Rule::kPaper
                                                                 : PointcloudOptions::Rule::kNormalized;
  o.output_mapping = k.value("output_mapping", o.output_mapping);
  o.tail = k.value("tail", o.tail);
  o.light_resolution = k.value("light_resolution", o.light_resolution);
  o.step = k.value("step", o.step);
  o.sky = needsSky(shot);
  o.seed = shot.bake.seed;
  return o;
}

BakeRenderOptions bakeRenderOptions(const ShotSpec& shot, int threads) {
  BakeRenderOptions o;
  o.step = knobsOf(shot).value("step", 0.0);
  o.samples_per_pixel = shot.bake.samples;
  o.seed = shot.bake.seed;
  o.threads = threads;
  return o;
}

std::vector<std::string> planBake(const ShotSpec& shot, bool cached) {
  if (cached) return {"light: already baked for this sun direction (no scattering computed)"};
  std::vector<std::string> lines;
  const bool pointcloud = shot.bake.method == BakeSpec::Method::kPointcloud;
  const int resolution = pointcloud ? pointcloudOptions(shot).light_resolution
                                    : singleBakeOptions(shot).light_resolution;
  lines.push_back(std::string("volume: ") + volumeTypeName(shot.volume) + ", resampled to a " +
                  std::to_string(resolution) + "-voxel lattice (longest side)");
  lines.push_back(shot.lighting.has_sun ? "sun transmittance: one ray march per lattice voxel"
                                        : "sun transmittance: computed, but the shot has no sun");
  lines.push_back(needsSky(shot) ? "sky visibility: 26 lattice-direction sweeps"
                                 : "sky visibility: skipped (black sky)");
  if (pointcloud) {
    const PointcloudOptions o = pointcloudOptions(shot);
    lines.push_back("multiple scattering: " + std::to_string(o.points) +
                    " points, up to " + std::to_string(o.passes) +
                    " passes (stop below a relative change of " + shortNumber(o.tolerance) +
                    "), rule " + (o.rule == PointcloudOptions::Rule::kPaper ? "paper" : "normalized"));
  } else {
    lines.push_back("multiple scattering: not modelled by method single");
  }
  return lines;
}

BakedLight bakeShotLight(const ShotSpec& shot, const Medium& medium,
                         const BakeProgressFn& progress, PointcloudStats* stats) {
  const Vec3 sun_dir = shot.lighting.has_sun ? shot.lighting.sun.direction : Vec3(0, 0, 1);
  switch (shot.bake.method) {
    case BakeSpec::Method::kSingle:
      return bakeSingle(medium, sun_dir, singleBakeOptions(shot), progress);
    case BakeSpec::Method::kPointcloud:
      return bakePointcloud(medium, sun_dir, pointcloudOptions(shot), progress, stats);
    default:
      throw InputError(std::string("/bake/method: '") + methodName(shot.bake.method) +
                       "' does not bake light");
  }
}

}  // namespace cloudbake
