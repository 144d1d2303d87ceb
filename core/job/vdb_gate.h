// User VDB files decoded in a child process (issue 15, fuzzing): OpenVDB 10.0 can be led past
// its buffers by a corrupt blosc block (core/volume/vdb_transcode.h), so a server has a child
// rewrite each user file with `reader` and reads only the rewrite. A crash, a limit or a
// timeout then ends the child, not the server, and the job fails as bad input naming the file.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/error.h"

namespace cloudbake {

/// How a run reads user VDB files (RunOptions::vdb_reader).
struct VdbReaderOptions {
  /// The command that rewrites IN to OUT when given the two paths after it (the server's own
  /// executable with --transcode-vdb, or `cloudbake transcode-vdb`); empty: read in-process.
  std::vector<std::string> command;
  double timeout_seconds = 600;  ///< then the child is killed and the file refused
};

/// Runs `options.command` IN OUT and waits for it, polling `keep_going` (false: the child is
/// killed and Cancelled thrown) about every 0.1 s. InputError naming `in` when the child fails:
/// its own message when it exits 2 (bad input), otherwise that the VDB reader crashed or ran
/// out of time on the file; StorageFullError when it exits 4 (the rewrite's volume is full);
/// InternalError when the command cannot be started.
void rewriteVdbInChild(const VdbReaderOptions& options, const std::string& in,
                       const std::string& out, const std::function<bool()>& keep_going);

/// Runs `read` (which reads the rewrite `rewrite` of the user's file `path`) with InputError
/// messages naming `path` instead of the rewrite, which the user never saw.
template <class Read>
auto readRewrite(const std::string& path, const std::string& rewrite, Read&& read) {
  try {
    return read();
  } catch (const InputError& e) {
    std::string message = e.what();
    for (size_t at; (at = message.find(rewrite)) != std::string::npos;) {
      message.replace(at, rewrite.size(), path);
    }
    throw InputError(message);
  }
}

}  // namespace cloudbake
