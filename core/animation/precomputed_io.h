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

/// A database in parts, for farm tasks (core/job/task_plan.h): the layout (layoutBasicVolumes:
/// layout.bin and each basic volume's lattice density, density_<i>.bin) and groups of
/// precomputed basic volumes (basic_<i>.bin, as in a whole database). Errors as above; ranges
/// are half-open and must lie within the database (InternalError otherwise).
void writePrecomputedLayout(const std::string& dir, const PrecomputedDatabase& db);
/// The layout, its basic volumes' densities left empty (one per basic volume).
PrecomputedDatabase readPrecomputedLayout(const std::string& dir);
/// Reads the densities of basic volumes [begin, end) of a layout into `db`.
void readLayoutDensities(const std::string& dir, PrecomputedDatabase& db, size_t begin, size_t end);
void writeBasicVolumes(const std::string& dir, const PrecomputedDatabase& db, size_t begin,
                       size_t end);
/// Reads basic volumes [begin, end) (their densities and precomputes) into a laid-out `db`.
void readBasicVolumes(const std::string& dir, PrecomputedDatabase& db, size_t begin, size_t end);

}  // namespace cloudbake
