#include "core/job/run_precomputed.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/animation/basic_volumes.h"
#include "core/animation/precomputed_io.h"
#include "core/bake/bake_lattice.h"
#include "core/bake/baked_light_vdb.h"
#include "core/bake/render_from_bake.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/error.h"
#include "core/job/bake_cache.h"
#include "core/job/bake_methods.h"
#include "core/job/run_outputs.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using Json = nlohmann::json;

}  // namespace

PrecomputedShotOptions precomputedOptions(const ShotSpec& shot) {
  const Json k = Json::parse(shot.bake.options_json);
  PrecomputedShotOptions o;
  o.light_resolution = k.value("light_resolution", o.light_resolution);
  o.precompute.sample_points = k.value("sample_points", o.precompute.sample_points);
  o.precompute.transfer_resolution =
      k.value("transfer_resolution", o.precompute.transfer_resolution);
  o.precompute.cuts.cut_error = k.value("cut_error", o.precompute.cuts.cut_error);
  o.precompute.seed = shot.bake.seed;
  o.frame.max_orders = k.value("iterations", o.frame.max_orders);
  o.frame.tolerance = k.value("tolerance", o.frame.tolerance);
  o.frame.similarity = k.value("similarity", o.frame.similarity);
  const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume);
  o.basic_volumes = seq ? seq->frames : 1;
  o.walk.sigma = k.value("sigma", o.walk.sigma);
  o.walk.dissolve_frames =
      k.value("dissolve", std::max(0, std::min(o.walk.dissolve_frames, o.basic_volumes - 2)));
  o.walk.seed = shot.bake.seed;
  o.frames = k.value("frames", o.basic_volumes);
  return o;
}

std::vector<std::string> planPrecomputed(const ShotSpec& shot, bool cached) {
  const PrecomputedShotOptions o = precomputedOptions(shot);
  std::vector<std::string> lines;
  if (cached) {
    lines.push_back("precompute: already in the cache for this database (no precompute)");
  } else {
    lines.push_back("basic volumes: " + std::to_string(o.basic_volumes) + " (" +
                    volumeTypeName(shot.volume) + "), each resampled to a " +
                    std::to_string(o.light_resolution) + "-voxel lattice (longest side)");
    lines.push_back("precompute per basic volume: optical-depth SH (64 direction sweeps), " +
                    std::to_string(o.precompute.sample_points) + " sample points, cuts on a " +
                    std::to_string(o.precompute.transfer_resolution) +
                    "-voxel receiver lattice (cut error " +
                    shortNumber(o.precompute.cuts.cut_error) + ")");
  }
  lines.push_back("frames: " + std::to_string(o.frames) + " of endless animation (sigma " +
                  shortNumber(o.walk.sigma) + ", cross-dissolve over " +
                  std::to_string(o.walk.dissolve_frames) + " frames), each lit by a sun sweep, " +
                  "SHEXP sky and up to " + std::to_string(o.frame.max_orders) +
                  " multiple-scattering orders");
  return lines;
}

std::string frameStem(const std::string& stem, int frame) {
  char buf[32];
  std::snprintf(buf, sizeof buf, ".%04d", frame);
  return stem + buf;
}

void runPrecomputed(
    const ShotSpec& shot, const RunOptions& opt, const ShotCacheKeys& keys, const Scene& lights,
    const std::function<DensityFieldPtr()>& density,
    const std::function<bool(const std::string&, double, const std::string&)>& report,
    RunResult& result) {
  const PrecomputedShotOptions o = precomputedOptions(shot);
  const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
  // Progress: the precompute weighs as much as all frames together.
  auto stage = [&](const std::string& name, double fraction, const std::string& message) {
    if (!report(name, fraction, message)) throw Cancelled();
  };
  auto build = [&]() {
    const auto t0 = std::chrono::steady_clock::now();
    stage("bake", 0, "building " + std::to_string(o.basic_volumes) + " basic volume(s)");
    BasicVolumeDatabase vols;
    const auto building = [&](double f) {
      return report("bake", 0.1 * f, "building basic volumes");
    };
    if (const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume)) {
      vols = buildBasicVolumes(*seq, o.light_resolution, opt.source, building);
    } else {
      BakedLight lattice = makeBakeLattice(*density(), o.light_resolution);
      vols.grid = lattice.grid;
      vols.frames.push_back(std::move(lattice.density));
    }
    PrecomputedDatabase db = precomputeBasicVolumes(
        std::move(vols), lights.medium.extinction, o.precompute,
        [&](double f) { return report("bake", 0.1 + 0.4 * f, "precomputing basic volumes"); });
    size_t bytes = 0;
    for (const BasicVolumePrecompute& b : db.basic) bytes += b.bytes();
    stage("bake", 0.5,
          "precomputed " + std::to_string(db.basic.size()) + " basic volume(s) in " +
              fixed(secondsSince(t0), 2) + " s (" + std::to_string(db.tree.points.size()) +
              " sample points; " + fixed(double(bytes) / db.basic.size() / (1 << 20), 1) +
              " MiB per basic volume)");
    return db;
  };
  PrecomputedDatabase db;
  if (opt.cache && !keys.precompute.empty()) {
    bool computed = false;
    const std::string entry = opt.cache->getOrCompute(
        keys.precompute,
        [&](const std::string& staging) {
          db = build();
          writePrecomputedDatabase(staging, db);
          computed = true;
        },
        [&] { return !report("bake", 0, "waiting for the same precompute"); });
    (computed ? result.bakes_computed : result.bakes_cached) += 1;
    if (!computed) {
      try {
        db = readPrecomputedDatabase(entry);
      } catch (const InputError& e) {
        // The cache verified the entry's checksums: unreadable data is our fault, not input.
        throw std::runtime_error(std::string("cached precompute unreadable: ") + e.what());
      }
      stage("bake", 0.5,
            "precompute of " + std::to_string(db.basic.size()) + " basic volume(s) from the cache");
    }
  } else {
    db = build();
    result.bakes_computed = 1;
  }

  // The walk over the database (a single basic volume repeats itself).
  const int n = int(db.basic.size());
  std::vector<BlendFrame> walk;
  if (n == 1) {
    walk.assign(size_t(o.frames), BlendFrame{0, 0, 1.0});
  } else {
    const std::vector<double> p =
        transitionProbabilities(frameDistances(db.volumes.frames), n, o.walk);
    walk = endlessWalk(p, n, o.frames, o.walk);
  }
  Json animation = {{"basic_volumes", n}, {"frames", Json::array()}};
  for (const BlendFrame& f : walk) {
    animation["frames"].push_back({{"a", f.a}, {"b", f.b}, {"w", f.w}});
  }
  {
    const std::string path = (fs::path(opt.out_dir) / "animation.json").string();
    std::ofstream out(path);
    out << animation.dump(1) << "\n";
    out.close();  // flushed before its size and checksum are recorded
    if (!out) throw std::runtime_error(path + ": write failed");
    result.files.push_back(describeOutput(opt.out_dir, "animation.json"));
  }

  const Vec3 sun_dir = shot.lighting.has_sun ? shot.lighting.sun.direction : Vec3(0, 0, 1);
  const std::array<ShCoefficients, 3> sky_sh =
      needsSky(shot) ? projectSkyRadiance(SkyLight(lights.sky)) : std::array<ShCoefficients, 3>{};
  const BakeRenderOptions ro = bakeRenderOptions(shot, opt.threads);
  FrameLightOptions frame_options = o.frame;
  frame_options.mean_cosine = lights.medium.phase->meanCosine();
  const int per_frame = n_views + (shot.outputs.vdb ? 1 : 0) + 1;
  const double units = double(o.frames) * per_frame;
  for (int f = 0; f < o.frames; ++f) {
    const BlendFrame& bf = walk[size_t(f)];
    const double base = 0.5 + 0.5 * (f * per_frame) / units;
    const auto t0 = std::chrono::steady_clock::now();
    FrameLightStats stats;
    const BakedLight light =
        lightAnimationFrame(db, bf, sun_dir, lights.medium.albedo, sky_sh, frame_options, &stats);
    stage("render", base,
          "frame " + std::to_string(f) + " (basic volumes " + std::to_string(bf.a) + ", " +
              std::to_string(bf.b) + ", w " + fixed(bf.w, 3) + "): lit in " +
              fixed(stats.seconds, 2) + " s, " + std::to_string(stats.orders) + " orders");
    for (int i = 0; i < n_views; ++i) {
      const Camera& camera = lights.cameras[size_t(i)];
      const auto t_view = std::chrono::steady_clock::now();
      RenderLayers layers =
          renderFromBake(light, lights.medium, lights.sun, lights.sky, camera, ro, [&](double fr) {
            return report("render", base + 0.5 * (1 + i + fr) / units,
                          "frame " + std::to_string(f) + ", view '" + camera.name + "'");
          });
      const std::string stem = frameStem(camera.name, f);
      const std::string path = (fs::path(opt.out_dir) / (stem + ".exr")).string();
      writeExr(path, toExrLayers(std::move(layers)),
               {{"cloudbake:shot", shot.name},
                {"cloudbake:view", camera.name},
                {"cloudbake:method", "precomputed"},
                {"cloudbake:frame", std::to_string(f)},
                {"cloudbake:blend",
                 std::to_string(bf.a) + " " + std::to_string(bf.b) + " " + std::to_string(bf.w)},
                {"cloudbake:samples", std::to_string(ro.samples_per_pixel)},
                {"cloudbake:seed", std::to_string(ro.seed)},
                {"cloudbake:units", "radiance, units of sun irradiance per sr"}});
      result.files.push_back(describeOutput(opt.out_dir, stem + ".exr"));
      ++result.views_from_bake;
      stage("render", base + 0.5 * (2 + i) / units,
            "frame " + std::to_string(f) + ", view '" + camera.name + "' " +
                std::to_string(camera.width_px) + "x" + std::to_string(camera.height_px) +
                " rendered in " + fixed(secondsSince(t_view), 2) + " s");
      if (opt.png) addPreview(opt, stem, path, result);
    }
    if (shot.outputs.vdb) {
      const std::string name = frameStem("bake", f) + ".vdb";
      writeBakedLight((fs::path(opt.out_dir) / name).string(), light);
      result.files.push_back(describeOutput(opt.out_dir, name));
    }
    stage("render", 0.5 + 0.5 * ((f + 1) * per_frame) / units,
          "frame " + std::to_string(f) + " done in " + fixed(secondsSince(t0), 2) + " s");
  }
}

}  // namespace cloudbake
