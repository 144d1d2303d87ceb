// Farm tasks (core/job/task_plan.h): a shot split into tasks that, run in order over one bake
// cache (each task with its own cache instance, as separate processes would), leave exactly
// the files of one whole run; done tasks are not run again, a cancelled task runs again, and
// plan files are checked.
#include "core/job/task_plan.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>

#include "core/bake/baked_light_vdb.h"
#include "core/error.h"
#include "core/job/bake_cache.h"
#include "core/job/sha256.h"
#include "core/shot/shot_parser.h"
#include "tests/core/job/job_test_util.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using Part = RunScope::Part;

const char* kViews = R"(
    "views": [{"name": "a", "camera": {"type": "orthographic", "position": [0, -5, 2],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 3}, "resolution": [16, 12]},
              {"name": "b", "camera": {"type": "orthographic", "position": [5, 0, 1],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 3}, "resolution": [12, 12]},
              {"name": "c", "camera": {"type": "orthographic", "position": [0, 0, 6],
               "look_at": [0, 0, 0], "up": [0, 1, 0], "width": 3}, "resolution": [8, 8]}],
    "outputs": {"exr": true, "vdb": true}})";

std::string sequenceShot() {
  return std::string(R"({"version": 1, "name": "anim",
    "volume": {"sequence": {"procedural": {"type": "perlin_cloud", "size": [2, 2, 1],
               "resolution": 16, "seed": 3}, "frames": 5, "time_step": 0.05}},
    "medium": {"extinction": 6, "albedo": 0.95, "phase": {"type": "hg", "g": 0.5}},
    "lighting": {"sun": {"direction": [0.3, 0.2, 1], "irradiance": [1, 1, 1]},
                 "sky": {"radiance": [0.1, 0.15, 0.3]}},
    "bake": {"method": "precomputed", "light_resolution": 14, "sample_points": 256,
             "transfer_resolution": 8, "frames": 7, "dissolve": 2},)") +
         kViews;
}

std::string sphereShot(const std::string& method, int samples) {
  return R"({"version": 1, "name": "ball",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 3, "albedo": 0.9, "phase": {"type": "hg", "g": 0.6}},
    "lighting": {"sun": {"direction": [0.3, 0.2, 1], "irradiance": [1, 1, 1]}},
    "bake": {"method": ")" +
         method + R"(", "samples": )" + std::to_string(samples) + R"(, "seed": 5)" +
         (method == "pathtrace" ? "" : R"(, "light_resolution": 24)") + "}," + kViews;
}

// A file's content as far as two runs of the same shot must agree: every byte, except that
// OpenVDB names each file with a fresh UUID (bytes 21-56 of its header) and a bake's metadata
// records the seconds its steps took.
std::string contentOf(const fs::path& path) {
  if (path.extension() != ".vdb") return sha256File(path.string());
  try {
    BakedLight b = readBakedLight(path.string());
    std::string content(reinterpret_cast<const char*>(b.density.data()), b.density.size() * 4);
    for (const auto& [name, c] : b.channels) {
      content +=
          name + std::string(reinterpret_cast<const char*>(c.data.data()), c.data.size() * 4);
    }
    for (const auto& [k, v] : b.metadata) {
      if (k.rfind("cloudbake:seconds", 0) != 0) content += k + "=" + v + ";";
    }
    return sha256Hex(content);
  } catch (const std::exception&) {  // not a bake: the density grid of pathtrace
    std::string bytes = readWholeFile(path.string());
    if (bytes.size() > 58) bytes.replace(21, 36, 36, '-');
    return sha256Hex(bytes);
  }
}

std::map<std::string, std::string> filesOf(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& f : fs::directory_iterator(dir)) {
    out[f.path().filename().string()] = contentOf(f.path());
  }
  return out;
}

// Every task in plan order, each with a cache instance of its own on one folder.
void runAll(const TaskPlan& plan, const fs::path& dir, const fs::path& out) {
  for (const FarmTask& t : plan.tasks) {
    BakeCache cache((dir / "shared" / "cache").string(), BakeCacheOptions{});
    RunOptions ro;
    ro.out_dir = out.string();
    ro.cache = &cache;
    const TaskRunResult r = runTask(plan, t.id, ro, (dir / "shared" / "tasks").string());
    EXPECT_FALSE(r.already_done) << t.id;
    std::set<std::string> wrote;
    for (const OutputFile& f : r.run.files) wrote.insert(f.name);
    EXPECT_EQ(wrote, std::set<std::string>(t.writes.begin(), t.writes.end())) << t.id;
  }
}

void expectSplitEqualsWhole(const std::string& text, int width, size_t tasks) {
  const fs::path dir = freshDir("farm");
  const ShotSpec shot = parseShot(text, "");
  RunOptions whole;
  whole.out_dir = (dir / "whole").string();
  runShot(shot, whole);
  const TaskPlan plan = planTasks(shot, width);
  EXPECT_EQ(plan.tasks.size(), tasks);
  runAll(plan, dir, dir / "split");
  const auto a = filesOf(dir / "whole"), b = filesOf(dir / "split");
  EXPECT_EQ(a.size(), b.size());
  for (const auto& [name, hash] : a) EXPECT_EQ(b.count(name) ? b.at(name) : "", hash) << name;
  fs::remove_all(dir);
}

TEST(TaskPlan, ASequenceSplitIntoTasksEqualsTheWholeRunBitForBit) {
  // layout, 3 precompute, bake, 3 render, gather
  expectSplitEqualsWhole(sequenceShot(), 3, 9);
}

TEST(TaskPlan, ABakeMethodSplitByViewsEqualsTheWholeRun) {
  expectSplitEqualsWhole(sphereShot("single", 2), 2, 4);  // bake, 2 render, gather
}

TEST(TaskPlan, PhotonAndPointcloudSplitByViewsEqualTheWholeRun) {
  std::string photon = sphereShot("photon", 2);
  photon.replace(photon.find("\"light_resolution\": 24"), 22,
                 "\"light_resolution\": 24, \"photons\": 20000");
  expectSplitEqualsWhole(photon, 3, 5);  // bake, 3 render, gather
  std::string points = sphereShot("pointcloud", 2);
  points.replace(points.find("\"light_resolution\": 24"), 22,
                 "\"light_resolution\": 24, \"points\": 2048, \"passes\": 2");
  expectSplitEqualsWhole(points, 2, 4);
}

TEST(TaskPlan, ThePathTracerSplitByViewsEqualsTheWholeRun) {
  std::string shot = sphereShot("pathtrace", 4);
  shot.replace(shot.find("\"vdb\": true"), 11, "\"vdb\": true, \"vdb_voxel_size\": 0.1");
  expectSplitEqualsWhole(shot, 8, 4);  // 3 render, gather
}

TEST(TaskPlan, StagesAreAsWideAsAskedAndGatherComesLast) {
  const TaskPlan p = planTasks(parseShot(sequenceShot(), ""), 2);
  std::vector<std::string> ids;
  for (const FarmTask& t : p.tasks) ids.push_back(t.id);
  EXPECT_EQ(ids, (std::vector<std::string>{"layout", "precompute.000", "precompute.001", "bake",
                                           "render.000", "render.001", "gather"}));
  EXPECT_EQ(p.tasks[1].scope.begin, 0);
  EXPECT_EQ(p.tasks[1].scope.end, 2);
  EXPECT_EQ(p.tasks[2].scope.end, 5);
  EXPECT_EQ(p.tasks.back().after.size(), p.tasks.size() - 1);
  for (const FarmTask& t : p.tasks) EXPECT_GT(t.cost_seconds, 0) << t.id;
  EXPECT_THROW(planTasks(parseShot(sequenceShot(), ""), 0), InputError);
  EXPECT_THROW(planTasks(parseShot(sequenceShot(), ""), 10001), InputError);
}

TEST(TaskPlan, ADoneTaskIsNotRunAgainUnlessItsFilesChanged) {
  const fs::path dir = freshDir("farm_rerun");
  const TaskPlan plan = planTasks(parseShot(sphereShot("single", 2), ""), 2);
  runAll(plan, dir, dir / "out");
  BakeCache cache((dir / "shared" / "cache").string(), BakeCacheOptions{});
  RunOptions ro;
  ro.out_dir = (dir / "out").string();
  ro.cache = &cache;
  const std::string markers = (dir / "shared" / "tasks").string();
  EXPECT_TRUE(runTask(plan, "render.000", ro, markers).already_done);
  const std::string before = sha256File((dir / "out" / "a.exr").string());
  std::ofstream(dir / "out" / "a.exr", std::ios::app) << "damage";
  const TaskRunResult again = runTask(plan, "render.000", ro, markers);
  EXPECT_FALSE(again.already_done);
  EXPECT_EQ(sha256File((dir / "out" / "a.exr").string()), before);
  EXPECT_THROW(runTask(plan, "render.9", ro, markers), InputError);
  // Gather, done, answers for the whole shot: a render's file gone since is not "already done"
  // (an outside probe's gather said so, exit 0, with a view missing).
  EXPECT_TRUE(runTask(plan, "gather", ro, markers).already_done);
  fs::remove(dir / "out" / "a.exr");
  try {
    runTask(plan, "gather", ro, markers);
    ADD_FAILURE() << "gather passed with a view missing";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("'render.000' has not finished"), std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
}

TEST(TaskPlan, ACancelledTaskLeavesNoMarkerAndRunsAgainToTheSameFiles) {
  const fs::path dir = freshDir("farm_cancel");
  const ShotSpec shot = parseShot(sphereShot("single", 2), "");
  const TaskPlan plan = planTasks(shot, 1);
  RunOptions whole;
  whole.out_dir = (dir / "whole").string();
  runShot(shot, whole);
  BakeCache cache((dir / "shared" / "cache").string(), BakeCacheOptions{});
  RunOptions ro;
  ro.out_dir = (dir / "out").string();
  ro.cache = &cache;
  int calls = 0;
  ro.progress = [&](const RunProgress& p) { return !(p.stage == "render" && ++calls > 3); };
  const std::string markers = (dir / "shared" / "tasks").string();
  EXPECT_FALSE(runTask(plan, "bake", ro, markers).already_done);
  EXPECT_THROW(runTask(plan, "render.000", ro, markers), Cancelled);
  ro.progress = nullptr;
  EXPECT_THROW(runTask(plan, "gather", ro, markers), InputError) << "render.000 is not done";
  EXPECT_FALSE(runTask(plan, "render.000", ro, markers).already_done);
  EXPECT_FALSE(runTask(plan, "gather", ro, markers).already_done);
  EXPECT_EQ(filesOf(dir / "out"), filesOf(dir / "whole"));
  fs::remove_all(dir);
}

TEST(TaskPlan, APlanFileRoundTripsAndAnEditedOrMalformedOneIsRefused) {
  const TaskPlan p = planTasks(parseShot(sequenceShot(), ""), 2);
  const std::string text = planToJson(p).dump(1);
  const TaskPlan back = planFromJson(text, "plan.json");
  EXPECT_EQ(back.id, p.id);
  EXPECT_EQ(back.tasks.size(), p.tasks.size());
  EXPECT_EQ(back.tasks[1].scope.part, Part::kPrecompute);
  EXPECT_EQ(back.tasks[4].scope.end, p.tasks[4].scope.end);
  auto refused = [&](nlohmann::json j, const std::string& pointer) {
    try {
      planFromJson(j.dump(), "plan.json");
      ADD_FAILURE() << "accepted: " << pointer;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(pointer), std::string::npos) << e.what();
    }
  };
  const nlohmann::json j = planToJson(p);
  nlohmann::json edited = j;
  edited["tasks"][1]["basic_volumes"] = {0, 1};
  refused(edited, "/id");
  nlohmann::json unknown = j;
  unknown["tasks"][0]["priority"] = 1;
  refused(unknown, "/tasks/0");
  nlohmann::json cyclic = j;
  cyclic["tasks"][0]["after"] = {"gather"};
  refused(cyclic, "/tasks/0/after/0");
  nlohmann::json kind = j;
  kind["tasks"][0]["kind"] = "bakery";
  refused(kind, "/tasks/0/kind");
  nlohmann::json format = j;
  format["format"] = "cloudbake-plan/0";
  refused(format, "/format");
  // Forged plans (their id computed again is no check): a task id or a written file that
  // leaves its folder, and a range past the shot's frames, are refused before anything runs.
  nlohmann::json escape = j;
  escape["tasks"][2]["id"] = "../../../PWNED";
  refused(escape, "/tasks/2/id");
  nlohmann::json writes = j;
  writes["tasks"][2]["writes"] = {"../../evil.exr"};
  refused(writes, "/tasks/2/writes/0");
  for (size_t i = 0; i < j["tasks"].size(); ++i) {
    for (const char* key : {"views", "frames", "basic_volumes"}) {
      if (!j["tasks"][i].contains(key)) continue;
      nlohmann::json past = j;
      past["tasks"][i][key] = {0, 1000000};
      refused(past, "/tasks/" + std::to_string(i) + "/" + key + "/1");
      // Another kind of range than the task's is refused, not read against no limit (an
      // outside probe: a render task's "frames" in a plan of views ran silently clamped).
      for (const char* other : {"views", "frames", "basic_volumes"}) {
        if (std::string(other) == key) continue;
        nlohmann::json swapped = j;
        swapped["tasks"][i].erase(key);
        swapped["tasks"][i][other] = {0, 1};
        refused(swapped, "/tasks/" + std::to_string(i) + "/" + other);
      }
    }
  }
  EXPECT_THROW(planFromJson("{\"format\": ", "plan.json"), InputError);
}

// An outside probe forged plans whose id it computed again after the edit: gather without its
// dependencies ran before anything it gathers and marked itself done, and a render task with
// another `writes` ran whole before failing as an internal error. A plan must be the graph
// `cloudbake plan` makes of its shot; every such edit is refused as the plan is read.
TEST(TaskPlan, AForgedGraphWithARecomputedIdIsRefused) {
  const TaskPlan p = planTasks(parseShot(sequenceShot(), ""), 2);
  const nlohmann::json j = planToJson(p);
  auto forged = [](nlohmann::json f) {
    f.erase("id");
    f["id"] = sha256Hex(f.dump());
    return f.dump();
  };
  EXPECT_EQ(planFromJson(forged(j), "plan.json").id, p.id);  // the forger's id is the real one
  auto refused = [&](const nlohmann::json& f, const std::string& pointer) {
    try {
      planFromJson(forged(f), "plan.json");
      ADD_FAILURE() << "accepted: " << pointer;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(pointer + ": "), std::string::npos) << e.what();
    }
  };
  const size_t gather = j["tasks"].size() - 1;
  nlohmann::json no_deps = j;
  no_deps["tasks"][gather]["after"] = nlohmann::json::array();
  refused(no_deps, "/tasks/" + std::to_string(gather) + "/after");
  nlohmann::json render_first = j;
  render_first["tasks"][4]["after"] = nlohmann::json::array();  // render.000 before the bake
  refused(render_first, "/tasks/4/after");
  nlohmann::json other_file = j;
  other_file["tasks"][4]["writes"] = {"other.exr"};
  refused(other_file, "/tasks/4/writes");
  nlohmann::json fewer = j;
  fewer["tasks"].erase(size_t(2));  // precompute.001 gone, and the bake's `after` with it
  fewer["tasks"][2]["after"] = {"precompute.000"};
  nlohmann::json& last_after = fewer["tasks"][fewer["tasks"].size() - 1]["after"];
  last_after.erase(std::find(last_after.begin(), last_after.end(), "precompute.001"));
  refused(fewer, "/tasks");
}

}  // namespace
}  // namespace cloudbake
