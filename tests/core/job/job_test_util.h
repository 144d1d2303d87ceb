// Helpers shared by the unit tests of core/job (job_test.cpp, run_shot_bake_test.cpp,
// run_shot_precomputed_test.cpp).
#pragma once

#include <filesystem>
#include <string>

#include "core/job/file_util.h"
#include "core/transport/image.h"

namespace cloudbake {

/// A new empty folder under the system's temporary folder, unique to this call.
inline std::filesystem::path freshDir(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("cloudbake_job_test_" + name + "_" + uniqueSuffix());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

/// Sum of one channel over every pixel.
inline double sumOf(const Image& image, int channel) {
  double s = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) s += image.at(x, y)[channel];
  return s;
}

}  // namespace cloudbake
