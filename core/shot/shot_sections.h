// Internal to core/shot: the per-section readers of the shot parser and the limits they share.
#pragma once

#include <cstdint>

#include "core/shot/json_reader.h"
#include "core/shot/shot.h"

namespace cloudbake::shotjson {

// Limits that keep one shot from exhausting the machine (docs/shot-format.md lists them).
constexpr double kMaxDensity = 1e6;  // density and extinction upper bound
// Their lower bound other than 0: the grids hold densities as floats, whose normal numbers end
// near 1e-38, and a denormal extinction made a bake's ratios of tiny numbers overflow.
constexpr double kMinDensity = 1e-30;
constexpr int64_t kMaxMeshResolution = 1022;  // as meshToVolume (core/volume/mesh_volume.cpp)
constexpr int64_t kMaxFrames = 100000;

/// A density or an extinction: 0 (unless `open_lo`) or within [kMinDensity, kMaxDensity].
double densityNumber(const Reader& r, const Json& v, const std::string& ptr, bool open_lo);

/// `volume`: exactly one source, validated (files resolved and checked by the Reader's policy).
VolumeSpec parseVolume(const Object& o);

}  // namespace cloudbake::shotjson
