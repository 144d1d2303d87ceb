#include "core/job/job_record.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "common/json_limits.h"
#include "common/printable.h"
#include "core/error.h"
#include "core/job/file_util.h"

namespace cloudbake {
namespace fs = std::filesystem;
using Json = nlohmann::json;

const char* jobStateName(JobState state) {
  switch (state) {
    case JobState::kQueued:
      return "QUEUED";
    case JobState::kRunning:
      return "RUNNING";
    case JobState::kSucceeded:
      return "SUCCEEDED";
    case JobState::kFailed:
      return "FAILED";
    case JobState::kCancelled:
      return "CANCELLED";
  }
  return "UNKNOWN";
}

namespace {

JobState stateFromName(const std::string& name) {
  for (JobState s : {JobState::kQueued, JobState::kRunning, JobState::kSucceeded, JobState::kFailed,
                     JobState::kCancelled}) {
    if (name == jobStateName(s)) return s;
  }
  throw std::runtime_error("unknown job state '" + name + "'");
}

Json toJson(const JobRecord& r) {
  Json outputs = Json::array();
  for (const OutputFile& f : r.outputs) {
    outputs.push_back({{"name", f.name}, {"size", f.size}, {"sha256", f.sha256}});
  }
  return {{"id", r.id},
          {"state", jobStateName(r.state)},
          {"shot_name", r.shot_name},
          {"method", r.method},
          {"owner", r.owner},
          {"views", r.views},
          {"created", r.created},
          {"started", r.started},
          {"finished", r.finished},
          {"stage", r.stage},
          {"fraction", r.fraction},
          {"error", r.error},
          {"error_is_input", r.error_is_input},
          {"error_no_space", r.error_no_space},
          {"outputs", outputs},
          {"views_rendered", r.views_rendered},
          {"views_cached", r.views_cached},
          {"bakes_computed", r.bakes_computed},
          {"bakes_cached", r.bakes_cached},
          {"views_from_bake", r.views_from_bake}};
}

JobRecord fromJson(const Json& j) {
  JobRecord r;
  r.id = j.at("id").get<std::string>();
  r.state = stateFromName(j.at("state").get<std::string>());
  r.shot_name = j.at("shot_name").get<std::string>();
  r.method = j.at("method").get<std::string>();
  r.owner = j.value("owner", "");  // absent from records written before tokens
  r.views = j.at("views").get<std::vector<std::string>>();
  r.created = j.at("created").get<double>();
  r.started = j.at("started").get<double>();
  r.finished = j.at("finished").get<double>();
  r.stage = j.at("stage").get<std::string>();
  r.fraction = j.at("fraction").get<double>();
  r.error = j.at("error").get<std::string>();
  r.error_is_input = j.at("error_is_input").get<bool>();
  r.error_no_space = j.value("error_no_space", false);  // absent from older records
  for (const Json& f : j.at("outputs")) {
    OutputFile o;
    o.name = f.at("name").get<std::string>();
    o.size = f.at("size").get<uint64_t>();
    o.sha256 = f.at("sha256").get<std::string>();
    r.outputs.push_back(o);
  }
  r.views_rendered = j.at("views_rendered").get<int>();
  r.views_cached = j.at("views_cached").get<int>();
  // Records written before bake methods existed lack these.
  r.bakes_computed = j.value("bakes_computed", 0);
  r.bakes_cached = j.value("bakes_cached", 0);
  r.views_from_bake = j.value("views_from_bake", 0);
  return r;
}

}  // namespace

JobStore::JobStore(std::string root) : root_(std::move(root)) { fs::create_directories(root_); }

std::string JobStore::jobDir(const std::string& id) const {
  return (fs::path(root_) / id).string();
}
std::string JobStore::inputDir(const std::string& id) const {
  return (fs::path(root_) / id / "input").string();
}
std::string JobStore::outputDir(const std::string& id) const {
  return (fs::path(root_) / id / "out").string();
}

void JobStore::save(const JobRecord& record) const {
  if (!isJobId(record.id)) throw InternalError("job store: '" + record.id + "' is not a job id");
  fs::create_directories(jobDir(record.id));
  writeFileAtomic((fs::path(jobDir(record.id)) / "job.json").string(), toJson(record).dump(1));
}

namespace {

// The reason (which names server paths) goes to the log; the client learns what happened.
JobRecord unreadableRecord(const std::string& id) {
  JobRecord r;
  r.id = id;
  r.state = JobState::kFailed;
  r.stage = jobStateName(JobState::kFailed);
  r.created = r.finished =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  r.error =
      "the server could not read this job's record (it is corrupt; details in the server log): "
      "its state and outputs are lost, resubmit the shot";
  return r;
}

// The record in `file`, the job.json of the folder named `id`. Its own id must be that name: the
// server builds every path of the job from it, and an edited record's "../../x" had it write
// outside its state folder.
JobRecord readRecord(const fs::path& file, const std::string& id) {
  JobRecord r = fromJson(parseJsonLimited(readWholeFile(file.string()), file.string()));
  if (r.id != id) {
    throw std::runtime_error("its id '" + r.id + "' is not its folder's name '" + id + "'");
  }
  return r;
}

}  // namespace

std::vector<JobRecord> JobStore::loadAll() const {
  std::vector<JobRecord> records;
  for (const auto& dir : fs::directory_iterator(root_)) {
    if (!dir.is_directory() || !isJobId(dir.path().filename().string())) continue;
    const fs::path file = dir.path() / "job.json";
    std::error_code ec;
    if (!fs::exists(file, ec)) {
      // A job folder without a record was never acknowledged to a client (the record is
      // durable before the client hears of the job).
      spdlog::warn("job store: skipping {}: no job.json", dir.path().string());
      continue;
    }
    try {
      records.push_back(readRecord(file, dir.path().filename().string()));
    } catch (const std::exception& e) {
      // A record that exists but cannot be read belonged to a job a client may know of: it is
      // reported FAILED with the reason rather than vanishing.
      spdlog::error("job store: {}: unreadable record: {}", dir.path().string(),
                    printable(e.what()));
      records.push_back(unreadableRecord(dir.path().filename().string()));
    }
  }
  std::sort(records.begin(), records.end(), [](const JobRecord& a, const JobRecord& b) {
    return a.created != b.created ? a.created < b.created : a.id < b.id;
  });
  return records;
}

std::optional<JobRecord> JobStore::load(const std::string& id) const {
  if (!isJobId(id)) return std::nullopt;
  const fs::path file = fs::path(jobDir(id)) / "job.json";
  std::error_code ec;
  if (!fs::exists(file, ec)) return std::nullopt;
  try {
    return readRecord(file, id);
  } catch (const std::exception& e) {
    spdlog::warn("job store: {}: unreadable record: {}", file.string(), printable(e.what()));
    return std::nullopt;
  }
}

void JobStore::remove(const std::string& id) const {
  std::error_code ec;
  fs::remove_all(jobDir(id), ec);
}

std::string newJobId() {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  static const char* kHex = "0123456789abcdef";
  std::string id = "j";
  uint64_t v = rng();
  for (int i = 0; i < 16; ++i) id.push_back(kHex[(v >> (4 * i)) & 15]);
  return id;
}

bool isJobId(const std::string& id) {
  if (id.size() != 17 || id[0] != 'j') return false;
  return std::all_of(id.begin() + 1, id.end(),
                     [](char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); });
}

}  // namespace cloudbake
