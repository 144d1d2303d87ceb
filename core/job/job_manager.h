// The job pool behind cloudbake-server: validation, a bounded queue, runners each executing a
// job in its own tbb::task_arena, progress events, cancellation, durable records, the caches.
// Independent of gRPC so it can be tested (and embedded) on its own.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/job/asset_limits.h"
#include "core/job/asset_store.h"
#include "core/job/bake_cache.h"
#include "core/job/cache_key.h"
#include "core/job/direction_index.h"
#include "core/job/job_record.h"
#include "core/job/phase_cache.h"
#include "core/job/run_shot.h"
#include "core/job/shared_jobs.h"
#include "core/job/slurm_executor.h"
#include "core/job/vdb_gate.h"
#include "core/job/verified_files.h"
#include "core/job/volume_cache.h"
#include "core/shot/shot.h"

namespace cloudbake {

/// Service limits on one job, on top of the shot format's own bounds. 0: no limit.
struct JobLimits {
  int64_t max_image_pixels = int64_t(1) << 22;  ///< per view (4 Mpixel)
  int max_views = 64;
  int64_t max_samples = 1 << 16;  ///< samples per pixel
  int64_t max_frames = 1000;      ///< frames of an animated volume (sequence)
  int64_t max_points =
      int64_t(1) << 22;  ///< points of a point-based bake (pointcloud, precomputed)
  /// Voxels of the volume: a mesh's resolution^3 or box (voxel_size over its bounds), a
  /// procedural grid, a VDB's active voxels, the bake.vdb grid of a box or sphere. 256 Mi
  /// voxels are 1 GiB of floats.
  uint64_t max_voxels = uint64_t(1) << 28;
};

/// What a runner reports when a job ends (for metrics): `method` is the one that ran (auto's
/// choice) or, when the job failed before choosing, the shot's; `steps` as RunResult's.
struct JobFinished {
  std::string id;
  std::string method;
  JobState state = JobState::kFailed;
  double seconds = 0;
  /// "hit": nothing was scattered, everything came from the cache; "miss": everything was
  /// computed; "partial": some of each; "none": the job failed before the cache was asked.
  std::string cache;
  std::vector<StepTime> steps;
};

/// Settings of a JobManager. Everything durable lives under `state_dir`: jobs/, cache/,
/// assets/.
struct JobManagerOptions {
  std::string state_dir;
  /// Optional: a folder shared with other servers and farm tasks (`cloudbake run-task
  /// --cache-dir`), possibly on NFS: the result cache lives in shared_dir/cache instead of
  /// state_dir/cache, so a bake one replica made is a hit on every other (core/job/bake_cache.h
  /// is safe across processes and hosts), and every job's record, progress and outputs are
  /// published to shared_dir/jobs (core/job/shared_jobs.h), so every replica answers get,
  /// events, output and cancel for any job. Each replica runs the jobs it accepted; its queue,
  /// assets and lock stay in state_dir.
  std::string shared_dir;
  /// "local" (default): jobs run in this process's TBB arena. "slurm": each job runs as farm
  /// tasks on Slurm (core/job/slurm_executor.h) with `slurm` and shared_dir (required), its
  /// inputs copied to shared_dir/inputs/<job id> so the nodes can read them.
  std::string executor = "local";
  SlurmOptions slurm;
  /// How jobs read users' VDB files: by default (the server) rewritten first in a child
  /// process, so that a file that crashes OpenVDB fails its job only (core/job/vdb_gate.h).
  VdbReaderOptions vdb_reader;
  unsigned worker_threads = 0;       ///< threads of each job's task_arena; 0: all hardware
  unsigned max_concurrent_jobs = 1;  ///< runners
  /// Queued (not running) jobs plus submits and dry runs being prepared (staging assets,
  /// measuring a scene for method auto): more get ResourceExhausted, so many small requests
  /// cannot pile up work outside the queue.
  size_t queue_bound = 16;
  uint64_t cache_max_bytes = uint64_t(1) << 30;
  uint64_t max_upload_bytes = uint64_t(1) << 30;
  /// Wall-clock seconds a job may run; past it the job is stopped (as a cancel, within about a
  /// second) and FAILED, naming --max-job-seconds. 0: no limit.
  double max_job_seconds = 86400;
  /// Finished jobs (records, inputs and outputs) are pruned once finished longer ago than this
  /// (seconds; 0: kept by age forever), and the oldest beyond `max_finished_jobs` (0: no
  /// limit), after each job ends, at each submit and at start. A job a client touched (status,
  /// events, an output) within `prune_grace_seconds` is kept: a fetch in progress is never cut
  /// (and a stream already open reads on from its open file).
  double keep_finished_seconds = 7 * 86400.0;
  size_t max_finished_jobs = 10000;
  double prune_grace_seconds = 600;
  /// Every stored output of a finished job and every uploaded asset is hashed again this often
  /// (seconds; 0: never), whatever its size and time say: a corrupt asset is dropped (the next
  /// upload stores it again), a corrupt output rebuilt from the cache when it can be.
  double scrub_interval_seconds = 86400;
  JobLimits limits;
  /// Optional: called by the runner once a job's final record is saved (not under the
  /// manager's lock; it must not call back into the manager).
  std::function<void(const JobFinished&)> on_job_finished;
};

/// A shot as a client submits it: JSON text (format v1) and the files it names, by path
/// relative to the shot's folder and content hash of an uploaded asset.
struct SubmitInput {
  std::string shot_json;
  /// The authenticated client that submits it (empty: the server has no authentication).
  std::string owner;
  std::vector<std::pair<std::string, std::string>> assets;  ///< (relative path, sha256)
  int samples = -1;                                         ///< override; -1: the shot's
  /// Reuse a cached render whose sun direction is within this angle (degrees; 0: exact only).
  double sun_tolerance_deg = 0;
  /// Optional: true once the caller's client gave up (its deadline passed or it cancelled).
  /// Staging assets and planning stop then with Cancelled, so a request nobody waits for does
  /// not keep the server busy.
  std::function<bool()> abandoned;
};

/// What a submit would do (dry run): per view whether its render is cached.
struct JobPlan {
  std::string shot_name;
  std::string method;
  std::vector<std::string> views;
  std::vector<bool> view_cached;
  bool vdb = false;
  bool volume_cached = false;
  double pixel_samples = 0;  ///< paths to trace (or rays to march from a bake): cost estimate
  std::string bake_key;
  std::vector<std::string> components;  ///< what will be computed, one line each
  bool bake_cached = false;             ///< single/pointcloud: the light is already baked
};

/// What one scrub found (JobManager::scrub).
struct ScrubReport {
  size_t outputs_checked = 0;
  size_t outputs_damaged = 0;
  size_t outputs_rebuilt = 0;  ///< of the damaged: rebuilt from the cache, bit for bit
  size_t assets_checked = 0;
  size_t assets_dropped = 0;
};

/// One progress event of a job. `seq` increases by one per job from 1; `eta_s` < 0: unknown.
struct JobEvent {
  uint64_t seq = 0;
  double time = 0;
  JobState state = JobState::kQueued;
  std::string stage;
  double fraction = 0;
  double eta_s = -1;
  std::string message;
};

/// Counters the service exposes (tests assert on `scatter_computations`).
struct JobManagerStats {
  uint64_t scatter_computations = 0;  ///< views path-traced + lights baked (not from cache)
  uint64_t views_from_cache = 0;
  uint64_t bakes_from_cache = 0;  ///< bakes (single, pointcloud) reused
  uint64_t volume_builds = 0;
  uint64_t jobs_submitted = 0;
  size_t queued = 0, running = 0;
  size_t succeeded = 0, failed = 0, cancelled = 0;  ///< finished jobs held (not yet pruned)
  uint64_t outputs_corrupt = 0;  ///< outputs refused because they no longer match their hash
  uint64_t assets_corrupt = 0;  ///< stored assets dropped because they no longer hash to their name
  BakeCacheStats cache;
};

class JobManager {
 public:
  /// Opens the state folder (locking it: a second manager on it throws std::runtime_error),
  /// loads job records (a job that was RUNNING when the previous
  /// process died is marked FAILED; QUEUED jobs are queued again) and starts the runners.
  explicit JobManager(JobManagerOptions options);
  /// Stops the runners: running jobs are cancelled and recorded as FAILED ("interrupted by
  /// server shutdown"); queued jobs stay queued on disk for the next start.
  ~JobManager();
  JobManager(const JobManager&) = delete;
  JobManager& operator=(const JobManager&) = delete;

  /// Validates and queues. Throws InputError (bad shot; message names the field),
  /// NotFoundError (an asset not uploaded), ResourceExhaustedError (queue full).
  JobRecord submit(const SubmitInput& input);
  /// Validates and plans without queueing (same errors as submit, except queue full).
  JobPlan plan(const SubmitInput& input);
  /// A new job rendering `views_json` (a JSON array of shot-format views) of job `job_id`'s
  /// shot, optionally with a new sun irradiance (JSON [r,g,b]; empty: unchanged). Reuses the
  /// job's assets; cached parts are not recomputed.
  JobRecord render(const std::string& job_id, const std::string& views_json,
                   const std::string& sun_irradiance_json, const std::string& owner = "");

  /// Throws NotFoundError.
  JobRecord get(const std::string& id) const;
  /// The job's owner (SubmitInput::owner), without counting as a use of it (prune keeps jobs
  /// used in the last minutes): NotFoundError for an unknown id.
  std::string ownerOf(const std::string& id) const;
  /// Newest first; `state` filters when set; at most `limit` (0: all).
  std::vector<JobRecord> list(std::optional<JobState> state, size_t limit) const;
  /// Cancels a queued or running job (a running one stops within about a second). Cancelling
  /// a finished job is a no-op that returns its record. Throws NotFoundError.
  JobRecord cancel(const std::string& id);
  /// Events with seq > `after`, waiting up to `wait` for one when there is none and the job is
  /// not finished. `record` receives the job's record. Throws NotFoundError.
  std::vector<JobEvent> events(const std::string& id, uint64_t after,
                               std::chrono::milliseconds wait, JobRecord* record) const;
  /// Absolute path and description of output `name` of a SUCCEEDED job, once the file is checked
  /// against its recorded SHA-256 (on first use and whenever it changed). Throws NotFoundError
  /// (job or name), FailedPreconditionError (job not succeeded, or the file is damaged).
  OutputFile output(const std::string& id, const std::string& name);

  /// Hashes every output of this replica's succeeded jobs and every asset again (the scrub the
  /// options schedule; callable at any time), rebuilding damaged outputs from the cache.
  ScrubReport scrub();

  AssetStore& assets() { return *assets_; }
  JobManagerStats stats() const;
  const JobManagerOptions& options() const { return options_; }

 private:
  struct Job;
  struct Prepared;
  struct Outcome;
  class PrepareSlot;
  Prepared prepare(const SubmitInput& input, const std::string& dir);
  std::shared_ptr<Job> find(const std::string& id) const;
  /// Removes the finished jobs the options say to prune (see keep_finished_seconds).
  void prune();
  void pushEventLocked(Job& job, const std::string& stage, double fraction,
                       const std::string& message);
  /// Saves job's record, logging a failure (a state the runner reaches on its own).
  void saveLocked(const Job& job);
  /// Saves `next` as job's record, then sets and publishes it; a failed save (a full volume)
  /// throws with nothing changed, so a client is never told what a restart would undo.
  void saveOrRefuseLocked(Job& job, const JobRecord& next);
  /// Publishes the job to shared_dir (when set); failures are logged, not fatal.
  void publishLocked(const Job& job);
  void publishFinished(const Job& job);
  /// A job another replica published (nullopt without shared_dir or when unknown there).
  std::optional<JobRecord> foreign(const std::string& id) const;
  std::vector<JobEvent> foreignEvents(const std::string& id, uint64_t after,
                                      std::chrono::milliseconds wait, JobRecord* record) const;
  void runnerLoop();
  void runJob(const std::shared_ptr<Job>& job);
  /// The caches and limits every run, and method auto's choice in a plan, use.
  RunOptions autoRunOptions();
  RunOptions runOptions(const std::shared_ptr<Job>& job);
  RunResult runInArena(Job& job, const RunOptions& ro, Outcome* outcome);
  /// The job's shot with its files copied to the shared folder, for the farm's nodes.
  ShotSpec sharedShot(const Job& job) const;
  OutputFile recordedOutput(const std::string& id, const std::string& name) const;
  /// Runs the part of job `id`'s shot that writes output `f` (a farm task's scope) with the
  /// cache, within `budget` seconds, and puts the file back when it hashes as recorded.
  bool rebuildOutput(const std::string& id, const OutputFile& f, double budget);
  bool stopping() const;
  bool inCache(const ShotSpec& shot, const RunScope& scope);
  void scrubberLoop();
  void reportFinished(const Job& job, const RunResult& result, const Outcome& outcome);
  /// Records the outcome durably; a success whose record cannot be saved becomes a failure.
  void finishJob(Job& job, const RunResult& result, Outcome* outcome);
  static void setOutcome(JobRecord* r, const Outcome& outcome);
  JobRecord enqueue(Prepared prepared, const std::string& dir, const std::string& id);

  JobManagerOptions options_;
  std::unique_ptr<JobStore> store_;
  std::unique_ptr<BakeCache> cache_;
  std::unique_ptr<AssetStore> assets_;
  std::unique_ptr<SharedJobs> shared_jobs_;
  VolumeCache volumes_;
  PhaseCache phases_;
  std::unique_ptr<DirectionIndex> directions_;
  mutable std::mutex mutex_;
  mutable VerifiedFiles verified_outputs_;
  mutable std::atomic<uint64_t> outputs_corrupt_{0};
  mutable std::condition_variable cv_;  // queue changes and new events
  std::map<std::string, std::shared_ptr<Job>> jobs_;
  std::deque<std::shared_ptr<Job>> queue_;
  size_t preparing_ = 0;  // submits and plans between their start and enqueue (PrepareSlot)
  size_t running_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> runners_;
  std::thread scrubber_;
  int lock_fd_ = -1;
  std::atomic<uint64_t> scatter_computations_{0}, views_from_cache_{0}, bakes_from_cache_{0},
      submitted_{0};
};

}  // namespace cloudbake
