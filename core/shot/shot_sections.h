// Internal to core/shot: the per-section readers of the shot parser and the limits they share.
#pragma once

#include <cstdint>

#include "core/shot/json_reader.h"
#include "core/shot/shot.h"

namespace cloudbake::shotjson {

// Limits that keep one shot from exhausting the machine (docs/shot-format.md lists them).
constexpr double kMaxDensity = 1e6;           // density and extinction upper bound
constexpr int64_t kMaxMeshResolution = 1022;  // as meshToVolume (core/volume/mesh_volume.cpp)
constexpr int64_t kMaxFrames = 100000;

/// `volume`: exactly one source, validated (files resolved and checked by the Reader's policy).
VolumeSpec parseVolume(const Object& o);

}  // namespace cloudbake::shotjson
