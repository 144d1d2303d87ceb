// Helpers shared by the tests of core/bake.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <string>

#include "core/bake/baked_light.h"
#include "core/error.h"

namespace cloudbake {

/// A bake lattice of nx x ny x nz voxels of edge `voxel` whose voxel (0, 0, 0) is centred at
/// `origin`, with zero density and no channels.
inline BakedLight emptyBake(const Vec3& origin, double voxel, int nx, int ny, int nz) {
  BakedLight b;
  b.grid.origin = origin;
  b.grid.voxel_size = voxel;
  b.grid.nx = nx;
  b.grid.ny = ny;
  b.grid.nz = nz;
  b.density.assign(b.grid.voxelCount(), 0.f);
  return b;
}

/// Expects `fn` to throw InputError whose message contains `what` (a field, grid or knob name).
inline void expectErrorNaming(const std::function<void()>& fn, const std::string& what) {
  try {
    fn();
    ADD_FAILURE() << "no error; expected one naming " << what;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

}  // namespace cloudbake
