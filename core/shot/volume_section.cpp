// Shot format v1: the `volume` section (box, sphere, vdb, mesh, procedural, sequence).
#include <algorithm>
#include <cmath>
#include <string>

#include "core/format.h"
#include "core/shot/shot_sections.h"
#include "core/volume/perlin_cloud.h"
#include "core/volume/voxel_limits.h"

namespace cloudbake::shotjson {

double densityNumber(const Reader& r, const Json& v, const std::string& ptr, bool open_lo) {
  const double d = r.numberIn(v, ptr, 0, kMaxDensity, open_lo);
  if (d > 0 && d < kMinDensity) {
    r.fail(ptr, std::string(open_lo ? "must be" : "must be 0 or") +
                    " at least 1e-30 (the grids hold densities as floats), got " + exactNumber(d));
  }
  return d;
}

namespace {

NoiseOptions parseNoise(const Object& o) {
  const Reader& r = o.reader();
  NoiseOptions n;
  if (auto* v = o.find("frequency"))
    n.frequency = r.numberIn(*v, o.path("frequency"), 0, 1e4, true);
  if (auto* v = o.find("octaves")) n.octaves = int(r.integer(*v, o.path("octaves"), 1, 12));
  if (auto* v = o.find("persistence")) {
    n.persistence = r.numberIn(*v, o.path("persistence"), 0, 1, true);
  }
  if (auto* v = o.find("amount")) n.amount = r.numberIn(*v, o.path("amount"), 0, 1);
  if (auto* v = o.find("seed")) n.seed = r.unsignedInteger(*v, o.path("seed"));
  return n;
}

double density(const Object& o) {
  const Json* v = o.find("density");
  return v ? densityNumber(o.reader(), *v, o.path("density"), false) : 1.0;
}

BoxVolumeSpec parseBox(const Object& o) {
  const Reader& r = o.reader();
  BoxVolumeSpec b;
  b.min = r.point(o.required("min"), o.path("min"));
  b.max = r.point(o.required("max"), o.path("max"));
  for (int a = 0; a < 3; ++a) {
    if (!(b.max[a] > b.min[a])) {
      r.fail(o.path("max") + "/" + std::to_string(a), "must be greater than min on every axis");
    }
  }
  b.density = density(o);
  return b;
}

// An analytic volume's centre within kMaxOffsetOverSize times its size of the origin.
void checkOffset(const Reader& r, const std::string& ptr, const Vec3& center, double size,
                 const char* size_name) {
  const double offset = std::max({std::abs(center.x), std::abs(center.y), std::abs(center.z)});
  if (offset > kMaxOffsetOverSize * size) {
    r.fail(ptr, "lies " + exactNumber(offset) + " world units from the origin, more than " +
                    exactNumber(kMaxOffsetOverSize) + " times its " + size_name + " (" +
                    exactNumber(size) +
                    "): its voxels would lose their precision; move the scene nearer the origin");
  }
}

SphereVolumeSpec parseSphere(const Object& o) {
  const Reader& r = o.reader();
  SphereVolumeSpec s;
  s.center = r.point(o.required("center"), o.path("center"));
  s.radius = r.numberIn(o.required("radius"), o.path("radius"), 0, 1e12, true);
  checkOffset(r, o.path("center"), s.center, s.radius, "radius");
  s.density = density(o);
  return s;
}

VdbVolumeSpec parseVdb(const Object& o) {
  const Reader& r = o.reader();
  VdbVolumeSpec v;
  v.path = r.filePath(o.required("path"), o.path("path"));
  if (auto* g = o.find("grid")) {
    v.grid = r.string(*g, o.path("grid"));
    if (v.grid.empty()) r.fail(o.path("grid"), "must be a non-empty grid name");
  }
  return v;
}

MeshVolumeSpec parseMesh(const Object& o) {
  const Reader& r = o.reader();
  MeshVolumeSpec m;
  m.path = r.filePath(o.required("path"), o.path("path"));
  const Json* vs = o.find("voxel_size");
  const Json* res = o.find("resolution");
  if (vs && res) r.fail(o.path("resolution"), "give either voxel_size or resolution, not both");
  if (!vs && !res) r.fail(o.ptr(), "needs voxel_size (world units) or resolution (voxels)");
  if (vs) m.voxel_size = r.numberIn(*vs, o.path("voxel_size"), 0, 1e12, true);
  if (res) m.resolution = int(r.integer(*res, o.path("resolution"), 1, kMaxMeshResolution));
  if (auto* v = o.find("density")) {
    m.density = densityNumber(r, *v, o.path("density"), true);
  }
  if (auto* n = o.find("noise")) {
    m.noise_enabled = true;
    m.noise = parseNoise(
        Object(r, *n, o.path("noise"), {"frequency", "octaves", "persistence", "amount", "seed"}));
  }
  return m;
}

ProceduralVolumeSpec parseProcedural(const Object& o) {
  const Reader& r = o.reader();
  ProceduralVolumeSpec p;
  p.type = r.string(o.required("type"), o.path("type"));
  if (p.type != "perlin_cloud") {
    r.fail(o.path("type"), "unknown procedural type '" + p.type + "' (known: perlin_cloud)");
  }
  PerlinCloudOptions& c = p.perlin;
  if (auto* v = o.find("seed")) c.seed = r.unsignedInteger(*v, o.path("seed"));
  if (auto* v = o.find("center")) c.center = r.point(*v, o.path("center"));
  if (auto* v = o.find("size")) {
    c.size = r.vec3(*v, o.path("size"));
    for (int a = 0; a < 3; ++a) {
      r.numberIn((*v)[a], o.path("size") + "/" + std::to_string(a), 0, 1e9, true);
    }
  }
  if (auto* v = o.find("resolution")) {
    c.resolution = int(r.integer(*v, o.path("resolution"), 8, 1024));
  }
  if (auto* v = o.find("cover")) c.cover = r.numberIn(*v, o.path("cover"), 0, 1);
  if (auto* v = o.find("sharpness")) {
    c.sharpness = r.numberIn(*v, o.path("sharpness"), 0, 1, true, true);
  }
  if (auto* v = o.find("density")) c.density = densityNumber(r, *v, o.path("density"), true);
  if (auto* v = o.find("octaves")) c.octaves = int(r.integer(*v, o.path("octaves"), 1, 12));
  if (auto* v = o.find("frequency")) {
    c.frequency = r.numberIn(*v, o.path("frequency"), 0, 1e4, true);
  }
  if (auto* v = o.find("persistence")) {
    c.persistence = r.numberIn(*v, o.path("persistence"), 0, 1, true);
  }
  if (auto* v = o.find("time")) c.time = r.numberIn(*v, o.path("time"), -1e6, 1e6);
  checkOffset(r, o.path("center"), c.center, std::max({c.size.x, c.size.y, c.size.z}),
              "largest size");
  // The remaining rule (at least 6 voxels along every axis) couples size and resolution. The
  // builder names the key it refuses ("perlin_cloud.size: ..."): the error names its pointer.
  try {
    validatePerlinCloudOptions(c);
  } catch (const InputError& e) {
    const std::string what = e.what(), prefix = "perlin_cloud.";
    const size_t colon = what.find(": ");
    if (what.rfind(prefix, 0) == 0 && colon != std::string::npos) {
      r.fail(o.path(what.substr(prefix.size(), colon - prefix.size())), what.substr(colon + 2));
    }
    r.fail(o.ptr(), what);
  }
  const double voxel = std::max({c.size.x, c.size.y, c.size.z}) / c.resolution;
  if (!(voxel >= kMinVoxelSize)) {
    r.fail(o.path("size"), "gives voxels of " + exactNumber(voxel) +
                               " world units (largest size / resolution), below the smallest " +
                               exactNumber(kMinVoxelSize) + ": scale the scene up");
  }
  return p;
}

#define CLOUDBAKE_PROCEDURAL_KEYS                                                             \
  "type", "seed", "center", "size", "resolution", "cover", "sharpness", "density", "octaves", \
      "frequency", "persistence", "time"

SequenceVolumeSpec parseSequence(const Object& o) {
  const Reader& r = o.reader();
  SequenceVolumeSpec s;
  const Json* paths = o.find("paths");
  const Json* proc = o.find("procedural");
  if (paths && proc) r.fail(o.path("procedural"), "give either paths or procedural, not both");
  if (!paths && !proc) r.fail(o.ptr(), "needs paths (one VDB per frame) or procedural");
  const Json* frames = o.find("frames");
  if (paths) {
    if (!paths->is_array()) {
      r.fail(o.path("paths"), "must be an array of file paths, got " + shotjson::typeName(*paths));
    }
    // Only precomputed renders sequences, and its endless animation needs two basic volumes:
    // one was accepted here and by a dry run, then failed when the job ran.
    if (paths->size() < 2) {
      r.fail(o.path("paths"),
             "must list at least 2 files (an endless animation needs at least 2 "
             "basic volumes), got " +
                 std::to_string(paths->size()));
    }
    if (int64_t(paths->size()) > kMaxFrames) {
      r.fail(o.path("paths"), "at most " + std::to_string(kMaxFrames) + " frames");
    }
    for (size_t i = 0; i < paths->size(); ++i) {
      s.paths.push_back(r.filePath((*paths)[i], o.path("paths") + "/" + std::to_string(i)));
    }
    if (auto* g = o.find("grid")) {
      s.grid = r.string(*g, o.path("grid"));
      if (s.grid.empty()) r.fail(o.path("grid"), "must be a non-empty grid name");
    }
    if (o.has("time_step")) r.fail(o.path("time_step"), "only applies to procedural");
    s.frames = int(paths->size());
    if (frames) {
      const int64_t n = r.integer(*frames, o.path("frames"), 2, kMaxFrames);
      if (n != s.frames) {
        r.fail(o.path("frames"), "is " + std::to_string(n) + " but paths lists " +
                                     std::to_string(s.frames) + " files");
      }
    }
  } else {
    if (o.has("grid")) r.fail(o.path("grid"), "only applies to paths");
    s.procedural =
        parseProcedural(Object(r, *proc, o.path("procedural"), {CLOUDBAKE_PROCEDURAL_KEYS}));
    if (!frames) r.fail(o.path("frames"), "missing (required with procedural)");
    s.frames = int(r.integer(*frames, o.path("frames"), 2, kMaxFrames));
    if (auto* t = o.find("time_step"))
      s.time_step = r.numberIn(*t, o.path("time_step"), 0, 1e3, true);
    // Frame f is the cloud at time + f x time_step, each within the time's range.
    const double last = s.procedural->perlin.time + double(s.frames - 1) * s.time_step;
    if (!(std::abs(last) <= 1e6)) {
      r.fail(o.path("time_step"), "puts the last frame's time at " + exactNumber(last) +
                                      " (time + (frames - 1) x time_step), beyond +-1e6");
    }
  }
  return s;
}

}  // namespace

VolumeSpec parseVolume(const Object& o) {
  const Reader& r = o.reader();
  o.allowOnly({"box", "sphere", "vdb", "mesh", "procedural", "sequence"});
  if (o.json().empty()) {
    r.fail(o.ptr(), "needs exactly one of box, sphere, vdb, mesh, procedural, sequence");
  }
  if (o.json().size() > 1) {
    auto it = o.json().begin();
    const std::string first = it.key();
    ++it;
    r.fail(o.path(it.key()), "a volume has exactly one source; '" + first + "' is also given");
  }
  const std::string kind = o.json().begin().key();
  const Json& v = o.json().begin().value();
  const std::string ptr = o.path(kind);
  if (kind == "box") return parseBox(Object(r, v, ptr, {"min", "max", "density"}));
  if (kind == "sphere") return parseSphere(Object(r, v, ptr, {"center", "radius", "density"}));
  if (kind == "vdb") return parseVdb(Object(r, v, ptr, {"path", "grid"}));
  if (kind == "mesh") {
    return parseMesh(Object(r, v, ptr, {"path", "voxel_size", "resolution", "density", "noise"}));
  }
  if (kind == "procedural") {
    return parseProcedural(Object(r, v, ptr, {CLOUDBAKE_PROCEDURAL_KEYS}));
  }
  return parseSequence(Object(r, v, ptr, {"paths", "grid", "procedural", "frames", "time_step"}));
}

}  // namespace cloudbake::shotjson
