// Where a shot (format v1) names files: the JSON pointers of the properties that
// docs/shot.schema.json types as "#/$defs/path". Clients upload exactly these files before a
// submit; tests/server/shot_paths_test.cpp keeps the list equal to the schema's.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace cloudbake::client {

/// JSON pointers, "*" standing for every element of an array. The Python client's copy is
/// client/python/cloudbake_shot_paths.py (checked against the schema too).
inline constexpr const char* kShotPathPointers[] = {
    "/volume/vdb/path",
    "/volume/mesh/path",
    "/volume/sequence/paths/*",
    "/lighting/sky/map",
};

/// One file a shot names: where (a concrete JSON pointer, e.g. "/volume/sequence/paths/1") and
/// its value.
struct ShotPath {
  std::string pointer;
  nlohmann::json* node;
};

/// The string values of `shot` at kShotPathPointers with their pointers, in that order.
std::vector<ShotPath> shotPaths(nlohmann::json& shot);

/// The string values of `shot` at kShotPathPointers, in that order (array elements in theirs),
/// so callers can read and rewrite them. Absent keys and values of other types are skipped: the
/// server, not the client, reports what is malformed.
std::vector<nlohmann::json*> shotPathNodes(nlohmann::json& shot);

}  // namespace cloudbake::client
