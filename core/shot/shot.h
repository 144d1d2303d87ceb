// In-memory form of a shot file (docs/shot-format.md): what to bake, how to light it, what to
// render. Produced by parseShot(); turned into a renderable scene by buildScene().
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "core/math/vec3.h"
#include "core/methods/knob.h"
#include "core/phase/phase_factory.h"
#include "core/transport/scene.h"
#include "core/volume/sources.h"

namespace cloudbake {

/// Homogeneous box: corners in world units (min < max on every axis), density >= 0.
struct BoxVolumeSpec {
  Vec3 min, max;
  double density = 1.0;
};

/// Homogeneous sphere: centre (world), radius > 0 (world units), density >= 0.
struct SphereVolumeSpec {
  Vec3 center;
  double radius = 1.0;
  double density = 1.0;
};

/// A float grid in an OpenVDB file; `path` is absolute after parsing.
using VdbVolumeSpec = VdbSourceOptions;

/// A voxelised triangle mesh (OBJ/PLY); `path` is absolute after parsing. Exactly one of
/// voxel_size / resolution is non-zero.
using MeshVolumeSpec = MeshSourceOptions;

/// A procedural cloud. Only type "perlin_cloud" (seed 004) exists in format v1.
struct ProceduralVolumeSpec {
  std::string type = "perlin_cloud";
  PerlinCloudOptions perlin;
};

/// An animated volume: either one VDB file per frame (`paths`, absolute after parsing; `frames`
/// equals paths.size()) or a procedural cloud evolving over `frames` frames.
struct SequenceVolumeSpec {
  std::vector<std::string> paths;
  std::string grid = "density";
  std::optional<ProceduralVolumeSpec> procedural;
  int frames = 0;
  /// procedural: cloud time between frames (frame i is the cloud at procedural.time + i * step)
  double time_step = 0.1;
};

/// `volume`: exactly one source.
using VolumeSpec = std::variant<BoxVolumeSpec, SphereVolumeSpec, VdbVolumeSpec, MeshVolumeSpec,
                                ProceduralVolumeSpec, SequenceVolumeSpec>;

/// `medium`: sigma_t = extinction * density per world unit; sigma_s = albedo * sigma_t.
struct MediumSpec {
  double extinction = 1.0;  ///< per world unit per unit density, in [0, 1e6]
  Rgb albedo{1, 1, 1};      ///< single-scattering albedo per channel, in [0, 1]
  PhaseSpec phase;
};

/// `lighting`: an optional sun (has_sun false: no sun) and a sky (default: black).
struct LightingSpec {
  bool has_sun = false;
  Sun sun;  ///< direction is unit length after parsing
  Sky sky;  ///< map_path is absolute after parsing
};

/// `bake`: the method (a name in the method registry, core/methods/registry.h), the knobs every
/// method has, and the method's own knobs, validated against its knob table.
struct BakeSpec {
  std::string method = "pathtrace";
  int samples = 64;  ///< paths (pathtrace) or rays (views from a bake) per pixel, 1..1e6
  uint64_t seed = 1;
  /// Every knob of the method's table with a fixed default, plus those the shot sets.
  KnobValues knobs;
};

/// The layers a view's EXR can hold (outputs.exr_layers), in the file's order: "cloud" is the
/// unprefixed R, G, B, A (docs/outputs.md).
inline const std::vector<std::string> kExrLayerNames = {"cloud", "background", "beauty",  "sun",
                                                        "sky",   "single",     "multiple"};

/// `outputs`: which files a render writes.
struct OutputSpec {
  bool exr = true;            ///< DIR/<view>.exr per view
  bool vdb = false;           ///< DIR/bake.vdb
  double vdb_voxel_size = 0;  ///< world units; required for box/sphere volumes when vdb
  /// Lossless compression of the EXRs: a name of kExrCompressionNames (core/io).
  std::string exr_compression = "zip";
  /// The layers each view's EXR holds, in the file's order: names of kExrLayerNames ("cloud"
  /// for the unprefixed R, G, B, A). Every layer by default.
  std::vector<std::string> exr_layers = kExrLayerNames;
};

/// A whole shot, validated. `views` holds the cameras with their names and pixel sizes.
struct ShotSpec {
  int version = 1;
  std::string name = "shot";
  VolumeSpec volume;
  MediumSpec medium;
  LightingSpec lighting;
  BakeSpec bake;
  std::vector<Camera> views;
  OutputSpec outputs;
};

/// Shot-format name of the volume's source ("box", "vdb", "sequence", ...).
inline const char* volumeTypeName(const VolumeSpec& volume) {
  static const char* const kNames[] = {"box", "sphere", "vdb", "mesh", "procedural", "sequence"};
  return kNames[volume.index()];
}

/// The bounds a `box` or `sphere` volume states (world units), known before anything is built;
/// nullopt for the other volumes, whose bounds are known once their files are read or their
/// field evaluated.
inline std::optional<Bounds3> statedBounds(const VolumeSpec& volume) {
  Bounds3 b;
  if (const auto* box = std::get_if<BoxVolumeSpec>(&volume)) {
    b.min = box->min;
    b.max = box->max;
  } else if (const auto* sphere = std::get_if<SphereVolumeSpec>(&volume)) {
    b.min = sphere->center - Vec3(sphere->radius);
    b.max = sphere->center + Vec3(sphere->radius);
  } else {
    return std::nullopt;
  }
  return b;
}

}  // namespace cloudbake
