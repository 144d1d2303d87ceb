// `cloudbake plan SHOT.json [--tasks N] [--json]` writes a shot's farm task graph;
// `cloudbake run-task PLAN.json TASK --cache-dir DIR --out DIR` runs one of its tasks
// (core/job/task_plan.h, docs/deployment.md "Farm").
#include <tbb/global_control.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <string>

#include "core/error.h"
#include "core/format.h"
#include "core/io/exr_io.h"
#include "core/job/bake_cache.h"
#include "core/job/file_util.h"
#include "core/job/task_plan.h"
#include "core/methods/registry.h"
#include "core/shot/shot_parser.h"
#include "tools/cloudbake/commands.h"
#include "tools/cloudbake/interrupt.h"

namespace cloudbake::tool {
namespace {
namespace fs = std::filesystem;

struct PlanOptions {
  std::string shot;
  int tasks = 8;
  bool json = false;
  int threads = 0;
};

struct RunTaskOptions {
  std::string plan;
  std::string task;
  std::string cache_dir;
  std::string out;
  int threads = 0;
  bool quiet = false;
  bool check = false;
};

std::unique_ptr<tbb::global_control> limitThreads(int threads) {
  if (threads < 0 || threads > 4096) {
    throw InputError("--threads: must be in [0, 4096] (0 = all cores), got " +
                     std::to_string(threads));
  }
  if (threads == 0) return nullptr;
  setExrThreads(threads);
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               size_t(threads));
}

void plan(const PlanOptions& opt) {
  const auto limit = limitThreads(opt.threads);
  const ShotSpec shot = parseShotFile(opt.shot);
  checkRunnable(shot, opt.shot);
  std::optional<RunOptions::AutoPreset> preset;
  if (isAutoShot(shot)) {
    // The choice is made once here (it measures the scene with a pilot render), so every task
    // runs the same method.
    RunOptions ro;
    ro.source = opt.shot;
    ro.threads = opt.threads;
    ro.vdb_reader.command = vdbReaderCommand();
    const AutoChoice choice = chooseAutoForRun(shot, ro);
    preset = RunOptions::AutoPreset{choice.shot, autoSummary(choice), choice.toJson()};
  }
  const TaskPlan p = planTasks(shot, opt.tasks, preset);
  if (opt.json) {
    std::cout << planToJson(p).dump(1) << "\n";
    return;
  }
  double total = 0;
  for (const FarmTask& t : p.tasks) {
    std::string after;
    for (const std::string& a : t.after) after += (after.empty() ? "" : ",") + a;
    std::cout << t.id << "  ~" << fixed(t.cost_seconds, 1) << " s  " << t.summary
              << (after.empty() ? "" : "  (after " + after + ")") << "\n";
    total += t.cost_seconds;
  }
  std::cout << p.tasks.size() << " tasks, ~" << fixed(total, 1)
            << " s predicted in all; --json writes the plan for run-task\n";
}

// Bytes this process read and wrote through system calls (Linux /proc/self/io: rchar, wchar),
// which on a farm node is mostly the shared folder: for sizing the farm's storage.
std::pair<uint64_t, uint64_t> ioBytes() {
  std::ifstream in("/proc/self/io");
  std::string key;
  uint64_t value = 0, read = 0, written = 0;
  while (in >> key >> value) {
    if (key == "rchar:") read = value;
    if (key == "wchar:") written = value;
  }
  return {read, written};
}

void runTaskCommand(const RunTaskOptions& opt) {
  const auto limit = limitThreads(opt.threads);
  // A FIFO or /dev/zero as the plan would block or fill the memory: a regular file of at most
  // the JSON reader's 64 MiB.
  const TaskPlan p = planFromJson(readRegularFile(opt.plan, 64u << 20), opt.plan);
  if (opt.check) {  // the plan and the task are valid: what a scheduler asks before submitting
    if (!p.find(opt.task)) {
      throw InputError("task: no task '" + opt.task + "' in the plan " + opt.plan);
    }
    std::cout << p.id << "\n";
    return;
  }
  const std::string cache_root = (fs::path(opt.cache_dir) / "cache").string();
  makeWritableFolder(cache_root, "--cache-dir");
  std::optional<BakeCache> cache;
  try {
    cache.emplace(cache_root, BakeCacheOptions{});
  } catch (const fs::filesystem_error& e) {
    // A cache whose folders another user made read-only: the flag's problem, not ours.
    throw InputError("--cache-dir: cannot use the cache in '" + cache_root +
                     "': " + e.code().message());
  }
  RunOptions ro;
  ro.out_dir = opt.out;
  ro.source = opt.plan;
  ro.threads = opt.threads;
  ro.cache = &*cache;
  ro.vdb_reader.command = vdbReaderCommand();  // a corrupt file fails the task, not the node's run
  std::string last;
  ro.progress = [&](const RunProgress& progress) {
    if (interrupted()) return false;
    if (!opt.quiet && progress.message != last) {
      last = progress.message;
      std::fprintf(stderr, "%s: %s\n", opt.task.c_str(), last.c_str());
    }
    return true;
  };
  const std::string markers = (fs::path(opt.cache_dir) / "tasks" / p.id).string();
  const TaskRunResult r = runTask(p, opt.task, ro, markers);
  if (r.already_done) {
    if (!opt.quiet)
      std::fprintf(stderr, "%s: already done (its files are intact)\n", opt.task.c_str());
    return;
  }
  for (const OutputFile& f : r.run.files) std::cout << f.path << "\n";
  if (!opt.quiet) {
    const auto [read, written] = ioBytes();
    std::fprintf(stderr, "%s: done in %.2f s; read %llu bytes, wrote %llu bytes\n",
                 opt.task.c_str(), r.run.seconds, (unsigned long long)read,
                 (unsigned long long)written);
  }
}

}  // namespace

void addFarmCommands(CLI::App& app, int* exit_code) {
  auto popt = std::make_shared<PlanOptions>();
  CLI::App* plan_cmd = app.add_subcommand(
      "plan", "Split a shot into farm tasks with dependencies (docs/deployment.md, \"Farm\")");
  plan_cmd->add_option("shot", popt->shot, "shot file (JSON, format v1)")->required();
  plan_cmd->add_option("--tasks", popt->tasks,
                       "most tasks per stage, i.e. how wide the farm runs it (default 8)");
  plan_cmd->add_flag("--json", popt->json, "write the plan as JSON on stdout (for run-task)");
  plan_cmd->add_option("--threads", popt->threads,
                       "worker threads for method auto's pilot (default 0 = all cores)");
  plan_cmd->callback([popt, exit_code] {
    plan(*popt);
    std::cout.flush();
    *exit_code = kOk;
  });

  auto ropt = std::make_shared<RunTaskOptions>();
  CLI::App* run_cmd = app.add_subcommand(
      "run-task", "Run one task of a plan; done tasks are not run again (docs/deployment.md)");
  run_cmd->add_option("plan", ropt->plan, "plan file (cloudbake plan --json)")->required();
  run_cmd->add_option("task", ropt->task, "the task's id")->required();
  run_cmd
      ->add_option("--cache-dir", ropt->cache_dir,
                   "the folder every task of the plan shares (may be on NFS)")
      ->required();
  run_cmd->add_option("--out", ropt->out, "output folder (created if missing)")->required();
  run_cmd->add_option("--threads", ropt->threads, "worker threads (default 0 = all cores)");
  run_cmd->add_flag("--quiet", ropt->quiet, "no progress on stderr");
  run_cmd->add_flag("--check", ropt->check,
                    "only check the plan (as `cloudbake plan` would make it of its shot) and the "
                    "task; print the plan's id and run nothing");
  run_cmd->callback([ropt, exit_code] {
    runTaskCommand(*ropt);
    std::cout.flush();
    *exit_code = kOk;
  });
}

}  // namespace cloudbake::tool
