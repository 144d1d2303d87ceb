// Rewrites a user's .vdb file into one written by cloudbake itself (issue 15, fuzzing): OpenVDB
// 10.0 decodes a corrupt blosc block past its buffers (io::bloscFromStream; a crafted 60 kB file
// aborts the process in free()), which no check before the read can rule out. A server therefore
// decodes user files only in a child process that runs transcodeVdb, and reads the rewrite.
#pragma once

#include <string>

namespace cloudbake {

/// Reads every grid and the file metadata of the OpenVDB file `in` (the header pre-check and the
/// stream that throws on short reads, as loadVdbVolume) and writes them to `out` uncompressed
/// but for OpenVDB's active-voxel masks (no blosc, no zip: no block sizes for a reader to trust),
/// through `out`.tmp and a rename; every write is checked. InputError naming `in` when it cannot be
/// read, or `out` when it cannot be written.
void transcodeVdb(const std::string& in, const std::string& out);

}  // namespace cloudbake
