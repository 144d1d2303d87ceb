// Durable, checked file writes shared by the format writers (EXR, PNG, VDB).
#pragma once

#include <string>

namespace cloudbake {

/// fsync(path): its data is on disk before it is renamed into place and reported. Throws
/// StorageFullError when the volume is full, std::runtime_error for another failure.
void syncFile(const std::string& path);

/// A temporary name beside `path`, unique across processes and threads (several farm tasks
/// may write one output at once): PATH.tmp.<pid>.<n>.
std::string temporaryNameFor(const std::string& path);

/// Writes `text` to a temporary file, syncs it and renames it over `path`. Errors as syncFile.
void writeTextAtomically(const std::string& path, const std::string& text);

}  // namespace cloudbake
