#include "core/job/task_plan.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "core/error.h"
#include "core/job/file_util.h"
#include "core/job/run_outputs.h"
#include "core/job/sha256.h"
#include "core/methods/precomputed.h"
#include "core/methods/registry.h"
#include "core/shot/json_reader.h"
#include "core/shot/shot_parser.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using Json = nlohmann::json;
using Part = RunScope::Part;

constexpr const char* kFormat = "cloudbake-plan/1";

// Per-unit costs on the reference machine (2 cores), measured by bench/farm_bench.py on the
// bundled examples; a scheduler's packing hint, not a promise.
constexpr double kPathSecondsPerSample = 2.0e-6;      // one path of one pixel (pathtrace)
constexpr double kViewSecondsPerRay = 1.5e-6;         // one ray of a view from a bake
constexpr double kBakeSecondsPerVoxel = 0.65e-6;      // a light bake, per lattice voxel
constexpr double kPrecomputeSecondsPerVoxel = 40e-6;  // one basic volume, per lattice voxel
constexpr double kFrameSecondsPerVoxel = 2e-6;        // lighting one animation frame

struct Range {
  int begin, end;
};

// `n` items in at most `width` contiguous groups whose sizes differ by at most one.
std::vector<Range> split(int n, int width) {
  const int groups = std::max(1, std::min(n, width));
  std::vector<Range> out;
  for (int g = 0; g < groups; ++g) {
    out.push_back({int(int64_t(n) * g / groups), int(int64_t(n) * (g + 1) / groups)});
  }
  return out;
}

std::string numbered(const std::string& kind, size_t i, size_t n) {
  std::string digits = std::to_string(i);
  const size_t width = std::max<size_t>(3, std::to_string(n - 1).size());
  return kind + "." + std::string(width - std::min(width, digits.size()), '0') + digits;
}

const char* partName(Part p) {
  switch (p) {
    case Part::kLayout:
      return "layout";
    case Part::kPrecompute:
      return "precompute";
    case Part::kBake:
      return "bake";
    case Part::kRender:
      return "render";
    case Part::kGather:
      return "gather";
    case Part::kAll:
      break;
  }
  return "all";
}

double latticeVoxels(const ShotSpec& shot) {
  const auto r = shot.bake.knobs.optionalInteger("light_resolution");
  return r ? std::pow(double(*r), 3) : 0.0;
}

double pixelsOf(const ShotSpec& shot, int begin, int end) {
  double pixels = 0;
  for (int i = begin; i < end; ++i) {
    pixels += double(shot.views[size_t(i)].width_px) * shot.views[size_t(i)].height_px;
  }
  return pixels * shot.bake.samples;
}

// The render tasks of a method whose views are independent (pathtrace, views from a bake).
void addViewTasks(TaskPlan& plan, const ShotSpec& shot, int width, const std::string& after) {
  const int n = shot.outputs.exr ? int(shot.views.size()) : 0;
  if (n == 0) return;
  const bool traced = !methodOf(shot).info().bakes_light;
  const std::vector<Range> groups = split(n, width);
  for (size_t g = 0; g < groups.size(); ++g) {
    FarmTask t;
    t.id = numbered("render", g, groups.size());
    t.scope = {Part::kRender, groups[g].begin, groups[g].end};
    if (!after.empty()) t.after = {after};
    for (int i = groups[g].begin; i < groups[g].end; ++i) {
      t.writes.push_back(shot.views[size_t(i)].name + ".exr");
    }
    t.cost_seconds = pixelsOf(shot, t.scope.begin, t.scope.end) *
                     (traced ? kPathSecondsPerSample : kViewSecondsPerRay);
    t.summary = "views " + std::to_string(t.scope.begin) + ".." + std::to_string(t.scope.end - 1) +
                (traced ? ", path traced" : ", from the bake");
    plan.tasks.push_back(std::move(t));
  }
}

// Precomputed: the database's parts (sequences), its assembly, frame groups.
void addPrecomputedTasks(TaskPlan& plan, const ShotSpec& shot, int width) {
  const PrecomputedShotOptions o = precomputedOptions(shot);
  const double voxels = latticeVoxels(shot);
  FarmTask bake{"bake", {Part::kBake, 0, 0}, {}, {}, 0, "the precomputed database"};
  if (std::holds_alternative<SequenceVolumeSpec>(shot.volume)) {
    plan.tasks.push_back({"layout",
                          {Part::kLayout, 0, 0},
                          {},
                          {},
                          o.basic_volumes * voxels * kBakeSecondsPerVoxel,
                          "every basic volume on one lattice; receivers and sample points"});
    const std::vector<Range> groups = split(o.basic_volumes, width);
    for (size_t g = 0; g < groups.size(); ++g) {
      const Range r = groups[g];
      FarmTask t{numbered("precompute", g, groups.size()),
                 {Part::kPrecompute, r.begin, r.end},
                 {"layout"},
                 {},
                 (r.end - r.begin) * voxels * kPrecomputeSecondsPerVoxel,
                 "basic volumes " + std::to_string(r.begin) + ".." + std::to_string(r.end - 1)};
      bake.after.push_back(t.id);
      plan.tasks.push_back(std::move(t));
    }
    bake.summary += ", assembled from its parts";
    bake.cost_seconds = o.basic_volumes * voxels * kBakeSecondsPerVoxel;
  } else {
    bake.cost_seconds = voxels * kPrecomputeSecondsPerVoxel;
  }
  plan.tasks.push_back(bake);
  const int n_views = shot.outputs.exr ? int(shot.views.size()) : 0;
  const std::vector<Range> groups = split(o.frames, width);
  for (size_t g = 0; g < groups.size(); ++g) {
    FarmTask t{numbered("render", g, groups.size()),
               {Part::kRender, groups[g].begin, groups[g].end},
               {"bake"},
               {},
               0,
               ""};
    for (int f = t.scope.begin; f < t.scope.end; ++f) {
      for (int i = 0; i < n_views; ++i) {
        t.writes.push_back(frameStem(shot.views[size_t(i)].name, f) + ".exr");
      }
      if (shot.outputs.vdb) t.writes.push_back(frameStem("bake", f) + ".vdb");
    }
    t.cost_seconds =
        (t.scope.end - t.scope.begin) *
        (voxels * kFrameSecondsPerVoxel + pixelsOf(shot, 0, n_views) * kViewSecondsPerRay);
    t.summary = "frames " + std::to_string(t.scope.begin) + ".." + std::to_string(t.scope.end - 1);
    plan.tasks.push_back(std::move(t));
  }
}

const char* rangeKey(Part p) {
  return p == Part::kPrecompute ? "basic_volumes" : p == Part::kRender ? "views" : "";
}

Json taskJson(const FarmTask& t, bool frames) {
  Json j = {{"id", t.id},         {"kind", partName(t.scope.part)}, {"after", t.after},
            {"writes", t.writes}, {"cost_seconds", t.cost_seconds}, {"summary", t.summary}};
  const std::string key =
      frames && t.scope.part == Part::kRender ? "frames" : rangeKey(t.scope.part);
  if (!key.empty()) j[key] = {t.scope.begin, t.scope.end};
  return j;
}

Json shotJson(const ShotSpec& shot) { return Json::parse(serializeShot(shot)); }

// The plan's content without its id: what the id hashes.
std::string contentId(const TaskPlan& plan) {
  Json j = planToJson(plan);
  j.erase("id");
  return sha256Hex(j.dump());
}

}  // namespace

Json planToJson(const TaskPlan& plan) {
  const ShotSpec& effective = plan.auto_preset ? plan.auto_preset->shot : plan.shot;
  const bool frames = methodOf(effective).info().animates;
  Json tasks = Json::array();
  for (const FarmTask& t : plan.tasks) tasks.push_back(taskJson(t, frames));
  Json j = {{"format", kFormat}, {"id", plan.id}, {"shot", shotJson(plan.shot)}, {"tasks", tasks}};
  j["auto"] = nullptr;
  if (plan.auto_preset) {
    j["auto"] = {{"shot", shotJson(plan.auto_preset->shot)},
                 {"summary", plan.auto_preset->summary},
                 {"record", plan.auto_preset->record}};
  }
  return j;
}

const FarmTask* TaskPlan::find(const std::string& task_id) const {
  for (const FarmTask& t : tasks) {
    if (t.id == task_id) return &t;
  }
  return nullptr;
}

TaskPlan planTasks(const ShotSpec& shot_in, int width,
                   std::optional<RunOptions::AutoPreset> auto_preset) {
  if (width < 1 || width > 10000) {
    throw InputError("--tasks: must be in [1, 10000], got " + std::to_string(width));
  }
  if (isAutoShot(shot_in) != auto_preset.has_value()) {
    throw InternalError("planTasks: a shot of method auto needs its choice, others none");
  }
  checkRunnable(shot_in);
  TaskPlan plan;
  plan.shot = shot_in;
  plan.auto_preset = std::move(auto_preset);
  const ShotSpec& shot = plan.auto_preset ? plan.auto_preset->shot : shot_in;
  const MethodInfo& info = methodOf(shot).info();
  if (info.animates) {
    addPrecomputedTasks(plan, shot, width);
  } else if (info.bakes_light) {
    plan.tasks.push_back({"bake",
                          {Part::kBake, 0, 0},
                          {},
                          {},
                          latticeVoxels(shot) * kBakeSecondsPerVoxel,
                          "the light of the shot's sun direction (" + info.name + ")"});
    addViewTasks(plan, shot, width, "bake");
  } else {
    addViewTasks(plan, shot, width, "");
  }
  FarmTask gather{"gather", {Part::kGather, 0, 0}, {}, {}, 1, "the shot's own files"};
  for (const FarmTask& t : plan.tasks) gather.after.push_back(t.id);
  if (info.animates) gather.writes.push_back("animation.json");
  if (!info.animates && shot.outputs.vdb) gather.writes.push_back("bake.vdb");
  if (plan.auto_preset) gather.writes.push_back("auto.json");
  plan.tasks.push_back(std::move(gather));
  plan.id = contentId(plan);
  return plan;
}

namespace {

Part partFromName(const shotjson::Reader& r, const std::string& name, const std::string& ptr) {
  for (Part p : {Part::kLayout, Part::kPrecompute, Part::kBake, Part::kRender, Part::kGather}) {
    if (name == partName(p)) return p;
  }
  r.fail(ptr, "unknown kind '" + name + "' (layout, precompute, bake, render or gather)");
}

std::vector<std::string> stringList(const shotjson::Reader& r, const Json& v,
                                    const std::string& ptr) {
  if (!v.is_array()) r.fail(ptr, "must be an array of strings, got " + shotjson::typeName(v));
  std::vector<std::string> out;
  for (size_t i = 0; i < v.size(); ++i)
    out.push_back(r.string(v[i], ptr + "/" + std::to_string(i)));
  return out;
}

// A task's id and the files it writes name files (DIR/<id>.json markers, DIR/<name>): plain
// names only, so a plan whose id was computed again after an edit cannot reach outside its
// folders.
void checkPlainName(const shotjson::Reader& r, const std::string& name, const std::string& ptr) {
  const bool plain =
      !name.empty() && name.size() <= 255 && name[0] != '.' &&
      std::all_of(name.begin(), name.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-';
      });
  if (!plain) {
    r.fail(ptr,
           "'" + name + "' is not a plain file name (A-Z a-z 0-9 _ . -, not starting with '.')");
  }
}

// How many views, frames or basic volumes a task's range may count, from the plan's shot; -1
// where the plan does not say (a frame count of a method other than precomputed).
int64_t rangeLimit(const ShotSpec& shot, const std::string& key) {
  const auto* sequence = std::get_if<SequenceVolumeSpec>(&shot.volume);
  const int64_t basic = sequence ? sequence->frames : 1;
  if (key == "views") return int64_t(shot.views.size());
  if (key == "basic_volumes") return basic;
  if (key == "frames" && shot.bake.method == "precomputed") {
    return shot.bake.knobs.optionalInteger("frames").value_or(basic);
  }
  return -1;
}

FarmTask readTask(const shotjson::Reader& r, const Json& v, const std::string& ptr,
                  const ShotSpec& shot) {
  const shotjson::Object o(r, v, ptr,
                           {"id", "kind", "after", "writes", "cost_seconds", "summary", "views",
                            "frames", "basic_volumes"});
  FarmTask t;
  t.id = r.string(o.required("id"), o.path("id"));
  checkPlainName(r, t.id, o.path("id"));
  t.scope.part = partFromName(r, r.string(o.required("kind"), o.path("kind")), o.path("kind"));
  t.after = stringList(r, o.required("after"), o.path("after"));
  t.writes = stringList(r, o.required("writes"), o.path("writes"));
  for (size_t i = 0; i < t.writes.size(); ++i) {
    checkPlainName(r, t.writes[i], o.path("writes") + "/" + std::to_string(i));
  }
  t.cost_seconds = r.numberIn(o.required("cost_seconds"), o.path("cost_seconds"), 0, 1e12);
  t.summary = r.string(o.required("summary"), o.path("summary"));
  // The range a task of this kind has in this shot, as taskJson writes it: another key would
  // be read against the wrong limit (an outside probe's forged plan ran frames past the views).
  const std::string expected = methodOf(shot).info().animates && t.scope.part == Part::kRender
                                   ? "frames"
                                   : rangeKey(t.scope.part);
  for (const char* key : {"views", "frames", "basic_volumes"}) {
    const Json* range = o.find(key);
    if (!range) continue;
    if (key != expected) {
      r.fail(o.path(key), std::string("a '") + partName(t.scope.part) + "' task of this shot has " +
                              (expected.empty() ? "no range" : "the range '" + expected + "'"));
    }
    if (!range->is_array() || range->size() != 2) r.fail(o.path(key), "must be [begin, end]");
    t.scope.begin = int(r.integer((*range)[0], o.path(key) + "/0", 0, 10000000));
    t.scope.end = int(r.integer((*range)[1], o.path(key) + "/1", t.scope.begin + 1, 10000000));
    const int64_t limit = rangeLimit(shot, key);
    if (limit >= 0 && t.scope.end > limit) {
      r.fail(o.path(key) + "/1", "runs past the shot's " + std::to_string(limit) + " " + key);
    }
  }
  return t;
}

// Ids unique, every `after` names an earlier task (so the list order is a schedule).
void checkGraph(const shotjson::Reader& r, const std::vector<FarmTask>& tasks) {
  std::set<std::string> seen;
  for (size_t i = 0; i < tasks.size(); ++i) {
    const std::string ptr = "/tasks/" + std::to_string(i);
    for (size_t k = 0; k < tasks[i].after.size(); ++k) {
      if (!seen.count(tasks[i].after[k])) {
        r.fail(ptr + "/after/" + std::to_string(k),
               "'" + tasks[i].after[k] + "' is not an earlier task of the plan");
      }
    }
    if (!seen.insert(tasks[i].id).second) r.fail(ptr + "/id", "duplicate '" + tasks[i].id + "'");
  }
}

// A plan is what `cloudbake plan` makes of its shot: the graph is made again from the shot, at
// the width its stages show, and compared task by task. A plan whose id was computed again
// after an edit could otherwise drop gather's dependencies (gather then ran, and marked itself
// done, before anything it gathers) or misname a task's files (found only after it ran).
void checkAgainstReplanned(const shotjson::Reader& r, const TaskPlan& plan) {
  std::map<Part, int> per_part;
  for (const FarmTask& t : plan.tasks) ++per_part[t.scope.part];
  int width = 1;
  for (const auto& [part, n] : per_part) width = std::max(width, n);
  const TaskPlan again = planTasks(plan.shot, std::min(width, 10000), plan.auto_preset);
  const std::string redo = ": plan again (`cloudbake plan` makes another graph of this shot)";
  if (again.tasks.size() != plan.tasks.size()) {
    r.fail("/tasks", "has " + std::to_string(plan.tasks.size()) +
                         " tasks where the shot's plan has " + std::to_string(again.tasks.size()) +
                         redo);
  }
  for (size_t i = 0; i < plan.tasks.size(); ++i) {
    const FarmTask &a = plan.tasks[i], &b = again.tasks[i];
    const std::string ptr = "/tasks/" + std::to_string(i);
    if (a.id != b.id || a.scope.part != b.scope.part || a.scope.begin != b.scope.begin ||
        a.scope.end != b.scope.end) {
      r.fail(ptr, "task '" + a.id + "' is not the shot's task '" + b.id + "' there" + redo);
    }
    if (a.after != b.after) r.fail(ptr + "/after", "differs from the shot's plan" + redo);
    if (a.writes != b.writes) r.fail(ptr + "/writes", "differs from the shot's plan" + redo);
  }
}

ShotSpec readShot(const Json& v, const std::string& source, const std::string& ptr) {
  ParseOptions po;
  po.source_name = source + " " + ptr;
  return parseShot(v.dump(), "", po);
}

}  // namespace

TaskPlan planFromJson(const std::string& text, const std::string& source) {
  const Json j = shotjson::parseStrict(text, source);
  const shotjson::Reader r(source, shotjson::PathPolicy{fs::current_path(), {}, false});
  const shotjson::Object o(r, j, "", {"format", "id", "shot", "auto", "tasks"});
  if (r.string(o.required("format"), "/format") != kFormat) {
    r.fail("/format",
           std::string("must be '") + kFormat + "' (a plan of another version: plan again)");
  }
  TaskPlan plan;
  plan.id = r.string(o.required("id"), "/id");
  plan.shot = readShot(o.required("shot"), source, "/shot");
  const Json& a = o.required("auto");
  if (!a.is_null()) {
    const shotjson::Object ao(r, a, "/auto", {"shot", "summary", "record"});
    plan.auto_preset = RunOptions::AutoPreset{readShot(ao.required("shot"), source, "/auto/shot"),
                                              r.string(ao.required("summary"), "/auto/summary"),
                                              ao.required("record")};
  }
  const Json& tasks = o.required("tasks");
  if (!tasks.is_array() || tasks.empty()) r.fail("/tasks", "must be a non-empty array");
  for (size_t i = 0; i < tasks.size(); ++i) {
    plan.tasks.push_back(readTask(r, tasks[i], "/tasks/" + std::to_string(i),
                                  plan.auto_preset ? plan.auto_preset->shot : plan.shot));
  }
  checkGraph(r, plan.tasks);
  if (contentId(plan) != plan.id) {
    r.fail("/id", "does not match the plan's content (edited, or its files changed): plan again");
  }
  checkAgainstReplanned(r, plan);
  return plan;
}

namespace {

Json fileList(const std::vector<OutputFile>& files) {
  Json out = Json::array();
  for (const OutputFile& f : files) {
    out.push_back({{"name", f.name}, {"size", f.size}, {"sha256", f.sha256}});
  }
  return out;
}

// True when the task's marker exists and every file it lists is in out_dir, intact.
bool markerIntact(const std::string& marker, const std::string& out_dir) {
  std::error_code ec;
  if (!fs::exists(marker, ec)) return false;
  try {
    const Json j = Json::parse(readWholeFile(marker));
    for (const Json& f : j.at("files")) {
      const fs::path p = fs::path(out_dir) / f.at("name").get<std::string>();
      if (!fs::is_regular_file(p) || fs::file_size(p) != f.at("size").get<uint64_t>() ||
          sha256File(p.string()) != f.at("sha256").get<std::string>()) {
        return false;
      }
    }
    return true;
  } catch (const std::exception&) {
    return false;  // unreadable: run the task again
  }
}

std::string markerPath(const std::string& markers_dir, const std::string& task_id) {
  return (fs::path(markers_dir) / (task_id + ".json")).string();
}

std::string taskIds(const TaskPlan& plan) {
  std::string ids;
  for (const FarmTask& t : plan.tasks) ids += (ids.empty() ? "" : ", ") + t.id;
  return ids;
}

}  // namespace

TaskRunResult runTask(const TaskPlan& plan, const std::string& task_id, RunOptions options,
                      const std::string& markers_dir) {
  const FarmTask* task = plan.find(task_id);
  if (!task) {
    throw InputError("task: no task '" + task_id + "' in the plan (" + taskIds(plan) + ")");
  }
  if (!options.cache) throw InputError("--cache-dir: a task needs the plan's shared cache");
  // Its marker goes here after the run: a folder it cannot write in is refused before the work
  // (an unwritable one failed as an internal error after the task had written its files).
  makeWritableFolder(markers_dir, "--cache-dir");
  // Gather answers for the whole shot: its dependencies are checked even when its own marker
  // holds (an output of another task deleted since had still read as "already done").
  if (task->scope.part == Part::kGather) {
    for (const std::string& dep : task->after) {
      if (!markerIntact(markerPath(markers_dir, dep), options.out_dir)) {
        throw InputError("task gather: task '" + dep +
                         "' has not finished into this output folder (run it first)");
      }
    }
  }
  TaskRunResult result;
  if (markerIntact(markerPath(markers_dir, task_id), options.out_dir)) {
    result.already_done = true;
    return result;
  }
  options.scope = task->scope;
  options.auto_preset = plan.auto_preset;
  result.run = runShot(plan.shot, options);
  const std::set<std::string> planned(task->writes.begin(), task->writes.end());
  for (const OutputFile& f : result.run.files) {
    if (!planned.count(f.name) && f.name.size() > 4 &&
        f.name.compare(f.name.size() - 4, 4, ".png") != 0) {
      throw InternalError("task " + task_id + " wrote '" + f.name + "', which its plan omits");
    }
  }
  try {
    writeFileAtomic(
        markerPath(markers_dir, task_id),
        Json{{"task", task_id}, {"plan", plan.id}, {"files", fileList(result.run.files)}}.dump(1));
  } catch (...) {
    // Files without their marker would be written again by the next run: a failed task leaves
    // none of its own behind, as a failed render does.
    std::error_code ec;
    for (const OutputFile& f : result.run.files) fs::remove(f.path, ec);
    throw;
  }
  return result;
}

}  // namespace cloudbake
