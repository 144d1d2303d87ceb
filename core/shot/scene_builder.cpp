#include "core/shot/scene_builder.h"

#include <cctype>
#include <memory>
#include <type_traits>

#include "core/error.h"
#include "core/format.h"
#include "core/phase/phase_factory.h"
#include "core/shot/shot_parser.h"
#include "core/transport/sky.h"
#include "core/volume/analytic.h"
#include "core/volume/sources.h"

namespace cloudbake {
namespace {

// Runs a factory, re-labelling its InputErrors with the shot field they came from, so a user
// sees "shot.json: /volume/vdb: grid 'dens' not found in ..." rather than a bare message.
template <typename F>
auto labelled(const std::string& source, const std::string& pointer, F&& make,
              const std::string& key_prefix = "") {
  try {
    return make();
  } catch (const MissingFileError&) {
    throw;
  } catch (const InputError& e) {
    throw InputError(source + ": " + volumeErrorAt(pointer, e.what(), key_prefix));
  }
}

}  // namespace

// A volume builder names the key it refuses as "<prefix><key>: " ("perlin_cloud.cover: ...",
// "cloud.ply: mesh.voxel_size: ..."): the error then names that key's pointer, which the
// message no longer repeats (an outside probe found "/volume/sequence/procedural:
// perlin_cloud.cover: ..." where the field is /volume/sequence/procedural/cover).
std::string volumeErrorAt(const std::string& pointer, const std::string& what,
                          const std::string& key_prefix) {
  const size_t at = key_prefix.empty() ? std::string::npos : what.find(key_prefix);
  const size_t key = at + key_prefix.size();
  const size_t colon = at == std::string::npos ? at : what.find(": ", key);
  if (colon == std::string::npos || colon == key) return pointer + ": " + what;
  std::string name = what.substr(key, colon - key);
  for (char& c : name) {
    if (c == '.') c = '/';  // mesh.noise.frequency
    if (!(std::islower(static_cast<unsigned char>(c)) || c == '_' || c == '/')) {
      return pointer + ": " + what;
    }
  }
  return pointer + "/" + name + ": " + what.substr(0, at) + what.substr(colon + 2);
}

DensityFieldPtr buildVolume(const VolumeSpec& volume, const std::string& source,
                            const std::function<bool()>& stop) {
  const std::string ptr = std::string("/volume/") + volumeTypeName(volume);
  return std::visit(
      [&](const auto& v) -> DensityFieldPtr {
        using T = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<T, BoxVolumeSpec>) {
          return labelled(source, ptr, [&]() -> DensityFieldPtr {
            return std::make_shared<BoxDensity>(v.min, v.max, v.density);
          });
        } else if constexpr (std::is_same_v<T, SphereVolumeSpec>) {
          return labelled(source, ptr, [&]() -> DensityFieldPtr {
            return std::make_shared<SphereDensity>(v.center, v.radius, v.density);
          });
        } else if constexpr (std::is_same_v<T, VdbVolumeSpec>) {
          return labelled(source, ptr, [&] { return loadVdbVolume(v); });
        } else if constexpr (std::is_same_v<T, MeshVolumeSpec>) {
          return labelled(
              source, ptr, [&] { return meshToVolume(v, stop); }, "mesh.");
        } else if constexpr (std::is_same_v<T, ProceduralVolumeSpec>) {
          return labelled(
              source, ptr, [&] { return makePerlinCloud(v.perlin, stop); }, "perlin_cloud.");
        } else {
          throw InputError(source + ": " + ptr +
                           ": an animated volume has one density per frame; build it frame by "
                           "frame");
        }
      },
      volume);
}

DensityFieldPtr buildSequenceFrame(const SequenceVolumeSpec& sequence, int frame,
                                   const std::string& source) {
  if (frame < 0 || frame >= sequence.frames) {
    throw InputError(source + ": /volume/sequence/frames: frame " + std::to_string(frame) +
                     " is outside [0, " + std::to_string(sequence.frames) + ")");
  }
  if (sequence.procedural) {
    // The cloud at its own time plus `frame` steps: the octaves drift (perlin_cloud.h).
    PerlinCloudOptions options = sequence.procedural->perlin;
    options.time += frame * sequence.time_step;
    return labelled(
        source, "/volume/sequence/procedural", [&] { return makePerlinCloud(options); },
        "perlin_cloud.");
  }
  VdbSourceOptions options;
  options.path = sequence.paths.at(static_cast<size_t>(frame));
  options.grid = sequence.grid;
  return labelled(source, "/volume/sequence/paths/" + std::to_string(frame),
                  [&] { return loadVdbVolume(options); });
}

void checkTrackableOpticalDepth(const ShotSpec& shot, const DensityField& density,
                                const std::string& source, const std::string& volume) {
  const Bounds3 b = density.bounds();
  const double size = length(b.max - b.min);
  const double tau = shot.medium.extinction * density.maxDensity() * size;
  if (!(tau <= kMaxTrackableOpticalDepth)) {
    throw InputError(source + ": /medium/extinction: extinction " + str(shot.medium.extinction) +
                     " x " + volume + "'s largest density " + str(density.maxDensity()) +
                     " x its diagonal " + str(size) + " is " + str(tau) +
                     " optical depths, beyond the " + str(kMaxTrackableOpticalDepth) +
                     " that tracking resolves in double precision; lower the extinction or the "
                     "volume's density");
  }
}

Scene buildScene(const ShotSpec& shot, const std::string& source, const PhaseBuilder& phase) {
  Scene scene;
  scene.medium.density = buildVolume(shot.volume, source);
  checkTrackableOpticalDepth(shot, *scene.medium.density, source);
  scene.medium.extinction = shot.medium.extinction;
  scene.medium.albedo = shot.medium.albedo;
  scene.medium.phase = labelled(source, "/medium/phase", [&] {
    return phase ? phase(shot.medium.phase) : makePhaseFunction(shot.medium.phase);
  });
  if (shot.lighting.has_sun) {
    scene.sun = shot.lighting.sun;
  } else {
    scene.sun.irradiance = Rgb(0, 0, 0);
  }
  scene.sky = shot.lighting.sky;
  if (scene.sky.type == Sky::Type::kMap) {
    // Read and checked now, before any bake: a map's bad pixel was otherwise found when the
    // first view rendered, after a bake of possibly minutes.
    labelled(source, "/lighting/sky/map", [&] { return SkyLight(scene.sky).black(); });
  }
  scene.cameras = shot.views;
  return scene;
}

}  // namespace cloudbake
