#include "core/job/run_outputs.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include "core/io/png_writer.h"
#include "core/job/sha256.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
}  // namespace

OutputFile describeOutput(const std::string& out_dir, const std::string& name) {
  OutputFile f;
  f.name = name;
  f.path = (fs::path(out_dir) / name).string();
  f.size = fs::file_size(f.path);
  f.sha256 = sha256File(f.path);
  return f;
}

void addPreview(const RunOptions& opt, const std::string& stem, const Image& beauty,
                RunResult& result) {
  const std::string png_name = stem + ".png";
  writePreviewPng((fs::path(opt.out_dir) / png_name).string(), beauty, opt.png_exposure);
  result.files.push_back(describeOutput(opt.out_dir, png_name));
}

}  // namespace cloudbake
