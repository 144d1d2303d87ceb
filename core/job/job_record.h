// A job's durable record and its on-disk store (files with atomic renames).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/job/run_shot.h"

namespace cloudbake {

enum class JobState { kQueued, kRunning, kSucceeded, kFailed, kCancelled };
const char* jobStateName(JobState state);

/// Everything the service remembers about a job. Times are Unix seconds. `error` is the
/// user-facing message of a failed job (internal details go to the log only);
/// `error_is_input` tells a bad-input failure from an internal one.
struct JobRecord {
  std::string id;
  JobState state = JobState::kQueued;
  std::string shot_name;
  std::string method;
  std::string owner;  ///< the authenticated client that submitted it ("" without tokens)
  std::vector<std::string> views;
  double created = 0, started = 0, finished = 0;
  std::string stage;
  double fraction = 0;
  std::string error;
  bool error_is_input = false;
  bool error_no_space = false;      ///< FAILED because the server's volume is full
  std::vector<OutputFile> outputs;  ///< `path` is not stored; JobStore::outputPath gives it
  int views_rendered = 0;
  int views_cached = 0;
  int bakes_computed = 0;
  int bakes_cached = 0;
  int views_from_bake = 0;
  bool terminal() const {
    return state == JobState::kSucceeded || state == JobState::kFailed ||
           state == JobState::kCancelled;
  }
};

/// ROOT/<id>/job.json (the record, replaced atomically on every change), ROOT/<id>/input/ (the
/// shot as submitted and its assets), ROOT/<id>/out/ (results). Not thread safe: JobManager
/// serialises access.
class JobStore {
 public:
  explicit JobStore(std::string root);
  void save(const JobRecord& record) const;
  /// Every record found, oldest first. Unreadable records are logged and skipped.
  std::vector<JobRecord> loadAll() const;
  /// Job `id`'s record, or nullopt when it has none (or it cannot be read).
  std::optional<JobRecord> load(const std::string& id) const;
  std::string jobDir(const std::string& id) const;
  std::string inputDir(const std::string& id) const;
  std::string outputDir(const std::string& id) const;
  void remove(const std::string& id) const;

 private:
  std::string root_;
};

/// A new job id: "j" + 16 hex digits (random), safe as a folder name.
std::string newJobId();

/// True when `id` has the form newJobId() gives (checked before it is used as a path).
bool isJobId(const std::string& id);

}  // namespace cloudbake
