// Helpers shared by the volume tests.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/math/rng.h"
#include "core/volume/density_field.h"

namespace cloudbake::testing {

/// Checks that density(p) <= the majorant of the cell containing p at `samples` random points
/// (half of them within 1% of a cell face, where trilinear footprints straddle cells), and that
/// density is 0 outside bounds(). Returns the number of points with non-zero density.
inline int checkMajorants(const DensityField& field, int samples, uint64_t seed = 7) {
  const MajorantGrid& mg = field.majorants();
  const Bounds3 mb = mg.bounds();
  const Bounds3 fb = field.bounds();
  for (int a = 0; a < 3; ++a) {
    EXPECT_LE(mb.min[a], fb.min[a] + 1e-9) << "majorant grid must cover the field bounds";
    EXPECT_GE(mb.max[a], fb.max[a] - 1e-9) << "majorant grid must cover the field bounds";
  }
  auto lookup = field.lookup();
  Rng rng(seed);
  const int n[3] = {mg.nx(), mg.ny(), mg.nz()};
  const Vec3 ext = mb.extent();
  int nonzero = 0, failures = 0;
  for (int s = 0; s < samples; ++s) {
    int c[3];
    Vec3 p;
    for (int a = 0; a < 3; ++a) {
      c[a] = std::min(n[a] - 1, static_cast<int>(rng.uniform() * n[a]));
      double u = rng.uniform();
      if (s % 2 == 0) u = rng.uniform() < 0.5 ? u * 0.01 : 1.0 - u * 0.01;
      p[a] = mb.min[a] + (c[a] + u) * ext[a] / n[a];
    }
    const double d = lookup->density(p);
    if (d > 0) ++nonzero;
    const double bound = mg.cell(c[0], c[1], c[2]);
    if (d > bound * (1 + 1e-6) + 1e-7 && failures++ < 5) {
      ADD_FAILURE() << "density " << d << " > majorant " << bound << " at (" << p.x << ", " << p.y
                    << ", " << p.z << ") cell " << c[0] << "," << c[1] << "," << c[2];
    }
    if (!fb.contains(p) && d != 0 && failures++ < 5) {
      ADD_FAILURE() << "non-zero density " << d << " outside bounds()";
    }
    EXPECT_LE(d, field.maxDensity() * (1 + 1e-6) + 1e-7);
  }
  EXPECT_EQ(failures, 0);
  return nonzero;
}

/// A fresh empty folder under the build tree's temp area for files a test writes.
inline std::string scratchDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("cloudbake_volume_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

inline void writeText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

inline std::string sharedData(const std::string& name) {
  return std::string(CLOUDBAKE_SHARED_DIR) + "/data/" + name;
}

}  // namespace cloudbake::testing
