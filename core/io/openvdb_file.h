// Internal: the OpenVDB file I/O that cloudbake's VDB writers and readers share (core/io's
// vdb_io.cpp, core/bake's baked_light_vdb.cpp). Include only from .cpp files: it pulls in the
// OpenVDB headers that the public headers keep out.
#pragma once

#include <openvdb/openvdb.h>

#include <map>
#include <string>

namespace cloudbake {

/// openvdb::initialize(), once per process (thread-safe).
void initOpenVdb();

/// Writes `grids` with file metadata `meta` to PATH.tmp and renames it over `path`, so readers
/// never see a partial file; PATH.tmp is removed on failure. InputError naming the path.
void writeVdbFileAtomically(const std::string& path, const openvdb::GridPtrVec& grids,
                            const openvdb::MetaMap& meta);

/// A whole .vdb file in memory, with its string-valued file metadata.
struct VdbFileContents {
  openvdb::GridPtrVec grids;
  std::map<std::string, std::string> metadata;
};

/// Reads every grid of `path` through a stream that throws on short reads (openvdb::io::File
/// loads truncated files silently). InputError naming the path: "<path>: VDB file not found",
/// "<path>: not a readable OpenVDB file (...)".
VdbFileContents readVdbFileChecked(const std::string& path);

/// The string-valued entries of a metadata map (file or grid).
std::map<std::string, std::string> stringMetadata(const openvdb::MetaMap& meta);

}  // namespace cloudbake
