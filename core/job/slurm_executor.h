// Runs a shot as farm tasks on Slurm (docs/deployment.md, "Farm"): what `cloudbake-server
// --executor slurm` does with each job instead of running it in-process. The shot is planned
// (core/job/task_plan.h), each stage is submitted as a job array with `afterok` dependencies,
// progress is the share of the plan's predicted cost whose tasks are done, a cancel or a
// deadline is `scancel`, and a failed task fails the run with the end of its log.
#pragma once

#include <chrono>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/job/run_shot.h"

namespace cloudbake {

/// How runs reach Slurm. Every folder must be visible at the same path on the nodes.
struct SlurmOptions {
  std::string shared_dir;  ///< required: plans, logs, the cache (shared_dir/cache), outputs
  std::string cloudbake;   ///< the `cloudbake` binary on the nodes
  int tasks = 8;           ///< most tasks per stage
  int cpus_per_task = 2;
  std::string partition;  ///< "": the cluster's default
  int retries = 2;        ///< extra attempts of a failed task, in place
  std::chrono::milliseconds poll{500};
};

/// A farm task failed after its retries: the message names it and ends with its log's last
/// lines (the shared folder's path replaced by "<shared>"), for the job's error.
class FarmTaskFailed : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The result of one command: its exit status and what it printed (stdout and stderr).
struct CommandResult {
  int status = -1;
  std::string output;
};

/// Runs `args` (no shell; args[0] looked up in PATH) and waits. Throws std::runtime_error when
/// it cannot be started.
CommandResult runCommand(const std::vector<std::string>& args);

/// Runs `shot` as farm tasks on Slurm and copies its outputs into options.out_dir, returning
/// them as runShot does (counters stay 0: the tasks counted them). Throws InputError for bad
/// options or a shot runShot would refuse, Cancelled when options.progress returns false (every
/// stage is cancelled first), FarmTaskFailed when a task fails after its retries, and
/// std::runtime_error when Slurm's commands fail.
RunResult runShotOnSlurm(const ShotSpec& shot, const RunOptions& options,
                         const SlurmOptions& slurm);

}  // namespace cloudbake
