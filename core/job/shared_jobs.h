// Jobs published on a folder shared by server replicas (docs/deployment.md, "Replicas"): each
// replica runs its own jobs and publishes their records, progress and finished outputs, so any
// replica behind one address can answer status, watch, fetch and cancel for any job.
#pragma once

#include <optional>
#include <string>

#include "core/job/job_record.h"

namespace cloudbake {

/// What a replica published of a job's progress: `revision` grows with every publication.
struct PublishedProgress {
  uint64_t revision = 0;
  std::string stage;
  double fraction = 0;
  std::string message;
};

/// ROOT/<id>/job.json (the record, as JobStore writes it), ROOT/<id>/progress.json,
/// ROOT/<id>/out/ (a finished job's outputs, linked or copied from the replica's own folder
/// before the record that names them) and ROOT/<id>/CANCEL (a request from another replica).
/// Every file is replaced atomically, so readers on other hosts see whole files. Thread safe.
class SharedJobs {
 public:
  explicit SharedJobs(std::string root);

  /// Publishes `record` (and, for a SUCCEEDED job, its outputs from `out_dir` first) with its
  /// progress. Throws std::runtime_error (StorageFullError when the volume is full).
  void publish(const JobRecord& record, const std::string& out_dir, const std::string& message);
  std::optional<JobRecord> record(const std::string& id) const;
  PublishedProgress progress(const std::string& id) const;
  std::string outputDir(const std::string& id) const;

  /// Another replica asks the owner to cancel job `id`; the owner polls cancelRequested.
  void requestCancel(const std::string& id) const;
  bool cancelRequested(const std::string& id) const;
  void remove(const std::string& id) const;

 private:
  JobStore store_;
};

}  // namespace cloudbake
