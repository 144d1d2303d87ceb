#include "core/bake/baked_light.h"

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/math/parallel.h"

namespace cloudbake {

std::vector<uint8_t> densitySupport(const BakeGrid& g, const std::vector<float>& density) {
  std::vector<uint8_t> support(g.voxelCount(), 0);
  // A gather (each voxel looks at its neighbours), so threads never write the same byte.
  parallelFor(0, g.nz, [&](int k) {
    for (int j = 0; j < g.ny; ++j) {
      for (int i = 0; i < g.nx; ++i) {
        bool any = false;
        for (int dk = -1; dk <= 1 && !any; ++dk)
          for (int dj = -1; dj <= 1 && !any; ++dj)
            for (int di = -1; di <= 1 && !any; ++di) {
              const int a = i + di, b = j + dj, c = k + dk;
              if (a < 0 || b < 0 || c < 0 || a >= g.nx || b >= g.ny || c >= g.nz) continue;
              any = density[g.index(a, b, c)] > 0;
            }
        support[g.index(i, j, k)] = any ? 1 : 0;
      }
    }
  });
  return support;
}

const BakeChannel* BakedLight::find(const std::string& name) const {
  auto it = channels.find(name);
  return it == channels.end() ? nullptr : &it->second;
}

BakeChannel& BakedLight::add(const std::string& name, int components) {
  BakeChannel& c = channels[name];
  c.components = components;
  c.data.assign(grid.voxelCount() * size_t(components), 0.f);
  return c;
}

BakeChannel& BakedLight::addOnTallyGrid(const std::string& name, int components) {
  BakeChannel& c = channels[name];
  c.components = components;
  c.on_tally_grid = true;
  c.data.assign(tally_grid.voxelCount() * size_t(components), 0.f);
  return c;
}

void BakedLight::addMeanRadiance() {
  const BakeChannel* sun = find(bake_grids::kSunTransmittance);
  const BakeChannel* co = find(bake_grids::kMultipleFluence);
  std::vector<float>& cd = add(bake_grids::kCd, 3).data;
  const size_t voxels = grid.voxelCount();
  for (size_t v = 0; v < voxels; ++v) {
    const double s = sun ? double(sun->data[v]) : 0.0;
    for (size_t c = 0; c < 3; ++c) {
      const double m = co ? double(co->data[3 * v + c]) : 0.0;
      cd[3 * v + c] = float((s + m) / (4 * kPi));
    }
  }
}

void BakedLight::trimToSupport() {
  if (density.size() != grid.voxelCount()) return;  // validate() reports it
  const std::vector<uint8_t> support = densitySupport(grid, density);
  for (size_t v = 0; v < support.size(); ++v) {
    if (support[v]) continue;
    for (auto& [name, c] : channels) {
      if (c.on_tally_grid || c.data.size() != grid.voxelCount() * size_t(c.components)) continue;
      for (int e = 0; e < c.components; ++e) c.data[v * size_t(c.components) + size_t(e)] = 0;
    }
  }
}

namespace {

void validateLattice(const std::string& what, const char* which, const BakeGrid& g) {
  if (g.nx < 1 || g.ny < 1 || g.nz < 1 || !(g.voxel_size > 0) || !std::isfinite(g.voxel_size) ||
      !isFinite(g.origin)) {
    std::ostringstream os;
    os << what << ": " << which << " " << g.nx << "x" << g.ny << "x" << g.nz << " of voxel size "
       << g.voxel_size << " is not usable (needs >= 1 voxel per axis, a finite size > 0)";
    throw InputError(os.str());
  }
}

}  // namespace

void BakedLight::validate(const std::string& what) const {
  validateLattice(what, "lattice", grid);
  for (const auto& [name, c] : channels) {
    if (c.on_tally_grid) {
      validateLattice(what, "tally lattice", tally_grid);
      break;
    }
  }
  if (!isFinite(sun_direction) || std::abs(length(sun_direction) - 1) > 1e-6) {
    throw InputError(what + ": sun direction is not a unit vector");
  }
  auto fail = [&](const std::string& name, size_t v, const std::string& problem) {
    const BakeGrid& g = name == bake_grids::kDensity ? grid : gridOf(channels.at(name));
    const int i = int(v % size_t(g.nx)), j = int((v / size_t(g.nx)) % size_t(g.ny)),
              k = int(v / (size_t(g.nx) * size_t(g.ny)));
    const Vec3 p = g.center(i, j, k);
    std::ostringstream os;
    os << what << ": grid '" << name << "': voxel (" << i << ", " << j << ", " << k << ") at ("
       << p.x << ", " << p.y << ", " << p.z << "): " << problem;
    throw InputError(os.str());
  };
  auto checkSize = [&](const std::string& name, size_t size, int components, const BakeGrid& g) {
    if (size != g.voxelCount() * size_t(components)) {
      throw InputError(what + ": grid '" + name + "' has " + std::to_string(size) +
                       " values, the lattice needs " +
                       std::to_string(g.voxelCount() * size_t(components)));
    }
  };
  checkSize(bake_grids::kDensity, density.size(), 1, grid);
  for (size_t v = 0; v < density.size(); ++v) {
    const float d = density[v];
    if (!std::isfinite(d)) fail(bake_grids::kDensity, v, "value is not finite");
    if (d < 0) fail(bake_grids::kDensity, v, "negative density " + std::to_string(d));
  }
  for (const auto& [name, c] : channels) {
    if (c.components != 1 && c.components != 3) {
      throw InputError(what + ": grid '" + name + "' has " + std::to_string(c.components) +
                       " components per voxel (1 or 3 expected)");
    }
    checkSize(name, c.data.size(), c.components, gridOf(c));
    const bool unit_range = name == bake_grids::kSunTransmittance ||
                            name == bake_grids::kSkyVisibility || name == bake_grids::kMieRatio;
    const bool non_negative = name == bake_grids::kMultipleFluence ||
                              name == bake_grids::kSkyMultipleFluence || name == bake_grids::kCd;
    const bool direction = name == bake_grids::kLightDir;
    const size_t n = gridOf(c).voxelCount();
    for (size_t v = 0; v < n; ++v) {
      const float* x = &c.data[v * size_t(c.components)];
      for (int e = 0; e < c.components; ++e) {
        if (!std::isfinite(x[e])) fail(name, v, "value is not finite");
        if (unit_range && (x[e] < 0 || x[e] > 1)) {
          fail(name, v, "value " + std::to_string(x[e]) + " outside [0, 1]");
        }
        if (non_negative && x[e] < 0) fail(name, v, "negative value " + std::to_string(x[e]));
      }
      if (direction && c.components == 3) {
        const double len =
            std::sqrt(double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
        if (len != 0 && std::abs(len - 1) > 1e-3) {
          fail(name, v, "direction of length " + std::to_string(len) + " (unit or zero expected)");
        }
      }
    }
  }
}

}  // namespace cloudbake
