#include "core/methods/common.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <sstream>

#include "core/bake/bake_lattice.h"
#include "core/bake/baked_light_vdb.h"
#include "core/bake/phase_lut.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/bake/sparse_film.h"
#include "core/error.h"
#include "core/format.h"
#include "core/phase/phase_factory.h"
#include "core/transport/layers_exr.h"

namespace cloudbake {
namespace {

// Where the cloud's bounds span fewer than kThinLatticeVoxels voxels along an axis of its lattice
// (a margin voxel on either side apart): the lattice blurs it across that axis, and an outside
// probe measured a bar 100:1:1 at the default light_resolution (2 voxels across) with `photon`'s
// multiple scattering at 0.39 of the path tracer's and its silhouette three times too tall. A
// note for the run's log, empty elsewhere.
constexpr int kThinLatticeVoxels = 4;
std::string thinAxesNote(const BakeGrid& g) {
  std::string axes;
  int fewest = kThinLatticeVoxels;
  const int n[3] = {g.nx, g.ny, g.nz};
  for (int a = 0; a < 3; ++a) {
    if (n[a] - 2 >= kThinLatticeVoxels) continue;
    axes += std::string(axes.empty() ? "" : " and ") + "xyz"[a];
    fewest = std::min(fewest, n[a] - 2);
  }
  if (axes.empty()) return "";
  return "; the cloud spans " + std::to_string(fewest) + " voxel(s) along " + axes +
         ", so the lattice blurs its light across them: raise light_resolution, or use pathtrace "
         "(docs/methods.md, \"The lattice\")";
}
namespace fs = std::filesystem;
using Json = nlohmann::json;

constexpr const char* kBakeFile = "bake.vdb";

double angleDeg(const Vec3& a, const Vec3& b) {
  const double c = std::clamp(dot(a, b) / (length(a) * length(b)), -1.0, 1.0);
  return std::acos(c) * 180.0 / M_PI;
}

// The cached bake of a sun direction within the run's tolerance, closest first; "" if none.
std::string nearbyBake(MethodRun& run, std::string* how) {
  const ShotSpec& shot = run.shot();
  if (!shot.lighting.has_sun || run.lookup(run.keys().light)) return "";
  for (const Vec3& d : run.nearbySunDirections(run.keys().light_family)) {
    if (auto found = run.lookup(run.lightKeyAt(d))) {
      RunResult& r = run.result();
      ++r.views_reused_direction;
      r.reused_angle_deg = angleDeg(d, sunDirection(shot));
      *how =
          "from the cached bake of a sun direction " + fixed(r.reused_angle_deg, 2) + " deg away";
      return *found;
    }
  }
  return "";
}

// The bake itself: from the cache when it holds it, else computed (and committed). Its progress
// runs over [0, share] of the run's.
BakedLight obtainBake(MethodRun& run, const LightBakeFn& bake, double share, std::string* entry) {
  const ShotSpec& shot = run.shot();
  auto compute = [&] {
    run.report("bake", 0, "baking light (method " + shot.bake.method + ")");
    return bake(run.scene().medium, sunDirection(shot), [&](double f, const std::string& stage) {
      return run.pollMessage(f * share, "bake: " + stage);
    });
  };
  const auto t0 = std::chrono::steady_clock::now();
  std::string how = "baked";
  std::optional<BakedLight> light;
  RunResult& result = run.result();
  if (!run.hasCache()) {
    light = compute();
    result.bakes_computed += 1;
  } else {
    *entry = nearbyBake(run, &how);
    if (entry->empty()) {
      bool computed = false;
      *entry = run.cached(
          run.keys().light,
          [&](const std::string& staging) {
            light = compute();
            writeBakedLight((fs::path(staging) / kBakeFile).string(), *light);
          },
          &computed);
      if (!computed) how = "from cache";
      if (computed && shot.lighting.has_sun) run.addSunDirection(run.keys().light_family);
      (computed ? result.bakes_computed : result.bakes_cached) += 1;
    } else {
      result.bakes_cached += 1;
    }
    if (!light) {
      try {
        light = readBakedLight((fs::path(*entry) / kBakeFile).string());
      } catch (const InputError& e) {
        // The cache verified the entry's checksum: an unreadable bake is our fault, not input.
        throw InternalError(std::string("cached bake unreadable: ") + e.what());
      }
    }
  }
  const BakeGrid& g = light->grid;
  result.steps.push_back(
      {"bake", "", -1, secondsSince(t0), {{"cached", how == "baked" ? 0.0 : 1.0}}});
  run.report("bake", share,
             "light " + how + " in " + fixed(secondsSince(t0), 2) + " s (" + std::to_string(g.nx) +
                 "x" + std::to_string(g.ny) + "x" + std::to_string(g.nz) + " lattice" +
                 thinAxesNote(g) + ")");
  return std::move(*light);
}

}  // namespace

Vec3 sunDirection(const ShotSpec& shot) {
  return shot.lighting.has_sun ? shot.lighting.sun.direction : Vec3(0, 0, 1);
}

void addLitFrom(const ShotSpec& shot, const Vec3& lit, std::map<std::string, std::string>* out) {
  // (The same direction read back from a bake's metadata differs by rounding at most.)
  if (!(length(normalize(lit) - sunDirection(shot)) > 1e-9)) return;
  const double angle = angleDeg(lit, sunDirection(shot));
  (*out)["cloudbake:lit_sun_direction"] =
      exactNumber(lit.x) + " " + exactNumber(lit.y) + " " + exactNumber(lit.z);
  (*out)["cloudbake:lit_sun_angle_deg"] = exactNumber(angle);
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

Knob stepKnob(const char* derived_default) {
  return Knob::number(
             "step", 0, 1e12, std::nullopt, "world units",
             "ray-march step of the view renders, from 1e-4 to 4 lattice voxels (not part of the "
             "bake's cache key)")
      .derivedDefault(derived_default)
      .viewOnly();
}

Knob filmSpacingKnob() {
  return Knob::integer(
             "film_spacing", 1, kMaxFilmSpacing, kMaxFilmSpacing,
             "pixels: the largest spacing (1, 2 or 4; 3 reads as 2) of the pixels a view traces "
             "first where the lattice's voxels are wider than that many pixels; the pixels between "
             "are traced where the image bends there and interpolated elsewhere; 1 traces every "
             "pixel (not part of the bake's cache key)")
      .viewOnly();
}

Knob lightResolutionKnob(int64_t default_resolution, bool aligned_to_grid) {
  return Knob::integer(
      "light_resolution", 8, 1024, default_resolution,
      aligned_to_grid
          ? "bake lattice voxels along the longest side of the volume; where that is at least 4/5 "
            "of a grid volume's own voxels n, the lattice is the grid's voxel centres at 1/m of "
            "their spacing, m = floor(light_resolution / n + 1/5), so views read the grid's own "
            "density"
          : "bake lattice voxels along the longest side of the volume");
}

bool needsSun(const ShotSpec& shot) {
  return shot.lighting.has_sun && maxComponent(shot.lighting.sun.irradiance) > 0;
}

nlohmann::json wholeMediumLightKey(const BakeMethod& method, const ShotSpec& shot,
                                   const nlohmann::json& canonical) {
  return {{"light",
           {{"medium", canonical["medium"]},
            {"seed", shot.bake.seed},
            {"sky", needsSky(shot)},
            {"knobs", bakeKnobMaterial(method, shot)}}}};
}

BakeRenderOptions bakeRenderOptions(const ShotSpec& shot, int threads) {
  BakeRenderOptions o;
  o.step = shot.bake.knobs.optionalNumber("step").value_or(0.0);
  o.max_film_spacing =
      int(shot.bake.knobs.optionalInteger("film_spacing").value_or(kMaxFilmSpacing));
  o.samples_per_pixel = shot.bake.samples;
  o.seed = shot.bake.seed;
  o.threads = threads;
  return o;
}

Json bakeKnobMaterial(const BakeMethod& method, const ShotSpec& shot) {
  // Resolved values, defaults included: a changed default changes the key.
  const std::map<std::string, KnobValue> values = shot.bake.knobs.resolved();
  Json knobs = Json::object();
  for (const Knob& k : method.info().knobs) {
    const auto it = values.find(k.key);
    if (k.view_only || it == values.end()) continue;
    std::visit(
        [&, key = k.key](const auto& v) {
          using T = std::decay_t<decltype(v)>;
          if constexpr (!std::is_same_v<T, std::monostate>) knobs[key] = v;
        },
        it->second);
  }
  return knobs;
}

void checkLatticeVoxels(int64_t resolution, double lattices_times_floats, const std::string& what,
                        const MethodLimits& limits, const std::string& source,
                        const std::string& pointer) {
  if (limits.max_voxels == 0) return;
  // Counted as a cube with a margin: an upper bound, since the volume's bounds are not known
  // before its files are read.
  const double n = lattices_times_floats * std::pow(double(resolution + 2), 3);
  if (n > double(limits.max_voxels)) {
    std::ostringstream os;
    os.precision(15);
    os << source << ": " << pointer << ": " << what << " of up to (" << resolution
       << " + 2)^3 gives " << n << " voxels, over the limit of " << limits.max_voxels
       << " (--max-voxels)";
    throw InputError(os.str());
  }
}

void checkPhaseTable(const ShotSpec& shot, const std::string& source, const char* method) {
  if (shot.medium.phase.type == PhaseSpec::Type::kMie) return;
  const PhaseLut lut(*makePhaseFunction(shot.medium.phase));
  const auto lambda = phaseEigenvalues(lut);
  double worst = 1;
  for (int c = 0; c < 3; ++c) {
    if (std::abs(lambda[size_t(c)][0] - 1) > std::abs(worst - 1)) worst = lambda[size_t(c)][0];
  }
  if (std::abs(worst - 1) <= kMaxPhaseTableError) return;
  throw InputError(source + ": /medium/phase: this phase's peak is narrower than method " + method +
                   "'s table of it resolves: the table integrates to " + str(worst, 4) +
                   " over the sphere, not 1 within " + str(kMaxPhaseTableError) +
                   " (an hg phase resolves up to |g| = 0.999). Use method pathtrace, or a "
                   "broader phase");
}

void checkAnalyticLattice(const ShotSpec& shot, int resolution, const std::string& source,
                          const std::string& pointer) {
  const std::optional<Bounds3> b = statedBounds(shot.volume);
  if (!b) return;
  const std::string knob = pointer.substr(pointer.rfind('/') + 1);
  try {
    bakeLatticeGeometry(*b, resolution, volumeTypeName(shot.volume), knob.c_str());
  } catch (const InputError& e) {
    // "<knob>: <resolution> gives a lattice of ..." with the field's whole path; the bounds'
    // own errors name the volume.
    const std::string what = e.what();
    if (what.rfind(knob + ":", 0) == 0) {
      throw InputError(source + ": " + pointer + what.substr(knob.size()));
    }
    throw InputError(source + ": /volume/" + volumeTypeName(shot.volume) + ": " + what);
  }
}

void checkPointCount(int64_t points, const std::string& pointer, const MethodLimits& limits,
                     const std::string& source) {
  if (limits.max_points > 0 && points > limits.max_points) {
    throw InputError(source + ": " + pointer + ": " + std::to_string(points) +
                     " points exceed this server's limit of " + std::to_string(limits.max_points) +
                     " (--max-points)");
  }
}

std::vector<std::string> lightBakePlanLines(const ShotSpec& shot, int64_t resolution) {
  // Analytic shapes are always box means; a grid only where it has over 1.25x the voxels asked.
  const bool analytic = std::holds_alternative<BoxVolumeSpec>(shot.volume) ||
                        std::holds_alternative<SphereVolumeSpec>(shot.volume);
  return {std::string("volume: ") + volumeTypeName(shot.volume) + ", resampled to a " +
              std::to_string(resolution) + "-voxel lattice (longest side)" +
              (analytic ? ""
                        : ", or on the grid's own voxels (at 1/m of their spacing) where it has "
                          "no more than 1.25x as many"),
          shot.lighting.has_sun ? "sun transmittance: one ray march per lattice voxel"
                                : "sun transmittance: computed, but the shot has no sun",
          needsSky(shot) ? "sky visibility: 26 lattice-direction sweeps"
                         : "sky visibility: skipped (black sky)"};
}

MethodPlan lightBakePlan(const ShotSpec& shot, const ShotCacheKeys& keys,
                         const std::function<bool(const std::string&)>& lookup,
                         std::vector<std::string> bake_lines) {
  MethodPlan plan;
  plan.bake_key = keys.light;
  plan.bake_cached = lookup(keys.light);
  if (plan.bake_cached) {
    plan.components = {"light: already baked for this sun direction (no scattering computed)"};
  } else {
    plan.components = std::move(bake_lines);
  }
  if (!shot.outputs.exr) return plan;
  for (const Camera& c : shot.views) {
    plan.view_cached.push_back(plan.bake_cached);
    plan.pixel_samples += double(c.width_px) * c.height_px * shot.bake.samples;
    plan.components.push_back("view '" + c.name + "': ray march from the bake, " +
                              std::to_string(c.width_px) + "x" + std::to_string(c.height_px) +
                              ", " + std::to_string(shot.bake.samples) + " ray(s) per pixel");
  }
  return plan;
}

double latticeSeconds(int64_t resolution) {
  return 0.04 + 1.0e-7 * 0.5 * std::pow(double(resolution), 3);
}

namespace {

// The views refuse a step under 1e-4 of the lattice's voxel (renderFromBake), which they would
// say only after a bake of possibly minutes. The lattice's voxel is not known before the bake
// builds it, but it is at least the box lattice's over 1.25 (a lattice on a grid's own voxels
// has at most 1.25x the voxels asked for per axis; 1.5 leaves room): a step under 1e-4 of that
// is refused by the views too, so it is refused here first.
// Called as the bake starts, with its medium: a bake found in the cache builds no volume for it.
void checkStepBeforeBake(const Medium& medium, double step, int64_t resolution, int n_views) {
  if (!(step > 0) || resolution <= 0 || n_views == 0) return;
  const DensityField& density = *medium.density;
  const double voxel =
      bakeLatticeGeometry(density.bounds(), int(resolution), density.describe()).voxel_size / 1.5;
  if (step < 1e-4 * voxel) {
    throw InputError("step: must be at least 1e-4 voxel (about " + exactNumber(1e-4 * voxel) +
                     " world units) or left out for half a voxel, got " + exactNumber(step));
  }
  // The views refuse a step over kMaxStepVoxels of the lattice's voxel; an aligned lattice's
  // voxel is under twice the box lattice's (a request just under twice the grid's voxels gets
  // the grid's own), so a step over that is refused by the views too.
  const double coarsest = 2 * 1.5 * voxel;
  if (step > kMaxStepVoxels * coarsest) {
    throw InputError("step: must be at most " + exactNumber(kMaxStepVoxels) +
                     " lattice voxels (about " + exactNumber(kMaxStepVoxels * voxel * 1.5) +
                     " world units; a coarser step would pass over the cloud between its "
                     "samples), got " +
                     exactNumber(step));
  }
}

}  // namespace

void runLightBake(MethodRun& run, const LightBakeFn& bake, const LightBakeWork& work) {
  const ShotSpec& shot = run.shot();
  const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
  const Scene& lights = run.lights();
  BakeRenderOptions ro = bakeRenderOptions(shot, run.threads());
  // The views share the bake's blocks and packs (up to 32 floats a voxel), freed after them.
  std::optional<BakeViewCache> view_cache;
  ro.cache = &view_cache.emplace();
  // Progress weights: predicted seconds of each part. A bake found in the cache is not known
  // before obtainBake looks (a lookup verifies the entry's checksums: not worth doing twice), so
  // the bar then jumps over the bake's share.
  const double bake_w = work.bake_seconds;
  std::vector<double> start(size_t(n_views) + 1, bake_w);
  for (int i = 0; i < n_views; ++i) {
    const Camera& c = lights.cameras[size_t(i)];
    start[size_t(i) + 1] = start[size_t(i)] + double(c.width_px) * c.height_px *
                                                  ro.samples_per_pixel * work.view_seconds_per_ray;
  }
  const double total = start.back() + (shot.outputs.vdb ? 0.05 * work.bake_seconds : 0.0);
  const LightBakeFn checked_bake = [&](const Medium& medium, const Vec3& sun,
                                       const BakeProgressFn& progress) {
    checkStepBeforeBake(medium, ro.step, work.light_resolution, n_views);
    return bake(medium, sun, progress);
  };
  std::string entry;
  const BakedLight light = obtainBake(run, checked_bake, bake_w / total, &entry);
  for (const char* key : {"tally_noise", "truncation"}) {
    const auto it = light.metadata.find(std::string("cloudbake:") + key);
    if (it != light.metadata.end())
      run.result().bake_estimates[key] = std::atof(it->second.c_str());
  }

  for (int i = 0; i < n_views; ++i) {
    if (!run.scope().renders(i)) continue;
    const Camera& camera = lights.cameras[size_t(i)];
    const std::string label = "view '" + camera.name + "' " + std::to_string(camera.width_px) +
                              "x" + std::to_string(camera.height_px) + " from the bake";
    const double v0 = start[size_t(i)] / total, v1 = start[size_t(i) + 1] / total;
    run.report("render", v0, label, camera.name);
    const auto t0 = std::chrono::steady_clock::now();
    RenderLayers layers = renderFromBake(light, lights.medium, lights.sun, lights.sky, camera, ro,
                                         [&](double f) { return run.poll(v0 + (v1 - v0) * f, f); });
    std::map<std::string, std::string> attributes = {
        {"cloudbake:samples", std::to_string(ro.samples_per_pixel)},
        {"cloudbake:seed", std::to_string(ro.seed)},
        {"cloudbake:film_spacing", std::to_string(filmSpacingOf(light, camera, ro))}};
    if (shot.lighting.has_sun) addLitFrom(shot, light.sun_direction, &attributes);
    const double traced = tracedShare(layers);
    const double write_s =
        run.writeView(camera.name, camera, renderLayersToExr(std::move(layers)), attributes);
    ++run.result().views_from_bake;
    run.result().steps.push_back(
        {"view", camera.name, -1, secondsSince(t0), {{"write", write_s}, {"traced", traced}}});
    run.poll(v1, 1);
    run.report("render", v1, label + ": rendered in " + fixed(secondsSince(t0), 2) + " s",
               camera.name);
  }
  view_cache.reset();
  ro.cache = nullptr;
  if (shot.outputs.vdb && run.scope().writesShotFiles()) {
    run.report("vdb", start.back() / total, "writing bake.vdb (the baked light)");
    auto write = [&] {
      run.writeOutput(kBakeFile, [&](const std::string& path) { writeBakedLight(path, light); });
    };
    if (entry.empty()) {
      write();
    } else {
      try {
        run.copyOutput(kBakeFile, (fs::path(entry) / kBakeFile).string());
      } catch (const fs::filesystem_error&) {
        write();  // the entry was evicted while the views rendered (another process's bound)
      }
    }
  }
}

}  // namespace cloudbake
