// A bake method as one registered plugin (in the manner of Mitsuba 3's plugins): its descriptor
// (name, summary with citation, algorithm version, knob table), its checks on a shot, its cache
// key material, its dry-run plan, its limits and its run. A method talks to the run that hosts
// it only through MethodRun, so core/methods depends on the physics below it and on no job
// machinery: runShot (core/job) implements MethodRun with the cache, the volume cache and the
// output folder.
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/io/exr_io.h"
#include "core/methods/knob.h"
#include "core/methods/run_types.h"
#include "core/shot/shot.h"
#include "core/transport/scene.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// What a method is, for the parser, the docs, ServerInfo and the cache.
struct MethodInfo {
  std::string name;
  std::string summary;   ///< one line, with the paper it implements (author and year)
  std::string citation;  ///< the paper(s), author and year
  /// Algorithm version: bumped on any change of the method's output, so a cache filled by an
  /// older build is never served (the golden tests in tests/core/methods fail until it is).
  int version = 1;
  int default_samples = 1;  ///< bake.samples when the shot omits it
  /// bake.samples at most: the path tracer's paths per pixel, or a view's rays per pixel from a
  /// bake (kMaxViewSamples).
  int max_samples = 1000000;
  std::vector<Knob> knobs;
  bool runnable = true;      ///< false: parsed (shots can be written ahead), refused by runs
  bool bakes_light = false;  ///< views render from a baked-light lattice (bake.vdb is it)
  bool animates = false;     ///< renders `sequence` volumes (frame sequences)
};

/// The server's limits a method checks before a job is queued (0: no limit).
struct MethodLimits {
  uint64_t max_voxels = 0;
  int64_t max_points = 0;
  int64_t max_frames = 0;
};

/// What a dry run says of a shot: one human line per component, and the cost in rays.
struct MethodPlan {
  std::vector<std::string> components;
  std::string bake_key;  ///< the key of the bake's cache entry ("" when nothing is baked)
  bool bake_cached = false;
  std::vector<bool> view_cached;
  double pixel_samples = 0;
};

/// The services a method's run uses; implemented by runShot. Every call that can take long
/// polls for cancellation (Cancelled).
class MethodRun {
 public:
  virtual ~MethodRun() = default;

  virtual const ShotSpec& shot() const = 0;  ///< with the run's overrides applied
  virtual const ShotCacheKeys& keys() const = 0;
  virtual int threads() const = 0;                ///< 0: the caller's TBB arena
  virtual const std::string& source() const = 0;  ///< prefix of error messages
  virtual RunResult& result() = 0;
  /// The part of the shot this run computes (everything unless it is a farm task).
  virtual const RunScope& scope() const = 0;

  /// Medium (extinction, albedo, phase), sun, sky and cameras; the density is a stand-in.
  virtual const Scene& lights() = 0;
  /// The whole scene; its density field is built on the first call (or comes from the volume
  /// cache), since that is the expensive part.
  virtual const Scene& scene() = 0;
  /// Frame `frame` of the shot's `sequence` volume, built anew on each call (methods that
  /// animate resample frame by frame rather than hold every frame's field).
  virtual DensityFieldPtr sequenceFrame(int frame) = 0;

  /// Progress of the method: `stage` ("bake", "render", "vdb"), `fraction` of its work in
  /// [0, 1], a line for logs and, while a view renders, its name. Throws Cancelled when the
  /// caller asks to stop.
  virtual void report(const std::string& stage, double fraction, const std::string& message,
                      const std::string& view = "") = 0;
  /// For callbacks of core loops: the last report's stage, message and view stay; false when
  /// the caller asks to stop. `view_fraction`: of the current view; `message`: replaces it.
  virtual bool poll(double fraction, double view_fraction = 0) = 0;
  virtual bool pollMessage(double fraction, const std::string& message) = 0;

  /// The cache entry `key`: its folder, computed into the staging folder by `compute` when it
  /// is absent; without a cache `compute` runs into a scratch folder that lives until the run
  /// ends. `computed` says which happened.
  virtual std::string cached(const std::string& key,
                             const std::function<void(const std::string& staging)>& compute,
                             bool* computed) = 0;
  virtual bool hasCache() const = 0;
  virtual std::optional<std::string> lookup(const std::string& key) = 0;

  /// Light-direction tolerance reuse: the cached sun directions of `family` within the run's
  /// tolerance, closest first (empty without a tolerance), and the record of a new one.
  virtual std::vector<Vec3> nearbySunDirections(const std::string& family) = 0;
  virtual void addSunDirection(const std::string& family) = 0;
  /// The key of the shot's light bake, or of view `view`'s render, had the sun come from
  /// `direction` (a quantised direction from nearbySunDirections).
  virtual std::string lightKeyAt(const Vec3& direction) = 0;
  virtual std::string viewKeyAt(int view, const Vec3& direction) = 0;

  /// Writes DIR/<stem>.exr with the run's common header attributes plus `attributes`, and its
  /// PNG preview when asked. Returns the seconds it took: a view's `write` in the run's steps.
  virtual double writeView(const std::string& stem, const Camera& camera,
                           const std::vector<ExrLayer>& layers,
                           const std::map<std::string, std::string>& attributes) = 0;
  /// DIR/<name> written by `write(path)`, or copied from `from` (a cache entry's file).
  virtual void writeOutput(const std::string& name,
                           const std::function<void(const std::string& path)>& write) = 0;
  virtual void copyOutput(const std::string& name, const std::string& from) = 0;
};

/// One bake method. Stateless: one const instance serves every run.
class BakeMethod {
 public:
  virtual ~BakeMethod() = default;
  virtual const MethodInfo& info() const = 0;

  /// Checks the method's constraints on the whole shot beyond each knob's own range (knobs
  /// that depend on each other or on the volume): InputError "<source>: <pointer>: ...".
  virtual void validate(const ShotSpec& shot, const std::string& source) const;

  /// Cache key material of the method's parts: "light" (with `light_family`, the same without
  /// the sun direction) for methods that bake light, "precompute" for precomputed. The caller
  /// salts each with the method's name and version. `canonical` is the shot's canonical JSON
  /// with files replaced by their hashes.
  virtual nlohmann::json keyMaterial(const ShotSpec& shot, const nlohmann::json& canonical) const;

  /// Dry-run lines; `lookup` tells whether a key is in the cache.
  virtual MethodPlan plan(const ShotSpec& shot, const ShotCacheKeys& keys,
                          const std::function<bool(const std::string&)>& lookup) const = 0;

  /// This server's limits for the shot (the method's lattices, points, frames): InputError
  /// naming the field and the server flag.
  virtual void checkLimits(const ShotSpec& shot, const MethodLimits& limits,
                           const std::string& source) const;

  /// Runs the shot: writes every view and the VDB the shot asks for through `run`.
  virtual void run(MethodRun& run) const = 0;
};

}  // namespace cloudbake
