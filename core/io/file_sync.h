// Durable, checked file writes shared by the format writers (EXR, PNG, VDB).
#pragma once

#include <string>

namespace cloudbake {

/// fsync(path): its data is on disk before it is renamed into place and reported. Throws
/// StorageFullError when the volume is full, std::runtime_error for another failure.
void syncFile(const std::string& path);

}  // namespace cloudbake
