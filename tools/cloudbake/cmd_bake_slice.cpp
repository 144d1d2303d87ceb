// `cloudbake bake-slice BAKE.vdb --grid NAME [--axis x|y|z] [--at WORLD] --png OUT.png
// [--range LO,HI]`: a colour-mapped slice through one grid of a bake (e.g. the pointcloud's
// mie_ratio, seed 000's Figure 8), for looking inside a bake without a DCC.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/bake/baked_light_vdb.h"
#include "core/error.h"
#include "core/io/png_writer.h"
#include "core/job/file_util.h"
#include "core/job/vdb_gate.h"
#include "tools/cloudbake/commands.h"

namespace cloudbake::tool {
namespace {

// Dark blue through teal to pale yellow: monotonic in lightness, readable in print.
Rgb colourMap(double t) {
  static const Rgb stops[] = {{0.05, 0.05, 0.25},
                              {0.1, 0.35, 0.55},
                              {0.2, 0.65, 0.55},
                              {0.75, 0.85, 0.35},
                              {1.0, 0.98, 0.75}};
  t = std::clamp(t, 0.0, 1.0) * 4;
  const int i = std::min(3, int(t));
  const double f = t - i;
  return stops[i] * (1 - f) + stops[i + 1] * f;
}

struct SliceOptions {
  std::string bake, grid, axis = "y", png, range;
  std::optional<double> at;  // unset: the middle of the lattice
};

// A number for a message: short, whatever its size.
std::string shortNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

// The slice of one grid: which voxel a pixel of the slice shows, and its value (a 3-component
// grid by its luminance).
struct Slice {
  const BakedLight& bake;
  const float* data = nullptr;  // the grid's values on the bake's lattice
  std::shared_ptr<std::vector<float>> resampled = nullptr;  // a tally on the bake's lattice
  int components = 1;
  int a = 1, u = 0, v = 2;  // slice normal, image right and up
  int n[3] = {0, 0, 0};
  int index = 0;  // along the normal

  size_t voxel(int iu, int iv) const {
    int ijk[3];
    ijk[a] = index;
    ijk[u] = iu;
    ijk[v] = iv;
    return bake.grid.index(ijk[0], ijk[1], ijk[2]);
  }
  double value(size_t voxel) const {
    const float* x = data + voxel * size_t(components);
    return components == 3 ? luminance(Rgb(x[0], x[1], x[2])) : double(x[0]);
  }
};

// The slice --grid, --axis and --at ask for; InputError naming the flag when the bake has no
// such grid or the coordinate is outside it.
Slice findSlice(const BakedLight& bake, const SliceOptions& opt) {
  Slice s{bake};
  s.data = bake.density.data();
  if (opt.grid != "density") {
    const BakeChannel* c = bake.find(opt.grid);
    if (!c) {
      std::string known = "density";
      for (const auto& [name, ch] : bake.channels) known += ", " + name;
      throw InputError("--grid: '" + opt.grid + "' is not in " + opt.bake + " (it has " + known +
                       ")");
    }
    s.data = c->data.data();
    s.components = c->components;
    if (c->on_tally_grid) {
      // Photon's tallies lie on their own lattice: shown as views read them, interpolated at
      // the voxel centres of the bake's lattice.
      s.resampled = std::make_shared<std::vector<float>>(
          resampleTrilinear(bake.tally_grid, c->data.data(), c->components, bake.grid));
      s.data = s.resampled->data();
    }
  }
  const BakeGrid& g = bake.grid;
  s.a = opt.axis[0] - 'x';
  s.u = s.a == 0 ? 1 : 0;
  s.v = s.a == 2 ? 1 : 2;
  s.n[0] = g.nx;
  s.n[1] = g.ny;
  s.n[2] = g.nz;
  s.index = s.n[s.a] / 2;
  if (opt.at) {
    if (!std::isfinite(*opt.at)) throw InputError("--at: must be a finite number");
    const double index = (*opt.at - g.origin[s.a]) / g.voxel_size;
    if (!(index > -0.5 && index < s.n[s.a] - 0.5)) {
      throw InputError("--at: " + shortNumber(*opt.at) + " is outside the bake along " + opt.axis);
    }
    s.index = int(std::lround(index));
  }
  return s;
}

// The colour map's ends: --range, else the range of the slice's voxels inside the cloud (lo >
// hi when there are none).
void sliceRange(const Slice& s, const std::string& range, double* lo, double* hi) {
  *lo = 1e300;
  *hi = -1e300;
  for (int iv = 0; iv < s.n[s.v]; ++iv)
    for (int iu = 0; iu < s.n[s.u]; ++iu) {
      const size_t voxel = s.voxel(iu, iv);
      if (!(s.bake.density[voxel] > 0)) continue;
      *lo = std::min(*lo, s.value(voxel));
      *hi = std::max(*hi, s.value(voxel));
    }
  if (!range.empty()) {
    int used = 0;
    const bool two =
        std::sscanf(range.c_str(), "%lf,%lf%n", lo, hi, &used) == 2 && size_t(used) == range.size();
    if (!two || !std::isfinite(*lo) || !std::isfinite(*hi) || !(*hi > *lo)) {
      throw InputError("--range: expected LO,HI, two finite numbers with HI > LO, got '" + range +
                       "'");
    }
    // The colour map divides by the difference: it must be finite too.
    if (!std::isfinite(*hi - *lo)) {
      throw InputError("--range: HI - LO overflows (got '" + range +
                       "'); the range must span less than 1.7e308");
    }
  }
}

// Writes the slice as a PNG, enlarged (nearest neighbour) so that small lattices are visible:
// at least 256 pixels across.
void writeSlicePng(const Slice& s, double lo, double hi, const std::string& png) {
  const int nu = s.n[s.u], nv = s.n[s.v];
  const int scale = std::max(1, 256 / std::max(nu, nv));
  const int w = nu * scale, h = nv * scale;
  std::vector<uint8_t> px(size_t(w) * size_t(h) * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t voxel = s.voxel(x / scale, nv - 1 - y / scale);  // up is +v
      Rgb c(0.12);                                                  // outside the cloud
      if (s.bake.density[voxel] > 0) {
        c = colourMap(hi > lo ? (s.value(voxel) - lo) / (hi - lo) : 0.5);
      }
      uint8_t* p = &px[(size_t(y) * size_t(w) + size_t(x)) * 3];
      for (int k = 0; k < 3; ++k) p[k] = uint8_t(std::lround(255 * std::clamp(c[k], 0.0, 1.0)));
    }
  writePng(png, w, h, 3, px);
}

// The bake read from a child process's rewrite of it (core/job/vdb_gate.h), as a run reads
// users' VDB files: a corrupt file is then an error naming it, not a crash of this process.
BakedLight readBakeViaChild(const std::string& path) {
  const std::vector<std::string> command = vdbReaderCommand();
  if (command.empty()) return readBakedLight(path);
  const std::filesystem::path rewrite =
      std::filesystem::temp_directory_path() / ("cloudbake-slice-" + uniqueSuffix() + ".vdb");
  struct Remove {
    std::filesystem::path p;
    ~Remove() {
      std::error_code ec;
      std::filesystem::remove(p, ec);
    }
  } remove{rewrite};
  VdbReaderOptions reader;
  reader.command = command;
  rewriteVdbInChild(reader, path, rewrite.string(), [] { return true; });
  return readRewrite(path, rewrite.string(), [&] { return readBakedLight(rewrite.string()); });
}

void runBakeSlice(const SliceOptions& opt) {
  if (opt.axis != "x" && opt.axis != "y" && opt.axis != "z") {
    throw InputError("--axis: must be x, y or z, got '" + opt.axis + "'");
  }
  std::error_code ec;
  if (!std::filesystem::exists(opt.bake, ec)) {
    throw MissingFileError(opt.bake + ": bake file not found");
  }
  if (!std::filesystem::is_regular_file(opt.bake, ec)) {
    throw InputError(opt.bake + ": not a file (a bake is a .vdb file)");
  }
  const BakedLight bake = readBakeViaChild(opt.bake);
  const Slice slice = findSlice(bake, opt);
  double lo, hi;
  sliceRange(slice, opt.range, &lo, &hi);
  writeSlicePng(slice, lo, hi, opt.png);
  // The lattice too, so that a script can give a knob in voxels of it (a view's `step`).
  const BakeGrid& g = bake.grid;
  std::cout << nlohmann::json{{"grid", opt.grid},
                              {"axis", opt.axis},
                              {"index", slice.index},
                              {"min", lo <= hi ? lo : 0.0},
                              {"max", lo <= hi ? hi : 0.0},
                              {"png", opt.png},
                              {"lattice", {g.nx, g.ny, g.nz}},
                              {"voxel_size", g.voxel_size}}
                   .dump()
            << std::endl;
}

}  // namespace

void addBakeSliceCommand(CLI::App& app, int* exit_code) {
  auto opt = std::make_shared<SliceOptions>();
  CLI::App* cmd = app.add_subcommand(
      "bake-slice",
      "Write a colour-mapped PNG of one slice through a grid of a light bake (bake.vdb of methods "
      "single, pointcloud, photon and precomputed); prints the slice's range, the lattice's voxels "
      "along each axis and "
      "its voxel size in world units as JSON");
  cmd->add_option("bake", opt->bake, "the bake (.vdb)")->required();
  cmd->add_option("--grid", opt->grid, "grid name: density, sun_transmittance, mie_ratio, Co, ...")
      ->required();
  cmd->add_option("--axis", opt->axis, "slice normal: x, y or z (default y)");
  cmd->add_option("--at", opt->at,
                  "world coordinate of the slice along the axis (default: the "
                  "middle of the lattice)");
  cmd->add_option("--png", opt->png, "output PNG")->required();
  cmd->add_option("--range", opt->range,
                  "LO,HI mapped to the ends of the colour map (default: "
                  "the slice's own range)");
  cmd->callback([opt, exit_code] {
    runBakeSlice(*opt);
    *exit_code = kOk;
  });
}

}  // namespace cloudbake::tool
