#include "core/methods/precomputed.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <tuple>

#include "core/animation/basic_volumes.h"
#include "core/animation/precomputed_io.h"
#include "core/bake/bake_lattice.h"
#include "core/bake/baked_light_vdb.h"
#include "core/bake/render_from_bake.h"
#include "core/bake/sky_sh_scatter.h"
#include "core/bake/sky_visibility.h"
#include "core/bake/sun_transmittance.h"
#include "core/error.h"
#include "core/format.h"
#include "core/io/file_sync.h"
#include "core/methods/common.h"
#include "core/transport/layers_exr.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using Json = nlohmann::json;

std::vector<Knob> precomputedKnobs() {
  const PrecomputedShotOptions d;
  return {
      stepKnob("one lattice voxel"),
      filmSpacingKnob(),
      lightResolutionKnob(d.light_resolution, false),
      Knob::integer("sample_points", 1, int64_t(1) << 20, d.precompute.sample_points,
                    "K: sample points of the multiple-scattering transfer, shared by every "
                    "basic volume"),
      Knob::integer("transfer_resolution", 4, 512, d.precompute.transfer_resolution,
                    "receiver voxels (where multiple scattering is computed) along the longest "
                    "side"),
      Knob::number("cut_error", 0, 1, d.precompute.cuts.cut_error, "",
                   "a cut is refined until each node's clustering error is below this fraction "
                   "of the receiver's total"),
      Knob::integer("iterations", 1, 1000, d.frame.max_orders,
                    "multiple-scattering orders at most (Eq. 8)"),
      Knob::number("tolerance", 0, 1, d.frame.tolerance, "",
                   "stop when an order changes the result by less than this (relative)"),
      Knob::integer("frames", 1, 1000000, std::nullopt,
                    "output frames of endless animation: `DIR/<view>.<ffff>.exr` and "
                    "`DIR/bake.<ffff>.vdb`")
          .derivedDefault("the sequence's frame count (1 for a static volume)"),
      Knob::number("sigma", 0, 1e6, d.walk.sigma, "",
                   "`sequence` volumes only: the walk's temperature, relative to the mean "
                   "RMS-like distance sqrt(D) between basic volumes (small: natural successors; "
                   "large: any jump)"),
      Knob::number("future_cost", 0, kMaxFutureCost, d.walk.future_cost, "",
                   "`sequence` volumes only: alpha, the weight of what a jump leads to (Schoedl "
                   "et al. 2000's future costs), so the walk does not loop at the input's end; "
                   "0: each jump's own cost only, which loops at the database's end",
                   /*exclusive_min=*/false),
      Knob::integer("dissolve", 0, 10000, std::nullopt,
                    "`sequence` volumes only: H, frames of cross-dissolve per jump; at most the "
                    "sequence's frames - 2")
          .derivedDefault("min(8, frames - 2)"),
      Knob::boolean("similarity", d.frame.similarity,
                    "multiple scattering on the similarity-reduced medium with the forward-"
                    "scattered beam and the P1 view model; false: plain isotropic multiple "
                    "scattering as Iwasaki et al. wrote it"),
      Knob::integer("sky_spacing", 1, 2, d.frame.sky_spacing,
                    "voxels between a frame's evaluations of the sky transmittance (SHEXP, Ren "
                    "et al. 2006) along each axis: 2 evaluates every second voxel inside the "
                    "cloud and interpolates the coefficients between where the evaluated mean "
                    "transmittance of the corners agrees within 0.1, evaluating the others (the "
                    "cloud's margin, thin sheets, steep edges); 1 evaluates every voxel "
                    "(version 7)"),
  };
}

// The shot's sequence as the database reads it: the run builds each frame (core/job turns a shot
// into volumes), and errors name the frame's field in the shot.
VolumeFrames sequenceFrames(MethodRun& run, const SequenceVolumeSpec& seq) {
  if (seq.frames < 2) {
    throw InputError(run.source() +
                     ": /volume/sequence/frames: an endless animation needs at least 2 basic "
                     "volumes, got " +
                     std::to_string(seq.frames));
  }
  VolumeFrames frames;
  frames.count = seq.frames;
  frames.build = [&run](int i) { return run.sequenceFrame(i); };
  frames.same_voxel_size = !seq.paths.empty();
  frames.name = [source = run.source()](int i) {
    return source + ": /volume/sequence/paths/" + std::to_string(i);
  };
  return frames;
}

// Reading a cache entry the cache verified: unreadable data is our fault, not input.
template <class F>
void readCached(const char* what, F&& read) {
  try {
    read();
  } catch (const InputError& e) {
    throw InternalError(std::string("cached ") + what + " unreadable: " + e.what());
  }
}

// The database's layout (every basic volume on one lattice, receivers, sample tree) from the
// cache, else built and committed; `entry` receives its folder. Densities are held only when
// it was built here (readLayoutDensities reads the others on demand).
PrecomputedDatabase obtainLayout(MethodRun& run, const PrecomputedShotOptions& o,
                                 std::string* entry) {
  const auto* seq = std::get_if<SequenceVolumeSpec>(&run.shot().volume);
  if (!seq || run.keys().precompute_layout.empty() || !run.hasCache()) {
    throw InternalError("the database's parts need a sequence volume and a cache");
  }
  PrecomputedDatabase layout;
  bool computed = false;
  *entry = run.cached(
      run.keys().precompute_layout,
      [&](const std::string& staging) {
        run.report("bake", 0, "laying out " + std::to_string(o.basic_volumes) + " basic volumes");
        BasicVolumeDatabase vols =
            buildBasicVolumes(sequenceFrames(run, *seq), o.light_resolution,
                              [&](double f) { return run.pollMessage(0.1 * f, "basic volumes"); });
        layout = layoutBasicVolumes(std::move(vols), run.lights().medium.extinction, o.precompute);
        writePrecomputedLayout(staging, layout);
      },
      &computed);
  if (!computed) readCached("layout", [&] { layout = readPrecomputedLayout(*entry); });
  layout.basic.resize(layout.volumes.frames.size());
  return layout;
}

// Basic volume `i` of a laid-out `db` from the cache, else precomputed and committed.
void obtainBasicVolume(MethodRun& run, PrecomputedDatabase& db, const PrecomputedShotOptions& o,
                       const std::string& layout_entry, size_t i) {
  const size_t n = db.volumes.frames.size();
  bool computed = false;
  const std::string entry = run.cached(
      run.keys().precompute_basic.at(i),
      [&](const std::string& staging) {
        if (db.volumes.frames[i].empty()) {
          readCached("layout", [&] { readLayoutDensities(layout_entry, db, i, i + 1); });
        }
        db.basic[i] = precomputeBasicVolume(db, i, o.precompute, [&](double f) {
          return run.pollMessage(0.1 + 0.4 * (double(i) + f) / double(n),
                                 "precomputing basic volume " + std::to_string(i));
        });
        writeBasicVolumes(staging, db, i, i + 1);
      },
      &computed);
  if (!computed) readCached("basic volume", [&] { readBasicVolumes(entry, db, i, i + 1); });
}

// A farm task's part of the database: its layout, or basic volumes [begin, end) of it. Each
// basic volume is dropped once committed, so a task's memory is one volume's.
void runDatabasePart(MethodRun& run, const PrecomputedShotOptions& o) {
  const RunScope& scope = run.scope();
  // The whole database is cached already (a whole run, or this database under other light):
  // its parts are not needed.
  if (run.lookup(run.keys().precompute)) return;
  std::string layout_entry;
  PrecomputedDatabase db = obtainLayout(run, o, &layout_entry);
  if (scope.part != RunScope::Part::kPrecompute) return;
  if (scope.begin < 0 || scope.end > int(db.volumes.frames.size()) || scope.begin >= scope.end) {
    throw InputError(run.source() + ": task: basic volumes [" + std::to_string(scope.begin) + ", " +
                     std::to_string(scope.end) + ") outside the database's " +
                     std::to_string(db.volumes.frames.size()));
  }
  for (int i = scope.begin; i < scope.end; ++i) {
    obtainBasicVolume(run, db, o, layout_entry, size_t(i));
    db.basic[size_t(i)] = {};
    db.volumes.frames[size_t(i)] = {};
  }
}

// The whole database from its parts in the cache (those a farm's tasks left; any missing one
// is computed here): the same database a whole run builds at once.
PrecomputedDatabase assembleDatabase(MethodRun& run, const PrecomputedShotOptions& o) {
  std::string layout_entry;
  PrecomputedDatabase db = obtainLayout(run, o, &layout_entry);
  for (size_t i = 0; i < db.volumes.frames.size(); ++i) {
    obtainBasicVolume(run, db, o, layout_entry, i);
  }
  finishDatabase(db);
  return db;
}

// The database's precompute: from the cache when it holds it, else built and committed, from
// `static_lattice` where staticLattice built it.
PrecomputedDatabase obtainDatabase(MethodRun& run, const PrecomputedShotOptions& o,
                                   std::optional<BakedLight> static_lattice) {
  const ShotSpec& shot = run.shot();
  auto build = [&]() {
    const auto t0 = std::chrono::steady_clock::now();
    run.report("bake", 0, "building " + std::to_string(o.basic_volumes) + " basic volume(s)");
    const bool sequence = std::holds_alternative<SequenceVolumeSpec>(shot.volume);
    if (sequence && !run.scope().all()) return assembleDatabase(run, o);
    BasicVolumeDatabase vols;
    if (const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume)) {
      vols = buildBasicVolumes(sequenceFrames(run, *seq), o.light_resolution, [&](double f) {
        return run.pollMessage(0.1 * f, "building basic volumes");
      });
    } else {
      BakedLight lattice = static_lattice
                               ? std::move(*static_lattice)
                               : makeBakeLattice(*run.scene().medium.density, o.light_resolution);
      vols.grid = lattice.grid;
      vols.frames.push_back(std::move(lattice.density));
    }
    PrecomputedDatabase db = precomputeBasicVolumes(
        std::move(vols), run.lights().medium.extinction, o.precompute,
        [&](double f) { return run.pollMessage(0.1 + 0.4 * f, "precomputing basic volumes"); });
    size_t bytes = 0;
    for (const BasicVolumePrecompute& b : db.basic) bytes += b.bytes();
    const double mib = double(bytes) / db.basic.size() / (1 << 20);
    run.result().steps.push_back({"precompute",
                                  "",
                                  -1,
                                  secondsSince(t0),
                                  {{"cached", 0.0},
                                   {"basic_volumes", double(db.basic.size())},
                                   {"mib_per_basic_volume", mib}}});
    run.report("bake", 0.5,
               "precomputed " + std::to_string(db.basic.size()) + " basic volume(s) in " +
                   fixed(secondsSince(t0), 2) + " s (" + std::to_string(db.tree.points.size()) +
                   " sample points; " + fixed(mib, 1) + " MiB per basic volume)");
    return db;
  };
  RunResult& result = run.result();
  if (!run.hasCache()) {
    result.bakes_computed += 1;
    return build();
  }
  PrecomputedDatabase db;
  bool computed = false;
  const std::string entry = run.cached(
      run.keys().precompute,
      [&](const std::string& staging) {
        db = build();
        writePrecomputedDatabase(staging, db);
      },
      &computed);
  (computed ? result.bakes_computed : result.bakes_cached) += 1;
  if (computed) return db;
  const auto t_read = std::chrono::steady_clock::now();
  try {
    db = readPrecomputedDatabase(entry);
  } catch (const InputError& e) {
    // The cache verified the entry's checksums: unreadable data is our fault, not input.
    throw InternalError(std::string("cached precompute unreadable: ") + e.what());
  }
  result.steps.push_back({"precompute",
                          "",
                          -1,
                          secondsSince(t_read),
                          {{"cached", 1.0}, {"basic_volumes", double(db.basic.size())}}});
  run.report(
      "bake", 0.5,
      "precompute of " + std::to_string(db.basic.size()) + " basic volume(s) from the cache");
  return db;
}

// The walk over the database (a single basic volume repeats itself).
std::vector<BlendFrame> walkDatabase(MethodRun& run, const PrecomputedDatabase& db,
                                     const PrecomputedShotOptions& o) {
  const int n = int(db.basic.size());
  if (n == 1) return std::vector<BlendFrame>(size_t(o.frames), BlendFrame{0, 0, 1.0});
  // Both are O(volumes^2): seconds for thousands of volumes, so they heed a cancel. The
  // distances' rows run on worker threads, which take turns asking.
  std::mutex mutex;
  bool stop = false;
  const std::function<bool()> keep_going = [&] {
    std::lock_guard<std::mutex> lock(mutex);
    if (!stop) stop = !run.poll(0);
    return !stop;
  };
  const std::vector<double> p =
      transitionProbabilities(frameDistances(db.volumes.frames, keep_going), n, o.walk, keep_going);
  return endlessWalk(p, n, o.frames, o.walk);
}

// animation.json, written after the frames: a run that fails midway leaves no walk naming
// frames it never wrote.
void writeAnimation(MethodRun& run, const std::vector<BlendFrame>& walk, int basic_volumes) {
  if (!run.scope().writesShotFiles()) return;
  const int n = basic_volumes;
  Json animation = {{"basic_volumes", n}, {"frames", Json::array()}};
  for (const BlendFrame& f : walk) {
    animation["frames"].push_back({{"a", f.a}, {"b", f.b}, {"w", f.w}});
  }
  run.writeOutput("animation.json", [&](const std::string& path) {
    writeTextAtomically(path, animation.dump(1) + "\n");  // two tasks may write it at once
  });
}

// Progress: the precompute weighs as much as all frames together.
struct FrameProgress {
  double units;
  int per_frame;
  double at(int frame, double unit) const { return 0.5 + 0.5 * (frame * per_frame + unit) / units; }
};

// Frames the walk shows again. An endless walk repeats its blends (a natural successor is a
// whole basic volume, and a jump back replays the same dissolve: examples/endless_cloud.json's
// 24 frames hold 13 blends), and the walk is known before any frame is lit, so a frame's light
// and its rendered views are kept from its first frame to the last later frame of the same
// blend, while what is kept fits in kRepeatedFrameBytes. A frame's light depends on nothing but
// its blend and the shot's cameras do not move, so a repeat is the same light and the same
// pixels; only the files, which name their frame, are written again.
struct KeptFrame {
  std::shared_ptr<const BakedLight> light;
  std::vector<RenderLayers> views;  // the shot's first views.size() views, as rendered
};

class RepeatedFrames {
 public:
  RepeatedFrames(const std::vector<BlendFrame>& walk, const RunScope& scope)
      : first_(walk.size()), last_(walk.size()) {
    std::map<std::tuple<int, int, double>, size_t> seen;  // a blend's first rendered frame
    for (size_t f = 0; f < walk.size(); ++f) {
      first_[f] = last_[f] = f;
      if (!scope.renders(int(f))) continue;
      const BlendFrame& b = walk[f];
      first_[f] = seen.emplace(std::make_tuple(b.a, b.b, b.w), f).first->second;
      last_[first_[f]] = f;
    }
  }

  /// What an earlier frame of frame f's blend kept, else null.
  const KeptFrame* find(size_t f) const {
    const auto it = kept_.find(first_[f]);
    return it == kept_.end() || first_[f] == f ? nullptr : &it->second;
  }

  /// Where frame f, the first of its blend, keeps its light and views for a later frame of its
  /// blend; null where none follows or its light does not fit.
  KeptFrame* keep(size_t f, const std::shared_ptr<const BakedLight>& light) {
    if (first_[f] != f || last_[f] == f || !admit(lightBytes(*light))) return nullptr;
    KeptFrame& k = kept_[f];
    k.light = light;
    return &k;
  }

  /// Counts `bytes` more kept where they fit.
  bool admit(size_t bytes) {
    if (bytes_ + bytes > kRepeatedFrameBytes) return false;
    bytes_ += bytes;
    return true;
  }

  /// Drops what frame f's blend kept where f is its last frame.
  void done(size_t f) {
    const auto it = kept_.find(first_[f]);
    if (it == kept_.end() || last_[first_[f]] != f) return;
    bytes_ -= lightBytes(*it->second.light);
    for (const RenderLayers& v : it->second.views) bytes_ -= layersBytes(v);
    kept_.erase(it);
  }

  static size_t layersBytes(const RenderLayers& l) {
    size_t floats = 0;
    for (const Image* i : {&l.beauty, &l.background, &l.sun, &l.sky, &l.single, &l.multiple}) {
      floats += i->data.size();
    }
    return floats * sizeof(float);
  }

 private:
  static constexpr size_t kRepeatedFrameBytes = size_t(1) << 30;
  static size_t lightBytes(const BakedLight& l) {
    size_t floats = l.density.size();
    for (const auto& [name, c] : l.channels) floats += c.data.size();
    return floats * sizeof(float);
  }
  std::vector<size_t> first_;  // per frame: the first rendered frame of its blend
  std::vector<size_t> last_;   // per first frame: the last rendered frame of its blend
  std::map<size_t, KeptFrame> kept_;
  size_t bytes_ = 0;
};

// A frame's part in RepeatedFrames: the views an earlier frame of its blend rendered
// (`replay`), or where it keeps its own (`keep`); both null where neither.
struct FrameReuse {
  const KeptFrame* replay = nullptr;
  KeptFrame* keep = nullptr;
  RepeatedFrames* frames = nullptr;
};

/// Renders frame f's views of `light`; `cache` keeps its memory from frame to frame and what it
/// holds from view to view of the frame.
void renderFrame(MethodRun& run, const BakedLight& light, const BlendFrame& bf, int f,
                 const FrameProgress& progress, BakeViewCache& cache,
                 const FrameReuse& reuse = {}) {
  const ShotSpec& shot = run.shot();
  const Scene& lights = run.lights();
  BakeRenderOptions ro = frameRenderOptions(shot, light, run.threads());
  cache.forget();  // another frame's light, maybe at the same addresses
  ro.cache = &cache;
  const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
  for (int i = 0; i < n_views; ++i) {
    const Camera& camera = lights.cameras[size_t(i)];
    const auto t_view = std::chrono::steady_clock::now();
    run.report("render", progress.at(f, 1 + i),
               "frame " + std::to_string(f) + ", view '" + camera.name + "'", camera.name);
    const bool replayed = reuse.replay && size_t(i) < reuse.replay->views.size();
    RenderLayers layers =
        replayed
            ? reuse.replay->views[size_t(i)]
            : renderFromBake(light, lights.medium, lights.sun, lights.sky, camera, ro,
                             [&](double fr) { return run.poll(progress.at(f, 1 + i + fr), fr); });
    if (!replayed && reuse.keep && reuse.keep->views.size() == size_t(i) &&
        reuse.frames->admit(RepeatedFrames::layersBytes(layers))) {
      reuse.keep->views.push_back(layers);
    }
    const double traced = tracedShare(layers);
    const double write_s = run.writeView(
        frameStem(camera.name, f), camera, renderLayersToExr(std::move(layers)),
        {{"cloudbake:frame", std::to_string(f)},
         {"cloudbake:blend",
          std::to_string(bf.a) + " " + std::to_string(bf.b) + " " + std::to_string(bf.w)},
         {"cloudbake:samples", std::to_string(ro.samples_per_pixel)},
         {"cloudbake:seed", std::to_string(ro.seed)},
         {"cloudbake:film_spacing", std::to_string(filmSpacingOf(light, camera, ro))}});
    ++run.result().views_from_bake;
    run.result().steps.push_back(
        {"view",
         camera.name,
         f,
         secondsSince(t_view),
         {{"write", write_s}, {"traced", traced}, {"repeated", replayed ? 1.0 : 0.0}}});
    run.report("render", progress.at(f, 2 + i),
               "frame " + std::to_string(f) + ", view '" + camera.name + "' " +
                   std::to_string(camera.width_px) + "x" + std::to_string(camera.height_px) +
                   " rendered in " + fixed(secondsSince(t_view), 2) + " s",
               camera.name);
  }
  if (shot.outputs.vdb) {
    run.writeOutput(frameStem("bake", f) + ".vdb",
                    [&](const std::string& path) { writeBakedLight(path, light); });
  }
}

class PrecomputedMethod final : public BakeMethod {
 public:
  PrecomputedMethod() {
    info_.name = "precomputed";
    info_.summary =
        "endless cloud animation from a database of basic volumes, each precomputed once "
        "independent of the light (Iwasaki, Nishino and Dobashi 2011)";
    info_.citation =
        "Iwasaki, Nishino and Dobashi 2011, \"Real-time rendering of endless cloud animation\" "
        "(Pacific Graphics, Computer Graphics Forum 30(7))";
    // 8: the sky transmittance's SHEXP on every second voxel, interpolated between (knob
    //    sky_spacing; 1 is version 7's output). 9: a box volume's exact means on the lattice.
    // 10: the walk's future costs (knob future_cost) on costs sqrt(D), and the last volume may
    //     jump to the first.
    // 11 was taken by the reverted bd0ae60 and c0838b0 (a sparse film refining its cells): the
    // next change is 12, so no cache holds two physics under one number.
    info_.version = 10;
    info_.default_samples = 1;
    info_.max_samples = kMaxViewSamples;
    info_.bakes_light = true;
    info_.animates = true;
    info_.knobs = precomputedKnobs();
  }
  const MethodInfo& info() const override { return info_; }

  void validate(const ShotSpec& shot, const std::string& source) const override;
  nlohmann::json keyMaterial(const ShotSpec& shot, const nlohmann::json& canonical) const override;
  MethodPlan plan(const ShotSpec& shot, const ShotCacheKeys& keys,
                  const std::function<bool(const std::string&)>& lookup) const override;
  void checkLimits(const ShotSpec& shot, const MethodLimits& limits,
                   const std::string& source) const override;
  void run(MethodRun& run) const override;

 private:
  MethodInfo info_;
};

// The walk's knobs need a database of basic volumes (a sequence), and the dissolve must fit in
// it (Iwasaki et al.: a jump to l plays l .. l + H - 1).
void PrecomputedMethod::validate(const ShotSpec& shot, const std::string& source) const {
  checkPhaseTable(shot, source, "precomputed");
  const KnobValues& k = shot.bake.knobs;
  const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume);
  if (!seq) {
    for (const char* key : {"sigma", "dissolve", "future_cost"}) {
      if (!k.has(key)) continue;
      throw InputError(source + ": /bake/" + key + ": applies to animated volumes only (a " +
                       volumeTypeName(shot.volume) +
                       " volume is one basic volume: every frame is the same)");
    }
    checkAnalyticLattice(shot, int(k.integer("light_resolution")), source);
    return;
  }
  const auto h = k.optionalInteger("dissolve");
  const int64_t n = seq->frames;
  if (h && *h > n - 2) {
    throw InputError(source + ": /bake/dissolve: " + std::to_string(*h) +
                     " frames of cross-dissolve do not fit a database of " + std::to_string(n) +
                     " basic volumes (at most frames - 2 = " +
                     std::to_string(std::max<int64_t>(0, n - 2)) + ")");
  }
}

Json PrecomputedMethod::keyMaterial(const ShotSpec& shot, const Json& canonical) const {
  // Not in it: sun, sky, albedo, phase, views, frames and the walk's knobs, so every lighting
  // and every animation of the same database reuses the precompute.
  const KnobValues& k = shot.bake.knobs;
  return {{"precompute",
           {{"extinction", canonical["medium"]["extinction"]},
            {"seed", shot.bake.seed},
            {"file_version", kPrecomputedFileVersion},
            {"light_resolution", k.integer("light_resolution")},
            {"sample_points", k.integer("sample_points")},
            {"transfer_resolution", k.integer("transfer_resolution")},
            {"cut_error", k.number("cut_error")}}}};
}

MethodPlan PrecomputedMethod::plan(const ShotSpec& shot, const ShotCacheKeys& keys,
                                   const std::function<bool(const std::string&)>& lookup) const {
  const PrecomputedShotOptions o = precomputedOptions(shot);
  MethodPlan plan;
  plan.bake_key = keys.precompute;
  plan.bake_cached = lookup(keys.precompute);
  if (plan.bake_cached) {
    plan.components.push_back("precompute: already in the cache for this database (no precompute)");
  } else {
    plan.components.push_back("basic volumes: " + std::to_string(o.basic_volumes) + " (" +
                              volumeTypeName(shot.volume) + "), each resampled to a " +
                              std::to_string(o.light_resolution) + "-voxel lattice (longest side)");
    plan.components.push_back(
        "precompute per basic volume: optical-depth SH (64 direction sweeps), " +
        std::to_string(o.precompute.sample_points) + " sample points, cuts on a " +
        std::to_string(o.precompute.transfer_resolution) + "-voxel receiver lattice (cut error " +
        shortNumber(o.precompute.cuts.cut_error) + ")");
  }
  plan.components.push_back(
      "frames: " + std::to_string(o.frames) + " of endless animation (sigma " +
      shortNumber(o.walk.sigma) + ", cross-dissolve over " +
      std::to_string(o.walk.dissolve_frames) +
      " frames), each lit by a sun sweep, the sky's SHEXP " +
      (o.frame.sky_spacing == 1 ? std::string("at every voxel")
                                : std::string("at every second voxel where the transmittance "
                                              "varies smoothly inside the cloud, else at each")) +
      " and up to " + std::to_string(o.frame.max_orders) + " multiple-scattering orders");
  if (shot.outputs.exr) {
    for (const Camera& c : shot.views) {
      plan.view_cached.push_back(plan.bake_cached);
      plan.pixel_samples += double(c.width_px) * c.height_px * shot.bake.samples * o.frames;
      plan.components.push_back("view '" + c.name + "': ray march from each frame's light, " +
                                std::to_string(o.frames) + " frame(s), " +
                                std::to_string(c.width_px) + "x" + std::to_string(c.height_px) +
                                ", " + std::to_string(shot.bake.samples) + " ray(s) per pixel");
    }
  }
  if (shot.outputs.vdb) plan.components.push_back("bake.<frame>.vdb: each frame's light lattice");
  return plan;
}

void PrecomputedMethod::checkLimits(const ShotSpec& shot, const MethodLimits& limits,
                                    const std::string& source) const {
  const PrecomputedShotOptions o = precomputedOptions(shot);
  // The database in memory: every basic volume's lattice, each voxel holding its density and
  // 16 optical-depth SH coefficients, so it counts 17 times (the cuts are on the much coarser
  // receiver lattice).
  checkLatticeVoxels(
      o.light_resolution, 17.0 * o.basic_volumes,
      "a database of " + std::to_string(o.basic_volumes) + " basic volume(s), 17 floats per voxel,",
      limits, source);
  // The walk's distances and transition probabilities: two n x n tables of doubles.
  const double walk_floats = 4.0 * double(o.basic_volumes) * double(o.basic_volumes);
  if (limits.max_voxels > 0 && walk_floats > double(limits.max_voxels)) {
    throw InputError(
        source + ": /volume/sequence/frames: the walk over " + std::to_string(o.basic_volumes) +
        " basic volumes holds two tables of frames^2 doubles, " + shortNumber(walk_floats) +
        " floats, over the limit of " + std::to_string(limits.max_voxels) + " (--max-voxels)");
  }
  checkPointCount(o.precompute.sample_points, "/bake/sample_points", limits, source);
  if (limits.max_frames > 0 && o.frames > limits.max_frames) {
    throw InputError(source + ": /bake/frames: " + std::to_string(o.frames) +
                     " output frames exceed this server's limit of " +
                     std::to_string(limits.max_frames) + " (--max-frames)");
  }
}

// A static volume's lattice where its database is to be built here (not for a sequence, nor a
// database the cache holds): built once, for the database and for the check of
// renderEmptyCloud.
std::optional<BakedLight> staticLattice(MethodRun& run, const PrecomputedShotOptions& o) {
  if (std::holds_alternative<SequenceVolumeSpec>(run.shot().volume)) return std::nullopt;
  if (run.hasCache() && run.lookup(run.keys().precompute)) return std::nullopt;
  return makeBakeLattice(*run.scene().medium.density, o.light_resolution);
}

// An empty cloud (a static volume whose density is 0 everywhere, or on every voxel of its
// lattice: a field sampled onto it whose features all fall between the samples) is a valid
// shot, as for every method: each frame renders the background from a zero bake. No database
// can be built for it (its sample points would have nowhere to go).
bool renderEmptyCloud(MethodRun& run, const PrecomputedShotOptions& o,
                      std::optional<BakedLight>& lattice) {
  const ShotSpec& shot = run.shot();
  if (std::holds_alternative<SequenceVolumeSpec>(shot.volume)) return false;
  const Scene& scene = run.scene();
  const bool field_empty = !(scene.medium.density->maxDensity() > 0);
  if (!field_empty && (!lattice || std::any_of(lattice->density.begin(), lattice->density.end(),
                                               [](float v) { return v > 0; }))) {
    return false;
  }
  BakedLight light =
      lattice ? std::move(*lattice) : makeBakeLattice(*scene.medium.density, o.light_resolution);
  lattice.reset();
  light.method = "precomputed";
  light.sun_direction = sunDirection(shot);
  computeSunTransmittance(light, light.sun_direction, scene.medium.extinction, {});
  computeSkyVisibility(light, scene.medium.extinction, {});
  light.metadata["cloudbake:empty_cloud"] = "1";
  run.result().bakes_computed += 1;
  const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
  const int per_frame = n_views + (shot.outputs.vdb ? 1 : 0) + 1;
  const FrameProgress progress{double(o.frames) * per_frame, per_frame};
  BakeViewCache cache;
  for (int f = 0; f < o.frames; ++f) {
    if (run.scope().renders(f)) renderFrame(run, light, BlendFrame{0, 0, 1}, f, progress, cache);
  }
  // A static volume is one basic volume, shown by every frame (an outside probe: the walk was
  // not written for an empty cloud, by a run or a farm's gather).
  writeAnimation(run, std::vector<BlendFrame>(size_t(o.frames), BlendFrame{0, 0, 1}), 1);
  return true;
}

void PrecomputedMethod::run(MethodRun& run) const {
  const ShotSpec& shot = run.shot();
  const PrecomputedShotOptions o = precomputedOptions(shot);
  std::optional<BakedLight> lattice = staticLattice(run, o);
  if (renderEmptyCloud(run, o, lattice)) return;
  const RunScope& scope = run.scope();
  if (scope.part == RunScope::Part::kLayout || scope.part == RunScope::Part::kPrecompute) {
    runDatabasePart(run, o);
    return;
  }
  const PrecomputedDatabase db = obtainDatabase(run, o, std::move(lattice));
  if (scope.part == RunScope::Part::kBake) return;
  const std::vector<BlendFrame> walk = walkDatabase(run, db, o);
  const int basic_volumes = int(db.basic.size());
  if (!scope.rendersAny()) {
    writeAnimation(run, walk, basic_volumes);
    return;
  }

  const Scene& lights = run.lights();
  const std::array<ShCoefficients, 3> sky_sh =
      needsSky(shot) ? projectSkyRadiance(SkyLight(lights.sky)) : std::array<ShCoefficients, 3>{};
  FrameLightOptions frame_options = o.frame;
  frame_options.mean_cosine = lights.medium.phase->meanCosine();
  const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
  const int per_frame = n_views + (shot.outputs.vdb ? 1 : 0) + 1;
  const FrameProgress progress{double(o.frames) * per_frame, per_frame};
  RepeatedFrames repeated(walk, scope);
  BakeViewCache cache;
  for (int f = 0; f < o.frames; ++f) {
    if (!scope.renders(f)) continue;
    const BlendFrame& bf = walk[size_t(f)];
    const auto t0 = std::chrono::steady_clock::now();
    FrameReuse reuse;
    reuse.frames = &repeated;
    reuse.replay = repeated.find(size_t(f));
    std::shared_ptr<const BakedLight> light = reuse.replay ? reuse.replay->light : nullptr;
    const std::string blend = "frame " + std::to_string(f) + " (basic volumes " +
                              std::to_string(bf.a) + ", " + std::to_string(bf.b) + ", w " +
                              fixed(bf.w, 3) + "): ";
    if (light) {
      run.result().steps.push_back({"light", "", f, 0.0, {{"repeated", 1.0}}});
      run.report("render", progress.at(f, 0),
                 blend + "lit and its first " + std::to_string(reuse.replay->views.size()) +
                     " view(s) rendered as an earlier frame of its blend");
    } else {
      FrameLightStats stats;
      light = std::make_shared<const BakedLight>(lightAnimationFrame(
          db, bf, sunDirection(shot), lights.medium.albedo, sky_sh, frame_options, &stats));
      reuse.keep = repeated.keep(size_t(f), light);
      run.result().steps.push_back(
          {"light", "", f, stats.seconds, {{"orders", double(stats.orders)}}});
      run.report("render", progress.at(f, 0),
                 blend + "lit in " + fixed(stats.seconds, 2) + " s, " +
                     std::to_string(stats.orders) + " orders");
    }
    renderFrame(run, *light, bf, f, progress, cache, reuse);
    repeated.done(size_t(f));
    run.report("render", progress.at(f + 1, 0),
               "frame " + std::to_string(f) + " done in " + fixed(secondsSince(t0), 2) + " s");
  }
  writeAnimation(run, walk, basic_volumes);
}

}  // namespace

const BakeMethod& precomputedMethod() {
  static const PrecomputedMethod kMethod;
  return kMethod;
}

BakeRenderOptions frameRenderOptions(const ShotSpec& shot, const BakedLight& frame, int threads) {
  BakeRenderOptions o = bakeRenderOptions(shot, threads);
  // A frame's sources vary on its lattice smoothly enough that a whole voxel a step costs no
  // measured accuracy and halves the march, the larger half of a frame's time. Measured against
  // `pathtrace` (two 1024-path renders) on bench/precomputed_bench.py's Perlin cloud, 160x120:
  // the scattered light's relative RMSE 0.319 -> 0.321 from the side, 0.761 -> 0.756 towards
  // the sun, the layers' means within 0.6 %.
  if (!(o.step > 0)) o.step = frame.grid.voxel_size;
  return o;
}

PrecomputedShotOptions precomputedOptions(const ShotSpec& shot) {
  const KnobValues& k = shot.bake.knobs;
  PrecomputedShotOptions o;
  o.light_resolution = int(k.integer("light_resolution"));
  o.precompute.sample_points = int(k.integer("sample_points"));
  o.precompute.transfer_resolution = int(k.integer("transfer_resolution"));
  o.precompute.cuts.cut_error = k.number("cut_error");
  o.precompute.seed = shot.bake.seed;
  o.frame.max_orders = int(k.integer("iterations"));
  o.frame.tolerance = k.number("tolerance");
  o.frame.similarity = k.boolean("similarity");
  o.frame.sky_spacing = int(k.integer("sky_spacing"));
  const auto* seq = std::get_if<SequenceVolumeSpec>(&shot.volume);
  o.basic_volumes = seq ? seq->frames : 1;
  o.walk.sigma = k.number("sigma");
  o.walk.future_cost = k.number("future_cost");
  o.walk.dissolve_frames =
      int(k.optionalInteger("dissolve")
              .value_or(std::max(0, std::min(o.walk.dissolve_frames, o.basic_volumes - 2))));
  o.walk.seed = shot.bake.seed;
  o.frames = int(k.optionalInteger("frames").value_or(o.basic_volumes));
  return o;
}

std::string frameStem(const std::string& stem, int frame) {
  char buf[32];
  std::snprintf(buf, sizeof buf, ".%04d", frame);
  return stem + buf;
}

}  // namespace cloudbake
