// The precomputed database on disk: what the bake cache stores for method `precomputed`, one
// file per basic volume (its density, optical-depth SH and cuts) and one for what they share
// (lattices, sample tree, SHEXP tables).
#pragma once

#include <string>

#include "core/animation/precomputed.h"

namespace cloudbake {

/// Version of the file layout, in the files' headers and in the cache key of a precompute (so a
/// new layout never meets an entry written by an older one).
constexpr int kPrecomputedFileVersion = 2;

/// Writes `db` into folder `dir` (created if missing) as shared.bin and basic_<i>.bin
/// (little-endian binary, versioned header). Throws std::runtime_error on I/O failure.
void writePrecomputedDatabase(const std::string& dir, const PrecomputedDatabase& db);

/// Reads a database written by writePrecomputedDatabase. InputError naming the file for a
/// missing or truncated file, a wrong header or sizes that do not fit together.
PrecomputedDatabase readPrecomputedDatabase(const std::string& dir);

}  // namespace cloudbake
