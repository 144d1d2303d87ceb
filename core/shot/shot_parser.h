// Reads and writes shot files (format v1, docs/shot-format.md) with full validation.
#pragma once

#include <string>
#include <vector>

#include "core/error.h"
#include "core/shot/shot.h"

namespace cloudbake {

struct ParseOptions {
  /// When non-empty, every file a shot names (vdb, mesh, sky map, sequence frames) must lie
  /// inside one of these folders after resolving symlinks and "..". Empty: any path.
  std::vector<std::string> allowed_roots;
  /// Prefix of error messages ("shot.json: /medium/albedo: ..."). parseShotFile sets it to the
  /// path it was given.
  std::string source_name = "shot.json";
  /// Check that named files exist and are regular files (MissingFileError otherwise). The
  /// service turns this off only to re-read canonical shots of assets it already holds.
  bool check_files_exist = true;
};

/// Parses shot JSON text. Relative paths resolve against `base_dir` (empty: the current
/// folder). Throws InputError "<source_name>: <json pointer>: <message>" on any invalid input
/// (malformed JSON, unknown or duplicate keys, wrong types, out-of-range values, paths outside
/// the allowed roots) and MissingFileError for referenced files that do not exist.
ShotSpec parseShot(const std::string& json_text, const std::string& base_dir,
                   const ParseOptions& options = {});

/// Reads and parses a shot file; relative paths resolve against the file's folder. Throws
/// MissingFileError when the file does not exist, InputError when it cannot be read or parsed.
ShotSpec parseShotFile(const std::string& path, ParseOptions options = {});

/// Which parts of a shot serializeShot writes (all by default).
struct SerializeOptions {
  bool name = true;
  bool views = true;
  bool outputs = true;
};

/// Canonical JSON text of a shot: every key present (defaults filled in), keys sorted, paths
/// absolute, the sun direction normalised, no whitespace, doubles in shortest round-trip form.
/// Two shots that parse to the same ShotSpec serialise to the same bytes, so the text can be
/// hashed as a cache key; parseShot(serializeShot(s), "") gives back `s`.
std::string serializeShot(const ShotSpec& shot, const SerializeOptions& options = {});

/// The top-level keys a shot may have (for docs and schema consistency checks).
std::vector<std::string> shotTopLevelKeys();

}  // namespace cloudbake
