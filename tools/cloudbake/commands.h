// Subcommands of the `cloudbake` tool. Each adds itself to the app and returns its exit code
// through the shared result slot when it runs.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

// Exit codes (kOk, kBadInput, ...) shared with cloudctl and the server.
#include "common/exit_codes.h"

namespace cloudbake::tool {

/// `cloudbake mie`: Lorenz-Mie efficiencies of one sphere (cmd_mie.cpp).
void addMieCommand(CLI::App& app, int* exit_code);
/// `cloudbake phase`: tabulate/plot a phase function (cmd_phase.cpp).
void addPhaseCommand(CLI::App& app, int* exit_code);
/// `cloudbake compare`: a view against a reference view, per layer (cmd_compare.cpp).
void addCompareCommand(CLI::App& app, int* exit_code);
/// `cloudbake bake-slice`: a colour-mapped slice of a bake's grid (cmd_bake_slice.cpp).
void addBakeSliceCommand(CLI::App& app, int* exit_code);
/// `cloudbake methods`: the registry's methods, knobs and generated docs (cmd_methods.cpp).
void addMethodsCommand(CLI::App& app, int* exit_code);
/// `cloudbake preview`: an sRGB PNG of an EXR's layer (cmd_preview.cpp).
void addPreviewCommand(CLI::App& app, int* exit_code);
/// `cloudbake plan` and `cloudbake run-task`: a shot as farm tasks (cmd_farm.cpp).
void addFarmCommands(CLI::App& app, int* exit_code);
/// `cloudbake transcode-vdb`: a VDB file read and written again (cmd_transcode.cpp).
void addTranscodeCommand(CLI::App& app, int* exit_code);
/// The command a run gives users' VDB files to, decoded in a child process (core/job/
/// vdb_gate.h): this executable's `transcode-vdb` (cmd_transcode.cpp), so that a corrupt file
/// fails the run as bad input instead of crashing it, as in the server.
std::vector<std::string> vdbReaderCommand();
/// `cloudbake render`: render a shot's views with the path tracer (cmd_render.cpp).
void addRenderCommand(CLI::App& app, int* exit_code);

}  // namespace cloudbake::tool
