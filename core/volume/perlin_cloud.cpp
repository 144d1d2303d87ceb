#include "core/volume/perlin_cloud.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/format.h"
#include "core/volume/noise.h"
#include "core/volume/openvdb_grid.h"

namespace cloudbake {
namespace {

struct CloudGeometry {
  Vec3 box_min, semi_axes;
  double h = 0;
  int dims[3] = {0, 0, 0};
};

CloudGeometry cloudGeometry(const PerlinCloudOptions& o) {
  CloudGeometry g;
  g.h = maxComponent(o.size) / o.resolution;
  for (int a = 0; a < 3; ++a) {
    g.dims[a] = std::max(1, static_cast<int>(std::lround(o.size[a] / g.h)));
    g.semi_axes[a] = 0.5 * g.dims[a] * g.h - 1.5 * g.h;
    // Centre the (rounded) voxel box on options.center.
    g.box_min[a] = o.center[a] - 0.5 * g.dims[a] * g.h;
  }
  return g;
}

}  // namespace

double cloudEnvelope(double r) { return std::max(0.0, 1.0 - r * r); }

double eliasCloudDensity(double v, double cover, double sharpness) {
  const double c = std::max(v - cover, 0.0);
  return 1.0 - std::pow(sharpness, 255.0 * c);
}

double evolvingFbm01(const PerlinNoise& noise, const Vec3& q, int octaves, double persistence,
                     double time) {
  double sum = 0, amplitude = 1, norm = 0, scale = 1;
  for (int oct = 0; oct < octaves; ++oct) {
    // PerlinNoise::fbm's octave offsets, plus a drift of (1 + oct/2) noise cells per unit time
    // in a direction that turns with the octave: at time 0 this is exactly fbm01.
    const double speed = time * (1 + 0.5 * oct);
    const Vec3 drift(std::cos(1.7 * oct) * speed, std::sin(1.7 * oct) * speed, 0.35 * speed);
    sum += amplitude * noise.noise(q * scale + Vec3(17.31 * oct, 5.77 * oct, 11.13 * oct) + drift);
    norm += amplitude;
    amplitude *= persistence;
    scale *= 2;
  }
  return std::clamp(0.5 + 0.5 * (norm > 0 ? sum / norm : 0.0), 0.0, 1.0);
}

void validatePerlinCloudOptions(const PerlinCloudOptions& o) {
  auto fail = [](const std::string& field, const std::string& rule, const std::string& got) {
    throw InputError("perlin_cloud." + field + ": must be " + rule + ", got " + got);
  };
  auto num = [](double v) {
    std::ostringstream os;
    os << v;
    return os.str();
  };
  auto vec = [&](const Vec3& v) {
    return "[" + num(v.x) + ", " + num(v.y) + ", " + num(v.z) + "]";
  };
  if (!isFinite(o.center) ||
      maxComponent(Vec3(std::abs(o.center.x), std::abs(o.center.y), std::abs(o.center.z))) > 1e9)
    fail("center", "finite (|c| <= 1e9)", vec(o.center));
  if (!isFinite(o.size) || !(o.size.x > 0 && o.size.y > 0 && o.size.z > 0) ||
      maxComponent(o.size) > 1e9)
    fail("size", "finite and in (0, 1e9] on every axis", vec(o.size));
  if (o.resolution < 8 || o.resolution > 1024)
    fail("resolution", "in [8, 1024]", std::to_string(o.resolution));
  if (!(o.cover >= 0 && o.cover <= 1)) fail("cover", "in [0, 1]", num(o.cover));
  if (!(o.sharpness > 0 && o.sharpness < 1)) fail("sharpness", "in (0, 1)", num(o.sharpness));
  if (!std::isfinite(o.density) || !(o.density > 0))
    fail("density", "finite and > 0", num(o.density));
  if (!std::isfinite(o.time) || std::abs(o.time) > 1e6)
    fail("time", "finite (|time| <= 1e6)", num(o.time));
  if (o.octaves < 1 || o.octaves > 12) fail("octaves", "in [1, 12]", std::to_string(o.octaves));
  if (!std::isfinite(o.frequency) || !(o.frequency > 0) || o.frequency > 1e6)
    fail("frequency", "finite and in (0, 1e6]", num(o.frequency));
  if (!(o.persistence > 0 && o.persistence <= 1))
    fail("persistence", "in (0, 1]", num(o.persistence));
  const CloudGeometry g = cloudGeometry(o);
  for (int a = 0; a < 3; ++a) {
    if (g.dims[a] < 6) {
      fail("size",
           "at least 6 voxels along every axis at resolution " + std::to_string(o.resolution),
           vec(o.size) + " (" + std::to_string(g.dims[a]) + " voxels along axis " +
               std::to_string(a) + ")");
    }
  }
}

DensityFieldPtr makePerlinCloud(const PerlinCloudOptions& o, const std::function<bool()>& stop) {
  validatePerlinCloudOptions(o);
  const CloudGeometry g = cloudGeometry(o);
  const PerlinNoise noise(o.seed);
  const double max_size = maxComponent(o.size);
  const Vec3 center_idx = Vec3(g.dims[0], g.dims[1], g.dims[2]) * 0.5;  // in voxel units
  const Vec3 inv_axes_idx = Vec3(g.h) / g.semi_axes;                    // 1 / semi-axis (voxels)
  const openvdb::CoordBBox box(openvdb::Coord(0),
                               openvdb::Coord(g.dims[0] - 1, g.dims[1] - 1, g.dims[2] - 1));
  auto grid = buildGridFromBlocks(
      box, g.h,
      [&](const openvdb::Coord& origin, float* values) {
        // Skip blocks entirely outside the ellipsoid: nearest point of the block to the centre.
        double r2_min = 0;
        for (int a = 0; a < 3; ++a) {
          const double lo = origin[a] + 0.5, hi = origin[a] + 7.5;
          const double d =
              std::max({lo - center_idx[a], center_idx[a] - hi, 0.0}) * inv_axes_idx[a];
          r2_min += d * d;
        }
        if (r2_min >= 1.0) {
          values[0] = 0.f;
          return true;
        }
        for (int i = 0; i < 512; ++i) {
          const openvdb::Coord c = origin + openvdb::FloatTree::LeafNodeType::offsetToLocalCoord(i);
          const Vec3 vi(c.x() + 0.5, c.y() + 0.5, c.z() + 0.5);  // voxel centre, voxel units
          const double r = length((vi - center_idx) * inv_axes_idx);
          const double env = cloudEnvelope(r);
          if (env <= 0) {
            values[i] = 0.f;
            continue;
          }
          const Vec3 q = vi * (g.h / max_size * o.frequency);
          const double v =
              env * 2.0 *
              (o.time == 0 ? fbm01(noise, q, o.octaves, o.persistence)
                           : evolvingFbm01(noise, q, o.octaves, o.persistence, o.time));
          values[i] = static_cast<float>(o.density * eliasCloudDensity(v, o.cover, o.sharpness));
        }
        return false;
      },
      stop);
  // Voxel ijk is centred at box_min + (ijk + 1/2) h.
  grid->transform().postTranslate(
      openvdb::Vec3d(g.box_min.x + 0.5 * g.h, g.box_min.y + 0.5 * g.h, g.box_min.z + 0.5 * g.h));
  grid->setName("density");
  if (grid->activeVoxelCount() == 0) {
    throw InputError("perlin_cloud.cover: " + exactNumber(o.cover) +
                     " leaves no cloud at all (lower it)");
  }
  return makeGridVolume(grid, "perlin_cloud");
}

}  // namespace cloudbake
