#include "core/job/shared_jobs.h"

#include <filesystem>
#include <nlohmann/json.hpp>

#include "common/json_limits.h"
#include "core/job/file_util.h"

namespace cloudbake {
namespace fs = std::filesystem;
using Json = nlohmann::json;

SharedJobs::SharedJobs(std::string root) : store_(std::move(root)) {}

std::string SharedJobs::outputDir(const std::string& id) const { return store_.outputDir(id); }

void SharedJobs::publish(const JobRecord& record, const std::string& out_dir,
                         const std::string& message) {
  fs::create_directories(store_.jobDir(record.id));
  if (record.state == JobState::kSucceeded) {
    for (const OutputFile& f : record.outputs) {
      const fs::path to = fs::path(outputDir(record.id)) / f.name;
      std::error_code ec;
      if (fs::exists(to, ec) && fs::file_size(to, ec) == f.size) continue;
      // Linked (one file, no copy) when the folders share a file system; a copy lands under a
      // temporary name and is renamed, so a reader never sees half a file.
      const std::string tmp = to.string() + ".tmp." + uniqueSuffix();
      linkOrCopy((fs::path(out_dir) / f.name).string(), tmp);
      fs::rename(tmp, to);
    }
  }
  const PublishedProgress before = progress(record.id);
  const Json p = {{"revision", before.revision + 1},
                  {"stage", record.stage},
                  {"fraction", record.fraction},
                  {"message", message}};
  store_.save(record);
  writeFileAtomic((fs::path(store_.jobDir(record.id)) / "progress.json").string(), p.dump());
}

std::optional<JobRecord> SharedJobs::record(const std::string& id) const { return store_.load(id); }

PublishedProgress SharedJobs::progress(const std::string& id) const {
  PublishedProgress p;
  if (!isJobId(id)) return p;
  const std::string path = (fs::path(store_.jobDir(id)) / "progress.json").string();
  std::error_code ec;
  if (!fs::exists(path, ec)) return p;
  try {
    const Json j = parseJsonLimited(readWholeFile(path), path);
    p.revision = j.at("revision").get<uint64_t>();
    p.stage = j.at("stage").get<std::string>();
    p.fraction = j.at("fraction").get<double>();
    p.message = j.at("message").get<std::string>();
  } catch (const std::exception&) {
    // Unreadable: as if nothing was published yet; the next publication replaces it.
  }
  return p;
}

void SharedJobs::requestCancel(const std::string& id) const {
  if (!isJobId(id)) return;
  writeFileAtomic((fs::path(store_.jobDir(id)) / "CANCEL").string(), "cancel\n");
}

bool SharedJobs::cancelRequested(const std::string& id) const {
  std::error_code ec;
  return isJobId(id) && fs::exists(fs::path(store_.jobDir(id)) / "CANCEL", ec);
}

void SharedJobs::remove(const std::string& id) const { store_.remove(id); }

}  // namespace cloudbake
