// Helpers shared by the unit tests of core/job (job_test.cpp, run_shot_bake_test.cpp).
#pragma once

#include <filesystem>
#include <string>

#include "core/job/file_util.h"

namespace cloudbake {

/// A new empty folder under the system's temporary folder, unique to this call.
inline std::filesystem::path freshDir(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("cloudbake_job_test_" + name + "_" + uniqueSuffix());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace cloudbake
