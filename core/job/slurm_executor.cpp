#include "core/job/slurm_executor.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include "core/error.h"
#include "core/format.h"
#include "core/job/file_util.h"
#include "core/job/run_outputs.h"
#include "core/job/task_plan.h"

extern char** environ;

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

std::string shellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

void checkOptions(const SlurmOptions& so) {
  if (so.shared_dir.empty()) throw InputError("--shared-dir: the slurm executor needs one");
  if (so.cloudbake.empty()) throw InputError("--slurm-cloudbake: must name the cloudbake binary");
  if (so.tasks < 1 || so.tasks > 10000) throw InputError("--slurm-tasks: must be in [1, 10000]");
  if (so.cpus_per_task < 1 || so.cpus_per_task > 4096) {
    throw InputError("--slurm-cpus-per-task: must be in [1, 4096]");
  }
  if (so.retries < 0 || so.retries > 10) throw InputError("--slurm-retries: must be in [0, 10]");
}

// Element i of a stage's array runs the stage's i-th task, retried in place.
std::string stageScript(const SlurmOptions& so, const std::string& plan_path,
                        const std::vector<std::string>& ids, const std::string& out) {
  std::ostringstream s;
  s << "#!/bin/bash\n# Written by cloudbake-server: element i of this array runs task IDS[i].\n";
  s << "IDS=(";
  for (const std::string& id : ids) s << " " << shellQuote(id);
  s << " )\nid=${IDS[${SLURM_ARRAY_TASK_ID:-0}]}\n";
  s << "for attempt in $(seq 1 " << so.retries + 1 << "); do\n";
  s << "  echo \"cloudbake: task $id, attempt $attempt on $(hostname)\"\n";
  s << "  " << shellQuote(so.cloudbake) << " run-task " << shellQuote(plan_path)
    << " \"$id\" --cache-dir " << shellQuote(so.shared_dir) << " --out " << shellQuote(out)
    << " --threads " << so.cpus_per_task << " && exit 0\ndone\n";
  s << "echo \"cloudbake: task $id failed after all attempts\" >&2\nexit 1\n";
  return s.str();
}

struct Stage {
  std::string kind;
  std::vector<std::string> ids;
};

std::vector<Stage> stagesOf(const TaskPlan& plan) {
  std::vector<Stage> stages;
  for (const FarmTask& t : plan.tasks) {
    const std::string kind = t.id.substr(0, t.id.find('.'));
    if (stages.empty() || stages.back().kind != kind) stages.push_back({kind, {}});
    stages.back().ids.push_back(t.id);
  }
  return stages;
}

// The submitted stages: Slurm job ids, and each task's log file.
struct Submitted {
  std::vector<std::string> jobs;
  std::map<std::string, std::string> log_of;
};

std::string sbatch(const SlurmOptions& so, const std::string& name, const std::string& script,
                   size_t count, const std::set<std::string>& after, const std::string& log) {
  std::vector<std::string> args = {"sbatch",
                                   "--parsable",
                                   "--job-name",
                                   name,
                                   "--output",
                                   log,
                                   "--cpus-per-task",
                                   std::to_string(so.cpus_per_task),
                                   "--kill-on-invalid-dep=yes"};
  if (count > 1) args.insert(args.end(), {"--array", "0-" + std::to_string(count - 1)});
  if (!after.empty()) {
    std::string dep = "afterok";
    for (const std::string& a : after) dep += ":" + a;
    args.insert(args.end(), {"--dependency", dep});
  }
  if (!so.partition.empty()) args.insert(args.end(), {"--partition", so.partition});
  args.push_back(script);
  const CommandResult r = runCommand(args);
  // --parsable prints "<id>[;<cluster>]" on a line of its own; warnings may surround it.
  std::istringstream lines(r.output);
  std::string line;
  while (r.status == 0 && std::getline(lines, line)) {
    const std::string id = line.substr(0, line.find(';'));
    if (!id.empty() && std::all_of(id.begin(), id.end(), ::isdigit)) return id;
  }
  throw std::runtime_error("sbatch failed: " + r.output);
}

void cancelJobs(const std::vector<std::string>& jobs) {
  if (jobs.empty()) return;
  std::vector<std::string> args = {"scancel"};
  args.insert(args.end(), jobs.begin(), jobs.end());
  const CommandResult r = runCommand(args);
  if (r.status != 0) throw std::runtime_error("scancel failed: " + r.output);
}

Submitted submitStages(const TaskPlan& plan, const SlurmOptions& so, const fs::path& dir,
                       const std::string& plan_path, const std::string& out) {
  Submitted s;
  std::map<std::string, std::string> job_of;
  const std::vector<Stage> stages = stagesOf(plan);
  for (size_t n = 0; n < stages.size(); ++n) {
    const Stage& st = stages[n];
    const std::string script =
        (dir / ("stage" + std::to_string(n) + "-" + st.kind + ".sh")).string();
    writeFileAtomic(script, stageScript(so, plan_path, st.ids, out));
    fs::permissions(script, fs::perms::owner_all | fs::perms::group_read | fs::perms::others_read);
    std::set<std::string> after;
    for (const std::string& id : st.ids) {
      for (const std::string& a : plan.find(id)->after) after.insert(job_of.at(a));
    }
    const bool array = st.ids.size() > 1;
    const std::string log = (dir / "logs" / (st.kind + (array ? ".%a.log" : ".log"))).string();
    std::string job;
    try {
      job = sbatch(so, "cb-" + plan.id.substr(0, 8) + "-" + st.kind, script, st.ids.size(), after,
                   log);
    } catch (...) {
      cancelJobs(s.jobs);  // none of a half-submitted plan is left to run
      throw;
    }
    s.jobs.push_back(job);
    for (size_t i = 0; i < st.ids.size(); ++i) {
      job_of[st.ids[i]] = job;
      s.log_of[st.ids[i]] =
          (dir / "logs" / (st.kind + (array ? "." + std::to_string(i) : "") + ".log")).string();
    }
  }
  return s;
}

// What squeue lists of `jobs` (array elements included), in any partition: how many tasks are
// still listed and how many of them run. A failing squeue (the controller restarting) is asked
// again for about a minute.
struct QueueState {
  size_t listed = 0;
  size_t running = 0;
};

QueueState queueState(const std::vector<std::string>& jobs) {
  CommandResult r;
  for (int attempt = 0; attempt < 30; ++attempt) {
    r = runCommand({"squeue", "-a", "-h", "-r", "-o", "%F %t"});
    if (r.status == 0) break;
    std::this_thread::sleep_for(std::chrono::seconds(2));
  }
  if (r.status != 0) throw std::runtime_error("squeue failed: " + r.output);
  std::istringstream in(r.output);
  std::string id, state;
  const std::set<std::string> ours(jobs.begin(), jobs.end());
  QueueState q;
  while (in >> id >> state) {
    if (!ours.count(id)) continue;
    ++q.listed;
    q.running += state == "R" || state == "CG";
  }
  return q;
}

bool done(const std::string& markers, const std::string& task) {
  std::error_code ec;
  return fs::exists(fs::path(markers) / (task + ".json"), ec);
}

std::string logTail(const std::string& path, size_t lines) {
  std::ifstream in(path);
  std::vector<std::string> all;
  std::string line;
  while (std::getline(in, line)) all.push_back(line);
  std::string out;
  for (size_t i = all.size() > lines ? all.size() - lines : 0; i < all.size(); ++i) {
    out += all[i] + "\n";
  }
  return out.empty() ? "(no log)\n" : out;
}

}  // namespace

CommandResult runCommand(const std::vector<std::string>& args) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error("pipe failed");
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, fds[1], 1);
  posix_spawn_file_actions_adddup2(&actions, fds[1], 2);
  std::vector<std::string> copy = args;
  std::vector<char*> argv;
  for (std::string& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  const int spawned = posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(fds[1]);
  if (spawned != 0) {
    ::close(fds[0]);
    throw std::runtime_error(args[0] + ": cannot run it (is it installed and on PATH?)");
  }
  CommandResult r;
  char buf[4096];
  ssize_t n;
  while ((n = ::read(fds[0], buf, sizeof buf)) > 0 || (n < 0 && errno == EINTR)) {
    if (n > 0) r.output.append(buf, size_t(n));
  }
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

namespace {

// Polls the stages until none is queued; progress is the done tasks' share of the predicted
// cost. A cancel (progress returns false) scancels every stage first.
void follow(const TaskPlan& plan, const Submitted& s, const std::string& markers,
            const RunOptions& ro, const SlurmOptions& so) {
  double total = 0;
  for (const FarmTask& t : plan.tasks) total += t.cost_seconds;
  for (;;) {
    double finished = 0;
    size_t count = 0;
    for (const FarmTask& t : plan.tasks) {
      if (!done(markers, t.id)) continue;
      finished += t.cost_seconds;
      ++count;
    }
    const QueueState q = queueState(s.jobs);
    RunProgress p;
    p.stage = "render";
    p.fraction = total > 0 ? finished / total : 0;
    p.message = std::to_string(count) + " of " + std::to_string(plan.tasks.size()) +
                " farm tasks done, " + std::to_string(q.running) + " running (Slurm jobs " +
                s.jobs.front() + ".." + s.jobs.back() + ")";
    if (ro.progress && !ro.progress(p)) {
      cancelJobs(s.jobs);
      throw Cancelled("cancelled: its Slurm jobs were cancelled");
    }
    if (q.listed == 0) return;
    std::this_thread::sleep_for(so.poll);
  }
}

// The failed tasks and the end of each one's log, without the shared folder's path.
std::string failureReport(const TaskPlan& plan, const Submitted& s, const std::string& markers,
                          const SlurmOptions& so) {
  std::string report;
  for (const FarmTask& t : plan.tasks) {
    if (done(markers, t.id)) continue;
    if (report.empty()) {
      report = "farm task " + t.id + " failed; its log ends:\n" + logTail(s.log_of.at(t.id), 4);
    } else {
      report += "not run: " + t.id + "\n";
    }
  }
  for (size_t at; (at = report.find(so.shared_dir)) != std::string::npos;) {
    report.replace(at, so.shared_dir.size(), "<shared>");
  }
  return report;
}

}  // namespace

RunResult runShotOnSlurm(const ShotSpec& shot_in, const RunOptions& ro, const SlurmOptions& so) {
  const auto t0 = std::chrono::steady_clock::now();
  checkOptions(so);
  ShotSpec shot = shot_in;
  checkSamplesOverride(ro.samples, "samples");
  if (ro.samples != -1) shot.bake.samples = ro.samples;
  checkRunnable(shot, ro.source);
  std::optional<RunOptions::AutoPreset> preset;
  if (isAutoShot(shot)) {
    const AutoChoice choice = chooseAutoForRun(shot, ro);
    preset = RunOptions::AutoPreset{choice.shot, autoSummary(choice), choice.toJson()};
    // The override is the chosen method's, as runShot applies it (the choice replaced it).
    if (ro.samples != -1) preset->shot.bake.samples = ro.samples;
  }
  const TaskPlan plan = planTasks(shot, so.tasks, preset);
  const fs::path dir = fs::path(so.shared_dir) / "tasks" / plan.id;
  fs::create_directories(dir / "logs");
  const std::string plan_path = (dir / "plan.json").string();
  writeFileAtomic(plan_path, planToJson(plan).dump(1));
  const std::string out = (fs::path(so.shared_dir) / "out" / plan.id).string();
  const Submitted s = submitStages(plan, so, dir, plan_path, out);
  try {
    follow(plan, s, dir.string(), ro, so);
  } catch (const Cancelled&) {
    throw;
  } catch (...) {
    cancelJobs(s.jobs);  // squeue failed for good: stop what runs rather than leave it
    throw;
  }
  if (!done(dir.string(), "gather")) throw FarmTaskFailed(failureReport(plan, s, dir.string(), so));

  RunResult result;
  result.method = preset ? preset->shot.bake.method : shot.bake.method;
  fs::create_directories(ro.out_dir);
  for (const FarmTask& t : plan.tasks) {
    for (const std::string& name : t.writes) {
      const fs::path from = fs::path(out) / name;
      if (!fs::exists(from)) continue;  // planned but not written (an empty cloud's walk)
      const std::string tmp = (fs::path(ro.out_dir) / (name + ".tmp." + uniqueSuffix())).string();
      linkOrCopy(from.string(), tmp);
      fs::rename(tmp, fs::path(ro.out_dir) / name);
      result.files.push_back(describeOutput(ro.out_dir, name));
    }
  }
  result.seconds = secondsSince(t0);
  return result;
}

}  // namespace cloudbake
