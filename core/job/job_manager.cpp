#include "core/job/job_manager.h"

#include <fcntl.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "common/json_limits.h"
#include "common/printable.h"
#include "core/error.h"
#include "core/format.h"
#include "core/job/cache_key.h"
#include "core/job/file_util.h"
#include "core/job/run_shot.h"
#include "core/job/volume_limits.h"
#include "core/methods/registry.h"
#include "core/shot/shot_parser.h"

namespace cloudbake {
namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace {

constexpr size_t kMaxEventsKept = 1000;
constexpr const char* kSubmittedFile = "submitted.json";

double unixNow() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

constexpr long kMaxAssetDepth = 32;  // folders in one asset path

// A client-chosen asset path becomes a path under the job's input folder: it must stay inside.
std::string checkAssetPath(const std::string& path, size_t index) {
  const std::string field = "assets[" + std::to_string(index) + "].path";
  if (path.empty()) throw InputError(field + ": must not be empty");
  if (path.size() > 1024) throw InputError(field + ": longer than 1024 characters");
  if (path.find('\0') != std::string::npos) throw InputError(field + ": contains a NUL byte");
  const fs::path p(path);
  if (p.is_absolute()) {
    throw InputError(field + ": '" + path + "' must be relative to the shot's folder");
  }
  const fs::path norm = p.lexically_normal();
  if (norm.empty() || *norm.begin() == ".." || norm == "." || norm.filename().empty()) {
    throw InputError(field + ": '" + path + "' escapes the shot's folder");
  }
  // Each component is a folder the server creates: a bound keeps one request from making
  // hundreds of thousands of them (1000 paths 500 folders deep made 477k).
  if (std::distance(norm.begin(), norm.end()) > kMaxAssetDepth) {
    throw InputError(field + ": '" + path.substr(0, 80) + "...' is nested deeper than " +
                     std::to_string(kMaxAssetDepth) + " folders");
  }
  return norm.string();
}

// Paths of which one is a folder of another ('a.vdb' and 'a.vdb/b'), or one path with two
// contents, cannot all be placed: an error naming both, not the file system's failure (it was
// INTERNAL). The same file named twice (a sequence repeating a frame) is fine.
void checkAssetConflicts(const std::vector<std::string>& paths, const SubmitInput& input) {
  std::vector<std::pair<std::string, size_t>> sorted;
  for (size_t i = 0; i < paths.size(); ++i) sorted.push_back({paths[i], i});
  std::sort(sorted.begin(), sorted.end());
  for (size_t k = 1; k < sorted.size(); ++k) {
    const auto& [a, i] = sorted[k - 1];
    for (size_t m = k; m < sorted.size() && sorted[m].first.rfind(a, 0) == 0; ++m) {
      const auto& [b, j] = sorted[m];
      const bool same = b.size() == a.size();
      if (same && input.assets[i].second == input.assets[j].second) continue;
      if (same || b[a.size()] == '/') {
        throw InputError("assets[" + std::to_string(j) + "].path: '" + b +
                         "' conflicts with assets[" + std::to_string(i) + "].path '" + a +
                         (same ? "' (one path, two contents)" : "' (a file, not a folder)"));
      }
    }
  }
}

// Error messages reach clients: show paths under a job's input folder as the client wrote them
// (relative to the shot's folder), not as server-internal absolute paths.
std::string clientPaths(std::string message, const std::string& input_dir) {
  std::error_code ec;
  const std::string canonical = fs::weakly_canonical(input_dir, ec).string();
  for (const std::string& prefix : {input_dir, canonical}) {
    if (prefix.empty()) continue;
    for (size_t at; (at = message.find(prefix + "/")) != std::string::npos;) {
      message.erase(at, prefix.size() + 1);
    }
    for (size_t at; (at = message.find(prefix)) != std::string::npos;) {
      message.replace(at, prefix.size(), "<shot folder>");
    }
  }
  return message;
}

// Submit checks the bound before the costly preparation and enqueue again under the lock: both
// refuse with the same words.
ResourceExhaustedError queueFull(size_t waiting, size_t bound) {
  return ResourceExhaustedError("the job queue is full (" + std::to_string(waiting) +
                                " jobs waiting or being prepared, bound " + std::to_string(bound) +
                                "); retry later");
}

// A job's submission, kept in its folder: it is requeued from it after a restart and RenderView
// jobs start from it. readSubmission throws when the file is missing or malformed.
void writeSubmission(const std::string& job_dir, const SubmitInput& input) {
  const Json submitted = {{"shot_json", input.shot_json},
                          {"assets", input.assets},
                          {"samples", input.samples},
                          {"sun_tolerance_deg", input.sun_tolerance_deg}};
  writeFileAtomic((fs::path(job_dir) / kSubmittedFile).string(), submitted.dump());
}

SubmitInput readSubmission(const std::string& job_dir) {
  const std::string file = (fs::path(job_dir) / kSubmittedFile).string();
  const Json s = parseJsonLimited(readWholeFile(file), file);
  SubmitInput input;
  input.shot_json = s.at("shot_json").get<std::string>();
  input.assets = s.at("assets").get<std::vector<std::pair<std::string, std::string>>>();
  input.samples = s.at("samples").get<int>();
  input.sun_tolerance_deg = s.value("sun_tolerance_deg", 0.0);
  return input;
}

}  // namespace

// A damaged output found by a fetch is rebuilt from the cache within this long, else refused; the
// scrub gives a rebuild longer.
constexpr double kRebuildSecondsOnFetch = 10;
constexpr double kRebuildSecondsOnScrub = 600;

// How often a running job's progress is published to the shared folder (and another replica's
// cancel request looked for).
constexpr auto kPublishInterval = std::chrono::seconds(1);

struct JobManager::Job {
  JobRecord record;
  ShotSpec shot;  // empty for a finished job restored after a restart (jobShot reads it)
  bool has_shot = false;
  double sun_tolerance_deg = 0;
  // The submit's samples override of an auto shot (-1: none), applied to the method auto
  // chooses as the run starts, as `cloudbake render --samples` does: written into the auto
  // shot, the choice replaced it (a --samples 4 ran at 27625 paths a pixel).
  int auto_samples = -1;
  std::atomic<bool> cancel{false};
  bool shutdown = false;  // cancelled because the manager stops, not by a client
  bool overtime = false;  // stopped by max_job_seconds (set under the manager's mutex)
  std::deque<JobEvent> events;
  uint64_t next_seq = 1;
  std::chrono::steady_clock::time_point started;
  // When a client last asked for the job (status, events, outputs): pruning spares it a while.
  std::chrono::steady_clock::time_point last_access = std::chrono::steady_clock::now();
  double last_fraction = -1;
  std::string last_message;
  std::chrono::steady_clock::time_point last_publish{};  // progress published to shared_dir
};

struct JobManager::Prepared {
  ShotSpec shot;
  ShotCacheKeys keys;
  SubmitInput input;
};

JobManager::JobManager(JobManagerOptions options) : options_(std::move(options)) {
  if (options_.state_dir.empty()) throw InputError("state_dir: must not be empty");
  if (options_.executor != "local" && options_.executor != "slurm") {
    throw InputError("--executor: must be local or slurm, got '" + options_.executor + "'");
  }
  if (options_.executor == "slurm" && options_.shared_dir.empty()) {
    throw InputError("--executor slurm: needs --shared-dir, a folder every node sees");
  }
  options_.slurm.shared_dir = options_.shared_dir;
  fs::create_directories(options_.state_dir);
  // One process per state folder: two would share queue files and cache entries unsafely.
  const std::string lock_path = (fs::path(options_.state_dir) / "LOCK").string();
  lock_fd_ = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (lock_fd_ < 0 || ::flock(lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    if (lock_fd_ >= 0) ::close(lock_fd_);
    throw std::runtime_error("state folder " + options_.state_dir +
                             " is in use by another cloudbake-server process");
  }
  store_ = std::make_unique<JobStore>((fs::path(options_.state_dir) / "jobs").string());
  const fs::path cache_root =
      fs::path(options_.shared_dir.empty() ? options_.state_dir : options_.shared_dir) / "cache";
  cache_ = std::make_unique<BakeCache>(cache_root.string(), options_.cache_max_bytes);
  assets_ = std::make_unique<AssetStore>((fs::path(options_.state_dir) / "assets").string(),
                                         options_.max_upload_bytes);
  if (!options_.shared_dir.empty()) {
    shared_jobs_ = std::make_unique<SharedJobs>((fs::path(options_.shared_dir) / "jobs").string());
  }
  directions_ =
      std::make_unique<DirectionIndex>((fs::path(options_.state_dir) / "directions").string());
  std::error_code ec;
  fs::remove_all(fs::path(options_.state_dir) / "tmp", ec);
  fs::create_directories(fs::path(options_.state_dir) / "tmp");

  for (JobRecord& record : store_->loadAll()) {
    auto job = std::make_shared<Job>();
    job->record = record;
    if (record.state == JobState::kRunning) {
      // Its outputs may be half-written: never serve them.
      job->record.state = JobState::kFailed;
      job->record.error = "interrupted: the server stopped while this job was running; resubmit";
      // The stage on disk is the last one saved (often "build" at 0 %), not where it stopped.
      job->record.stage = "interrupted";
      job->record.fraction = 0;
      job->record.finished = unixNow();
      job->record.outputs.clear();
      fs::remove_all(store_->outputDir(record.id), ec);
      store_->save(job->record);
    } else if (record.state == JobState::kQueued) {
      try {
        const SubmitInput input = readSubmission(store_->jobDir(record.id));
        job->shot = prepare(input, store_->jobDir(record.id)).shot;
        job->has_shot = true;
        job->sun_tolerance_deg = input.sun_tolerance_deg;
        job->auto_samples = isAutoShot(job->shot) ? input.samples : -1;
        queue_.push_back(job);
      } catch (const std::exception& e) {
        spdlog::error("job {}: cannot requeue after restart: {}", record.id, e.what());
        job->record.state = JobState::kFailed;
        job->record.error = "could not be resumed after a server restart; resubmit";
        job->record.finished = unixNow();
        store_->save(job->record);
      }
    }
    pushEventLocked(
        *job, job->record.stage.empty() ? "restored" : job->record.stage, job->record.fraction,
        job->record.error.empty() ? "restored after server restart" : job->record.error);
    publishLocked(*job);
    jobs_[record.id] = job;
  }
  if (!jobs_.empty()) {
    spdlog::info("job store: {} job(s) restored, {} requeued", jobs_.size(), queue_.size());
  }
  prune();
  const unsigned runners = std::max(1u, options_.max_concurrent_jobs);
  for (unsigned i = 0; i < runners; ++i) runners_.emplace_back([this] { runnerLoop(); });
  if (options_.scrub_interval_seconds > 0) scrubber_ = std::thread([this] { scrubberLoop(); });
}

void JobManager::prune() {
  const double now = unixNow();
  const auto steady_now = std::chrono::steady_clock::now();
  std::vector<std::string> doomed;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<std::pair<double, std::string>> finished;  // (finished, id), oldest first
    for (const auto& [id, job] : jobs_) {
      if (job->record.terminal()) finished.push_back({job->record.finished, id});
    }
    std::sort(finished.begin(), finished.end());
    const size_t over =
        options_.max_finished_jobs > 0 && finished.size() > options_.max_finished_jobs
            ? finished.size() - options_.max_finished_jobs
            : 0;
    for (size_t i = 0; i < finished.size(); ++i) {
      const auto& [when, id] = finished[i];
      const bool old =
          options_.keep_finished_seconds > 0 && now - when > options_.keep_finished_seconds;
      if (!old && i >= over) continue;
      const double idle =
          std::chrono::duration<double>(steady_now - jobs_[id]->last_access).count();
      if (idle < options_.prune_grace_seconds) continue;
      jobs_.erase(id);
      doomed.push_back(id);
    }
  }
  for (const std::string& id : doomed) {
    store_->remove(id);
    if (shared_jobs_) {
      shared_jobs_->remove(id);
      std::error_code ec;
      fs::remove_all(fs::path(options_.shared_dir) / "inputs" / id, ec);
    }
  }
  if (!doomed.empty()) {
    spdlog::info("job store: pruned {} finished job(s) (--keep-jobs-hours, --max-finished-jobs)",
                 doomed.size());
  }
}

JobManager::~JobManager() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    for (auto& [id, job] : jobs_) {
      if (job->record.state == JobState::kRunning) {
        job->shutdown = true;
        job->cancel = true;
      }
    }
  }
  cv_.notify_all();
  for (std::thread& t : runners_) t.join();
  if (scrubber_.joinable()) scrubber_.join();
  ::close(lock_fd_);  // releases the flock
}

namespace {

void stopIfAbandoned(const SubmitInput& input, const char* when) {
  if (input.abandoned && input.abandoned()) {
    throw Cancelled(std::string("submit abandoned by its client (deadline passed or cancelled) ") +
                    when);
  }
}

}  // namespace

JobManager::Prepared JobManager::prepare(const SubmitInput& input, const std::string& dir) {
  Prepared p;
  p.input = input;
  const std::string input_dir = (fs::path(dir) / "input").string();
  if (input.assets.size() > kMaxJobAssets) {
    throw InputError("assets: " + std::to_string(input.assets.size()) + " files, more than the " +
                     std::to_string(kMaxJobAssets) + " a job may name");
  }
  std::vector<std::string> rels;
  for (size_t i = 0; i < input.assets.size(); ++i) {
    rels.push_back(checkAssetPath(input.assets[i].first, i));
  }
  checkAssetConflicts(rels, input);
  fs::create_directories(input_dir);
  for (size_t i = 0; i < input.assets.size(); ++i) {
    stopIfAbandoned(input, "while its assets were staged");
    const std::string& rel = rels[i];
    const std::string& sha = input.assets[i].second;
    if (!isSha256Hex(sha)) {
      throw InputError("assets[" + std::to_string(i) + "].sha256: must be 64 lowercase hex digits");
    }
    const std::string stored = assets_->find(sha);
    if (stored.empty()) {
      throw NotFoundError("assets[" + std::to_string(i) + "]: '" + rel + "' (sha256 " + sha +
                          ") has not been uploaded; call UploadAsset first");
    }
    linkOrCopy(stored, (fs::path(input_dir) / rel).string());
  }
  stopIfAbandoned(input, "before its shot was read");
  ParseOptions po;
  po.allowed_roots = {input_dir};
  po.source_name = "shot.json";
  try {
    p.shot = parseShot(input.shot_json, input_dir, po);
  } catch (const MissingFileError& e) {
    throw MissingFileError(clientPaths(e.what(), input_dir));
  } catch (const InputError& e) {
    throw InputError(clientPaths(e.what(), input_dir));
  }
  checkSamplesOverride(input.samples, "samples");
  if (input.samples != -1 && !isAutoShot(p.shot)) p.shot.bake.samples = input.samples;
  if (!(input.sun_tolerance_deg >= 0 && input.sun_tolerance_deg <= 90)) {
    throw InputError("sun_tolerance_deg: must be in [0, 90] degrees, got " +
                     std::to_string(input.sun_tolerance_deg));
  }
  const JobLimits& lim = options_.limits;
  // Before checkRunnable: a limit is this server's answer whatever the method supports.
  checkShotFrames(p.shot, lim.max_frames, "shot.json");
  checkShotVoxels(p.shot, lim.max_voxels, "shot.json");
  checkShotPoints(p.shot, lim.max_points, "shot.json");
  checkRunnable(p.shot, "shot.json");
  if (lim.max_views > 0 && p.shot.views.size() > size_t(lim.max_views)) {
    throw InputError("shot.json: /views: " + std::to_string(p.shot.views.size()) +
                     " views exceed this server's limit of " + std::to_string(lim.max_views));
  }
  for (size_t i = 0; i < p.shot.views.size(); ++i) {
    const Camera& c = p.shot.views[i];
    const int64_t pixels = int64_t(c.width_px) * c.height_px;
    if (lim.max_image_pixels > 0 && pixels > lim.max_image_pixels) {
      throw InputError(
          "shot.json: /views/" + std::to_string(i) + "/resolution: " + std::to_string(pixels) +
          " pixels exceed this server's limit of " + std::to_string(lim.max_image_pixels));
    }
  }
  if (lim.max_samples > 0 && p.shot.bake.samples > lim.max_samples) {
    throw InputError("shot.json: /bake/samples: " + std::to_string(p.shot.bake.samples) +
                     " exceeds this server's limit of " + std::to_string(lim.max_samples));
  }
  if (lim.max_samples > 0 && input.samples > lim.max_samples) {
    throw InputError("samples: " + std::to_string(input.samples) +
                     " exceeds this server's limit of " + std::to_string(lim.max_samples));
  }
  p.keys = computeCacheKeys(p.shot);
  return p;
}

// A submit's or a dry run's place against the queue bound while it is prepared: staging
// assets and measuring a scene are work, and without a place a burst of small requests would
// pile it up beside the queue (issue 15, defect 6).
class JobManager::PrepareSlot {
 public:
  explicit PrepareSlot(JobManager& jobs) : jobs_(jobs) {
    std::lock_guard<std::mutex> lock(jobs_.mutex_);
    const size_t waiting = jobs_.queue_.size() + jobs_.preparing_;
    if (waiting >= jobs_.options_.queue_bound) throw queueFull(waiting, jobs_.options_.queue_bound);
    ++jobs_.preparing_;
  }
  ~PrepareSlot() {
    std::lock_guard<std::mutex> lock(jobs_.mutex_);
    --jobs_.preparing_;
  }
  PrepareSlot(const PrepareSlot&) = delete;
  PrepareSlot& operator=(const PrepareSlot&) = delete;

 private:
  JobManager& jobs_;
};

JobPlan JobManager::plan(const SubmitInput& input) {
  const PrepareSlot slot(*this);
  const std::string dir = (fs::path(options_.state_dir) / "tmp" / uniqueSuffix()).string();
  struct Cleanup {
    std::string dir;
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cleanup{dir};
  Prepared p = prepare(input, dir);
  stopIfAbandoned(input, "before its plan was made");
  std::vector<std::string> auto_lines;
  if (isAutoShot(p.shot)) {
    // The choice rests on the scene and a pilot render of it: the plan measures them as the
    // run will (the volume goes to the memory cache the run then finds it in).
    RunOptions ro = autoRunOptions();
    ro.threads = int(options_.worker_threads);
    ro.progress = [&](const RunProgress&) { return !(input.abandoned && input.abandoned()); };
    try {
      const AutoChoice choice = chooseAutoForRun(p.shot, ro);
      auto_lines = choice.planLines();
      p.shot = choice.shot;
      if (input.samples != -1) {
        auto_lines.push_back("samples: " + std::to_string(input.samples) +
                             " from the request, not the choice's " +
                             std::to_string(p.shot.bake.samples));
        p.shot.bake.samples = input.samples;
      }
    } catch (const InputError& e) {
      throw InputError(clientPaths(e.what(), (fs::path(dir) / "input").string()));
    }
    p.keys = computeCacheKeys(p.shot);
  }
  JobPlan plan;
  plan.shot_name = p.shot.name;
  plan.method = p.shot.bake.method;
  plan.vdb = p.shot.outputs.vdb;
  const MethodPlan mp = methodOf(p.shot).plan(
      p.shot, p.keys, [&](const std::string& key) { return cache_->lookup(key).has_value(); });
  plan.bake_key = mp.bake_key.empty() ? p.keys.bake : mp.bake_key;
  plan.bake_cached = mp.bake_cached;
  plan.components = auto_lines;
  plan.components.insert(plan.components.end(), mp.components.begin(), mp.components.end());
  const unsigned threads =
      options_.worker_threads ? options_.worker_threads : std::thread::hardware_concurrency();
  const std::string phase = phasePlanLine(p.shot.medium.phase, &phases_, int(threads));
  if (!phase.empty()) plan.components.push_back(phase);
  plan.view_cached = mp.view_cached;
  plan.pixel_samples = mp.pixel_samples;
  if (p.shot.outputs.exr) {
    for (const Camera& c : p.shot.views) plan.views.push_back(c.name);
  }
  return plan;
}

JobRecord JobManager::enqueue(Prepared prepared, const std::string& dir, const std::string& id) {
  auto job = std::make_shared<Job>();
  job->shot = std::move(prepared.shot);
  job->has_shot = true;
  job->sun_tolerance_deg = prepared.input.sun_tolerance_deg;
  job->auto_samples = isAutoShot(job->shot) ? prepared.input.samples : -1;
  JobRecord& r = job->record;
  r.id = id;
  r.shot_name = job->shot.name;
  r.method = job->shot.bake.method;
  r.owner = prepared.input.owner;
  for (const Camera& c : job->shot.views) r.views.push_back(c.name);
  r.created = unixNow();
  r.stage = "queued";
  writeSubmission(dir, prepared.input);
  std::lock_guard<std::mutex> lock(mutex_);
  if (stopping_) throw ResourceExhaustedError("the server is shutting down; retry on restart");
  if (queue_.size() >= options_.queue_bound) {
    throw queueFull(queue_.size(), options_.queue_bound);
  }
  saveOrRefuseLocked(*job, job->record);  // durable before the client hears of it
  pushEventLocked(*job, "queued", 0, "queued at position " + std::to_string(queue_.size() + 1));
  jobs_[id] = job;
  queue_.push_back(job);
  ++submitted_;
  cv_.notify_all();
  return r;
}

JobRecord JobManager::submit(const SubmitInput& input) {
  prune();
  // Fails fast before linking assets and hashing volumes; enqueue checks the queue again.
  const PrepareSlot slot(*this);
  const std::string id = newJobId();
  const std::string dir = store_->jobDir(id);
  try {
    Prepared p = prepare(input, dir);
    return enqueue(std::move(p), dir, id);
  } catch (...) {
    store_->remove(id);
    throw;
  }
}

JobRecord JobManager::render(const std::string& job_id, const std::string& views_json,
                             const std::string& sun_irradiance_json, const std::string& owner) {
  const std::shared_ptr<Job> old = find(job_id);
  {
    // A view is rendered from a finished job's bake, which only a succeeded job has: from a
    // cancelled, failed or running one the "render" was a whole new run of its shot.
    std::lock_guard<std::mutex> lock(mutex_);
    if (old->record.state != JobState::kSucceeded) {
      throw FailedPreconditionError("job " + job_id + " is " + jobStateName(old->record.state) +
                                    "; views are rendered from SUCCEEDED jobs only (submit its "
                                    "shot again to run it)");
    }
  }
  SubmitInput input;
  try {
    input = readSubmission(store_->jobDir(job_id));
  } catch (const std::exception& e) {
    spdlog::error("job {}: cannot read its submission: {}", job_id, e.what());
    throw FailedPreconditionError("job " + job_id + " has no stored submission to render from");
  }
  Json shot = parseJsonLimited(input.shot_json, "job " + job_id + ": stored shot");
  if (!views_json.empty()) {
    const Json views = parseJsonLimited(views_json, "views_json");
    if (!views.is_array()) {
      throw InputError("views_json: must be a JSON array of shot-format views");
    }
    shot["views"] = views;
  }
  if (!sun_irradiance_json.empty()) {
    const Json e = parseJsonLimited(sun_irradiance_json, "sun_irradiance_json");
    if (!shot.contains("lighting") || !shot["lighting"].contains("sun")) {
      throw InputError("sun_irradiance_json: the shot of job " + job_id + " has no sun");
    }
    shot["lighting"]["sun"]["irradiance"] = e;
  }
  input.shot_json = shot.dump();
  input.owner = owner;
  return submit(input);
}

std::shared_ptr<JobManager::Job> JobManager::find(const std::string& id) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = jobs_.find(id);
  if (it == jobs_.end()) throw NotFoundError("job '" + id.substr(0, 64) + "' not found");
  it->second->last_access = std::chrono::steady_clock::now();
  return it->second;
}

std::string JobManager::ownerOf(const std::string& id) const {
  if (auto other = foreign(id)) return other->owner;
  // Not through find(): asking whose a job is does not use it, so another client's question
  // must not keep it from being pruned.
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = jobs_.find(id);
  if (it == jobs_.end()) throw NotFoundError("job '" + id.substr(0, 64) + "' not found");
  return it->second->record.owner;
}

JobRecord JobManager::get(const std::string& id) const {
  if (auto other = foreign(id)) return *other;
  auto job = find(id);
  std::lock_guard<std::mutex> lock(mutex_);
  return job->record;
}

std::optional<JobRecord> JobManager::foreign(const std::string& id) const {
  if (!shared_jobs_) return std::nullopt;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (jobs_.count(id)) return std::nullopt;  // ours
  }
  return shared_jobs_->record(id);
}

// Events of a job another replica runs, from what it published: one event per publication
// (seq is the publication's revision), waiting up to `wait` for a new one.
std::vector<JobEvent> JobManager::foreignEvents(const std::string& id, uint64_t after,
                                                std::chrono::milliseconds wait,
                                                JobRecord* record) const {
  const auto until = std::chrono::steady_clock::now() + wait;
  for (;;) {
    const std::optional<JobRecord> r = shared_jobs_->record(id);
    if (!r) throw NotFoundError("job '" + id.substr(0, 64) + "' not found");
    const PublishedProgress p = shared_jobs_->progress(id);
    if (record) *record = *r;
    if (p.revision > after) {
      JobEvent e;
      e.seq = p.revision;
      e.time = unixNow();
      e.state = r->state;
      e.stage = p.stage;
      e.fraction = p.fraction;
      e.eta_s = r->terminal() ? 0 : -1;
      e.message = p.message;
      return {e};
    }
    if (r->terminal() || std::chrono::steady_clock::now() >= until) return {};
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
}

std::vector<JobRecord> JobManager::list(std::optional<JobState> state, size_t limit) const {
  std::vector<JobRecord> out;
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& [id, job] : jobs_) {
    if (!state || job->record.state == *state) out.push_back(job->record);
  }
  std::sort(out.begin(), out.end(), [](const JobRecord& a, const JobRecord& b) {
    return a.created != b.created ? a.created > b.created : a.id > b.id;
  });
  if (limit > 0 && out.size() > limit) out.resize(limit);
  return out;
}

JobRecord JobManager::cancel(const std::string& id) {
  if (auto other = foreign(id)) {
    // The replica that runs it stops it within about a second of seeing the request.
    if (!other->terminal()) shared_jobs_->requestCancel(id);
    return *other;
  }
  auto job = find(id);
  std::lock_guard<std::mutex> lock(mutex_);
  if (job->record.state == JobState::kQueued) {
    // Saved before anything changes: a cancel the disk could not keep (a full volume) is
    // refused, not reported done and undone by a restart.
    JobRecord cancelled = job->record;
    cancelled.state = JobState::kCancelled;
    cancelled.finished = unixNow();
    cancelled.stage = "cancelled";
    saveOrRefuseLocked(*job, cancelled);
    queue_.erase(std::remove(queue_.begin(), queue_.end(), job), queue_.end());
    pushEventLocked(*job, "cancelled", job->record.fraction, "cancelled while queued");
  } else if (job->record.state == JobState::kRunning) {
    job->cancel = true;  // the runner records the final state when the work has stopped
  }
  return job->record;
}

std::vector<JobEvent> JobManager::events(const std::string& id, uint64_t after,
                                         std::chrono::milliseconds wait, JobRecord* record) const {
  if (foreign(id)) return foreignEvents(id, after, wait, record);
  auto job = find(id);
  std::unique_lock<std::mutex> lock(mutex_);
  auto ready = [&] {
    return stopping_ || job->record.terminal() ||
           (!job->events.empty() && job->events.back().seq > after);
  };
  cv_.wait_for(lock, wait, ready);
  std::vector<JobEvent> out;
  for (const JobEvent& e : job->events) {
    if (e.seq > after) out.push_back(e);
  }
  if (record) *record = job->record;
  return out;
}

OutputFile JobManager::output(const std::string& id, const std::string& name) {
  OutputFile out = recordedOutput(id, name);
  // Served only as recorded: a file changed since it was written (a bad disk, a hand) would
  // stream under its original checksum. Rebuilt from the cache when that is quick.
  if (!verified_outputs_.check(out.path, out.sha256) &&
      !rebuildOutput(id, out, kRebuildSecondsOnFetch)) {
    ++outputs_corrupt_;
    std::error_code ec;
    const bool gone = !fs::exists(out.path, ec);
    spdlog::error("job {}: output '{}' {}", id, name,
                  gone ? "is gone" : "does not match its recorded size and SHA-256");
    // The rebuild has just failed, so the cache may no longer hold what the job computed: a
    // resubmission reuses whatever it still holds.
    throw FailedPreconditionError("job " + id + ": output '" + name + "' is " +
                                  (gone ? "gone from" : "damaged on") +
                                  " the server and cannot be served; resubmit the job (it reuses "
                                  "the server's cache where that still holds the bake)");
  }
  return out;
}

OutputFile JobManager::recordedOutput(const std::string& id, const std::string& name) const {
  JobRecord record;
  std::string dir;
  if (auto other = foreign(id)) {
    record = *other;
    dir = shared_jobs_->outputDir(id);
  } else {
    auto job = find(id);
    std::lock_guard<std::mutex> lock(mutex_);
    record = job->record;
    dir = store_->outputDir(id);
  }
  if (record.state != JobState::kSucceeded) {
    throw FailedPreconditionError("job " + id + " is " + jobStateName(record.state) +
                                  "; results exist only for SUCCEEDED jobs");
  }
  for (const OutputFile& f : record.outputs) {
    if (f.name == name) {
      // Records of other replicas are read from the shared folder: a name there that is not a
      // plain file name (an edited record's "../../x") would serve a file outside the job.
      const fs::path p(f.name);
      if (f.name.empty() || p.has_parent_path() || p.is_absolute() || f.name == "." ||
          f.name == "..") {
        throw FailedPreconditionError("job " + id + ": its record names output '" +
                                      f.name.substr(0, 256) +
                                      "', which is not a file name; it is not served");
      }
      OutputFile out = f;
      out.path = (fs::path(dir) / f.name).string();
      return out;
    }
  }
  std::string names;
  for (const OutputFile& f : record.outputs) names += (names.empty() ? "" : ", ") + f.name;
  throw NotFoundError("job " + id + " has no output '" + name.substr(0, 256) +
                      "' (it has: " + names + ")");
}

namespace {

// The farm scope (core/methods/run_types.h) whose run writes output `name` of `shot`: its view
// (or, for an animation, its frame) or the shot's own files; nullopt when none writes it alone.
std::optional<RunScope> scopeWriting(const ShotSpec& shot, const std::string& name) {
  using Part = RunScope::Part;
  if (methodOf(shot).info().animates) {
    if (name == "animation.json") return RunScope{Part::kGather, 0, 0};
    const size_t dot2 = name.rfind('.');
    const size_t dot1 =
        dot2 == std::string::npos || dot2 == 0 ? std::string::npos : name.rfind('.', dot2 - 1);
    if (dot1 == std::string::npos || dot2 - dot1 < 5 || dot2 - dot1 > 8) return std::nullopt;
    const std::string digits = name.substr(dot1 + 1, dot2 - dot1 - 1);
    if (!std::all_of(digits.begin(), digits.end(), ::isdigit)) return std::nullopt;
    const int frame = std::stoi(digits);
    return RunScope{Part::kRender, frame, frame + 1};
  }
  if (name == "bake.vdb") return RunScope{Part::kGather, 0, 0};
  for (size_t i = 0; i < shot.views.size(); ++i) {
    if (shot.views[i].name + ".exr" == name) return RunScope{Part::kRender, int(i), int(i) + 1};
  }
  return std::nullopt;
}

}  // namespace

// What a rebuild of `scope` reads is in the cache: the precompute, the light bake, or the view
// (pathtrace; its density VDB for bake.vdb). A rebuild never computes scattering anew.
bool JobManager::inCache(const ShotSpec& shot, const RunScope& scope) {
  const ShotCacheKeys keys = computeCacheKeys(shot);
  const MethodInfo& info = methodOf(shot).info();
  std::string key = info.animates                           ? keys.precompute
                    : info.bakes_light                      ? keys.light
                    : scope.part == RunScope::Part::kGather ? keys.vdb
                                                            : keys.views.at(size_t(scope.begin));
  return !key.empty() && cache_->lookup(key).has_value();
}

bool JobManager::stopping() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stopping_;
}

bool JobManager::rebuildOutput(const std::string& id, const OutputFile& f, double budget) {
  std::shared_ptr<Job> job;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = jobs_.find(id);
    if (it == jobs_.end()) return false;  // another replica's: it rebuilds its own
    job = it->second;
  }
  ShotSpec shot = job->shot;
  double sun_tolerance_deg = job->sun_tolerance_deg;
  if (!job->has_shot) {
    // A job finished before a restart keeps its submission, not its parsed shot (a damaged
    // output of one was refused though the cache held what it needed: an outside probe).
    try {
      const SubmitInput input = readSubmission(store_->jobDir(id));
      shot = prepare(input, store_->jobDir(id)).shot;
      sun_tolerance_deg = input.sun_tolerance_deg;
    } catch (const std::exception& e) {
      spdlog::warn("job {}: cannot read its submission to rebuild '{}': {}", id, f.name,
                   printable(e.what()));
      return false;
    }
  }
  const std::optional<RunScope> scope = scopeWriting(shot, f.name);
  if (!scope || isAutoShot(shot)) return false;  // auto would choose again
  if (!inCache(shot, *scope)) return false;
  RunOptions ro = autoRunOptions();
  ro.cache = cache_.get();
  ro.directions = directions_.get();
  ro.sun_tolerance_deg = sun_tolerance_deg;
  ro.scope = *scope;
  ro.out_dir = (fs::path(options_.state_dir) / "tmp" / ("rebuild-" + uniqueSuffix())).string();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(budget);
  ro.progress = [&](const RunProgress&) {
    return std::chrono::steady_clock::now() < deadline && !stopping();
  };
  bool rebuilt = false;
  std::error_code ec;
  try {
    tbb::task_arena arena(options_.worker_threads > 0 ? int(options_.worker_threads)
                                                      : tbb::task_arena::automatic);
    arena.execute([&] { runShot(shot, ro); });
    const fs::path from = fs::path(ro.out_dir) / f.name,
                   to = fs::path(store_->outputDir(id)) / f.name;
    // Only the recorded bytes go back: a file that cannot be made again bit for bit (a VDB
    // written anew carries a fresh UUID) stays refused.
    if (fs::exists(from) && sha256File(from.string()) == f.sha256) {
      fs::rename(from, to);
      verified_outputs_.remember(to.string());
      rebuilt = true;
    }
  } catch (const std::exception& e) {
    spdlog::warn("job {}: rebuilding output '{}' failed: {}", id, f.name, printable(e.what()));
  }
  fs::remove_all(ro.out_dir, ec);
  spdlog::warn("job {}: output '{}' was damaged; {}", id, f.name,
               rebuilt ? "rebuilt from the cache" : "it could not be rebuilt bit for bit");
  return rebuilt;
}

ScrubReport JobManager::scrub() {
  ScrubReport report;
  std::vector<std::pair<std::string, OutputFile>> outputs;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& [id, job] : jobs_) {
      if (job->record.state != JobState::kSucceeded) continue;
      for (OutputFile f : job->record.outputs) {
        f.path = (fs::path(store_->outputDir(id)) / f.name).string();
        outputs.push_back({id, f});
      }
    }
  }
  for (const auto& [id, f] : outputs) {
    if (stopping()) break;
    ++report.outputs_checked;
    verified_outputs_.forget(f.path);  // bit rot changes neither size nor time
    if (verified_outputs_.check(f.path, f.sha256)) continue;
    ++report.outputs_damaged;
    ++outputs_corrupt_;
    if (rebuildOutput(id, f, kRebuildSecondsOnScrub)) ++report.outputs_rebuilt;
  }
  std::tie(report.assets_checked, report.assets_dropped) = assets_->scrub();
  spdlog::info(
      "scrub: {} output(s) checked, {} damaged, {} rebuilt; {} asset(s) checked, {} dropped",
      report.outputs_checked, report.outputs_damaged, report.outputs_rebuilt, report.assets_checked,
      report.assets_dropped);
  return report;
}

void JobManager::scrubberLoop() {
  const auto interval = std::chrono::duration<double>(options_.scrub_interval_seconds);
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    if (cv_.wait_for(lock, interval, [&] { return stopping_; })) return;
    lock.unlock();
    scrub();
    lock.lock();
  }
}

JobManagerStats JobManager::stats() const {
  JobManagerStats s;
  s.scatter_computations = scatter_computations_;
  s.views_from_cache = views_from_cache_;
  s.bakes_from_cache = bakes_from_cache_;
  s.volume_builds = volumes_.builds();
  s.jobs_submitted = submitted_;
  s.cache = cache_->stats();
  s.outputs_corrupt = outputs_corrupt_;
  s.assets_corrupt = assets_->corruptDropped();
  std::lock_guard<std::mutex> lock(mutex_);
  s.queued = queue_.size();
  s.running = running_;
  for (const auto& [id, job] : jobs_) {
    const JobState state = job->record.state;
    s.succeeded += state == JobState::kSucceeded;
    s.failed += state == JobState::kFailed;
    s.cancelled += state == JobState::kCancelled;
  }
  return s;
}

void JobManager::saveLocked(const Job& job) {
  try {
    store_->save(job.record);
  } catch (const std::exception& e) {
    spdlog::error("job {}: cannot save record: {}", job.record.id, e.what());
  }
  publishLocked(job);
}

void JobManager::saveOrRefuseLocked(Job& job, const JobRecord& next) {
  store_->save(next);  // throws (StorageFullError on a full volume) before anything changes
  job.record = next;
  publishLocked(job);
}

void JobManager::publishLocked(const Job& job) {
  if (!shared_jobs_) return;
  try {
    shared_jobs_->publish(job.record, store_->outputDir(job.record.id), job.last_message);
  } catch (const std::exception& e) {
    spdlog::error("job {}: cannot publish to the shared folder: {}", job.record.id, e.what());
  }
}

void JobManager::pushEventLocked(Job& job, const std::string& stage, double fraction,
                                 const std::string& message) {
  JobEvent e;
  e.seq = job.next_seq++;
  e.time = unixNow();
  e.state = job.record.state;
  e.stage = stage;
  e.fraction = fraction;
  if (job.record.state == JobState::kRunning && fraction > 0.01) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - job.started).count();
    e.eta_s = elapsed / fraction * (1 - fraction);
  } else if (job.record.terminal()) {
    e.eta_s = 0;
  }
  e.message = message;
  job.events.push_back(e);
  while (job.events.size() > kMaxEventsKept) job.events.pop_front();
  job.last_fraction = fraction;
  job.last_message = message;
  cv_.notify_all();
}

void JobManager::runnerLoop() {
  for (;;) {
    std::shared_ptr<Job> job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      job = queue_.front();
      queue_.pop_front();
      ++running_;
    }
    runJob(job);
    std::lock_guard<std::mutex> lock(mutex_);
    --running_;
  }
}

// How a run ended, as the job's record and last event report it.
struct JobManager::Outcome {
  JobState state = JobState::kSucceeded;
  std::string error;
  bool error_is_input = false;
  bool error_no_space = false;
};

namespace {

// The last event's line of a succeeded job: what was computed and what came from the cache.
std::string successMessage(const RunResult& result) {
  const std::string parts =
      result.bakes_computed + result.bakes_cached > 0
          ? std::string(result.bakes_computed ? "light baked, " : "bake from cache, ") +
                std::to_string(result.views_from_bake) + " view(s) rendered from the bake)"
          : std::to_string(result.views_rendered) + " view(s) rendered, " +
                std::to_string(result.views_cached) + " from cache)";
  return fmt::format("succeeded in {:.2f} s (", result.seconds) + parts;
}

// Whether a run was served by the cache: scattering computations against cached reuses.
std::string cacheOutcome(const RunResult& r) {
  const int computed = r.views_rendered + r.bakes_computed;
  const int cached = r.views_cached + r.bakes_cached;
  if (computed + cached == 0) return "none";
  return computed == 0 ? "hit" : cached == 0 ? "miss" : "partial";
}

}  // namespace

void JobManager::runJob(const std::shared_ptr<Job>& job) {
  const std::string& id = job->record.id;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (shared_jobs_ && shared_jobs_->cancelRequested(id)) {
      // Cancelled through another replica while it waited in this one's queue.
      job->record.state = JobState::kCancelled;
      job->record.finished = unixNow();
      job->record.stage = "cancelled";
      saveLocked(*job);
      pushEventLocked(*job, "cancelled", 0, "cancelled while queued");
      return;
    }
    job->record.state = JobState::kRunning;
    job->record.started = unixNow();
    job->record.stage = "build";
    job->started = std::chrono::steady_clock::now();
    saveLocked(*job);
    pushEventLocked(*job, "build", 0, "started");
  }
  spdlog::info("job {}: started ('{}', {} view(s))", id, printable(job->record.shot_name),
               job->record.views.size());
  const RunOptions ro = runOptions(job);
  Outcome outcome;
  RunResult result = runInArena(*job, ro, &outcome);
  scatter_computations_ += uint64_t(result.views_rendered) + uint64_t(result.bakes_computed);
  views_from_cache_ += uint64_t(result.views_cached);
  bakes_from_cache_ += uint64_t(result.bakes_cached);
  finishJob(*job, result, &outcome);
  if (outcome.state != JobState::kSucceeded) {
    // A failed or cancelled job keeps no partial outputs.
    std::error_code ec;
    fs::remove_all(ro.out_dir, ec);
  }
  publishFinished(*job);
  reportFinished(*job, result, outcome);
  prune();
}

void JobManager::reportFinished(const Job& job, const RunResult& result, const Outcome& outcome) {
  JobFinished f;
  f.id = job.record.id;
  f.method = result.method.empty() ? job.record.method : result.method;
  f.state = outcome.state;
  f.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - job.started).count();
  f.cache = cacheOutcome(result);
  f.steps = result.steps;
  // One line per finished job with what a log search needs (docs/deployment.md, "Logs").
  spdlog::info("job {}: finished: {}, method {}, {:.2f} s, cache {}{}", f.id, jobStateName(f.state),
               f.method, f.seconds, f.cache,
               outcome.error.empty() ? "" : ": " + printable(outcome.error));
  if (options_.on_job_finished) options_.on_job_finished(f);
}

RunOptions JobManager::autoRunOptions() {
  RunOptions ro;
  ro.volumes = &volumes_;
  ro.phases = &phases_;
  ro.max_voxels = options_.limits.max_voxels;
  ro.max_samples = int(std::min<int64_t>(options_.limits.max_samples, 1000000));
  ro.vdb_reader = options_.vdb_reader;
  return ro;
}

RunOptions JobManager::runOptions(const std::shared_ptr<Job>& job) {
  RunOptions ro = autoRunOptions();
  ro.out_dir = store_->outputDir(job->record.id);
  ro.cache = cache_.get();
  ro.directions = directions_.get();
  ro.sun_tolerance_deg = job->sun_tolerance_deg;
  ro.samples = job->auto_samples;
  // An event per new message or per percent of progress, so a long run does not flood the
  // event log; the answer is whether the run may go on.
  ro.progress = [this, job](const RunProgress& p) {
    std::lock_guard<std::mutex> lock(mutex_);
    job->record.stage = p.stage;
    job->record.fraction = p.fraction;
    if (p.message != job->last_message || p.fraction >= job->last_fraction + 0.01) {
      pushEventLocked(*job, p.stage, p.fraction,
                      p.message == job->last_message ? std::string() : p.message);
      job->last_message = p.message;
    }
    if (shared_jobs_ && std::chrono::steady_clock::now() - job->last_publish >= kPublishInterval) {
      // Progress for the other replicas, and their cancel requests, about once a second.
      job->last_publish = std::chrono::steady_clock::now();
      publishLocked(*job);
      if (shared_jobs_->cancelRequested(job->record.id)) job->cancel = true;
    }
    if (options_.max_job_seconds > 0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - job->started).count() >
            options_.max_job_seconds) {
      job->overtime = true;
      return false;
    }
    return !job->cancel.load();
  };
  return ro;
}

RunResult JobManager::runInArena(Job& job, const RunOptions& ro, Outcome* outcome) {
  RunResult result;
  try {
    const int threads =
        options_.worker_threads > 0 ? int(options_.worker_threads) : tbb::task_arena::automatic;
    tbb::task_arena arena(threads);
    if (options_.executor == "slurm") {
      arena.execute([&] { result = runShotOnSlurm(sharedShot(job), ro, options_.slurm); });
    } else {
      arena.execute([&] { result = runShot(job.shot, ro); });
    }
  } catch (const Cancelled&) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (job.overtime) {
      outcome->state = JobState::kFailed;
      outcome->error = "deadline exceeded: the job ran past this server's limit of " +
                       exactNumber(options_.max_job_seconds) +
                       " s per job (--max-job-seconds) and was stopped";
    } else {
      outcome->state = job.shutdown ? JobState::kFailed : JobState::kCancelled;
      outcome->error = job.shutdown ? "interrupted by server shutdown; resubmit" : "cancelled";
    }
  } catch (const StorageFullError& e) {
    // Resource, not input: the client may retry once space is freed; no server path in it.
    outcome->state = JobState::kFailed;
    outcome->error = std::string(e.what()) + "; resubmit once space is freed";
    outcome->error_no_space = true;
    spdlog::error("job {}: {}", job.record.id, e.detail());
  } catch (const InputError& e) {
    outcome->state = JobState::kFailed;
    // Files are named as the client named them, whichever copy of the input a run read.
    outcome->error = clientPaths(e.what(), store_->inputDir(job.record.id));
    if (!options_.shared_dir.empty()) {
      outcome->error = clientPaths(
          outcome->error,
          (fs::path(options_.shared_dir) / "inputs" / job.record.id / "input").string());
    }
    outcome->error_is_input = true;
  } catch (const FarmTaskFailed& e) {
    outcome->state = JobState::kFailed;
    outcome->error = e.what();
    spdlog::error("job {}: {}", job.record.id, e.what());
  } catch (const std::exception& e) {
    // Internal details stay in the server log; the client learns where to look.
    outcome->state = JobState::kFailed;
    outcome->error = "internal error while running the job (details in the server log, job " +
                     job.record.id + ")";
    spdlog::error("job {}: {}", job.record.id, e.what());
  }
  return result;
}

ShotSpec JobManager::sharedShot(const Job& job) const {
  const std::string from = store_->inputDir(job.record.id);
  const std::string to =
      (fs::path(options_.shared_dir) / "inputs" / job.record.id / "input").string();
  std::error_code ec;
  for (const auto& f : fs::recursive_directory_iterator(from, ec)) {
    if (!f.is_regular_file()) continue;
    const fs::path dest = fs::path(to) / fs::relative(f.path(), from);
    if (!fs::exists(dest)) linkOrCopy(f.path().string(), dest.string());
  }
  // The shot names its files by absolute path inside its input folder: the same names under
  // the shared copy.
  std::string text = serializeShot(job.shot);
  const std::string quoted = "\"" + from + "/";
  for (size_t at = 0; (at = text.find(quoted, at)) != std::string::npos;) {
    text.replace(at, quoted.size(), "\"" + to + "/");
    at += to.size() + 2;
  }
  ParseOptions po;
  po.source_name = "shot.json";
  return parseShot(text, "", po);
}

void JobManager::finishJob(Job& job, const RunResult& result, Outcome* outcome) {
  std::lock_guard<std::mutex> lock(mutex_);
  JobRecord& r = job.record;
  r.finished = unixNow();
  r.views_rendered = result.views_rendered;
  r.views_cached = result.views_cached;
  r.bakes_computed = result.bakes_computed;
  r.bakes_cached = result.bakes_cached;
  r.views_from_bake = result.views_from_bake;
  if (outcome->state == JobState::kSucceeded) {
    for (OutputFile f : result.files) {
      f.path.clear();  // clients fetch outputs by name, never by a server path
      r.outputs.push_back(f);
    }
  }
  setOutcome(&r, *outcome);
  try {
    store_->save(r);
  } catch (const std::exception& e) {
    spdlog::error("job {}: cannot save record: {}", r.id, e.what());
    if (outcome->state == JobState::kSucceeded) {
      // A success a restart would take back is never reported: the job fails now, as it
      // would after a restart (a RUNNING record on disk is marked FAILED).
      const bool no_space = dynamic_cast<const StorageFullError*>(&e) != nullptr;
      outcome->state = JobState::kFailed;
      outcome->error_no_space = no_space;
      outcome->error = no_space ? std::string(e.what()) + "; resubmit once space is freed"
                                : "internal error: the job's record could not be saved (details "
                                  "in the server log, job " +
                                      r.id + ")";
      r.outputs.clear();
      setOutcome(&r, *outcome);
      saveLocked(job);
    }
  }
  pushEventLocked(job, "done", r.fraction,
                  outcome->state == JobState::kSucceeded ? successMessage(result) : outcome->error);
}

// The final record and the outputs, published outside the lock: linking or copying outputs to
// another file system must not stall every call.
void JobManager::publishFinished(const Job& job) {
  if (!shared_jobs_) return;
  JobRecord record;
  std::string message;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    record = job.record;
    message = job.last_message;
  }
  try {
    shared_jobs_->publish(record, store_->outputDir(record.id), message);
  } catch (const std::exception& e) {
    spdlog::error("job {}: cannot publish to the shared folder: {}", record.id, e.what());
  }
}

void JobManager::setOutcome(JobRecord* r, const Outcome& outcome) {
  r->state = outcome.state;
  r->error = outcome.error;
  r->error_is_input = outcome.error_is_input;
  r->error_no_space = outcome.error_no_space;
  r->stage = jobStateName(outcome.state);
  if (outcome.state == JobState::kSucceeded) r->fraction = 1;
}

}  // namespace cloudbake
