#include "core/bake/baked_light.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <sstream>

#include "core/error.h"
#include "core/math/parallel.h"

namespace cloudbake {

std::vector<uint8_t> dilateSupport(const BakeGrid& g, const std::vector<uint8_t>& mask) {
  // The 3^3 neighbourhood is a box, so "any voxel set in it" is three passes of "any of the 3
  // neighbours along one axis": 9 reads a voxel where the 27 of each voxel were 0.1 s of the
  // bunny's bake, which asks for the support three times.
  const int nx = g.nx, ny = g.ny, nz = g.nz;
  std::vector<uint8_t> along_x(g.voxelCount()), along_xy(g.voxelCount()), out(g.voxelCount());
  parallelFor(0, nz, [&](int k) {
    for (int j = 0; j < ny; ++j) {
      const uint8_t* m = mask.data() + g.index(0, j, k);
      uint8_t* o = along_x.data() + g.index(0, j, k);
      for (int i = 0; i < nx; ++i) o[i] = (i > 0 && m[i - 1]) || m[i] || (i + 1 < nx && m[i + 1]);
    }
  });
  parallelFor(0, nz, [&](int k) {
    for (int j = 0; j < ny; ++j) {
      const uint8_t* mid = along_x.data() + g.index(0, j, k);
      const uint8_t* lo = j > 0 ? mid - nx : mid;
      const uint8_t* hi = j + 1 < ny ? mid + nx : mid;
      uint8_t* o = along_xy.data() + g.index(0, j, k);
      for (int i = 0; i < nx; ++i) o[i] = lo[i] | mid[i] | hi[i];
    }
  });
  const size_t slice = size_t(nx) * size_t(ny);
  parallelFor(0, nz, [&](int k) {
    const uint8_t* mid = along_xy.data() + size_t(k) * slice;
    const uint8_t* lo = k > 0 ? mid - slice : mid;
    const uint8_t* hi = k + 1 < nz ? mid + slice : mid;
    uint8_t* o = out.data() + size_t(k) * slice;
    for (size_t v = 0; v < slice; ++v) o[v] = lo[v] | mid[v] | hi[v];
  });
  return out;
}

std::vector<uint8_t> densitySupport(const BakeGrid& g, const std::vector<float>& density) {
  std::vector<uint8_t> positive(g.voxelCount());
  parallelFor(0, int64_t(g.nz), [&](int64_t k) {
    const size_t v0 = size_t(k) * size_t(g.nx) * size_t(g.ny);
    const size_t v1 = v0 + size_t(g.nx) * size_t(g.ny);
    for (size_t v = v0; v < v1; ++v) positive[v] = density[v] > 0;
  });
  return dilateSupport(g, positive);
}

std::vector<uint8_t> sunTransmittanceSupport(const BakeGrid& g,
                                             const std::vector<uint8_t>& support) {
  return dilateSupport(g, dilateSupport(g, support));
}

bool supportSpan(const uint8_t* row, int n, int* first, int* last) {
  int a = 0, b = n - 1;
  while (a <= b && !row[a]) ++a;
  while (b >= a && !row[b]) --b;
  *first = a;
  *last = b;
  return a <= b;
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
  FirstTouchFloats& cd = add(bake_grids::kCd, 3).data;
  parallelFor(0, int64_t(grid.voxelCount()),
              [&](size_t v) {
                const double s = sun ? double(sun->data[v]) : 0.0;
                for (size_t c = 0; c < 3; ++c) {
                  const double m = co ? double(co->data[3 * v + c]) : 0.0;
                  cd[3 * v + c] = float((s + m) / (4 * kPi));
                }
              },
              {kCheapIterationGrain});
}

void BakedLight::trimToSupport() {
  if (density.size() != grid.voxelCount()) return;  // validate() reports it
  trimToSupport(densitySupport(grid, density));
}

void BakedLight::trimToSupport(const std::vector<uint8_t>& support) {
  if (density.size() != grid.voxelCount() || support.size() != grid.voxelCount()) return;
  // Channel by channel, in parallel chunks of voxels: a precomputed frame's 25 grids were
  // trimmed voxel by voxel through the channel map, 0.06 s of its 1.1 s (issue 18).
  constexpr int64_t kChunk = 1 << 14;
  std::vector<uint8_t> sun_support;
  for (auto& [name, c] : channels) {
    if (c.on_tally_grid || c.data.size() != grid.voxelCount() * size_t(c.components)) continue;
    const size_t k = size_t(c.components);
    float* data = c.data.data();
    const bool sun = name == bake_grids::kSunTransmittance;
    if (sun && sun_support.empty()) sun_support = sunTransmittanceSupport(grid, support);
    const std::vector<uint8_t>& keep = sun ? sun_support : support;
    parallelFor(0, int64_t((support.size() + kChunk - 1) / kChunk), [&](int64_t chunk) {
      const size_t v0 = size_t(chunk * kChunk), v1 = std::min(support.size(), v0 + kChunk);
      for (size_t v = v0; v < v1; ++v) {
        if (keep[v]) continue;
        for (size_t e = 0; e < k; ++e) data[v * k + e] = 0;
      }
    });
  }
}

namespace {

// The first index in [0, n) with bad(i), or n: chunks scanned in parallel, each in order, so
// the index a serial scan stops at (validate's message names it).
template <class Bad>
size_t firstBad(size_t n, const Bad& bad) {
  constexpr int64_t kChunk = 1 << 15;
  std::atomic<size_t> first{n};
  parallelFor(0, int64_t((n + kChunk - 1) / kChunk), [&](int64_t chunk) {
    const size_t b = size_t(chunk * kChunk), e = std::min(n, b + size_t(kChunk));
    for (size_t i = b; i < e && i < first.load(std::memory_order_relaxed); ++i) {
      if (!bad(i)) continue;
      size_t seen = first.load();
      while (i < seen && !first.compare_exchange_weak(seen, i)) {
      }
      return;
    }
  });
  return first.load();
}

// Whether any of x[0, n) is NaN or outside [lo, hi]: a loop GCC vectorises (this file is
// compiled with -fno-trapping-math for it), so a valid grid costs one pass at memory speed.
// Scanned voxel by voxel, a precomputed frame's 25 grids took 0.04-0.08 s (`perf`, issue 18).
bool anyOutside(const float* __restrict x, size_t n, float lo, float hi) {
  int bad = 0;
  for (size_t i = 0; i < n; ++i) bad |= x[i] >= lo && x[i] <= hi ? 0 : 1;
  return bad != 0;
}

// Throws, by fail(voxel, problem), at the first voxel of channel `name` (n voxels) whose values
// break its grid's rules (BakedLight::validate).
template <class Fail>
void checkValues(const std::string& name, const BakeChannel& c, size_t n, const Fail& fail) {
  const bool unit_range = name == bake_grids::kSunTransmittance ||
                          name == bake_grids::kSkyVisibility || name == bake_grids::kMieRatio;
  const bool non_negative = name == bake_grids::kMultipleFluence ||
                            name == bake_grids::kSkyMultipleFluence || name == bake_grids::kCd;
  const bool direction = name == bake_grids::kLightDir;
  const bool signed_unit = name == bake_grids::kSkyVisibilityVector;
  // Checks the voxel's values in order; with `report` it throws at the first bad one,
  // otherwise it says whether there is one (the parallel scan finds the voxel, then the
  // report names it as a serial scan would).
  auto check = [&](size_t v, bool report) {
    const float* x = &c.data[v * size_t(c.components)];
    for (int e = 0; e < c.components; ++e) {
      const bool finite = std::isfinite(x[e]);
      const bool outside =
          (unit_range && (x[e] < 0 || x[e] > 1)) || (signed_unit && (x[e] < -1 || x[e] > 1));
      const bool negative = non_negative && x[e] < 0;
      if (!report && (!finite || outside || negative)) return true;
      if (!finite) fail(v, "value is not finite");
      if (outside) {
        fail(v,
             "value " + std::to_string(x[e]) + " outside " + (signed_unit ? "[-1, 1]" : "[0, 1]"));
      }
      if (negative) fail(v, "negative value " + std::to_string(x[e]));
    }
    if (direction && c.components == 3) {
      const double len = std::sqrt(double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
      if (len != 0 && std::abs(len - 1) > 1e-3) {
        if (!report) return true;
        fail(v, "direction of length " + std::to_string(len) + " (unit or zero expected)");
      }
    }
    return false;
  };
  if (!direction) {
    // The values' rules as one range: finite, and >= 0 or within [0, 1] where the grid says.
    const float lo = unit_range || non_negative ? 0.f
                     : signed_unit              ? -1.f
                                                : -std::numeric_limits<float>::max();
    const float hi = unit_range || signed_unit ? 1.f : std::numeric_limits<float>::max();
    const size_t values = n * size_t(c.components);
    constexpr size_t kChunk = size_t(1) << 16;
    std::atomic<bool> any{false};
    parallelFor(0, int64_t((values + kChunk - 1) / kChunk), [&](int64_t chunk) {
      const size_t b = size_t(chunk) * kChunk, e = std::min(values, b + kChunk);
      if (anyOutside(c.data.data() + b, e - b, lo, hi)) any = true;
    });
    if (!any) return;
  }
  // Some value breaks a rule (or the grid holds directions): find the first voxel to name it.
  const size_t bad = firstBad(n, [&](size_t v) { return check(v, false); });
  if (bad < n) check(bad, true);
}

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
  const size_t bad_density = firstBad(density.size(), [&](size_t v) {
    const float d = density[v];
    return !std::isfinite(d) || d < 0;
  });
  if (bad_density < density.size()) {
    const float d = density[bad_density];
    if (!std::isfinite(d)) fail(bake_grids::kDensity, bad_density, "value is not finite");
    fail(bake_grids::kDensity, bad_density, "negative density " + std::to_string(d));
  }
  for (const auto& entry : channels) {
    // Named references, not a structured binding: the lambda below captures them, which C++17
    // does not allow of a binding (clang refuses it).
    const std::string& name = entry.first;
    const BakeChannel& c = entry.second;
    if (c.components != 1 && c.components != 3) {
      throw InputError(what + ": grid '" + name + "' has " + std::to_string(c.components) +
                       " components per voxel (1 or 3 expected)");
    }
    checkSize(name, c.data.size(), c.components, gridOf(c));
    checkValues(name, c, gridOf(c).voxelCount(),
                [&](size_t v, const std::string& problem) { fail(name, v, problem); });
  }
}

}  // namespace cloudbake
