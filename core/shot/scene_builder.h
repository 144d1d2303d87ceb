// Turns a validated ShotSpec into what the renderers consume: medium, lights, cameras.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/shot/shot.h"
#include "core/transport/scene.h"
#include "core/volume/density_field.h"

namespace cloudbake {

/// Builds the density field of a single-frame volume: analytic box/sphere (exact), a VDB grid,
/// a voxelised mesh or a Perlin cloud. Loading errors from the factories come back as
/// InputError prefixed with `source` and the volume's JSON pointer ("shot.json: /volume/vdb:
/// ..."). A `sequence` volume throws InputError (use buildSequenceFrame). `stop`, when given,
/// is polled while a mesh or a Perlin cloud is evaluated: true throws Cancelled.
DensityFieldPtr buildVolume(const VolumeSpec& volume, const std::string& source = "shot.json",
                            const std::function<bool()>& stop = {});

/// Frame `frame` (0-based, < frames) of a sequence: that frame's VDB grid, or the procedural cloud
/// at time procedural.time + frame * time_step. Throws InputError for an out-of-range frame.
DensityFieldPtr buildSequenceFrame(const SequenceVolumeSpec& sequence, int frame,
                                   const std::string& source = "shot.json");

/// A volume builder's message `what` as a shot error under the volume's `pointer`: "<pointer>:
/// <what>", or, where `what` names the key it refuses as "<key_prefix><key>: " ("perlin_cloud.
/// cover: ...", "cloud.ply: mesh.voxel_size: ..."), "<pointer>/<key>: " and the message without
/// that part (dots in the key become slashes: mesh.noise.frequency).
std::string volumeErrorAt(const std::string& pointer, const std::string& what,
                          const std::string& key_prefix);

/// Builds a phase function from its description (e.g. through a server's cache).
using PhaseBuilder = std::function<std::shared_ptr<const PhaseFunction>(const PhaseSpec&)>;

/// Optical depth across a volume (extinction x largest density x bounding-box diagonal) beyond
/// which trackers stall: an exponential step from a distance t is then below the precision of t
/// (about 4.5e15 optical depths across; a 16^3 VDB of density 1e38 hung a job). 1e12 is the
/// densest shot the parser's bounds allow (density and extinction 1e6 over a unit), and it tracks.
constexpr double kMaxTrackableOpticalDepth = 1e14;

/// InputError naming /medium/extinction when the shot's volume is beyond
/// kMaxTrackableOpticalDepth; buildScene calls it for every method.
void checkTrackableOpticalDepth(const ShotSpec& shot, const DensityField& density,
                                const std::string& source,
                                const std::string& volume = "the volume");

/// Medium (density, extinction, albedo, phase function), sun, sky and cameras of a shot.
/// Throws InputError (with `source` and the JSON pointer) when a part cannot be built. The phase
/// function comes from `phase` when given, else makePhaseFunction.
Scene buildScene(const ShotSpec& shot, const std::string& source = "shot.json",
                 const PhaseBuilder& phase = {});

}  // namespace cloudbake
