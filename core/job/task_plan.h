// A shot as a graph of farm tasks (docs/deployment.md, "Farm"): `cloudbake plan` writes it,
// any scheduler runs its tasks in an order that respects `after`, and `cloudbake run-task` runs
// one. Tasks meet in one bake cache (core/job/bake_cache.h: safe across processes and hosts),
// so the tasks together leave exactly the files one whole run writes.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/job/run_shot.h"
#include "core/methods/run_types.h"
#include "core/shot/shot.h"

namespace cloudbake {

/// One task of a plan.
struct FarmTask {
  std::string id;                   ///< "layout", "precompute.000", "bake", "render.000", "gather"
  RunScope scope;                   ///< the part of the shot it computes
  std::vector<std::string> after;   ///< tasks that must have finished first
  std::vector<std::string> writes;  ///< files it writes in the output folder
  /// Predicted seconds on the reference machine (2 cores), for a scheduler's packing only: the
  /// per-unit costs in task_plan.cpp, measured by bench/farm_bench.py.
  double cost_seconds = 0;
  std::string summary;  ///< one human line
};

/// The task graph of one shot.
struct TaskPlan {
  ShotSpec shot;  ///< as written (method auto included), files with absolute paths
  /// For a shot of method auto: the choice, made once when planning (every task runs it).
  std::optional<RunOptions::AutoPreset> auto_preset;
  std::vector<FarmTask> tasks;  ///< in an order that respects `after`
  std::string id;               ///< hex SHA-256 of the plan's content

  const FarmTask* find(const std::string& task_id) const;
};

/// Splits `shot` into tasks, each stage into at most `width` tasks (1..10000; InputError naming
/// --tasks otherwise):
/// - precomputed with a sequence: layout; precompute groups of basic volumes; bake (the
///   database); render groups of frames; gather (animation.json);
/// - precomputed of one volume: bake; render groups of frames; gather;
/// - single, pointcloud, photon: bake (the shot's one light direction); render groups of views;
///   gather (bake.vdb);
/// - pathtrace: render groups of views; gather (bake.vdb).
/// Every plan ends with `gather`, after every other task. A shot of method auto needs
/// `auto_preset` (chooseAutoForRun's choice); others must not have one.
TaskPlan planTasks(const ShotSpec& shot, int width,
                   std::optional<RunOptions::AutoPreset> auto_preset = std::nullopt);

/// The plan file: {"format": "cloudbake-plan/1", "id", "shot", "auto", "tasks": [{"id",
/// "kind", "views" | "frames" | "basic_volumes": [begin, end], "after", "writes",
/// "cost_seconds", "summary"}]} (docs/deployment.md).
nlohmann::json planToJson(const TaskPlan& plan);
/// Reads a plan file's text. InputError "<source>: <pointer>: ..." for malformed JSON, unknown
/// or missing fields, a task graph that is not one (unknown or cyclic `after`, duplicate ids,
/// empty ranges), and a plan whose id does not match its content (edited by hand: that also
/// covers ranges changed to lie outside the shot).
TaskPlan planFromJson(const std::string& text, const std::string& source);

/// What running a task did.
struct TaskRunResult {
  bool already_done = false;  ///< its marker and every file it wrote were intact: nothing ran
  RunResult run;
};

/// Runs task `task_id` of `plan` with `options` (out_dir, cache: required; scope and
/// auto_preset are set from the plan). A task whose done marker (markers_dir/<task>.json, its
/// files' sizes and SHA-256) matches the output folder is not run again; a task killed half-way
/// leaves no marker and simply runs again (outputs are written atomically). `gather` first
/// checks that every other task's files are present and intact. InputError naming the task for
/// an unknown id or an unfinished dependency of gather.
TaskRunResult runTask(const TaskPlan& plan, const std::string& task_id, RunOptions options,
                      const std::string& markers_dir);

}  // namespace cloudbake
