// SIGINT and SIGTERM as a cancel for the commands that run a shot (`render`, `farm run-task`):
// the first asks the run to stop, so its progress callback returns false, runShot throws
// Cancelled within about a second and leaves none of the run's outputs, and the command exits
// with 6 (cancelled). A second signal ends the process at once, as the signal's default does,
// unless it comes within 1 s of the first (the same stop sent twice: `timeout`, a scheduler). A
// signal the parent process set to be ignored (nohup, a shell's background job) stays ignored.
// Without this, Ctrl-C killed the process where it stood and could leave a view's temporary
// file beside the finished ones (an outside probe).
#pragma once

namespace cloudbake::tool {

/// Installs the handlers; call once, as the process starts (main, for `render` and `run-task`).
void installInterruptHandler();

/// True once SIGINT or SIGTERM has arrived.
bool interrupted();

/// The first of them that arrived (SIGINT or SIGTERM), 0 before either.
int interruptSignal();

}  // namespace cloudbake::tool
