#include "core/job/run_shot.h"

#include <fcntl.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <utility>

#include "core/error.h"
#include "core/format.h"
#include "core/io/exr_io.h"
#include "core/job/bake_cache.h"
#include "core/job/cache_key.h"
#include "core/job/direction_index.h"
#include "core/job/file_util.h"
#include "core/job/phase_cache.h"
#include "core/job/replaced_outputs.h"
#include "core/job/run_outputs.h"
#include "core/job/volume_cache.h"
#include "core/job/volume_limits.h"
#include "core/methods/common.h"
#include "core/methods/registry.h"
#include "core/shot/scene_builder.h"
#include "core/transport/camera.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

void checkRunOptions(const RunOptions& opt) {
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
  checkSamplesOverride(opt.samples, "samples");
  if (!opt.scope.all() && !opt.cache) {
    throw InputError("scope: a part of a shot (a farm task) needs a bake cache");
  }
}

// The shot's EXR compression. A shot built in code, not parsed, may carry any name: runShot
// checks it before anything runs (checkRunnable), and writeView looks it up again.
ExrCompression exrCompressionOf(const ShotSpec& shot, const std::string& source) {
  const auto c = exrCompressionFromName(shot.outputs.exr_compression);
  if (!c) {
    throw InputError(source + ": /outputs/exr_compression: unknown EXR compression '" +
                     shot.outputs.exr_compression + "' (known: " + exrCompressionNamesList() +
                     "; lossless only)");
  }
  return *c;
}

const ExrLayer& layerNamed(const std::vector<ExrLayer>& layers, const std::string& name) {
  for (const ExrLayer& l : layers) {
    if (l.name == name) return l;
  }
  throw InternalError("a view's layers lack '" + name + "'");
}

// The layers of outputs.exr_layers, in its order, from a view's every layer ("cloud" is the
// unprefixed one). Copies: a view is written once, and the copy is small beside its compression.
std::vector<ExrLayer> chosenLayers(const std::vector<ExrLayer>& layers,
                                   const std::vector<std::string>& names) {
  if (names.empty()) throw InternalError("outputs.exr_layers: no layer to write");
  std::vector<ExrLayer> chosen;
  for (const std::string& name : names) {
    chosen.push_back(layerNamed(layers, name == "cloud" ? "" : name));
  }
  return chosen;
}

// MethodRun over runShot's options: the cache, the volume cache, the direction index, the
// output folder and the progress callback. The method's fraction of its work is the run's.
class ShotRun final : public MethodRun {
 public:
  ShotRun(const ShotSpec& shot, const RunOptions& opt, ShotCacheKeys keys)
      : shot_(shot), opt_(opt), keys_(std::move(keys)) {}
  /// `density`: the shot's field, already built (by auto's measurement).
  void setDensity(DensityFieldPtr density) { density_ = std::move(density); }
  /// Header attributes every view gets (auto's choice).
  void setHeader(std::map<std::string, std::string> header) { header_ = std::move(header); }
  /// The run failed and removed its files: the earlier files they replaced come back. One that
  /// cannot stays under its hidden name, which the log names.
  void restoreReplaced() {
    for (const std::string& hidden : replaced_.restore()) {
      pollMessage(progress_.fraction, "could not put back the earlier file kept as " + hidden);
    }
  }
  /// The run succeeded: the earlier files it replaced are deleted.
  void commitReplaced() { replaced_.commit(); }
  ~ShotRun() override {
    std::error_code ec;
    if (!scratch_.empty()) fs::remove_all(scratch_, ec);
  }

  const ShotSpec& shot() const override { return shot_; }
  const ShotCacheKeys& keys() const override { return keys_; }
  int threads() const override { return opt_.threads; }
  const std::string& source() const override { return opt_.source; }
  RunResult& result() override { return result_; }
  const RunScope& scope() const override { return opt_.scope; }

  const Scene& lights() override {
    if (!scene_) {
      ShotSpec light = shot_;
      light.volume = BoxVolumeSpec{{0, 0, 0}, {1, 1, 1}, 0.0};  // stand-in until scene()
      scene_ = buildScene(light, opt_.source, [this](const PhaseSpec& spec) {
        const auto t0 = std::chrono::steady_clock::now();
        bool cached = false;
        auto phase = cachedPhase(spec, opt_.phases, &cached, [this] { return keepGoing(); });
        if (spec.type == PhaseSpec::Type::kMie) {
          result_.steps.push_back(
              {"phase", "", -1, secondsSince(t0), {{"cached", cached ? 1.0 : 0.0}}});
        }
        return phase;
      });
    }
    return *scene_;
  }

  const Scene& scene() override;
  DensityFieldPtr sequenceFrame(int frame) override {
    const auto* sequence = std::get_if<SequenceVolumeSpec>(&shot_.volume);
    if (!sequence) throw InternalError("sequenceFrame: the shot's volume is not a sequence");
    DensityFieldPtr density;
    if (sequence->paths.empty() || opt_.vdb_reader.command.empty()) {
      density = buildSequenceFrame(*sequence, frame, opt_.source);
    } else {
      SequenceVolumeSpec readable = *sequence;
      const std::string& path = sequence->paths.at(size_t(frame));
      readable.paths[size_t(frame)] =
          readableVdb(path, "/volume/sequence/paths/" + std::to_string(frame));
      density = readRewrite(path, readable.paths[size_t(frame)],
                            [&] { return buildSequenceFrame(readable, frame, opt_.source); });
    }
    // Each frame as a static volume is: densities past what tracking resolves are refused.
    const std::string which = sequence->paths.empty()
                                  ? "frame " + std::to_string(frame)
                                  : "/volume/sequence/paths/" + std::to_string(frame);
    checkTrackableOpticalDepth(shot_, *density, opt_.source, which);
    return density;
  }

  void report(const std::string& stage, double fraction, const std::string& message,
              const std::string& view = "") override {
    if (view != progress_.view) progress_.view_fraction = 0;
    progress_.view = view;
    progress_.stage = stage;
    progress_.message = message;
    if (!send(fraction)) throw Cancelled();
  }
  bool poll(double fraction, double view_fraction) override {
    progress_.view_fraction = view_fraction;
    return send(fraction);
  }
  bool pollMessage(double fraction, const std::string& message) override {
    progress_.message = message;
    return send(fraction);
  }
  /// For long builds on worker threads (a Lorenz-Mie table): thread safe, asks the progress
  /// callback at most every 0.1 s and answers from its last reply in between.
  bool keepGoing() {
    std::lock_guard<std::mutex> lock(keep_going_mutex_);
    const auto now = std::chrono::steady_clock::now();
    if (now - last_keep_going_ >= std::chrono::milliseconds(100)) {
      last_keep_going_ = now;
      keep_going_ = send(progress_.fraction);
    }
    return keep_going_;
  }

  std::string cached(const std::string& key,
                     const std::function<void(const std::string& staging)>& compute,
                     bool* computed) override;
  bool hasCache() const override { return opt_.cache != nullptr; }
  std::optional<std::string> lookup(const std::string& key) override {
    return opt_.cache ? opt_.cache->lookup(key) : std::nullopt;
  }

  std::vector<Vec3> nearbySunDirections(const std::string& family) override {
    if (!opt_.directions || !(opt_.sun_tolerance_deg > 0) || !shot_.lighting.has_sun) return {};
    return opt_.directions->near(family, quantiseDirection(shot_.lighting.sun.direction),
                                 opt_.sun_tolerance_deg);
  }
  void addSunDirection(const std::string& family) override {
    if (opt_.directions && shot_.lighting.has_sun) {
      opt_.directions->add(family, quantiseDirection(shot_.lighting.sun.direction));
    }
  }
  std::string lightKeyAt(const Vec3& d) override { return cloudbake::lightKeyAt(keys_, d); }
  std::string viewKeyAt(int view, const Vec3& d) override {
    return cloudbake::viewKeyAt(keys_, size_t(view), d);
  }

  double writeView(const std::string& stem, const Camera& camera,
                   const std::vector<ExrLayer>& layers,
                   const std::map<std::string, std::string>& attributes) override;
  void writeOutput(const std::string& name,
                   const std::function<void(const std::string& path)>& write) override {
    const std::string path = (fs::path(opt_.out_dir) / name).string();
    replaced_.keep(path);
    write(path);
    result_.files.push_back(describeOutput(opt_.out_dir, name));
  }
  void copyOutput(const std::string& name, const std::string& from) override {
    // A copy, not a link: the job's file must not change if the cache entry is tampered with.
    const fs::path path = fs::path(opt_.out_dir) / name;
    const std::string tmp = path.string() + ".tmp." + uniqueSuffix();
    try {
      fs::copy_file(from, tmp, fs::copy_options::overwrite_existing);
      replaced_.keep(path.string());
      fs::rename(tmp, path);
    } catch (const fs::filesystem_error& e) {
      std::error_code ec;
      fs::remove(tmp, ec);
      throwIfNoSpace(e.code().value(), e.what());
      throw;
    }
    result_.files.push_back(describeOutput(opt_.out_dir, name));
  }

 private:
  // Progress never goes back: a method's parts report within their shares, and a part that
  // re-reports its start (a stage's first line after its last poll) must not pull the bar back.
  bool send(double fraction) {
    progress_.fraction = std::max(progress_.fraction, std::clamp(fraction, 0.0, 1.0));
    return !opt_.progress || opt_.progress(progress_);
  }

  const ShotSpec& shot_;
  const RunOptions& opt_;
  const ShotCacheKeys keys_;
  RunResult result_;
  ReplacedOutputs replaced_;
  RunProgress progress_;
  std::optional<Scene> scene_;
  bool density_built_ = false;
  DensityFieldPtr density_;
  std::map<std::string, std::string> header_;
  std::mutex keep_going_mutex_;
  std::chrono::steady_clock::time_point last_keep_going_{};
  bool keep_going_ = true;
  // The shot's volume, its VDB file read from a child's rewrite with a VDB reader command.
  DensityFieldPtr buildReadableVolume() {
    const auto* vdb = std::get_if<VdbVolumeSpec>(&shot_.volume);
    if (!vdb || opt_.vdb_reader.command.empty()) {
      return buildVolume(shot_.volume, opt_.source, [this] { return !keepGoing(); });
    }
    VdbVolumeSpec readable = *vdb;
    readable.path = readableVdb(vdb->path, "/volume/vdb");
    return readRewrite(vdb->path, readable.path,
                       [&] { return buildVolume(VolumeSpec(readable), opt_.source); });
  }
  // The rewrite of user VDB file `path` (vdb_gate.h), made once per run in the scratch folder;
  // errors name the shot's field `pointer`.
  std::string readableVdb(const std::string& path, const std::string& pointer) {
    auto it = rewritten_.find(path);
    if (it != rewritten_.end()) return it->second;
    const std::string out =
        (fs::path(scratchDir()) / ("vdb-" + std::to_string(rewritten_.size()) + ".vdb")).string();
    try {
      rewriteVdbInChild(opt_.vdb_reader, path, out, [this] { return keepGoing(); });
    } catch (const InputError& e) {
      throw InputError(opt_.source + ": " + pointer + ": " + e.what());
    }
    return rewritten_[path] = out;
  }
  std::string scratchDir() {
    if (scratch_.empty()) {
      scratch_ = (fs::temp_directory_path() / ("cloudbake-run-" + uniqueSuffix())).string();
    }
    fs::create_directories(scratch_);
    return scratch_;
  }

  std::map<std::string, std::string> rewritten_;  // user VDB path -> its rewrite
  // Removed with the run: where cached() computes without a cache, and the VDB rewrites.
  std::string scratch_;
  int scratch_count_ = 0;
};

const Scene& ShotRun::scene() {
  Scene& s = const_cast<Scene&>(lights());
  if (density_built_) return s;
  if (density_) {
    checkTrackableOpticalDepth(shot_, *density_, opt_.source);
    s.medium.density = density_;
    density_built_ = true;
    return s;
  }
  const auto t0 = std::chrono::steady_clock::now();
  // Limits that need the files: checked before voxelising a mesh, and on a loaded VDB before it
  // enters the memory cache.
  auto build = [&] {
    checkMeshVoxels(shot_, opt_.max_voxels, opt_.source);
    DensityFieldPtr field = buildReadableVolume();
    checkLoadedVoxels(shot_, *field, opt_.max_voxels, opt_.source);
    return field;
  };
  s.medium.density = opt_.volumes
                         ? opt_.volumes->getOrBuild(keys_.volume, build, &result_.volume_cached)
                         : build();
  // Per shot, not in build: a cached field may come from a shot of another extinction.
  checkTrackableOpticalDepth(shot_, *s.medium.density, opt_.source);
  density_built_ = true;
  result_.steps.push_back(
      {"volume", "", -1, secondsSince(t0), {{"cached", result_.volume_cached ? 1.0 : 0.0}}});
  // Built lazily, inside whichever stage first needs it: keep that stage and fraction.
  report(progress_.stage, progress_.fraction,
         "built " + s.medium.density->describe() + " in " + fixed(secondsSince(t0), 2) + " s" +
             (result_.volume_cached ? " (volume from memory cache)" : ""),
         progress_.view);
  return s;
}

std::string ShotRun::cached(const std::string& key,
                            const std::function<void(const std::string& staging)>& compute,
                            bool* computed) {
  *computed = false;
  if (!opt_.cache) {
    const std::string dir = (fs::path(scratchDir()) / std::to_string(scratch_count_++)).string();
    fs::create_directories(dir);
    compute(dir);
    *computed = true;
    return dir;
  }
  const RunProgress at = progress_;
  return opt_.cache->getOrCompute(
      key,
      [&](const std::string& staging) {
        compute(staging);
        *computed = true;
      },
      [&] { return opt_.progress && !opt_.progress(at); });
}

// A view whose pixels are not all finite is never written. An infinity is light beyond what an
// EXR's 32-bit floats hold (pointcloud's rule "paper" grows without bound with its passes: at
// a sun irradiance of 1e10 it wrote inf pixels and succeeded); a NaN is a bug.
void checkFinitePixels(const std::vector<ExrLayer>& layers, const std::string& view) {
  for (const ExrLayer& layer : layers) {
    const std::vector<float>& d = layer.image.data;
    const auto bad = std::find_if(d.begin(), d.end(), [](float v) { return !std::isfinite(v); });
    if (bad == d.end()) continue;
    const size_t pixel = size_t(bad - d.begin()) / size_t(std::max(layer.image.channels, 1));
    const std::string where = "view '" + view + "': layer '" +
                              (layer.name.empty() ? std::string("beauty") : layer.name) +
                              "' at pixel (" + std::to_string(pixel % size_t(layer.image.width)) +
                              ", " + std::to_string(pixel / size_t(layer.image.width)) + ")";
    if (std::isnan(*bad)) throw InternalError(where + " is NaN; please report it with the shot");
    throw InputError(where +
                     " is infinite: its light exceeds what an EXR's 32-bit floats hold "
                     "(3.4e38); lower the irradiance or radiance under /lighting, or the passes "
                     "of pointcloud's rule 'paper', whose light grows with each");
  }
}

double ShotRun::writeView(const std::string& stem, const Camera& camera,
                          const std::vector<ExrLayer>& layers,
                          const std::map<std::string, std::string>& attributes) {
  const auto t0 = std::chrono::steady_clock::now();
  checkFinitePixels(layers, camera.name);
  std::map<std::string, std::string> header = {
      {"cloudbake:shot", shot_.name},
      {"cloudbake:view", camera.name},
      {"cloudbake:method", shot_.bake.method},
      {"cloudbake:units", "radiance, units of sun irradiance per sr"}};
  if (shot_.lighting.has_sun) {
    const Vec3& d = shot_.lighting.sun.direction;
    const Rgb& e = shot_.lighting.sun.irradiance;
    header["cloudbake:sun_direction"] =
        exactNumber(d.x) + " " + exactNumber(d.y) + " " + exactNumber(d.z);
    header["cloudbake:sun_irradiance"] =
        exactNumber(e.x) + " " + exactNumber(e.y) + " " + exactNumber(e.z);
  }
  std::string names;
  for (const std::string& n : shot_.outputs.exr_layers) names += (names.empty() ? "" : " ") + n;
  header[kExrLayersAttribute] = names;
  for (const auto& [k, v] : header_) header[k] = v;
  for (const auto& [k, v] : attributes) header[k] = v;
  // The camera in OpenEXR's standard attributes, which compositing packages read.
  const CameraRays rays(camera);
  std::map<std::string, ExrMatrix> matrices;
  for (const auto& [key, m] : {std::pair{"worldToCamera", rays.worldToCamera()},
                               std::pair{"worldToNDC", rays.worldToNdc()}}) {
    for (int k = 0; k < 16; ++k) matrices[key][size_t(k)] = float(m[size_t(k)]);
  }
  const std::string name = stem + ".exr";
  const std::string path = (fs::path(opt_.out_dir) / name).string();
  const ExrCompression compression = exrCompressionOf(shot_, opt_.source);
  replaced_.keep(path);
  if (opt_.png) replaced_.keep((fs::path(opt_.out_dir) / (stem + ".png")).string());
  if (shot_.outputs.exr_layers == kExrLayerNames) {  // every layer, as the methods give them
    writeExr(path, layers, header, matrices, compression);
  } else {
    writeExr(path, chosenLayers(layers, shot_.outputs.exr_layers), header, matrices, compression);
  }
  result_.files.push_back(describeOutput(opt_.out_dir, name));
  if (opt_.png) addPreview(opt_, stem, layerNamed(layers, "beauty").image, result_);
  return secondsSince(t0);
}

}  // namespace

void checkSamplesOverride(int samples, const std::string& field) {
  if (samples != -1 && (samples < 1 || samples > 1000000)) {
    throw InputError(field + ": must be in [1, 1000000] or unset, got " + std::to_string(samples));
  }
}

void checkRunnable(const ShotSpec& shot, const std::string& source) {
  const MethodInfo& info = methodOf(shot).info();
  if (!info.runnable) {
    throw InputError(source + ": /bake/method: '" + info.name +
                     "' is not implemented in this version (use " + joinedMethodNames(true) + ")");
  }
  if (std::holds_alternative<SequenceVolumeSpec>(shot.volume) && !info.animates) {
    throw InputError(source + ": /volume/sequence: animated volumes are rendered by method " +
                     "'precomputed' only, not '" + info.name + "'");
  }
  if (shot.outputs.exr) exrCompressionOf(shot, source);  // as the parser: only with EXRs
}

namespace {

// auto.json: the choice, what it rested on, and the bake's own error estimates when the chosen
// method gives them.
void writeAutoRecord(MethodRun& run, nlohmann::json record) {
  record["bake_estimates"] = run.result().bake_estimates;
  run.writeOutput("auto.json",
                  [&](const std::string& path) { writeFileAtomic(path, record.dump(1) + "\n"); });
}

// Runs the method; its core code names a knob it refuses as "radius: ..." (core/ knows no JSON),
// which the user wrote as /bake/radius of their file: the error says so.
void runMethod(const BakeMethod& method, MethodRun& run, const std::string& source) {
  try {
    method.run(run);
  } catch (const MissingFileError&) {
    throw;
  } catch (const InputError& e) {
    const std::string what = e.what();
    for (const Knob& k : method.info().knobs) {
      if (what.rfind(k.key + ": ", 0) == 0) throw InputError(source + ": /bake/" + what);
    }
    throw;
  }
}

}  // namespace

AutoChoice chooseAutoForRun(const ShotSpec& shot, const RunOptions& opt,
                            std::vector<StepTime>* steps, DensityFieldPtr* density) {
  const bool need_keys = opt.cache || opt.volumes;
  ShotRun probe(shot, opt, need_keys ? computeCacheKeys(shot) : ShotCacheKeys{});
  probe.report("build", 0, "auto: measuring the scene");
  const bool sequence = std::holds_alternative<SequenceVolumeSpec>(shot.volume);
  const Scene& scene = sequence ? probe.lights() : probe.scene();
  AutoOptions ao;
  ao.threads = opt.threads;
  ao.limits.max_voxels = opt.max_voxels;
  ao.max_samples = opt.max_samples;
  ao.source = opt.source;
  ao.progress = [&](double f) {
    return probe.pollMessage(0, "auto: pilot render " + std::to_string(int(100 * f)) + " %");
  };
  AutoChoice choice = chooseAuto(shot, scene, ao);
  if (density && !sequence) *density = scene.medium.density;
  if (steps) {
    *steps = probe.result().steps;
    if (!sequence) {
      steps->push_back({"auto_pilot", "", -1, choice.pilot.seconds, {}});
    }
  }
  return choice;
}

RunResult runShot(const ShotSpec& shot_in, const RunOptions& opt) {
  const auto t_start = std::chrono::steady_clock::now();
  checkRunOptions(opt);
  ShotSpec shot = shot_in;
  checkRunnable(shot, opt.source);
  // A folder the run cannot write in is refused now, not after the render it would hold (a
  // read-only --out failed at the first EXR, the whole render's work lost).
  makeWritableFolder(opt.out_dir, "out");

  // Auto resolves into the chosen method's shot before anything is baked, so its cache entries
  // are those of a shot naming that method; the density it measured is reused.
  std::optional<RunOptions::AutoPreset> chosen = opt.auto_preset;
  std::vector<StepTime> auto_steps;
  DensityFieldPtr density;
  if (isAutoShot(shot) && !chosen) {
    const AutoChoice choice = chooseAutoForRun(shot, opt, &auto_steps, &density);
    chosen = RunOptions::AutoPreset{choice.shot, autoSummary(choice), choice.toJson()};
    if (opt.progress) {
      RunProgress p;
      p.stage = "build";
      p.message = choice.planLines().front();
      if (!opt.progress(p)) throw Cancelled();
    }
  }
  if (isAutoShot(shot)) shot = chosen->shot;
  if (opt.samples != -1) {
    const MethodInfo& info = methodOf(shot).info();
    if (opt.samples > info.max_samples) {
      throw InputError("samples: method '" + info.name + "' takes at most " +
                       std::to_string(info.max_samples) +
                       (info.bakes_light ? " rays per pixel of a view from its bake" : " samples") +
                       ", got " + std::to_string(opt.samples));
    }
    shot.bake.samples = opt.samples;
  }

  const bool need_keys = opt.cache || opt.volumes;
  ShotRun run(shot, opt, need_keys ? computeCacheKeys(shot) : ShotCacheKeys{});
  if (isAutoShot(shot_in)) {
    run.result().steps = auto_steps;
    run.setHeader({{"cloudbake:auto", chosen->summary}});
    if (density) run.setDensity(density);
  }
  run.report("build", 0, "building " + std::string(volumeTypeName(shot.volume)) + " volume");
  try {
    // Validate the medium, lights and cameras up front even when everything is cached, so bad
    // input fails the same way with and without a cache (a sequence is built by its method).
    if (!opt.cache && !methodOf(shot).info().animates) run.scene();
    run.lights();
    runMethod(methodOf(shot), run, opt.source);
    if (isAutoShot(shot_in) && opt.scope.writesShotFiles()) writeAutoRecord(run, chosen->record);
    // A cancel that comes after the last file still cancels, and puts the earlier files back:
    // once they are deleted below, nothing cancels (a signal there gave exit 6 over a finished
    // run whose earlier files were gone: an outside probe).
    run.report("done", 1, "done in " + fixed(secondsSince(t_start), 2) + " s");
  } catch (...) {
    // A run that fails leaves none of its outputs: a view written before the bake's file failed
    // (a full disk) looked finished. What they replaced comes back (replaced_outputs.h).
    std::error_code ec;
    for (const OutputFile& f : run.result().files) fs::remove(f.path, ec);
    run.restoreReplaced();
    throw;
  }
  run.commitReplaced();
  RunResult result = run.result();
  result.method = shot.bake.method;
  result.seconds = secondsSince(t_start);
  return result;
}

}  // namespace cloudbake
