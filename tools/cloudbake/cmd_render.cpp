// `cloudbake render SHOT.json --out DIR [--threads N] [--samples N] [--quiet] [--png]`: renders
// every view of a shot in-process with the shot's bake method (docs/shot-format.md) and writes
// DIR/<view>.exr (beauty + sun, sky, single, multiple layers) and DIR/bake.vdb on request.
#include <sys/resource.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/format.h"
#include "core/io/exr_io.h"
#include "core/job/file_util.h"
#include "core/job/run_shot.h"
#include "core/job/volume_limits.h"
#include "core/methods/registry.h"
#include "core/shot/shot_parser.h"
#include "tools/cloudbake/commands.h"
#include "tools/cloudbake/interrupt.h"

namespace cloudbake::tool {
namespace {

struct RenderOptions {
  std::string shot;
  std::string out;
  int threads = 0;
  int samples = -1;
  bool samples_given = false;  // else the shot's bake.samples (-1 is a value, refused)
  bool quiet = false;
  bool png = false;
  double png_exposure = 0;
  std::string stats_json;  // "": none
  bool dry_run = false;
  int64_t max_voxels = 0;         // 0: no limit; unless given, from this machine's memory
  bool max_voxels_given = false;  // else defaultMaxVoxels()
  bool vdb_in_process = false;
};

// The floats (4 bytes each) that fit in half of this machine's physical memory: what a shot's
// lattices, tallies and volume may hold before the run is refused, naming the field that asks
// for more, rather than failing on an allocation midway (or waking the OOM killer).
uint64_t defaultMaxVoxels() {
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page <= 0) return 0;
  return uint64_t(pages) * uint64_t(page) / 2 / 4;
}

// What the run would do, without doing it: method auto's choice (it measures the scene and
// renders its pilot, which is what the choice rests on) and the method's plan.
std::vector<std::string> dryRun(const ShotSpec& shot, const RunOptions& run) {
  std::vector<std::string> lines;
  ShotSpec resolved = shot;
  if (isAutoShot(shot)) {
    const AutoChoice choice = chooseAutoForRun(shot, run);
    lines = choice.planLines();
    std::cout << "auto.json: " << choice.toJson().dump() << "\n";
    resolved = choice.shot;
  }
  if (run.samples != -1) resolved.bake.samples = run.samples;
  const MethodPlan plan =
      methodOf(resolved).plan(resolved, ShotCacheKeys{}, [](const std::string&) { return false; });
  lines.insert(lines.end(), plan.components.begin(), plan.components.end());
  // A view from a bake may trace a sparse film (docs/methods.md): its rays are a bound.
  lines.push_back(
      std::string(resolved.bake.method == "pathtrace" ? "paths: " : "view rays, at most: ") +
      exactNumber(plan.pixel_samples));
  return lines;
}

// The run's numbers for benchmarks and pipelines (docs/cli.md): counters, per-step seconds, the
// seconds per kind of step, and the process's peak resident memory.
void writeStatsJson(const std::string& path, const ShotSpec& shot, const RunResult& r) {
  nlohmann::json steps = nlohmann::json::array();
  std::map<std::string, double> totals;
  for (const StepTime& s : r.steps) {
    nlohmann::json j = {{"step", s.step}, {"seconds", s.seconds}};
    if (!s.view.empty()) j["view"] = s.view;
    if (s.frame >= 0) j["frame"] = s.frame;
    for (const auto& [k, v] : s.values) j[k] = v;
    steps.push_back(j);
    totals[s.step] += s.seconds;
  }
  struct rusage usage {};
  getrusage(RUSAGE_SELF, &usage);  // ru_maxrss is in KiB on Linux
  const nlohmann::json stats = {{"shot", shot.name},
                                {"method", shot.bake.method},
                                {"seconds", r.seconds},
                                {"peak_rss_mib", double(usage.ru_maxrss) / 1024.0},
                                {"seconds_by_step", totals},
                                {"steps", steps},
                                {"counters",
                                 {{"views_rendered", r.views_rendered},
                                  {"views_cached", r.views_cached},
                                  {"bakes_computed", r.bakes_computed},
                                  {"bakes_cached", r.bakes_cached},
                                  {"views_from_bake", r.views_from_bake},
                                  {"views_reused_direction", r.views_reused_direction}}}};
  try {
    writeFileAtomic(path, stats.dump(1) + "\n");  // no partial file, even on a full disk
  } catch (const StorageFullError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(std::string("--stats-json: ") + e.what());
  }
}

// Per-view progress on stderr: an updating line on a terminal, one line per 10% otherwise (logs
// and CI capture stay readable).
class ProgressLine {
 public:
  ProgressLine(std::string label, bool quiet)
      : label_(std::move(label)), quiet_(quiet), tty_(isatty(fileno(stderr)) != 0) {}

  void update(double fraction) {
    if (quiet_) return;
    const int percent = static_cast<int>(std::floor(std::clamp(fraction, 0.0, 1.0) * 100.0));
    if (tty_) {
      if (percent == last_) return;
      std::fprintf(stderr, "\r%s: %3d%%", label_.c_str(), percent);
    } else {
      const int decile = percent / 10 * 10;
      if (decile <= last_) return;
      std::fprintf(stderr, "%s: %d%%\n", label_.c_str(), decile);
    }
    std::fflush(stderr);
    last_ = tty_ ? percent : percent / 10 * 10;
  }

  /// Ends the line (the caller then prints the view's summary).
  void done() {
    if (quiet_ || done_) return;
    done_ = true;
    if (tty_) {
      std::fprintf(stderr, "\r%s: 100%%\n", label_.c_str());
    } else if (last_ < 100) {
      std::fprintf(stderr, "%s: 100%%\n", label_.c_str());
    }
    std::fflush(stderr);
  }

 private:
  std::string label_;
  bool quiet_, tty_;
  bool done_ = false;
  int last_ = -1;
};

// Validates the CLI's own options, then runs the shot with core/job's runShot: the same code
// path as a job of cloudbake-server (without its caches), so both write identical files.
std::vector<std::string> render(const RenderOptions& opt) {
  if (opt.threads < 0 || opt.threads > 4096) {
    throw InputError("--threads: must be in [0, 4096] (0 = all cores), got " +
                     std::to_string(opt.threads));
  }
  if (opt.samples_given && (opt.samples < 1 || opt.samples > 1000000)) {
    throw InputError("--samples: must be in [1, 1000000], got " + std::to_string(opt.samples));
  }
  // Limits every parallel stage (volume building too), not only the path tracer.
  std::unique_ptr<tbb::global_control> limit;
  if (opt.threads > 0) {
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  static_cast<size_t>(opt.threads));
    setExrThreads(opt.threads);
  }
  // The default is a flag of its own, not a value (-1 was, and --max-voxels -1 passed).
  if (opt.max_voxels < 0) {
    throw InputError("--max-voxels: must be at least 0 (0 = no limit), got " +
                     std::to_string(opt.max_voxels));
  }
  const uint64_t max_voxels = opt.max_voxels_given ? uint64_t(opt.max_voxels) : defaultMaxVoxels();
  const ShotSpec shot = parseShotFile(opt.shot);
  checkRunnable(shot, opt.shot);
  checkShotVoxels(shot, max_voxels, opt.shot);

  RunOptions run;
  run.out_dir = opt.out;
  run.source = opt.shot;
  run.threads = opt.threads;
  run.samples = opt.samples_given ? opt.samples : -1;
  run.png = opt.png;
  run.png_exposure = opt.png_exposure;
  run.max_voxels = max_voxels;
  if (!opt.vdb_in_process) run.vdb_reader.command = vdbReaderCommand();
  // runShot reports each view once with its label at 0, then the tracer's fractions, then once
  // more with a summary message at the end; other stages report a message each.
  std::unique_ptr<ProgressLine> line;
  std::string view, last_message;
  run.progress = [&](const RunProgress& p) {
    if (interrupted()) return false;
    if (opt.quiet) return true;
    if (p.stage == "render") {
      if (!line || p.view != view) {
        if (line) line->done();
        view = p.view;
        last_message = p.message;
        line = std::make_unique<ProgressLine>(shot.name + ": " + p.message, opt.quiet);
      }
      line->update(p.view_fraction);
      if (p.message != last_message) {
        line->done();
        last_message = p.message;
        std::fprintf(stderr, "%s: %s\n", shot.name.c_str(), p.message.c_str());
      }
    } else if (p.message != last_message) {
      if (line) line->done();
      last_message = p.message;
      std::fprintf(stderr, "%s: %s\n", shot.name.c_str(), p.message.c_str());
    }
    return true;
  };
  if (opt.dry_run) {
    const std::vector<std::string> plan = dryRun(shot, run);
    if (interrupted()) throw Cancelled();
    for (const std::string& line : plan) std::cout << line << "\n";
    return {};
  }
  const RunResult result = runShot(shot, run);
  if (!opt.stats_json.empty()) writeStatsJson(opt.stats_json, shot, result);
  std::vector<std::string> written;
  for (const OutputFile& f : result.files) written.push_back(f.path);
  return written;
}

}  // namespace

void addRenderCommand(CLI::App& app, int* exit_code) {
  auto opt = std::make_shared<RenderOptions>();
  CLI::App* cmd = app.add_subcommand(
      "render", "Render every view of a shot in-process with its bake.method (" + [] {
        std::string names;
        for (const std::string& n : methodNames(true)) {
          names += (names.empty() ? "" : ", ") + n;
        }
        return names;
      }() + "; docs/shot-format.md)");
  cmd->add_option("shot", opt->shot, "shot file (JSON, format v1)")->required();
  cmd->add_option("--out", opt->out, "output folder (created if missing)")->required();
  cmd->add_option("--threads", opt->threads, "worker threads (default 0 = all cores)");
  cmd->add_option("--samples", opt->samples,
                  "paths (pathtrace) or rays (views from a bake) per pixel, overriding the "
                  "shot's bake.samples (1..1000000)")
      ->each([opt](const std::string&) { opt->samples_given = true; });
  cmd->add_flag("--quiet", opt->quiet, "no progress on stderr");
  cmd->add_flag("--vdb-in-process", opt->vdb_in_process,
                "read the shot's VDB files in this process, not first rewritten by a child "
                "process (faster for large files, but a corrupt file can then crash the run)");
  cmd->add_option("--max-voxels", opt->max_voxels,
                  "most floats (4 bytes each) the shot's volume, lattices and tallies may hold, "
                  "checked before anything runs (default: half of this machine's memory; 0 = no "
                  "limit)")
      ->each([opt](const std::string&) { opt->max_voxels_given = true; });
  cmd->add_flag("--dry-run", opt->dry_run,
                "print what the run would do (method auto: its choice, predicted error and "
                "cost, after measuring the scene with a short pilot render) and write nothing");
  cmd->add_flag("--png", opt->png,
                "also write an auto-exposed sRGB preview DIR/<view>.png beside each EXR");
  cmd->add_option("--stats-json", opt->stats_json,
                  "also write the run's counters, per-step seconds and peak memory as JSON to "
                  "this file (docs/cli.md)");
  cmd->add_option("--png-exposure", opt->png_exposure,
                  "fixed exposure of the PNG previews (radiance multiplier; default: auto), so "
                  "previews of different lighting compare");
  // Failures go to main(), which maps them like every other program (common/exit_codes.h).
  cmd->callback([opt, exit_code] {
    for (const std::string& path : render(*opt)) std::cout << path << "\n";
    std::cout.flush();
    *exit_code = kOk;
  });
}

}  // namespace cloudbake::tool
