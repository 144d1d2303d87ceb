// A pre-check of a .vdb file's header before OpenVDB reads it (issue 15, fuzzing): OpenVDB
// allocates every string and metadata value at the size the file declares before reading it, so
// a corrupt length made it ask for gigabytes (1.7 GB seen from a 300-byte input). Plain byte
// parsing, no OpenVDB.
#pragma once

#include <string>

namespace cloudbake {

/// Walks the header, the file metadata and the first grid descriptor of the OpenVDB file `path`
/// (the layout of openvdb::io::Archive, file format versions 211 and later) and throws
/// InputError naming the path when a declared length or count is more than the file holds.
/// Says nothing about the grids' data: OpenVDB's own checks and our throwing stream cover that.
void checkVdbHeader(const std::string& path);

}  // namespace cloudbake
