#include "core/job/run_shot.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <utility>

#include "core/bake/baked_light_vdb.h"
#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/io/png_writer.h"
#include "core/io/vdb_io.h"
#include "core/job/bake_cache.h"
#include "core/job/bake_methods.h"
#include "core/job/cache_key.h"
#include "core/job/direction_index.h"
#include "core/job/file_util.h"
#include "core/job/run_outputs.h"
#include "core/job/run_precomputed.h"
#include "core/job/sha256.h"
#include "core/job/volume_cache.h"
#include "core/job/volume_limits.h"
#include "core/shot/scene_builder.h"
#include "core/transport/path_tracer.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

constexpr const char* kCachedViewFile = "view.exr";
constexpr const char* kCachedVdbFile = "bake.vdb";

// Methods single and pointcloud: the light is baked once per light direction (or taken from the
// cache: then no scattering is computed at all), and every view is ray-marched from the bake.
template <class NeedLights, class NeedScene, class Report, class ShouldStop>
void runBakeMethod(const ShotSpec& shot, const RunOptions& opt, const ShotCacheKeys& keys,
                   NeedLights& needLights, NeedScene& needScene, Report& report,
                   ShouldStop& should_stop, RunProgress& progress, double total,
                   RunResult& result) {
  const Scene& lights = needLights();  // phase, sky and cameras; no density
  const auto t_bake = std::chrono::steady_clock::now();
  std::optional<BakedLight> fresh;
  auto compute = [&]() -> BakedLight {
    const Scene& s = needScene();
    report("bake", 0, std::string("baking light (method ") + methodName(shot.bake.method) + ")");
    return bakeShotLight(shot, s.medium, [&](double f, const std::string& stage) {
      progress.stage = "bake";
      progress.fraction = std::clamp(f / total, 0.0, 1.0);
      progress.message = "bake: " + stage;
      return !opt.progress || opt.progress(progress);
    });
  };
  std::string entry;
  std::string how = "baked";
  if (opt.cache) {
    // Tolerance reuse: a cached bake of a nearby sun direction (closest first).
    if (opt.directions && opt.sun_tolerance_deg > 0 && shot.lighting.has_sun &&
        !opt.cache->lookup(keys.light)) {
      const Vec3 own = quantiseDirection(shot.lighting.sun.direction);
      for (const Vec3& d : opt.directions->near(keys.light_family, own, opt.sun_tolerance_deg)) {
        ShotSpec alt = shot;
        alt.lighting.sun.direction = d;
        if (auto found = opt.cache->lookup(computeCacheKeys(alt).light)) {
          entry = *found;
          ++result.views_reused_direction;
          result.reused_angle_deg = angleDeg(d, own);
          how = "from the cached bake of a sun direction " + fixed(result.reused_angle_deg, 2) +
                " deg away";
          break;
        }
      }
    }
    bool computed = false;
    if (entry.empty()) {
      entry = opt.cache->getOrCompute(
          keys.light,
          [&](const std::string& staging) {
            fresh = compute();
            writeBakedLight((fs::path(staging) / kCachedVdbFile).string(), *fresh);
            computed = true;
          },
          should_stop);
      if (!computed) how = "from cache";
      if (computed && opt.directions && shot.lighting.has_sun) {
        opt.directions->add(keys.light_family, quantiseDirection(shot.lighting.sun.direction));
      }
    }
    (computed ? result.bakes_computed : result.bakes_cached) += 1;
    if (!fresh) {
      try {
        fresh = readBakedLight((fs::path(entry) / kCachedVdbFile).string());
      } catch (const InputError& e) {
        // The cache verified the entry's checksum: an unreadable bake is our fault, not input.
        throw std::runtime_error(std::string("cached bake unreadable: ") + e.what());
      }
    }
  } else {
    fresh = compute();
    result.bakes_computed = 1;
  }
  const BakedLight& bake = *fresh;
  report("bake", 1,
         std::string("light ") + how + " in " + fixed(secondsSince(t_bake), 2) + " s (" +
             std::to_string(bake.grid.nx) + "x" + std::to_string(bake.grid.ny) + "x" +
             std::to_string(bake.grid.nz) + " lattice)");

  const BakeRenderOptions ro = bakeRenderOptions(shot, opt.threads);
  const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
  for (int i = 0; i < n_views; ++i) {
    const Camera& camera = lights.cameras[size_t(i)];
    const std::string label = "view '" + camera.name + "' " + std::to_string(camera.width_px) +
                              "x" + std::to_string(camera.height_px) + " from the bake";
    progress.view = camera.name;
    progress.view_fraction = 0;
    report("render", 1 + i, label);
    const auto t0 = std::chrono::steady_clock::now();
    RenderLayers layers =
        renderFromBake(bake, lights.medium, lights.sun, lights.sky, camera, ro, [&](double f) {
          progress.view_fraction = f;
          progress.fraction = std::clamp((1 + i + f) / total, 0.0, 1.0);
          return !opt.progress || opt.progress(progress);
        });
    const std::string name = camera.name + ".exr";
    const std::string path = (fs::path(opt.out_dir) / name).string();
    writeExr(path, toExrLayers(std::move(layers)),
             {{"cloudbake:shot", shot.name},
              {"cloudbake:view", camera.name},
              {"cloudbake:method", methodName(shot.bake.method)},
              {"cloudbake:samples", std::to_string(ro.samples_per_pixel)},
              {"cloudbake:seed", std::to_string(ro.seed)},
              {"cloudbake:units", "radiance, units of sun irradiance per sr"}});
    result.files.push_back(describeOutput(opt.out_dir, name));
    ++result.views_from_bake;
    progress.view_fraction = 1;
    report("render", 2 + i, label + ": rendered in " + fixed(secondsSince(t0), 2) + " s");
    if (opt.png) addPreview(opt, camera.name, path, result);
  }
  progress.view.clear();
  if (shot.outputs.vdb) {
    report("vdb", 1 + n_views, "writing bake.vdb (the baked light)");
    const std::string path = (fs::path(opt.out_dir) / kCachedVdbFile).string();
    if (!entry.empty()) {
      // A copy, not a link: the job's file must not change if the cache entry is tampered with.
      const std::string tmp = path + ".tmp." + uniqueSuffix();
      fs::copy_file(fs::path(entry) / kCachedVdbFile, tmp, fs::copy_options::overwrite_existing);
      fs::rename(tmp, path);
    } else {
      writeBakedLight(path, bake);
    }
    result.files.push_back(describeOutput(opt.out_dir, kCachedVdbFile));
  }
}

}  // namespace

void checkRunnable(const ShotSpec& shot, const std::string& source) {
  const bool precomputed = shot.bake.method == BakeSpec::Method::kPrecomputed;
  if (shot.bake.method != BakeSpec::Method::kPathtrace && !bakesLight(shot) && !precomputed) {
    throw InputError(source + ": /bake/method: '" + methodName(shot.bake.method) +
                     "' is not implemented in this version (use 'pathtrace', 'single', "
                     "'pointcloud' or 'precomputed')");
  }
  if (std::holds_alternative<SequenceVolumeSpec>(shot.volume) && !precomputed) {
    throw InputError(source +
                     ": /volume/sequence: animated volumes are rendered by method "
                     "'precomputed' only, not '" +
                     std::string(methodName(shot.bake.method)) + "'");
  }
}

RunResult runShot(const ShotSpec& shot_in, const RunOptions& opt) {
  const auto t_start = std::chrono::steady_clock::now();
  if (opt.threads < 0 || opt.threads > 4096) {
    throw InputError("threads: must be in [0, 4096] (0 = all cores), got " +
                     std::to_string(opt.threads));
  }
  if (!(opt.sun_tolerance_deg >= 0 && opt.sun_tolerance_deg <= 90)) {
    throw InputError("sun_tolerance_deg: must be in [0, 90] degrees, got " +
                     std::to_string(opt.sun_tolerance_deg));
  }
  if (!(opt.png_exposure >= 0 && opt.png_exposure <= 1e12)) {
    throw InputError("png_exposure: must be in [0, 1e12] (0 = auto), got " +
                     std::to_string(opt.png_exposure));
  }
  if (opt.samples != -1 && (opt.samples < 1 || opt.samples > 1000000)) {
    throw InputError("samples: must be in [1, 1000000], got " + std::to_string(opt.samples));
  }
  ShotSpec shot = shot_in;
  if (opt.samples != -1) shot.bake.samples = opt.samples;
  checkRunnable(shot, opt.source);

  std::error_code ec;
  fs::create_directories(opt.out_dir, ec);
  if (ec || !fs::is_directory(opt.out_dir)) {
    throw InputError("out: cannot create folder '" + opt.out_dir + "'" +
                     (ec ? ": " + ec.message() : ""));
  }

  const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
  const bool bake_method = bakesLight(shot);
  const double total = std::max(1, n_views + (shot.outputs.vdb ? 1 : 0) + (bake_method ? 1 : 0));
  RunProgress progress;
  auto report = [&](const std::string& stage, double done, const std::string& message) {
    progress.stage = stage;
    progress.fraction = std::clamp(done / total, 0.0, 1.0);
    progress.message = message;
    if (opt.progress && !opt.progress(progress)) throw Cancelled();
  };
  auto should_stop = [&] { return opt.progress && !opt.progress(progress); };

  RunResult result;
  report("build", 0, "building " + std::string(volumeTypeName(shot.volume)) + " volume");
  const ShotCacheKeys keys = opt.cache || opt.volumes ? computeCacheKeys(shot) : ShotCacheKeys{};

  // The scene's lights, phase function and cameras are cheap; its density field is the
  // expensive part, built only when something is computed (with a volume cache it comes from
  // memory when an earlier job built it).
  std::optional<Scene> scene;
  bool density_built = false;
  auto needLights = [&]() -> Scene& {
    if (!scene) {
      ShotSpec light = shot;
      light.volume = BoxVolumeSpec{{0, 0, 0}, {1, 1, 1}, 0.0};  // stand-in until needScene
      scene = buildScene(light, opt.source);
    }
    return *scene;
  };
  auto needScene = [&]() -> const Scene& {
    Scene& s = needLights();
    if (density_built) return s;
    const auto t0 = std::chrono::steady_clock::now();
    // Limits that need the files: checked before voxelising a mesh, and on a loaded VDB
    // before it enters the memory cache.
    auto build = [&] {
      checkMeshVoxels(shot, opt.max_voxels, opt.source);
      DensityFieldPtr field = buildVolume(shot.volume, opt.source);
      checkLoadedVoxels(shot, *field, opt.max_voxels, opt.source);
      return field;
    };
    s.medium.density =
        opt.volumes ? opt.volumes->getOrBuild(keys.volume, build, &result.volume_cached) : build();
    density_built = true;
    // Built lazily, inside whichever stage first needs it: keep that stage and fraction.
    report(progress.stage, progress.fraction * total,
           "built " + s.medium.density->describe() + " in " + fixed(secondsSince(t0), 2) + " s" +
               (result.volume_cached ? " (volume from memory cache)" : ""));
    return s;
  };
  if (shot.bake.method == BakeSpec::Method::kPrecomputed) {
    runPrecomputed(
        shot, opt, keys, needLights(), [&] { return needScene().medium.density; },
        [&](const std::string& stage, double fraction, const std::string& message) {
          progress.stage = stage;
          progress.fraction = std::clamp(fraction, 0.0, 1.0);
          progress.message = message;
          return !opt.progress || opt.progress(progress);
        },
        result);
    result.seconds = secondsSince(t_start);
    report("done", total, "done in " + fixed(result.seconds, 2) + " s");
    return result;
  }
  // Validate the medium, lights and cameras up front even when everything is cached, so bad
  // input fails the same way with and without a cache.
  if (!opt.cache) needScene();
  if (bake_method) {
    runBakeMethod(shot, opt, keys, needLights, needScene, report, should_stop, progress, total,
                  result);
    result.seconds = secondsSince(t_start);
    report("done", total, "done in " + fixed(result.seconds, 2) + " s");
    return result;
  }

  PathTracerOptions pt;
  pt.samples_per_pixel = shot.bake.samples;
  pt.seed = shot.bake.seed;
  if (shot.bake.max_depth) pt.max_depth = *shot.bake.max_depth;
  pt.threads = opt.threads;

  for (int i = 0; i < n_views; ++i) {
    const Camera& camera = shot.views[size_t(i)];
    const std::string label = "view '" + camera.name + "' " + std::to_string(camera.width_px) +
                              "x" + std::to_string(camera.height_px) + ", " +
                              std::to_string(pt.samples_per_pixel) + " spp";
    progress.view = camera.name;
    progress.view_fraction = 0;
    report("render", i, label);
    const auto t0 = std::chrono::steady_clock::now();
    auto render = [&](const Sun& sun) {
      const Scene& s = needScene();
      return renderPathTraced(s.medium, sun, s.sky, s.cameras[size_t(i)], pt, [&](double f) {
        progress.view_fraction = f;
        progress.fraction = std::clamp((i + f) / total, 0.0, 1.0);
        return !opt.progress || opt.progress(progress);
      });
    };
    std::vector<ExrLayer> layers;
    bool from_cache = false;
    if (opt.cache) {
      bool computed = false;
      std::string entry;
      // Tolerance reuse: a cached render of a nearby sun direction (closest first). The entry is
      // read at once; if it vanished meanwhile (eviction) the view is rendered as usual.
      if (opt.directions && opt.sun_tolerance_deg > 0 && shot.lighting.has_sun &&
          !opt.cache->lookup(keys.views[size_t(i)])) {
        const Vec3 own = quantiseDirection(shot.lighting.sun.direction);
        for (const Vec3& d : opt.directions->near(keys.family, own, opt.sun_tolerance_deg)) {
          ShotSpec alt = shot;
          alt.lighting.sun.direction = d;
          const ShotCacheKeys alt_keys = computeCacheKeys(alt);
          if (auto found = opt.cache->lookup(alt_keys.views[size_t(i)])) {
            try {
              layers = readLayers((fs::path(*found) / kCachedViewFile).string());
              entry = *found;
              ++result.views_reused_direction;
              result.reused_angle_deg = std::max(result.reused_angle_deg, angleDeg(d, own));
              break;
            } catch (const std::exception&) {
              layers.clear();
            }
          }
        }
      }
      if (entry.empty()) {
        entry = opt.cache->getOrCompute(
            keys.views[size_t(i)],
            [&](const std::string& staging) {
              Sun sun = needScene().sun;
              if (keys.sun_scaled) sun.irradiance = Rgb(1.0);
              writeExr((fs::path(staging) / kCachedViewFile).string(), toExrLayers(render(sun)),
                       {{"cloudbake:units",
                         keys.sun_scaled ? "radiance per unit sun irradiance" : "radiance"}});
              computed = true;
            },
            should_stop);
        layers = readLayers((fs::path(entry) / kCachedViewFile).string());
        if (computed && opt.directions && shot.lighting.has_sun) {
          opt.directions->add(keys.family, quantiseDirection(shot.lighting.sun.direction));
        }
      }
      if (keys.sun_scaled) {
        for (ExrLayer& layer : layers) scaleRgb(layer.image, shot.lighting.sun.irradiance);
      }
      from_cache = !computed;
      (computed ? result.views_rendered : result.views_cached) += 1;
    } else {
      layers = toExrLayers(render(scene->sun));
      ++result.views_rendered;
    }
    const std::string name = camera.name + ".exr";
    const std::string path = (fs::path(opt.out_dir) / name).string();
    const std::map<std::string, std::string> attributes = {
        {"cloudbake:shot", shot.name},
        {"cloudbake:view", camera.name},
        {"cloudbake:method", methodName(shot.bake.method)},
        {"cloudbake:samples", std::to_string(pt.samples_per_pixel)},
        {"cloudbake:seed", std::to_string(pt.seed)},
        {"cloudbake:units", "radiance, units of sun irradiance per sr"}};
    writeExr(path, layers, attributes);
    result.files.push_back(describeOutput(opt.out_dir, name));
    progress.view_fraction = 1;
    report("render", i + 1,
           label +
               (from_cache ? (result.views_reused_direction > 0
                                  ? ": from the cached bake of a sun direction " +
                                        fixed(result.reused_angle_deg, 2) + " deg away, in "
                                  : ": from cache in ")
                           : ": rendered in ") +
               fixed(secondsSince(t0), 2) + " s");
    if (opt.png) addPreview(opt, camera.name, path, result);
  }
  progress.view.clear();

  if (shot.outputs.vdb) {
    report("vdb", n_views, "writing bake.vdb");
    auto write = [&](const std::string& path) {
      const Scene& s = needScene();
      VdbWriteOptions vdb;
      vdb.voxel_size = shot.outputs.vdb_voxel_size;
      vdb.file_metadata = {{"cloudbake:shot", shot.name},
                           {"cloudbake:method", methodName(shot.bake.method)},
                           {"cloudbake:volume", s.medium.density->describe()}};
      writeVdb(path, *s.medium.density, vdb);
    };
    const std::string path = (fs::path(opt.out_dir) / kCachedVdbFile).string();
    if (opt.cache) {
      // The shot name is in the file's metadata, so it is part of this entry's key.
      bool computed = false;
      const std::string entry = opt.cache->getOrCompute(
          sha256Hex(keys.vdb + "/" + shot.name + "/" + methodName(shot.bake.method)),
          [&](const std::string& staging) {
            write((fs::path(staging) / kCachedVdbFile).string());
            computed = true;
          },
          should_stop);
      result.vdb_cached = !computed;
      // A copy, not a link: the job's file must not change if the cache entry is tampered with.
      const std::string tmp = path + ".tmp." + uniqueSuffix();
      fs::copy_file((fs::path(entry) / kCachedVdbFile), tmp, fs::copy_options::overwrite_existing);
      fs::rename(tmp, path);
    } else {
      write(path);
    }
    result.files.push_back(describeOutput(opt.out_dir, kCachedVdbFile));
  }
  result.seconds = secondsSince(t_start);
  report("done", total, "done in " + fixed(result.seconds, 2) + " s");
  return result;
}

}  // namespace cloudbake
