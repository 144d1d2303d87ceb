// Small filesystem helpers for durable state: atomic replace, whole-file reads.
#pragma once

#include <string>

namespace cloudbake {

/// Writes `data` to PATH.tmp.<unique>, fsyncs it and renames it over `path`, so a reader (or a
/// restart after a crash) sees either the old or the new content, never a partial file. Throws
/// std::runtime_error naming the path on failure (the temporary file is removed).
void writeFileAtomic(const std::string& path, const std::string& data);

/// Whole file as bytes. Throws InputError naming `path` when it cannot be read.
/// A regular file's bytes, at most `max_bytes` of them: MissingFileError where it does not exist,
/// InputError naming it where it is not a regular file (a FIFO would block, /dev/zero never
/// end) or is larger, checked before anything is read.
std::string readRegularFile(const std::string& path, uint64_t max_bytes);
std::string readWholeFile(const std::string& path);

/// Creates folder `dir` (and its parents) and checks that a file can be made in it, so a run
/// refuses a folder it could not write before its work, not after. InputError "<what>: cannot
/// create folder ..." or "<what>: cannot write in folder ...", with the system's reason.
void makeWritableFolder(const std::string& dir, const std::string& what);

/// A name unique within this process and very likely across processes (pid, time, counter):
/// used for temporary files and folders next to their final location.
std::string uniqueSuffix();

/// Links `from` to `to` (a hard link: no copy, same inode), copying when the link fails (other
/// file system). Creates `to`'s parent folders. Throws std::runtime_error on failure.
void linkOrCopy(const std::string& from, const std::string& to);

}  // namespace cloudbake
