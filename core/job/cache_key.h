// Cache keys of a shot's computed parts (docs/DESIGN.md, "Cache").
#pragma once

#include <string>
#include <vector>

#include "core/methods/method.h"
#include "core/methods/run_types.h"
#include "core/shot/shot.h"

namespace cloudbake {

/// Step of the sun-direction quantisation: each component of the unit direction is rounded to
/// a multiple of it before hashing, so directions that differ only by float noise share a bake.
constexpr double kSunDirectionQuantum = 1e-6;

/// Keys of a validated shot (files it names must exist: they are hashed, with an in-memory
/// memo keyed by path, size and modification time). Throws InputError when a file cannot be
/// read.
ShotCacheKeys computeCacheKeys(const ShotSpec& shot);

/// The keys of the light bake, and of view `view`'s render, had the shot's sun come from
/// `direction` (light-direction tolerance reuse), without recomputing the other keys.
std::string lightKeyAt(const ShotCacheKeys& keys, const Vec3& direction);
std::string viewKeyAt(const ShotCacheKeys& keys, size_t view, const Vec3& direction);

/// "pointcloud/2 volume/2 phase/2 transport/2 ...": the method's algorithm version and those of the
/// shared pieces it uses, salted into every key of what it computes.
std::string algorithmSalt(const MethodInfo& info);

/// Rounds each component of `direction` (normalised first) to kSunDirectionQuantum.
Vec3 quantiseDirection(const Vec3& direction);

}  // namespace cloudbake
