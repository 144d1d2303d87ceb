#include "core/methods/pathtrace.h"

#include <filesystem>
#include <map>
#include <optional>
#include <string>

#include "core/error.h"
#include "core/format.h"
#include "core/io/vdb_io.h"
#include "core/methods/common.h"
#include "core/transport/layers_exr.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

constexpr const char* kViewFile = "view.exr";
constexpr const char* kVdbFile = "bake.vdb";

// A view from the cache (a render of the shot's own sun direction, or of one within the
// tolerance), else traced now and committed. Returns the layers at the shot's irradiance.
std::vector<ExrLayer> cachedView(MethodRun& run, int i,
                                 const std::function<RenderLayers(const Sun&)>& render,
                                 bool* from_cache, std::optional<Vec3>* lit_from) {
  const ShotSpec& shot = run.shot();
  const ShotCacheKeys& keys = run.keys();
  RunResult& result = run.result();
  std::vector<ExrLayer> layers;
  bool computed = false;
  if (shot.lighting.has_sun && !run.lookup(keys.views[size_t(i)])) {
    for (const Vec3& d : run.nearbySunDirections(keys.family)) {
      auto found = run.lookup(run.viewKeyAt(i, d));
      if (!found) continue;
      try {  // the entry may vanish meanwhile (eviction): then the view is traced as usual
        layers = readRenderLayersExr((fs::path(*found) / kViewFile).string());
      } catch (const std::exception&) {
        continue;
      }
      ++result.views_reused_direction;
      *lit_from = d;
      const double c = std::clamp(dot(d, sunDirection(shot)), -1.0, 1.0);
      result.reused_angle_deg = std::max(result.reused_angle_deg, std::acos(c) * 180.0 / M_PI);
      break;
    }
  }
  if (layers.empty()) {
    const std::string entry = run.cached(
        keys.views[size_t(i)],
        [&](const std::string& staging) {
          Sun sun = run.scene().sun;
          if (keys.sun_scaled) sun.irradiance = Rgb(1.0);
          writeExr((fs::path(staging) / kViewFile).string(), renderLayersToExr(render(sun)),
                   {{"cloudbake:units",
                     keys.sun_scaled ? "radiance per unit sun irradiance" : "radiance"}});
        },
        &computed);
    layers = readRenderLayersExr((fs::path(entry) / kViewFile).string());
    if (computed && shot.lighting.has_sun) run.addSunDirection(keys.family);
  }
  if (keys.sun_scaled) {
    for (ExrLayer& layer : layers) scaleRgb(layer.image, shot.lighting.sun.irradiance);
  }
  *from_cache = !computed;
  (computed ? result.views_rendered : result.views_cached) += 1;
  return layers;
}

// DIR/bake.vdb: the density grid (analytic volumes voxelised at outputs.vdb_voxel_size).
void writeDensityVdb(MethodRun& run) {
  const ShotSpec& shot = run.shot();
  auto write = [&](const std::string& path) {
    const Scene& s = run.scene();
    VdbWriteOptions vdb;
    vdb.voxel_size = shot.outputs.vdb_voxel_size;
    vdb.file_metadata = {{"cloudbake:shot", shot.name},
                         {"cloudbake:method", shot.bake.method},
                         {"cloudbake:volume", s.medium.density->describe()}};
    try {
      writeVdb(path, *s.medium.density, vdb);
    } catch (const MissingFileError&) {
      throw;
    } catch (const InputError& e) {
      // An analytic volume no voxel centre of this size samples (a box thinner than a voxel).
      if (std::string(e.what()).rfind("voxelize: ", 0) != 0) throw;
      throw InputError(run.source() + ": /outputs/vdb_voxel_size: " + e.what());
    }
  };
  if (!run.hasCache()) {
    run.writeOutput(kVdbFile, write);
    return;
  }
  bool computed = false;
  const std::string entry = run.cached(
      run.keys().vdb,
      [&](const std::string& staging) { write((fs::path(staging) / kVdbFile).string()); },
      &computed);
  run.result().vdb_cached = !computed;
  run.copyOutput(kVdbFile, (fs::path(entry) / kVdbFile).string());
}

class PathtraceMethod final : public BakeMethod {
 public:
  PathtraceMethod() {
    info_.name = "pathtrace";
    info_.summary =
        "the unbiased reference: volumetric path tracing with decomposition tracking (Kutz et "
        "al. 2017), residual ratio tracking (Novak et al. 2014) and next-event estimation "
        "(Novak et al. 2018), sun-directional importance sampling and shadow-ray splitting "
        "(Buras & Mayer 2011)";
    info_.citation =
        "Novak, Georgiev, Hanika and Jarosz 2018, \"Monte Carlo methods for volumetric light "
        "transport simulation\" (Eurographics STAR); Kutz, Habel, Li and Novak 2017, "
        "\"Spectral and decomposition tracking for rendering heterogeneous volumes\" (SIGGRAPH); "
        "Novak, Selle and Jarosz 2014, \"Residual ratio tracking for estimating attenuation in "
        "participating media\" (SIGGRAPH Asia); Buras and Mayer 2011, \"Efficient unbiased "
        "variance reduction techniques for Monte Carlo simulations of radiative transfer in "
        "cloudy atmospheres: the solution\" (JQSRT 112)";
    // 2: sun-directional importance sampling and shadow-ray splitting/roulette by default.
    // 3: decomposition and residual ratio tracking on a tracking grid chosen for the density,
    //    shadow rays rouletted and split by a transmittance predictor.
    info_.version = 4;
    info_.default_samples = 64;
    info_.knobs = {
        Knob::integer("max_depth", 1, 1000000, PathTracerOptions{}.max_depth,
                      "scattering events per path"),
        Knob::number("sun_guiding", 0, 0.95, std::nullopt, "",
                     "probability that a collision also starts a walk along the phase function "
                     "about the sun (sun-directional importance sampling, Buras & Mayer 2011); "
                     "0 turns it off",
                     /*exclusive_min=*/false)
            .derivedDefault("0.5 V / (V + 40), V = 4 pi integral(p^2) - 1 of the phase"),
        Knob::integer("sun_split_max", 1, 64, std::nullopt,
                      "most shadow rays towards the sun at one collision (split where the "
                      "predicted contribution is large, rouletted where small); 1 turns "
                      "splitting off (and the roulette, unless shadow rays are predicted)")
            .derivedDefault(
                "8 where shadow rays are predicted (decomposition tracking through a VDB, mesh "
                "or procedural volume) or V > 100 (droplet Mie tables), else 1"),
        Knob::choice("tracking", {"decomposition", "delta"}, "decomposition",
                     "free paths and shadow-ray transmittance: 'decomposition' splits each "
                     "tracking cell's density into a minorant handled analytically and a "
                     "residual (decomposition tracking, Kutz et al. 2017; residual ratio "
                     "tracking, Novak et al. 2014); 'delta' is delta and ratio tracking "
                     "against majorants alone (version 2)"),
        Knob::integer("majorant_cell", 1, 64, std::nullopt,
                      "voxels per tracking-grid cell edge for VDB, mesh and procedural "
                      "volumes (a power of two): fine cells bound the density tightly (fewer "
                      "lookups), coarse ones are crossed less often")
            .derivedDefault("chosen per medium by a cost model of lookups and cell crossings; with "
                            "tracking 'delta', the density's own 8^3-voxel blocks"),
    };
  }
  const MethodInfo& info() const override { return info_; }

  void validate(const ShotSpec& shot, const std::string& source) const override {
    const auto cell = shot.bake.knobs.optionalInteger("majorant_cell");
    if (cell && (*cell & (*cell - 1)) != 0) {
      throw InputError(source +
                       ": /bake/majorant_cell: must be a power of two (1, 2, 4, ... 64), "
                       "got " +
                       std::to_string(*cell));
    }
  }

  MethodPlan plan(const ShotSpec& shot, const ShotCacheKeys& keys,
                  const std::function<bool(const std::string&)>& lookup) const override {
    MethodPlan plan;
    if (shot.outputs.exr) {
      for (size_t i = 0; i < shot.views.size(); ++i) {
        const Camera& c = shot.views[i];
        const bool cached = lookup(keys.views[i]);
        plan.view_cached.push_back(cached);
        if (cached) {
          plan.components.push_back("view '" + c.name + "': from the cache");
          continue;
        }
        plan.pixel_samples += double(c.width_px) * c.height_px * shot.bake.samples;
        plan.components.push_back("view '" + c.name + "': path trace " +
                                  std::to_string(c.width_px) + "x" + std::to_string(c.height_px) +
                                  " at " + std::to_string(shot.bake.samples) + " spp");
      }
    }
    if (shot.outputs.vdb) plan.components.push_back("bake.vdb: the density grid");
    return plan;
  }

  void run(MethodRun& run) const override {
    const ShotSpec& shot = run.shot();
    const PathTracerOptions pt = pathTracerOptions(shot, run.threads());
    const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
    const double total = std::max(1, n_views + (shot.outputs.vdb ? 1 : 0));
    for (int i = 0; i < n_views; ++i) {
      if (!run.scope().renders(i)) continue;
      const Camera& camera = shot.views[size_t(i)];
      const std::string label = "view '" + camera.name + "' " + std::to_string(camera.width_px) +
                                "x" + std::to_string(camera.height_px) + ", " +
                                std::to_string(pt.samples_per_pixel) + " spp";
      run.report("render", i / total, label, camera.name);
      const auto t0 = std::chrono::steady_clock::now();
      auto render = [&](const Sun& sun) {
        const Scene& s = run.scene();
        return renderPathTraced(s.medium, sun, s.sky, s.cameras[size_t(i)], pt,
                                [&](double f) { return run.poll((i + f) / total, f); });
      };
      bool from_cache = false;
      std::optional<Vec3> lit_from;
      const std::vector<ExrLayer> layers = run.hasCache()
                                               ? cachedView(run, i, render, &from_cache, &lit_from)
                                               : renderLayersToExr(render(run.scene().sun));
      if (!run.hasCache()) ++run.result().views_rendered;
      std::map<std::string, std::string> attributes = {
          {"cloudbake:samples", std::to_string(pt.samples_per_pixel)},
          {"cloudbake:seed", std::to_string(pt.seed)}};
      if (lit_from) addLitFrom(shot, *lit_from, &attributes);
      const double write_s = run.writeView(camera.name, camera, layers, attributes);
      RunResult& r = run.result();
      r.steps.push_back({"view",
                         camera.name,
                         -1,
                         secondsSince(t0),
                         {{"cached", from_cache ? 1.0 : 0.0}, {"write", write_s}}});
      const std::string how = !from_cache ? ": rendered in "
                              : r.views_reused_direction > 0
                                  ? ": from the cached bake of a sun direction " +
                                        fixed(r.reused_angle_deg, 2) + " deg away, in "
                                  : ": from cache in ";
      run.poll((i + 1) / total, 1);
      run.report("render", (i + 1) / total, label + how + fixed(secondsSince(t0), 2) + " s",
                 camera.name);
    }
    if (shot.outputs.vdb && run.scope().writesShotFiles()) {
      run.report("vdb", n_views / total, "writing bake.vdb");
      writeDensityVdb(run);
    }
  }

 private:
  MethodInfo info_;
};

}  // namespace

const BakeMethod& pathtraceMethod() {
  static const PathtraceMethod kMethod;
  return kMethod;
}

PathTracerOptions pathTracerOptions(const ShotSpec& shot, int threads) {
  PathTracerOptions pt;
  pt.samples_per_pixel = shot.bake.samples;
  pt.seed = shot.bake.seed;
  pt.max_depth = int(shot.bake.knobs.integer("max_depth"));
  pt.sun_guiding = shot.bake.knobs.optionalNumber("sun_guiding").value_or(-1.0);
  pt.sun_split_max = int(shot.bake.knobs.optionalInteger("sun_split_max").value_or(-1));
  pt.decomposition_tracking = shot.bake.knobs.choice("tracking") == "decomposition";
  pt.majorant_cell = int(shot.bake.knobs.optionalInteger("majorant_cell").value_or(0));
  pt.threads = threads;
  return pt;
}

}  // namespace cloudbake
