// Helpers shared by the core/shot tests.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>

namespace cloudbake::testing {

/// The example of DESIGN.md's "Shot format v1 (contract)", verbatim.
inline const char* kDesignSlab = R"({
  "version": 1,
  "name": "slab",
  "volume":  { "box": { "min": [-50, -50, 0], "max": [50, 50, 1], "density": 1.0 } },
  "medium":  { "extinction": 2.0, "albedo": 0.9, "phase": { "type": "hg", "g": 0.75 } },
  "lighting": { "sun": { "direction": [0, 0, 1], "irradiance": [3.14159, 3.14159, 3.14159] },
                "sky": { "radiance": [0, 0, 0] } },
  "bake":    { "method": "pathtrace", "samples": 256, "seed": 1 },
  "views":   [ { "name": "nadir",
                 "camera": { "type": "orthographic", "position": [0, 0, 10], "look_at": [0, 0, 0],
                             "up": [0, 1, 0], "width": 2.0 },
                 "resolution": [32, 32] } ],
  "outputs": { "exr": true, "vdb": false }
})";

/// A fresh, empty temporary folder removed on destruction.
class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() /
            ("cloudbake_shot_test_" + std::to_string(rd()) + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path write(const std::string& name, const std::string& text) const {
    const auto p = path_ / name;
    std::filesystem::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
    return p;
  }

 private:
  std::filesystem::path path_;
};

inline std::string readText(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

}  // namespace cloudbake::testing
